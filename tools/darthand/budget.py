"""What one command may allocate: a memory budget, checked against an estimate before the large allocations.

Loaders check the sizes a file declares (array shapes, JSON size) and commands check what their options ask for
(image size, texture size, rings, poses) before allocating, so an absurd request fails at once with one line naming
what was asked, the estimate and the budget, instead of a MemoryError traceback, a swapping machine or an
out-of-memory kill. The budget is half the machine's physical memory unless the user says otherwise: the
`--max-memory SIZE` option every command takes, or the DARTHAND_MAX_MEMORY environment variable (for scripts and
make), e.g. `64G`.
"""

from __future__ import annotations

import os
import re

from darthand.errors import InputError

ENV = "DARTHAND_MAX_MEMORY"
FRACTION_OF_RAM = 0.5
_UNITS = {"": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}

_limit: int | None = None        # set by the CLI's --max-memory (None: the environment, else half the RAM)


class BudgetError(InputError):
    """A request needs more memory than the command's budget allows."""


def physical_memory() -> int:
    """Bytes of physical memory (8 GiB when the system does not say)."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return 8 << 30


def parse_size(text: str) -> int:
    """Bytes from '512M', '16G', '1.5T', '1e9' or a plain number of bytes; ValueError otherwise."""
    m = re.fullmatch(r"\s*([0-9]+(?:\.[0-9]*)?(?:[eE][0-9]{1,2})?)\s*([KMGT]?)i?B?\s*", str(text), re.I)
    if not m:
        raise ValueError(f"{text!r} is not a size such as 512M, 16G or 2T")
    value = float(m.group(1)) * _UNITS[m.group(2).upper()]
    if not 0 < value < 1 << 60:
        raise ValueError(f"{text!r} is not a size between 1 byte and 1 EB")
    return int(value)


def format_size(n: float) -> str:
    """'1.9 TB', '512 MB', '340 kB' (decimal units, as people read them)."""
    for unit, scale in (("EB", 1e18), ("PB", 1e15), ("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{int(n)} bytes"


def set_memory_limit(nbytes: int | None) -> None:
    """Set this process's budget (None: back to DARTHAND_MAX_MEMORY or half the RAM)."""
    global _limit
    _limit = None if nbytes is None else int(nbytes)


def memory_limit() -> tuple[int, str]:
    """(bytes, where the figure comes from)."""
    if _limit is not None:
        return _limit, "--max-memory"
    if os.environ.get(ENV):
        try:
            return parse_size(os.environ[ENV]), ENV
        except ValueError as e:
            raise InputError(f"{ENV}: {e}") from None
    return int(FRACTION_OF_RAM * physical_memory()), "half this machine's memory"


def check_memory(what: str, nbytes: float) -> None:
    """Raise BudgetError when `what` needs more than the budget; `nbytes` is an estimate of its peak use."""
    limit, source = memory_limit()
    if nbytes > limit:
        ask = format_size(min(nbytes * 1.2, 1 << 60)).replace(" ", "").replace("B", "").replace("k", "K")
        raise BudgetError(f"{what} needs about {format_size(nbytes)} of memory, above the budget of "
                          f"{format_size(limit)} ({source}); give --max-memory {ask} if you mean it")
