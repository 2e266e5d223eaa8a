"""Worker processes that behave on interruption: Ctrl-C is their parent's to handle (the parent stops them cleanly,
so no worker prints a KeyboardInterrupt traceback or leaks a semaphore), and a worker never outlives its parent (a
SIGKILL of the parent ends its workers at once instead of leaving them to finish, or to wait, alone).

    with deaf_to_ctrl_c():                      # workers start while they import: Ctrl-C must not reach them then
        pool = ProcessPoolExecutor(..., initializer=init_worker)    # or call init_worker() in your initializer
        futures = [pool.submit(...) ...]        # (spawned workers are started by submit)
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import tempfile
import threading

PR_SET_PDEATHSIG = 1     # linux/prctl.h
M_TRIM_THRESHOLD, M_TOP_PAD, M_MMAP_THRESHOLD = -1, -2, -3      # glibc malloc.h


WATCHDOG_S = 0.5        # where the kernel cannot be asked, how often a worker looks for its parent


def init_worker(parent: int | None = None) -> None:
    """In a worker process: ignore SIGINT, and end when the parent process (`parent`, default this process's
    parent) dies: killed by the kernel on Linux, else by a watchdog thread that notices the re-parenting."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    parent = os.getppid() if parent is None else parent
    if not die_with_parent():
        threading.Thread(target=_watch_parent, args=(parent,), daemon=True, name="darthand-watchdog").start()
    if os.getppid() != parent:        # the parent died before any of this took effect
        os._exit(1)


def _watch_parent(parent: int) -> None:
    import time

    while os.getppid() == parent:
        time.sleep(WATCHDOG_S)
    os._exit(3)


def die_with_parent(sig: int = signal.SIGKILL) -> bool:
    """Ask the kernel to send `sig` to this process when its parent exits; False where prctl is not available.
    The worker's partial outputs are temporaries (fileio.atomic_path), which the next run removes."""
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(PR_SET_PDEATHSIG, int(sig), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def keep_freed_memory(largest: int = 32 << 20) -> bool:
    """Ask glibc's malloc to serve blocks up to `largest` bytes (its ceiling is 32 MB) from the heap and to keep
    freed memory for reuse, instead of mapping every large array afresh and unmapping it when freed: a worker that
    makes and drops many arrays of a few MB per job (one per texel field of a 2048^2 texture) otherwise pays the
    kernel for fresh zeroed pages each time (measured: 1.96 s of system time down to 0.55 s over 42 texture
    variants; the process keeps its peak size). False where glibc is not there."""
    try:
        import ctypes

        libc = ctypes.CDLL(None)
        return all(libc.mallopt(param, value) == 1 for param, value in (
            (M_MMAP_THRESHOLD, largest), (M_TRIM_THRESHOLD, 1 << 30), (M_TOP_PAD, 64 << 20)))
    except (OSError, AttributeError):
        return False


@contextlib.contextmanager
def ctrl_c_held():
    """Hold a Ctrl-C (SIGINT) that arrives in the block and deliver it when the block ends: for work in which a
    KeyboardInterrupt would be raised inside C callbacks (LLVM's, while numba compiles), where Python prints it as
    an ignored exception with a traceback and drops it. Python runs signal handlers in the main thread only, so
    elsewhere the block changes nothing (the interrupt is raised in the main thread's own code)."""
    if threading.current_thread() is not threading.main_thread() or signal.getsignal(signal.SIGINT) is None:
        yield                   # (None: a handler set outside Python, which could not be put back)
        return
    caught = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: caught.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        if caught:
            signal.raise_signal(signal.SIGINT)


@contextlib.contextmanager
def deaf_to_ctrl_c():
    """Block SIGINT in this thread while worker processes are started: they inherit the blocked signal, so a Ctrl-C
    arriving while they import (before `init_worker` runs) cannot interrupt them; this process gets it when the
    block ends."""
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


@contextlib.contextmanager
def native_stderr_captured():
    """File descriptor 2 sent to a temporary file for the block, then restored: C libraries that print their own
    diagnostics there (libpng's 'libpng error: ...' while OpenImageIO decodes a damaged PNG) stay quiet, and the
    caller reports the failure in its one line. Yields a callable returning what was written (text)."""
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as sink:
        os.dup2(sink.fileno(), 2)
        try:
            yield lambda: (sink.seek(0), sink.read().decode(errors="replace"))[1]
        finally:
            os.dup2(saved, 2)
            os.close(saved)
