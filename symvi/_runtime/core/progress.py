"""Progress of long batches: a ``tqdm`` bar, the ecosystem's convention (issue 24).

``tqdm`` is optional for a generated package (which needs only NumPy and cffi): without
it, ``progress=None`` shows nothing and ``progress=True`` is refused with the remedy.
Workers report from their threads; the bar's counter is guarded by a lock.
"""
from __future__ import annotations

import threading


class Progress:
    """A counter of finished members shown as a bar on stderr; :meth:`update` is
    thread-safe, and the bar is closed when the ``with`` block ends."""

    def __init__(self, total: int, what: str, enabled: bool | None):
        self.lock = threading.Lock()
        self.bar = _bar(total, what, enabled)

    def update(self, n: int = 1) -> None:
        if self.bar is not None:
            with self.lock:
                self.bar.update(n)

    def __enter__(self) -> "Progress":
        return self

    def __exit__(self, *exc) -> None:
        if self.bar is not None:
            self.bar.close()


def _bar(total: int, what: str, enabled: bool | None):
    """The tqdm bar, or None. ``enabled``: True (a bar; tqdm required), False (none) or
    None (a bar when tqdm is installed and stderr is a terminal)."""
    if enabled not in (True, False, None):
        raise ValueError(f"progress must be True, False or None, got {enabled!r}")
    if enabled is False:
        return None
    try:
        from tqdm.auto import tqdm
    except ImportError:
        if enabled:
            raise ValueError("progress=True needs tqdm (pip install tqdm); pass "
                             "progress=False for none") from None
        return None
    # disable=None: tqdm's own test, off when stderr is not a terminal
    return tqdm(total=total, unit=f" {what}", disable=None if enabled is None else False,
                dynamic_ncols=True, smoothing=0.1)
