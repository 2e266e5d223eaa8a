"""Files: atomic writing (a temporary file in the target folder, then a rename) and careful reading of untrusted
ones (regular files only, sizes and JSON nesting checked before parsing).

An interrupted build never leaves a half-written file that a later run would trust; its temporaries carry the
writing process's id, so the next run can remove those of processes that died (`remove_stale_temporaries`). A FIFO,
device or folder given where a file is expected is refused without being opened for reading (it could block
forever or never end).
"""

from __future__ import annotations

import contextlib
import hashlib
import itertools
import json
import math
import os
import re
import shutil
import stat
import tempfile
from pathlib import Path
from typing import Iterator

from darthand.budget import check_memory
from darthand.errors import InputError

MAX_JSON_DEPTH = 64            # darthand's deepest contract nests about 6 levels
MAX_JSON_INT_DIGITS = 40       # 2**128 has 39 digits: seeds fit, integers of hundreds of digits do not
JSON_BYTES_PER_FILE_BYTE = 16  # parsed JSON takes up to this many bytes of memory per byte of text


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path next to `path`; on success rename it over `path`, on failure remove it.

    `suffix` defaults to the target's own suffix so that writers that pick a format by extension still work.
    """
    path = Path(path)
    make_folder(path.parent)
    try:
        fd, tmp = tempfile.mkstemp(prefix=temporary_prefix(path.name),
                                   suffix=suffix if suffix is not None else path.suffix, dir=path.parent)
    except OSError as e:
        raise _write_error(path, e) from None
    tmp = Path(tmp)
    try:                               # from here on a Ctrl-C (KeyboardInterrupt) removes the temporary too
        os.close(fd)
        yield tmp
        os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp creates 0600; outputs get the usual permissions
        try:
            os.replace(tmp, path)
        except IsADirectoryError:
            raise InputError(f"{path}: cannot write this file: a folder is in the way") from None
        # rename() is a no-op when both names are hard links to one file (re-placing a linked texture).
        tmp.unlink(missing_ok=True)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def _read_umask() -> int:
    """The process umask, read once at import: reading it means setting it, which is not safe while other threads
    create files."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


_UMASK = _read_umask()


def write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write `data` to `path` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def write_json(path: str | os.PathLike, obj, indent: int | None = 2) -> None:
    """Write `obj` as JSON (sorted keys, trailing newline) to `path` atomically. NaN and Infinity are not JSON: a
    document holding them is refused (InputError naming the file and field), never written."""
    try:
        text = json.dumps(obj, indent=indent, sort_keys=True, allow_nan=False)
    except ValueError:
        raise InputError(f"{path}: not written: field '{first_non_finite(obj)}' is not a finite number") from None
    write_bytes(path, (text + "\n").encode())


def first_non_finite(obj) -> str:
    """Path ('a.b.3', as schemas.check_schema names fields) of the first NaN or infinite float in a JSON-like
    document ('' when there is none)."""
    found = _non_finite(obj)
    return found[0] if found else ""


def _non_finite(obj) -> tuple[str, float] | None:
    """(path, value) of the first NaN or infinite float in a JSON-like document, or None."""
    todo = [("", obj)]
    while todo:
        where, x = todo.pop()
        if isinstance(x, float) and not math.isfinite(x):
            return where or "(top level)", x
        if isinstance(x, (dict, list, tuple)):
            items = x.items() if isinstance(x, dict) else enumerate(x)
            todo += [(f"{where}.{field_key(k)}" if where else field_key(k), v) for k, v in reversed(list(items))]
    return None


def field_key(key) -> str:
    """A key or index as it appears in a dotted field name: escaped when it holds a newline or other character
    that would break the one-line error message (a key from a hostile file can be anything)."""
    text = str(key)
    return text if text.isprintable() else ascii(text)[1:-1]


# ------------------------------------------------------------------------------------------------ reading


def regular_file(path: str | os.PathLike, what: str = "file") -> os.stat_result:
    """stat of `path` (symlinks followed), after checking it is a regular file; InputError naming it otherwise.
    Nothing is opened."""
    path = Path(path)
    try:
        st = path.stat()
    except (FileNotFoundError, NotADirectoryError):
        raise InputError(f"{path}: no such {what}") from None
    except OSError as e:
        raise InputError(f"{path}: cannot read it ({e.strerror or type(e).__name__})") from None
    if not stat.S_ISREG(st.st_mode):
        raise InputError(not_regular(path, st.st_mode, what))
    return st


def not_regular(path, mode: int, what: str = "file") -> str:
    return f"{path}: is {file_kind(mode)}, not a regular file" + ("" if what == "file" else f" ({what} expected)")


def file_kind(mode: int) -> str:
    """'a folder', 'a FIFO', 'a device', ... for a stat mode."""
    for test, kind in ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISSOCK, "a socket"), (stat.S_ISREG, "a regular file")):
        if test(mode):
            return kind
    return "not a regular file"


@contextlib.contextmanager
def open_regular(path: str | os.PathLike, what: str = "file", max_bytes: int | None = None):
    """A binary file object for a regular file. Opened without blocking and checked on the open descriptor, so a
    FIFO or device put in its place after a check is refused too; InputError naming the file when it is missing,
    not a regular file, or larger than `max_bytes` (default: the memory budget)."""
    path = Path(path)
    regular_file(path, what)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError as e:
        raise InputError(f"{path}: cannot read it ({e.strerror or type(e).__name__})") from None
    f = os.fdopen(fd, "rb")
    with f:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise InputError(not_regular(path, st.st_mode, what))
        if max_bytes is not None and st.st_size > max_bytes:
            raise InputError(f"{path}: {st.st_size} bytes, above the limit of {max_bytes} for a {what}")
        check_memory(f"reading {path} ({what})", st.st_size)
        yield f


def read_bytes(path: str | os.PathLike, what: str = "file", max_bytes: int | None = None) -> bytes:
    """The bytes of a regular file (see `open_regular`)."""
    with open_regular(path, what, max_bytes) as f:
        return f.read()


def read_npz(path: str | os.PathLike, what: str, required: tuple = ()) -> dict:
    """{name: array} of an .npz file (no pickles); InputError '<path>: unreadable <what> (...)' when it is missing, not
    a regular file or not a readable archive, and '<path>: field '<name>' is missing' for an absent `required` one."""
    # Imported here: every command imports fileio, and numpy stays out of `darthand --help`'s start-up.
    import zipfile

    import numpy as np

    try:
        with open_regular(path, what) as f, np.load(f, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except InputError as e:
        raise InputError(f"{path}: unreadable {what} ({str(e).split(': ', 1)[-1]})") from None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as e:
        raise InputError(f"{path}: unreadable {what} ({e})") from None
    for key in required:
        if key not in arrays:
            raise InputError(f"{path}: field '{key}' is missing")
    return arrays


def read_json(path: str | os.PathLike, what: str = "JSON file", max_bytes: int | None = None):
    """The parsed JSON of `path`; InputError naming the file (and `what` it should be) when it is missing, not a
    regular file, too large for the memory budget, not UTF-8 text or not valid JSON (see `parse_json`)."""
    path = Path(path)
    st = regular_file(path, what)
    check_memory(f"parsing {path} ({what}, {st.st_size} bytes)", st.st_size * JSON_BYTES_PER_FILE_BYTE)
    return parse_json(read_bytes(path, what, max_bytes), path, what)


class _Refused(ValueError):
    """A JSON token the parser hooks refuse."""


def _parse_int(text: str) -> int:
    if len(text.lstrip("-")) > MAX_JSON_INT_DIGITS:
        raise _Refused(f"an integer of {len(text.lstrip('-'))} digits (at most {MAX_JSON_INT_DIGITS} are read)")
    return int(text)




_STRINGS = re.compile(rb'"(?:[^"\\]|\\.)*"')


_NOT_BRACKETS = bytes(b for b in range(256) if b not in b"[]{}")
_PLAIN_PYTHON_BRACKETS = 1 << 16   # up to this many brackets (a build's manifest: ~9,000) no NumPy import (~0.1 s)


def _depth(stripped: bytes) -> int:
    """How deeply the arrays and objects of a JSON text (its strings emptied) nest, without parsing it."""
    brackets = stripped.translate(None, _NOT_BRACKETS)
    if len(brackets) <= _PLAIN_PYTHON_BRACKETS:
        return max(0, max(itertools.accumulate(1 if b in b"[{" else -1 for b in brackets), default=0))
    import numpy as np

    low = np.frombuffer(brackets, np.uint8) & 0xDF           # '{' -> '[', '}' -> ']' (clears the 0x20 bit)
    return int(np.cumsum(np.where(low == 0x5B, 1, -1)).max(initial=0))


# Outside strings, these mark numbers a JSON document must not hold: NaN and Infinity (not JSON), exponents that
# overflow a float64 (1e999), integers of more than MAX_JSON_INT_DIGITS digits. Only a document that has one is
# walked to name the field.
_BIG_EXPONENT = re.compile(rb"[eE][+]?0*(?:[3-9][0-9]{2}|[0-9]{4})")
_LONG_INTEGER = re.compile(rb"[0-9]{%d}" % (MAX_JSON_INT_DIGITS + 1))


def _suspect(stripped: bytes) -> bool:
    return (b"NaN" in stripped or b"Infinity" in stripped or _LONG_INTEGER.search(stripped) is not None
            or ((b"e" in stripped or b"E" in stripped) and _BIG_EXPONENT.search(stripped) is not None))


def parse_json(data: bytes | str, source, what: str = "JSON file", max_depth: int = MAX_JSON_DEPTH):
    """Strict JSON from bytes or text: UTF-8, nested at most `max_depth` deep, no NaN or Infinity, no number too
    large for a float64, no integer of more than MAX_JSON_INT_DIGITS digits. InputError naming `source` (and the
    field) otherwise."""
    raw = data.encode("utf-8", "surrogatepass") if isinstance(data, str) else bytes(data)
    if raw.startswith(b"\xef\xbb\xbf"):
        raw = raw[3:]
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise InputError(f"{source}: not a UTF-8 text file, so not a {what}") from None
    stripped = _STRINGS.sub(b'""', raw)
    depth = _depth(stripped)
    if depth > max_depth:
        raise InputError(f"{source}: not a {what}: its JSON nests {depth} levels deep (at most {max_depth} are read)")
    try:
        if not _suspect(stripped):
            return json.loads(text)
        doc = json.loads(text, parse_int=_parse_int)
        bad = _non_finite(doc)      # NaN, Infinity (not JSON) or a number beyond float64 (1e999): named by field
        if bad:
            raise InputError(f"{source}: field '{bad[0]}' is {bad[1]}, not a finite number (JSON has no NaN or "
                             "Infinity)")
        return doc
    except _Refused as e:
        raise InputError(f"{source}: not valid JSON for a {what}: {e}") from None
    except json.JSONDecodeError as e:
        raise InputError(f"{source}: not valid JSON (line {e.lineno}, column {e.colno}: {e.msg})") from None
    except (ValueError, RecursionError) as e:      # a surrogate, a number Python refuses to convert
        raise InputError(f"{source}: not valid JSON for a {what} ({str(e)[:120]})") from None


def file_in(folder: str | os.PathLike, name: str, what: str = "file", must_exist: bool = True) -> Path:
    """folder/name after checking that `name` is relative, stays inside `folder` (symlinks resolved) and is a
    regular file (or, without `must_exist`, nothing yet): for file names read from a document (a catalogue's
    entries), which must not lead anywhere else."""
    folder = Path(folder)
    path = Path(os.path.normpath(folder / name))
    real, real_folder = os.path.realpath(path), os.path.realpath(folder)
    if os.path.isabs(name) or not str(path).startswith(str(Path(os.path.normpath(folder))) + os.sep) \
            or not real.startswith(real_folder + os.sep):
        raise InputError(f"{folder}: {what} {name!r} leads outside the folder; not opened")
    if must_exist or os.path.lexists(path):
        regular_file(path, what)
    return path


# ------------------------------------------------------------------------------------------------ folders


def make_folder(folder: str | os.PathLike) -> Path:
    """mkdir -p, with an InputError naming the folder when it cannot be made (a file in the way, /proc, no
    permission, a full disk)."""
    folder = Path(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise InputError(f"{folder}: cannot make this folder: a file is in the way") from None
    except OSError as e:
        raise _write_error(folder, e) from None
    return folder


def _write_error(path: Path, e: OSError):
    return InputError(describe_os_error(e, path))


def describe_os_error(e: OSError, path=None) -> str:
    """One line for a file-system error: '<path>: <what went wrong>', in words for the usual output mistakes."""
    path = path if path is not None else (e.filename or "")
    if isinstance(e, NotADirectoryError):
        return f"{path}: cannot write here: a part of the path is a file, not a folder"
    if isinstance(e, FileExistsError):
        return f"{path}: cannot make this folder: a file is in the way"
    return f"{path}: {e.strerror or type(e).__name__}" if path else f"{e.strerror or e}"


def temporary_prefix(name: str) -> str:
    """Prefix of this process's temporaries for the output `name`: '.name.tmp-<pid>.'."""
    return f".{name}.tmp-{os.getpid()}."


def staging_folder(out: str | os.PathLike) -> Path:
    """A new, private folder beside `out` to build a whole output folder in before it replaces `out` (named with
    `temporary_prefix`); the staging folders of `out` that dead processes left (a SIGKILL mid-write) are removed
    first."""
    out = Path(out)
    make_folder(out.parent)
    remove_stale_temporaries(out.parent, recursive=False)
    try:
        return Path(tempfile.mkdtemp(prefix=temporary_prefix(out.name), dir=out.parent))
    except OSError as e:
        raise _write_error(out, e) from None


def replace_folder(tmp: Path, out: Path) -> None:
    """Move the finished folder `tmp` (a `staging_folder`) to `out`, replacing a previous `out` (renamed aside
    first, then removed): readers see the old folder or the new one, never a mix."""
    old = None
    if out.exists():
        old = staging_folder(out)
        os.replace(out, old / out.name)
    os.chmod(tmp, 0o755)  # mkdtemp made it private
    os.replace(tmp, out)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


_TEMPORARY = re.compile(r"^\..+\.tmp-(\d+)\.")


def remove_stale_temporaries(folder: str | os.PathLike, recursive: bool = True) -> list[Path]:
    """Remove, under `folder` (or in it only), the temporary files and staging folders (`temporary_prefix` names)
    of processes that are no longer running: what an interrupted or killed run left. Returns what was removed."""
    removed = []
    for root, dirs, files in os.walk(os.fspath(folder)):
        for name in dirs + files:
            m = _TEMPORARY.match(name)
            if m and not _process_alive(int(m.group(1))):
                path = Path(root) / name
                if path.is_dir() and not path.is_symlink():
                    shutil.rmtree(path, ignore_errors=True)
                else:
                    path.unlink(missing_ok=True)
                removed.append(path)
        dirs[:] = [d for d in dirs if recursive and not _TEMPORARY.match(d)]
    return removed


def _process_alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def sha256_file(path: str | os.PathLike, chunk: int = 1 << 20) -> str:
    """Hex sha256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
    return h.hexdigest()
