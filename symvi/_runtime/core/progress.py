"""Progress of long calls on stderr.

Batches (issue 24): a ``tqdm`` bar of finished members, the ecosystem's convention.
``tqdm`` is optional for a generated package (which needs only NumPy and cffi): without
it, ``progress=None`` shows nothing and ``progress=True`` is refused with the remedy.
Workers report from their threads; the bar's counter is guarded by a lock.

Single calls (issue 53): a :class:`ProgressLine`, one line rewritten in place once the
call has run :data:`DELAY` seconds, at most every :data:`INTERVAL` — ``integrate``
updates it between two chunks of its C loop (about every 50 ms already), ``solve_bvp``
at each Newton or interior-point iteration (:mod:`.log`, through the line the call
opened in this context: :func:`report`). No cost per step, and none at all below the
delay but one clock reading per chunk or iteration. It is erased when the call ends.
"""
from __future__ import annotations

import sys
import threading
import time
from contextvars import ContextVar
from typing import Callable

#: Seconds a single call runs before its progress line appears.
DELAY = 3.0
#: Seconds between two updates of the line.
INTERVAL = 0.25


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


class ProgressLine:
    """One line on stderr saying how far a long single call (``what``) has come:
    ``enabled`` True (shown, terminal or not), False (never) or None (when stderr is a
    terminal). Used as a ``with`` block: inside it, :func:`report` updates this line, and
    it is erased at the end."""

    def __init__(self, what: str, enabled: bool | None, delay: float | None = None):
        if enabled not in (True, False, None):
            raise ValueError(f"progress must be True, False or None, got {enabled!r}")
        self.what = what
        self.on = _terminal() if enabled is None else enabled
        self.delay = DELAY if delay is None else delay
        self.start = time.monotonic()
        self.last = -float("inf")
        self.width = 0
        self._token = None

    def update(self, text: Callable[[], str]) -> None:
        """Show ``text()`` (called only when the line is due) and the time elapsed."""
        if not self.on:
            return
        now = time.monotonic()
        if now - self.start < self.delay or now - self.last < INTERVAL:
            return
        line = f"symvi: {self.what}: {text()} — {now - self.start:.0f} s"
        sys.stderr.write("\r" + line.ljust(self.width))
        sys.stderr.flush()
        self.width, self.last = len(line), now

    def close(self) -> None:
        """Erase the line, if it was shown."""
        if self.width:
            sys.stderr.write("\r" + " " * self.width + "\r")
            sys.stderr.flush()
            self.width = 0

    def __enter__(self) -> "ProgressLine":
        self._token = _CURRENT.set(self)
        return self

    def __exit__(self, *exc) -> None:
        _CURRENT.reset(self._token)
        self.close()


#: The progress line of the single call running in this context (a thread, a task), if
#: any: how the solvers' iteration log reaches it without passing it through every phase.
_CURRENT: ContextVar[ProgressLine | None] = ContextVar("symvi_progress_line", default=None)


def report(text: Callable[[], str]) -> None:
    """Update the progress line of the call running in this context, if it has one."""
    line = _CURRENT.get()
    if line is not None:
        line.update(text)


def _terminal() -> bool:
    """Whether stderr is a terminal (a closed or replaced stream without ``isatty``: no)."""
    try:
        return bool(sys.stderr.isatty())
    except (AttributeError, ValueError):
        return False
