"""Reading a pickle without running its code: an allow-list unpickler with bounded nesting and memory.

A pickle can call any importable function while it loads, so `read_pickle` reads it with a `SafeUnpickler`, which
resolves globals only from the allow-list it is given: a dict {(module, name): value} keyed by the exact names
written in the file. A value is a `Guard` (a callable that checks the arguments a REDUCE gives it before calling
the real constructor), a `token` (a global that may only appear as an argument) or a `StandIn` class (it only
records its pickled state); any other global raises `Refused` at the moment it is looked up, before it can be
called. `BASE_GLOBALS` allows what numpy arrays, dtypes and scalars, sets, bytes and new-style objects pickle to; a
format's loader adds its own stand-ins. Before unpickling, `read_pickle` checks the memory budget and refuses
objects nested deeper than `MAX_PICKLE_DEPTH` (found from the opcodes alone, `pickle_depth`).
"""

from __future__ import annotations

import hashlib
import io
import pickle
import pickletools
from pathlib import Path

import numpy as np

from darthand.budget import check_memory
from darthand.errors import InputError, UnsafePickleError
from darthand.fileio import read_bytes


class Refused(Exception):
    """Raised inside the unpickler when a global or a call is not allowed; `read_pickle` adds the file name."""


# --------------------------------------------------------------------------------------------------------------------
# Guards: what the unpickler gets instead of an allowed global.


class Guard:
    """A callable standing in for an allowed global: it checks the arguments a REDUCE gives it, then builds the value.

    `build(*args)` returns the value, or `REFUSE` when the arguments are not the expected ones. A guard has no
    __dict__ and refuses BUILD, so a pickle cannot change it; being shared between loads is safe.
    """

    __slots__ = ("qualname", "_build")

    def __init__(self, qualname: str, build):
        self.qualname = qualname
        self._build = build

    def __call__(self, *args):
        value = self._build(*args)
        if value is REFUSE:
            kinds = ", ".join(a.qualname if isinstance(a, Guard) else type(a).__name__ for a in args)
            raise Refused(f"refused call {self.qualname}({kinds}): not a constructor call this loader expects")
        return value

    def __setstate__(self, state):
        raise Refused(f"refused BUILD on {self.qualname}")

    def __repr__(self):
        return f"<allowed {self.qualname}>"


REFUSE = object()  # returned by a guard's builder when the arguments are not the expected ones


def token(qualname: str) -> Guard:
    """A global that may only appear as an argument (numpy.ndarray, builtins.object): calling it is refused."""
    return Guard(qualname, lambda *args: REFUSE)


_NDARRAY = token("numpy.ndarray")
_OBJECT = token("builtins.object")

# The real numpy functions, taken from what numpy itself pickles (their module moved from numpy.core to
# numpy._core in numpy 2; asking the objects avoids importing either path).
_NP_RECONSTRUCT = np.ndarray.__reduce__(np.empty(0))[0]
_NP_SCALAR = np.float64(0).__reduce__()[0]
_NP_FROMBUFFER = np.zeros(1).__reduce_ex__(5)[0]


def _is_shape(shape) -> bool:
    return isinstance(shape, tuple) and all(isinstance(n, int) and n >= 0 for n in shape)


def _latin1_bytes(data):
    """Python 2 `str` payloads arrive as latin-1 decoded text; numpy wants the original bytes."""
    return data.encode("latin1") if isinstance(data, str) else data


def _build_reconstruct(subtype=None, shape=None, typecode=None, *extra):
    # numpy pickles every ndarray as _reconstruct(ndarray, (0,), b'b') followed by BUILD(state).
    if extra or subtype is not _NDARRAY or not _is_shape(shape) or _latin1_bytes(typecode) != b"b":
        return REFUSE
    return _NP_RECONSTRUCT(np.ndarray, shape, b"b")


def _build_dtype(spec=None, align=False, copy=True, *extra):
    if extra or not isinstance(spec, (str, bytes)) or not isinstance(align, (bool, int)):
        return REFUSE
    spec = spec.decode("latin1") if isinstance(spec, bytes) else spec
    # Always a copy: BUILD then sets the state on it, never on numpy's shared builtin dtype.
    return np.dtype(spec, align=bool(align), copy=True)


def _build_scalar(dtype=None, data=None, *extra):
    if extra or not isinstance(dtype, np.dtype) or dtype.hasobject or not isinstance(data, (str, bytes)):
        return REFUSE
    return _NP_SCALAR(dtype, _latin1_bytes(data))


def _build_frombuffer(buf=None, dtype=None, shape=None, order="C", *extra):
    # numpy >= 1.16 with pickle protocol 5: _frombuffer(buffer, dtype, shape, order).
    if (extra or not isinstance(buf, (bytes, bytearray, memoryview, pickle.PickleBuffer))
            or not isinstance(dtype, np.dtype) or dtype.hasobject or not _is_shape(shape) or order not in ("C", "F")):
        return REFUSE
    return _NP_FROMBUFFER(buf, dtype, shape, order)


def _build_set(items=(), *extra):
    if extra or not isinstance(items, (list, tuple)):
        return REFUSE
    return set(items)


def _build_empty_bytes(*args):
    # Python 3 pickles b'' at protocol < 3 as bytes().
    return b"" if not args else REFUSE


def _build_codecs_encode(text=None, encoding=None, *extra):
    # Python 3 pickles non-empty bytes at protocol < 3 as _codecs.encode(text, 'latin1').
    if extra or not isinstance(text, str) or encoding not in ("latin1", "latin-1"):
        return REFUSE
    return text.encode("latin1")


def _build_reconstructor(cls=None, base=None, state=None, *extra):
    # Protocol 0/1 pickles a new-style object as copy_reg._reconstructor(cls, object, None) followed by BUILD.
    if extra or not _is_stand_in_class(cls) or base is not _OBJECT or state is not None:
        return REFUSE
    return cls.__new__(cls)


def _build_newobj(cls=None, *args):
    if args or not _is_stand_in_class(cls):
        return REFUSE
    return cls.__new__(cls)


# --------------------------------------------------------------------------------------------------------------------
# Stand-ins: classes that record their pickled state and nothing else.


class StandIn:
    """Base of the stand-in classes. NEWOBJ creates one empty; BUILD records the pickled state dict.

    A concrete stand-in sets its own `qualname` (the class it replaces); a base without one cannot be built.
    """

    __slots__ = ("state",)
    qualname = "?"

    def __new__(cls, *args, **kwargs):
        if args or kwargs:
            raise Refused(f"refused call {cls.qualname} with arguments")
        obj = object.__new__(cls)
        obj.state = {}
        return obj

    def __init__(self, *args, **kwargs):
        # Only reached when a pickle calls the class directly (REDUCE/INST); NEWOBJ does not call __init__.
        raise Refused(f"refused call {self.qualname}(...): only NEWOBJ/copy_reg reconstruction is expected")

    def __setstate__(self, state):
        if isinstance(state, tuple) and len(state) == 2:  # (dict state, slot state)
            state = {**(state[0] or {}), **(state[1] or {})}
        if not isinstance(state, dict):
            raise ValueError(f"{self.qualname} state is a {type(state).__name__}, expected a dict")
        self.state = {k.decode("latin1") if isinstance(k, bytes) else k: v for k, v in state.items()}

    def term(self, key: str):
        if key not in self.state:
            raise ValueError(f"{self.qualname} has no '{key}'")
        return self.state[key]


def _is_stand_in_class(cls) -> bool:
    return isinstance(cls, type) and issubclass(cls, StandIn) and "qualname" in vars(cls)


# --------------------------------------------------------------------------------------------------------------------
# The allow-list and the unpickler.

_set = Guard("builtins.set", _build_set)
_bytes = Guard("builtins.bytes", _build_empty_bytes)
_reconstructor = Guard("copyreg._reconstructor", _build_reconstructor)
_newobj = Guard("copyreg.__newobj__", _build_newobj)

#: The globals numpy arrays and plain Python values pickle to, by the exact (module, name) written in the file.
#: Python 2 names (__builtin__, copy_reg) are listed as such: the unpickler's own Python 2 renaming is bypassed.
BASE_GLOBALS = {
    ("numpy.core.multiarray", "_reconstruct"): Guard("numpy.core.multiarray._reconstruct", _build_reconstruct),
    ("numpy._core.multiarray", "_reconstruct"): Guard("numpy._core.multiarray._reconstruct", _build_reconstruct),
    ("numpy.core.multiarray", "scalar"): Guard("numpy.core.multiarray.scalar", _build_scalar),
    ("numpy._core.multiarray", "scalar"): Guard("numpy._core.multiarray.scalar", _build_scalar),
    ("numpy.core.numeric", "_frombuffer"): Guard("numpy.core.numeric._frombuffer", _build_frombuffer),
    ("numpy._core.numeric", "_frombuffer"): Guard("numpy._core.numeric._frombuffer", _build_frombuffer),
    ("numpy", "ndarray"): _NDARRAY,
    ("numpy", "dtype"): Guard("numpy.dtype", _build_dtype),
    ("__builtin__", "set"): _set,
    ("builtins", "set"): _set,
    ("__builtin__", "bytes"): _bytes,
    ("builtins", "bytes"): _bytes,
    ("__builtin__", "object"): _OBJECT,
    ("builtins", "object"): _OBJECT,
    ("copy_reg", "_reconstructor"): _reconstructor,
    ("copyreg", "_reconstructor"): _reconstructor,
    ("copy_reg", "__newobj__"): _newobj,
    ("copyreg", "__newobj__"): _newobj,
    ("_codecs", "encode"): Guard("_codecs.encode", _build_codecs_encode),
}


def printable(text: str, limit: int = 120) -> str:
    """A name from an untrusted file, made safe for a one-line message."""
    return str(text).encode("unicode_escape").decode("ascii")[:limit]


def first_line(e: BaseException) -> str:
    """The first line of an exception's message (at most 200 characters), for a one-line error."""
    return (str(e).splitlines() or [type(e).__name__])[0][:200]


class SafeUnpickler(pickle.Unpickler):
    """An Unpickler that resolves only the globals of `allowed`; any other global raises before anything is called.

    Reads with ``encoding='latin1'`` (Python 2 `str` payloads are bytes). Raises `Refused`; `read_pickle` turns that
    into an `UnsafePickleError` naming the file. `kind` names the format in messages ("MANO pickle").
    """

    def __init__(self, file, allowed: dict, kind: str = "pickle"):
        super().__init__(file, encoding="latin1")
        self.allowed = allowed
        self.kind = kind

    def find_class(self, module, name):
        try:
            return self.allowed[(module, name)]
        except (KeyError, TypeError):
            raise Refused(f"refused global '{printable(module)}.{printable(name)}' "
                          f"(not on the {self.kind} allow-list)") from None

    def persistent_load(self, pid):
        raise Refused(f"refused persistent id (not used by {self.kind}s)")


def read_pickle(path: str | Path, allowed: dict, kind: str = "pickle") -> tuple[object, str]:
    """Safely unpickle the file at `path` with the globals of `allowed`; return (the object, sha256 hex of the bytes).

    Raises UnsafePickleError for a refused global or call, InputError for a missing, unreadable or corrupt file or
    one nested deeper than `MAX_PICKLE_DEPTH`. `kind` names the format in messages.
    """
    path = Path(path)
    data = read_bytes(path, "file")
    check_memory(f"unpickling {path}", 4 * len(data))
    try:
        depth = pickle_depth(data, MAX_PICKLE_DEPTH)
    except Exception as e:  # noqa: BLE001 - pickletools parsing untrusted bytes: any failure is a corrupt file
        raise InputError(f"{path}: not a readable pickle, truncated or corrupt ({first_line(e)})") from None
    if depth > MAX_PICKLE_DEPTH:
        raise InputError(f"{path}: not a {kind}: its objects nest more than {MAX_PICKLE_DEPTH} levels deep; "
                         "nothing in the file was executed")
    try:
        obj = SafeUnpickler(io.BytesIO(data), allowed, kind).load()
    except Refused as e:
        raise UnsafePickleError(f"{path}: {e}; nothing in the file was executed") from None
    except (EOFError, pickle.UnpicklingError) as e:
        raise InputError(f"{path}: not a readable pickle, truncated or corrupt ({first_line(e)})") from None
    except Exception as e:  # noqa: BLE001 - anything an untrusted byte stream provokes is bad input, not a bug
        raise InputError(f"{path}: not a readable {kind} ({type(e).__name__}: {first_line(e)})") from None
    return obj, hashlib.sha256(data).hexdigest()


# Objects may nest this deep (a MANO pickle nests about 6: dict, Ch, state dict, ndarray, state tuple, shape).
MAX_PICKLE_DEPTH = 100
# Opcodes that add to an object already on the stack (the object stays, one level above what it receives).
_IN_PLACE = {"APPEND", "APPENDS", "SETITEM", "SETITEMS", "ADDITEMS", "BUILD"}
_MEMO_PUT = {"PUT", "BINPUT", "LONG_BINPUT", "MEMOIZE"}
_MEMO_GET = {"GET", "BINGET", "LONG_BINGET"}


def pickle_depth(data: bytes, limit: int | None = None) -> int:
    """How deeply the objects a pickle builds nest, from its opcodes alone (nothing is built or called).

    Hashing or comparing a tuple nested a million deep recurses in C and overflows the stack, so such a file must
    be refused before it is unpickled. Each stack entry carries the depth of the object it stands for; an opcode
    that builds a container from entries pushes one more than the deepest of them. Stops as soon as the depth
    passes `limit`. ValueError for bytes that are not a pickle (pickletools' own checks).
    """
    mark = object()
    stack: list = []
    memo: dict = {}
    deepest = 0
    for op, arg, _ in pickletools.genops(data):
        name = op.name
        if name == "MARK":
            stack.append(mark)
            continue
        if name in _MEMO_PUT:
            memo[len(memo) if name == "MEMOIZE" else arg] = stack[-1] if stack else 0
            continue
        if name in _MEMO_GET:
            stack.append(memo.get(arg, 0))
            continue
        if name in ("STOP", "PROTO", "FRAME"):
            continue
        if name == "POP":
            if stack:
                stack.pop()
            continue
        if name == "DUP":
            stack.append(stack[-1] if stack else 0)
            continue
        taken = []
        before = op.stack_before
        if pickletools.markobject in before:
            while stack and stack[-1] is not mark:
                taken.append(stack.pop())
            if stack:
                stack.pop()
            below = before.index(pickletools.markobject)
        else:
            below = len(before)
        for _ in range(below):
            if stack and stack[-1] is not mark:
                taken.append(stack.pop())
        if name in _IN_PLACE and taken:           # the container (popped last: lowest on the stack) stays
            depth = max(taken[-1], 1 + max(taken[:-1], default=-1))
            stack.append(depth)
        else:
            depth = 1 + max(taken, default=-1)
            stack += [depth] * len(op.stack_after)
        deepest = max(deepest, depth)
        if limit is not None and deepest > limit:
            break
    return deepest
