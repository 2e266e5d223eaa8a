"""Compiled loops: the one way darthand compiles a numpy chain into a single pass (numba), and why it is set up so.

Some per-frame work is a chain of numpy passes over the same samples (a texture lookup is index arithmetic, four
gathers, a decode and a blend: a dozen temporaries of the batch's size); a compiled loop does it in one pass, in
registers. `kernel` marks such a loop. Rules the kernels follow:

- Same numbers as the numpy they replace: float32 arithmetic in the same order (numba keeps float32 when every
  operand is float32; a Python float literal is float64, so constants are written np.float32(...)), no fastmath
  (it would let LLVM reorder and fuse operations: other bits, machine-dependent).
- Serial and GIL-free (nogil): dataset workers are processes of one thread each; a renderer's own threads
  (trace.in_chunks) and the frame writer's thread run alongside a kernel.
- Arrays passed in contiguous and of fixed dtypes (callers normalise them), so each kernel compiles for one or two
  signatures, not one per layout.
- Divisions: numba checks every division for a zero divisor (Python's ZeroDivisionError), and that branch keeps LLVM
  from vectorising the loop. A kernel whose divisors cannot be zero (each guarded, as max(|v|, 1e-30)) says
  `@kernel(error_model="numpy")`: the check goes, the numbers stay (IEEE division either way); SIMD lanes do the
  same float32 operations in the same order, so vectorising changes no bit.
- Self-contained: a kernel calls no other kernel (so `kernel` can stay lazy, below, and a cached kernel never
  outlives a change in a function it inlined: numba's cache checks only the kernel's own source file). The one
  exception is a plain scalar function marked `inlined`, defined in the same source file as the kernels calling it.

Compilation is lazy twice over: numba is imported at the first call of any kernel (importing it costs about 0.2 s
of CPU, which commands that never run one, like `darthand validate`, should not pay), and each kernel is compiled
at its first call for the argument types given. The machine code is cached on disk (numba's cache=True): in the
`__pycache__` folder beside the source file when that folder is writable (an editable install, as `make` makes),
otherwise in numba's per-user cache folder (NUMBA_CACHE_DIR overrides it). So a process pays the compilation only
when no earlier process on the machine has, and otherwise loads the cached code. Measured (quiet 2-core machine,
every kernel a dataset frame runs, 2026-11-24): a process's first dataset frame costs 14.6 s of CPU when it compiles
them all, 1.8 s when it loads them (with numba's import, its dispatcher's start and the frame's texture loads).
Processes compiling the same kernel at once (pytest-xdist workers, dataset workers) are safe:
numba writes each cache file under a temporary name and renames it into place.
"""

from __future__ import annotations

import functools
import threading

from darthand.processes import ctrl_c_held

_LOCK = threading.Lock()
_INLINED: list = []         # `inlined` functions, registered with numba at the first compilation of any kernel
_REGISTERED: set = set()


def inlined(func=None, *, always: bool = False):
    """`func`, a plain scalar function (it stays plain Python outside kernels), made callable from kernels: each
    kernel calling it compiles it in. It lives in the same source file as those kernels (numba's cache checks only
    a kernel's own file) and guards its own divisions (it is compiled with error_model="numpy"). As
    `@inlined(always=True)`: its body is put into each caller's before compiling (numba's inline="always"), for a
    helper called in a hot loop: left to LLVM, a helper taking arrays stays a call (measured: render/raster.py's
    coverage helpers, 45 % slower as calls)."""
    if func is None:
        return lambda f: inlined(f, always=always)
    _INLINED.append((func, "always" if always else "never"))
    return func


def _register_inlined(numba) -> None:
    """Make every `inlined` function not yet registered callable from numba (under _LOCK)."""
    for func, inline in _INLINED:
        if func not in _REGISTERED:
            numba.extending.register_jitable(error_model="numpy", inline=inline)(func)
            _REGISTERED.add(func)


def kernel(func=None, *, error_model: str = "python"):
    """`func` as a numba kernel (njit, cache=True, nogil=True), compiled at its first call; `func` itself stays
    available as `.py_func` (plain Python, for debugging). As `@kernel(error_model="numpy")`: no zero-divisor checks
    (see the rules above)."""
    if func is None:
        return lambda f: kernel(f, error_model=error_model)
    compiled = None

    @functools.wraps(func)
    def call(*args):
        nonlocal compiled
        if compiled is None:
            with _LOCK:
                if compiled is None:
                    import numba
                    import numba.extending

                    _register_inlined(numba)
                    dispatcher = numba.njit(cache=True, nogil=True, error_model=error_model)(func)
                    # The first call compiles (or loads the cache): a Ctrl-C waits for it (processes.ctrl_c_held)
                    with ctrl_c_held():
                        result = dispatcher(*args)
                    compiled = dispatcher
                    return result
        return compiled(*args)

    call.py_func = func  # type: ignore[attr-defined]
    return call
