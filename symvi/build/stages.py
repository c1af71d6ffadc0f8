"""Stage timing of a build: progress lines, and a deadline (``compile_model(timeout=)``).

The deadline counts from the clock's creation: ``compile_model``'s start, or the
command's start for ``symvi compile``, whose first stage loads the model file.

The symbolic stages (discretise, derive, emit) run in this process and are interrupted
at the deadline by :func:`symvi.timing.interrupted_after` (``SIGALRM``, which Python only
allows in the main thread): called from another thread, a stage that overruns the
deadline runs to its end and the build gives up then. The C compile runs in a subprocess
that is killed at the deadline wherever the build was called from.
"""
from __future__ import annotations

import contextlib
import time
from typing import Callable, Iterator

from ..errors import BuildError
from ..timing import Expired, announced, interrupted_after

#: A stage that runs longer than this (seconds) is announced while it runs.
SLOW_STAGE = 2.0

Progress = Callable[[str], None]
__all__ = ["Expired", "Progress", "SLOW_STAGE", "StageClock"]


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

    def remaining(self) -> float | None:
        """Seconds left before the deadline (None: no deadline)."""
        return None if self.deadline is None else self.deadline - time.monotonic()

    @contextlib.contextmanager
    def stage(self, label: str, interruptible: bool = True) -> Iterator[None]:
        """Run one stage: announce it if slow, interrupt it at the deadline (main thread
        and ``interruptible`` only), and raise :class:`BuildError` if it overran."""
        began = time.monotonic()
        if self.deadline is not None and began >= self.deadline:
            raise self.expired(label, None)
        say = None if self.progress is None else self._say
        remaining = self.remaining() if interruptible else None
        try:
            with announced(label, say, SLOW_STAGE, self.verbose), interrupted_after(remaining):
                yield
        except Expired:
            raise self.expired(label, began) from None
        ended = time.monotonic()
        if self.deadline is not None and ended > self.deadline:
            raise self.expired(label, began)
        self.finished.append((label, ended - began))

    def expired(self, label: str, began: float | None) -> BuildError:
        """The error for a build that gave up at the deadline during stage ``label``
        (which began at ``began``; None: before it could begin). It says how long since
        the start, so that time spent outside the stages (waiting for another build's
        lock) is not hidden."""
        now = time.monotonic()
        done = ", ".join(f"{stage} {seconds:.2f} s" for stage, seconds in self.finished)
        where = f"before stage '{label}' could begin" if began is None else \
            f"in stage '{label}' (running for {now - began:.1f} s)"
        return BuildError(
            f"{self.name}: gave up at the timeout of {self.timeout:g} s, "
            f"{now - self.start:.1f} s after the start, {where}; finished stages: "
            f"{done or 'none'}")

    # -- progress -------------------------------------------------------------------------
    def _say(self, line: str) -> None:
        if self.progress is not None:
            self.progress(f"{self.name}: {line}")
