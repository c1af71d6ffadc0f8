"""What a request needs in memory, checked before anything is allocated.

A path of 10⁹ steps needs tens of gigabytes; NumPy would reserve them lazily and the
process would grow until the operating system kills it. Refusing up front, with the
estimate, is the only answer a user can act on.
"""
from __future__ import annotations

import os

GIB = 2.0**30

#: Requests below this many bytes are not checked: any machine that runs Python has them
#: to spare, and reading the system's figure costs more than a small solve's iteration.
SMALL = 2.0**26


def available_bytes() -> float | None:
    """Memory the system can give this process without swapping (Linux: MemAvailable),
    or None when the platform does not say."""
    try:
        with open("/proc/meminfo") as handle:
            for line in handle:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return float(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, ValueError, OSError):
        return None


def require(needed: float, what: str, hint: str) -> None:
    """Raise MemoryError (naming ``what``, the estimate and ``hint``) when ``needed``
    bytes exceed the memory available."""
    if needed < SMALL:
        return
    available = available_bytes()
    if available is not None and needed > available:
        raise MemoryError(f"{what} needs about {needed / GIB:.3g} GiB but only "
                          f"{available / GIB:.3g} GiB of memory are available; {hint}")
