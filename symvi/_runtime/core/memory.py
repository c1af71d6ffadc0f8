"""What a request needs in memory, checked before anything is allocated.

A path of 10⁹ steps needs tens of gigabytes; NumPy would reserve them lazily and the
process would grow until the operating system kills it. Refusing up front, with the
estimate, is the only answer a user can act on.

The memory a process can use is the least of three limits: what the machine has free
(MemAvailable), what its cgroup (a container, a batch system's job) may still take, and
its own address-space limit (``ulimit -v``, RLIMIT_AS). A job limited to 4 GiB on a
machine with 200 GiB free is killed at 4 GiB.
"""
from __future__ import annotations

import os
from pathlib import Path

GIB = 2.0**30

#: Requests below this many bytes are not checked: any machine that runs Python has them
#: to spare, and reading the system's figure costs more than a small solve's iteration.
SMALL = 2.0**26

#: Where the kernel shows this process's cgroups, and where their files are mounted.
PROC_CGROUP = Path("/proc/self/cgroup")
CGROUP_ROOT = Path("/sys/fs/cgroup")
#: cgroup v1 writes "no limit" as a huge number (2⁶³ rounded down to a page), not "max".
V1_UNLIMITED = 2.0**60


def available_bytes() -> float | None:
    """Memory this process can still allocate without swapping or being killed: the least
    of the system's MemAvailable, its cgroup's limit minus its usage and its RLIMIT_AS
    minus its current virtual size — or None when none of them is known."""
    known = [room for room in (_system_available(), cgroup_room(), address_space_room())
             if room is not None]
    return min(known) if known else None


def _system_available() -> float | None:
    """Linux's MemAvailable, else free physical pages (other Unixes), else None."""
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


def cgroup_room(proc_cgroup: Path = PROC_CGROUP, root: Path = CGROUP_ROOT) -> float | None:
    """What this process's cgroups may still take: the least over its cgroup and those
    above it of limit − usage (v2: ``memory.max`` − ``memory.current``; v1:
    ``memory.limit_in_bytes`` − ``memory.usage_in_bytes``), reclaimable page cache
    (``inactive_file``) not counted as used; None without a limit."""
    try:
        lines = proc_cgroup.read_text().splitlines()
    except OSError:
        return None
    rooms = []
    for line in lines:
        parts = line.split(":", 2)         # hierarchy-ID:controllers:path
        if len(parts) != 3:
            continue
        _, controllers, path = parts
        if controllers == "":
            rooms += _rooms(root, path, "memory.max", "memory.current", "inactive_file")
        elif "memory" in controllers.split(","):
            rooms += _rooms(root / "memory", path, "memory.limit_in_bytes",
                            "memory.usage_in_bytes", "total_inactive_file")
    return min(rooms) if rooms else None


def _rooms(mount: Path, path: str, limit_file: str, usage_file: str,
           cache_key: str) -> list[float]:
    """limit − usage of the cgroup at ``path`` under ``mount`` and of each above it. In a
    container the path may be one of the host's (no such folder): its parents are tried
    up to the mount, which is the container's own cgroup."""
    rooms = []
    folder = mount / path.lstrip("/")
    for directory in (folder, *folder.parents):
        limit = _number(directory / limit_file)
        if limit is not None and limit < V1_UNLIMITED:
            usage = _number(directory / usage_file) or 0.0
            rooms.append(max(0.0, limit - max(0.0, usage - _cache(directory, cache_key))))
        if directory == mount:
            break
    return rooms


def _number(file: Path) -> float | None:
    """The number in a cgroup file; None where there is none ("max": no limit)."""
    try:
        text = file.read_text().strip()
    except OSError:
        return None
    return float(text) if text.isdigit() else None


def _cache(directory: Path, key: str) -> float:
    """Reclaimable page cache of a cgroup (``memory.stat``'s ``key``), else 0."""
    try:
        for line in (directory / "memory.stat").read_text().splitlines():
            name, _, value = line.partition(" ")
            if name == key and value.strip().isdigit():
                return float(value)
    except OSError:
        pass
    return 0.0


def address_space_room() -> float | None:
    """RLIMIT_AS minus this process's current virtual size, or None without a limit. The
    limit counts virtual memory, which NumPy's and BLAS's threads already make large,
    so the room is what is left of it, not the limit itself."""
    try:
        import resource
    except ImportError:            # not on Unix
        return None
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft == resource.RLIM_INFINITY:
        return None
    try:
        pages = int(Path("/proc/self/statm").read_text().split()[0])
        current = pages * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        current = 0
    return max(0.0, float(soft - current))


class AddressSpaceCap:
    """A ``with`` block in which this process's virtual size may grow by no more than the
    memory available (RLIMIT_AS lowered to its current size plus
    :func:`available_bytes`, restored on exit): an allocation past it raises MemoryError
    instead of the operating system killing the process. For a factorisation whose fill
    cannot be bounded beforehand (SuperLU: the pure minimum-time double integrator's
    active-set Newton at N = 10⁵ grew past 24 GB and was killed). A no-op where the
    limit or the sizes are unknown."""

    def __enter__(self) -> "AddressSpaceCap":
        self._restore = None
        try:
            import resource
            pages = int(Path("/proc/self/statm").read_text().split()[0])
            current = pages * os.sysconf("SC_PAGE_SIZE")
        except (ImportError, OSError, ValueError, IndexError):
            return self
        room = available_bytes()
        if room is None:
            return self
        soft, hard = resource.getrlimit(resource.RLIMIT_AS)
        cap = int(current + room)
        for limit in (soft, hard):
            if limit != resource.RLIM_INFINITY:
                cap = min(cap, limit)
        resource.setrlimit(resource.RLIMIT_AS, (cap, hard))
        self._restore = (resource, soft, hard)
        return self

    def __exit__(self, *exc) -> None:
        if self._restore is not None:
            resource, soft, hard = self._restore
            resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


def require(needed: float, what: str, hint: str) -> None:
    """Raise MemoryError (naming ``what``, the estimate and ``hint``) when ``needed``
    bytes exceed the memory available."""
    if needed < SMALL:
        return
    available = available_bytes()
    if available is not None and needed > available:
        raise MemoryError(f"{what} needs about {needed / GIB:.3g} GiB but only "
                          f"{available / GIB:.3g} GiB of memory are available; {hint}")
