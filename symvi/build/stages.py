"""Stage timing of a build: progress lines, and a deadline (``compile_model(timeout=)``).

The symbolic stages (discretise, derive, emit) run in this process and are interrupted
by ``SIGALRM`` (``setitimer``), which Python only allows in the main thread: called from
another thread, a stage that overruns the deadline runs to its end and the build gives
up then. The C compile runs in a subprocess that is killed at the deadline wherever
the build was called from.
"""
from __future__ import annotations

import contextlib
import signal
import threading
import time
from typing import Callable, Iterator

from ..errors import BuildError

#: A stage that runs longer than this (seconds) is announced while it runs.
SLOW_STAGE = 2.0
#: Once the deadline has passed, SIGALRM is repeated this often (seconds), in case code
#: of the stage catches the first interruption and carries on.
_REPEAT = 0.1

Progress = Callable[[str], None]


class Expired(BaseException):
    """Raised inside a stage when the deadline passes. A BaseException so that the
    stage's own ``except Exception`` clauses (SymPy has many) do not swallow it."""


class StageClock:
    """Runs the stages of one build against an optional deadline and reports progress.

    ``progress`` receives one line when a stage has run for :data:`SLOW_STAGE` seconds
    and one when such a stage ends (``verbose``: one line at the end of every stage).
    """

    def __init__(self, name: str, timeout: float | None = None,
                 progress: Progress | None = None, verbose: bool = False):
        if timeout is not None and not timeout > 0:
            raise ValueError(f"timeout must be a positive number of seconds, got {timeout!r}")
        self.name, self.timeout, self.progress, self.verbose = name, timeout, progress, verbose
        self.start = time.monotonic()
        self.deadline = None if timeout is None else self.start + timeout
        self.finished: list[tuple[str, float]] = []
        self._armed = False

    def remaining(self) -> float | None:
        """Seconds left before the deadline (None: no deadline)."""
        return None if self.deadline is None else self.deadline - time.monotonic()

    @contextlib.contextmanager
    def stage(self, label: str, interruptible: bool = True) -> Iterator[None]:
        """Run one stage: announce it if slow, interrupt it at the deadline (main thread
        and ``interruptible`` only), and raise :class:`BuildError` if it overran."""
        began = time.monotonic()
        if self.deadline is not None and began >= self.deadline:
            raise self.expired(label, began)
        try:
            with self._announced(label, began), self._alarm(interruptible):
                yield
        except Expired:
            raise self.expired(label, began) from None
        ended = time.monotonic()
        if self.deadline is not None and ended > self.deadline:
            raise self.expired(label, began)
        self.finished.append((label, ended - began))

    def expired(self, label: str, began: float) -> BuildError:
        """The error for a build that gave up at the deadline during stage ``label``."""
        done = ", ".join(f"{stage} {seconds:.2f} s" for stage, seconds in self.finished)
        return BuildError(
            f"{self.name}: gave up at the timeout of {self.timeout:g} s in stage '{label}' "
            f"(running for {time.monotonic() - began:.1f} s); finished stages: "
            f"{done or 'none'}")

    # -- progress -------------------------------------------------------------------------
    def _say(self, line: str) -> None:
        if self.progress is not None:
            self.progress(f"{self.name}: {line}")

    @contextlib.contextmanager
    def _announced(self, label: str, began: float) -> Iterator[None]:
        announce = threading.Timer(SLOW_STAGE, self._say,
                                   [f"{label} is running (over {SLOW_STAGE:g} s so far) ..."])
        announce.daemon = True
        if self.progress is not None:
            announce.start()
        try:
            yield
        finally:
            announce.cancel()
            elapsed = time.monotonic() - began
            if self.verbose or elapsed >= SLOW_STAGE:
                self._say(f"{label} took {elapsed:.2f} s")

    # -- deadline -------------------------------------------------------------------------
    @contextlib.contextmanager
    def _alarm(self, interruptible: bool) -> Iterator[None]:
        """Raise :class:`Expired` in this thread at the deadline, when possible."""
        remaining = self.remaining()
        if (remaining is None or not interruptible
                or threading.current_thread() is not threading.main_thread()):
            yield
            return
        saved_handler = signal.signal(signal.SIGALRM, self._on_alarm)
        saved_delay, saved_interval = signal.setitimer(signal.ITIMER_REAL,
                                                       max(remaining, 1e-3), _REPEAT)
        armed_at = time.monotonic()
        self._armed = True
        try:
            yield
        finally:
            try:
                self._armed = False
            finally:   # runs even if the alarm fired just before the line above
                self._disarm(saved_handler, saved_delay, saved_interval, armed_at)

    @staticmethod
    def _disarm(saved_handler, saved_delay: float, saved_interval: float,
                armed_at: float) -> None:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, saved_handler if saved_handler is not None
                      else signal.SIG_DFL)
        if saved_delay > 0:   # someone else's timer: re-arm it for what is left of it
            left = saved_delay - (time.monotonic() - armed_at)
            signal.setitimer(signal.ITIMER_REAL, max(left, 1e-3), saved_interval)

    def _on_alarm(self, signum, frame) -> None:
        if self._armed:
            raise Expired()
