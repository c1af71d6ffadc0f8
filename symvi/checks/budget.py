"""The time budget of each check (issue 26): optional, costly parts are attempted within
what is left of it and skipped with a note past it; the verdict never is.

The costly parts known so far are the regularity check's singular locus — factoring the
determinant of the step matrix took 222 s on a planar Kepler model, whose rank (the
verdict) takes milliseconds — and the equations check's symbolic location of where a
display differs, after its verdict at sampled points (:mod:`.sampled`): solving a triple
pendulum's 3×3 mass matrix symbolically ran 32 minutes (issue 53). A part is interrupted at the budget by
:func:`symvi.timing.interrupted_after` (main thread only; elsewhere it is attempted only
while budget is left, and runs to its end).
"""
from __future__ import annotations

import time
from typing import Callable, TypeVar

from ..timing import Expired, interrupted_after

#: Seconds per check by default (``symvi check --budget``).
DEFAULT_BUDGET = 20.0

T = TypeVar("T")
#: What :meth:`Budget.attempt` returns for a part skipped for the budget.
SKIPPED = object()


class Budget:
    """The budget of the check being run: :meth:`begin` starts it, :meth:`attempt` runs
    an optional part within it; ``skipped`` names the parts the budget cut."""

    def __init__(self, seconds: float | None = DEFAULT_BUDGET):
        if seconds is not None and not (isinstance(seconds, (int, float))
                                        and not isinstance(seconds, bool)
                                        and 0 < seconds < float("inf")):
            raise ValueError(f"budget must be a positive, finite number of seconds, or None "
                             f"for no limit; got {seconds!r}")
        self.seconds = None if seconds is None else float(seconds)
        self.deadline: float | None = None
        self.skipped: list[str] = []

    def begin(self) -> None:
        """Start a check's budget."""
        self.deadline = None if self.seconds is None else time.monotonic() + self.seconds
        self.skipped = []

    def attempt(self, label: str, part: Callable[..., T], *args) -> T | object:
        """``part(*args)``, or :data:`SKIPPED` (recorded as ``label``) when the budget ran
        out before or during it."""
        remaining = None if self.deadline is None else self.deadline - time.monotonic()
        if remaining is not None and remaining <= 0:
            self.skipped.append(label)
            return SKIPPED
        try:
            with interrupted_after(remaining):
                return part(*args)
        except Expired:
            self.skipped.append(label)
            return SKIPPED

    def note(self, label: str) -> str:
        """The summary's words for a part skipped for the budget."""
        return f"{label} skipped: over the check's time budget of {self.seconds:g} s (--budget)"
