"""Connecting the driver to a Ray cluster: the address a user gives (`--ray [ADDRESS]`) checked quickly, then
ray.init; and the code digest that every node must share with the driver for a frame to be the same bytes on every
node (checked when an actor says hello, dataset/ray/runner.py)."""

from __future__ import annotations

import hashlib
import logging
import socket
from pathlib import Path

import embreex
import numpy
import OpenImageIO

import darthand
from darthand.errors import InputError

CONNECT_TIMEOUT_S = 10.0


def connect(address: str | None):
    """(the `ray` module, whether this call connected it), connected to the cluster at `address` ('host:port' of
    its head, 'auto', or None: RAY_ADDRESS, else the cluster started on this machine, else a new local one).
    InputError when Ray is not installed or no cluster answers."""
    try:
        import ray                            # optional, and ~1 s to import: only when a run asks for a cluster
    except ImportError:
        raise InputError("--ray: Ray is not installed (pip install 'darthand[cluster]', or `make venv` in a "
                         "checkout)") from None
    if ray.is_initialized():
        return ray, False
    _check_reachable(address)
    try:
        ray.init(address=address or None, logging_level=logging.ERROR, log_to_driver=False,
                 include_dashboard=False if not address else None)
    except Exception as e:                    # Ray raises ConnectionError, RuntimeError, ValueError...
        first = (str(e).strip().splitlines() or [type(e).__name__])[0]
        raise InputError(f"--ray {address or ''}: cannot connect to a Ray cluster ({first})".replace("  ", " ")) \
            from None
    return ray, True


def _check_reachable(address: str | None) -> None:
    """A quick TCP check of a 'host:port' address (ray.init waits a minute on an address nobody answers)."""
    if not address or address == "auto" or "://" in address:
        return
    host, _, port = address.rpartition(":")
    if not host or not port.isdigit():
        raise InputError(f"--ray {address}: not an address of the form HOST:PORT (the head node's, e.g. "
                         "10.0.0.1:6379) or 'auto'")
    try:
        socket.create_connection((host, int(port)), timeout=CONNECT_TIMEOUT_S).close()
    except OSError as e:
        raise InputError(f"--ray {address}: no Ray cluster answers there ({e.strerror or e})") from None


def code_digest() -> str:
    """sha256 (16 hex digits) of darthand's Python sources and the versions of the libraries a frame's bytes depend
    on: nodes must agree on it for frames to be the same bytes on every node."""
    import numba                              # ~1 s to import, which only rendering needs (this needs its version)

    h = hashlib.sha256()
    root = Path(darthand.__file__).parent
    for path in sorted(root.rglob("*.py")):
        h.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes())
    for module in (numpy, numba, embreex, OpenImageIO):     # numba compiles darthand/jit.py's kernels
        h.update(f"{module.__name__} {getattr(module, '__version__', '?')}".encode())
    return h.hexdigest()[:16]
