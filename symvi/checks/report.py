"""Results of the derivation checks: one :class:`CheckResult` per check, gathered in a
:class:`CheckReport` that prints one line per check (details on failure) or JSON."""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

PASS, FAIL, SKIP = "pass", "fail", "skip"
#: The ``data`` key naming the parts of a check skipped for its time budget.
BUDGET_SKIPPED = "skipped_for_budget"


@dataclass(frozen=True)
class CheckResult:
    """Outcome of one check.

    ``status`` is ``"pass"``, ``"fail"`` or ``"skip"`` (the check does not apply to the
    model, e.g. Noether without a declared symmetry); ``summary`` is one line;
    ``details`` name what failed (the offending term, equation or sample point); ``data``
    holds measured numbers (orders, residual norms), JSON-serialisable.
    """

    name: str
    status: str
    summary: str
    details: tuple[str, ...] = ()
    data: Mapping[str, Any] = field(default_factory=dict)

    @classmethod
    def passed(cls, name: str, summary: str, **data) -> "CheckResult":
        return cls(name, PASS, summary, (), data)

    @classmethod
    def failed(cls, name: str, summary: str, details: Sequence[str] = (),
               **data) -> "CheckResult":
        return cls(name, FAIL, summary, tuple(details), data)

    @classmethod
    def skipped(cls, name: str, reason: str) -> "CheckResult":
        return cls(name, SKIP, reason)

    def lines(self, width: int = 0) -> list[str]:
        """The report's line for this check, failure details indented below it."""
        return [f"  {self.status.upper():4s}  {self.name:{width}s}  {self.summary}"] + \
            [f"          {line}" for d in self.details for line in d.splitlines()]

    @property
    def ok(self) -> bool:
        """True unless the check failed (a skipped check is not a failure)."""
        return self.status != FAIL

    def to_dict(self) -> dict:
        return {"name": self.name, "status": self.status, "summary": self.summary,
                "details": list(self.details), "data": _plain(self.data)}


@dataclass(frozen=True)
class CheckReport:
    """All checks run on one model; ``exit_code`` is 0 when none failed, else 1."""

    model: str
    results: tuple[CheckResult, ...]

    @property
    def passed(self) -> bool:
        return all(r.ok for r in self.results)

    @property
    def exit_code(self) -> int:
        return 0 if self.passed else 1

    def __getitem__(self, name: str) -> CheckResult:
        for r in self.results:
            if r.name == name:
                return r
        raise KeyError(f"no check {name!r} in this report; ran {[r.name for r in self.results]}")

    def format(self) -> str:
        """Human-readable: one line per check, failure details indented below it, the
        counts, and the parts skipped for the time budget."""
        width = max((len(r.name) for r in self.results), default=0)
        lines = [f"symvi check {self.model}"]
        for r in self.results:
            lines += r.lines(width)
        return "\n".join(lines + self.closing())

    def closing(self) -> list[str]:
        """The counts line and, when the budget cut parts of checks, which."""
        counts = {s: sum(r.status == s for r in self.results) for s in (PASS, FAIL, SKIP)}
        lines = [f"{len(self.results)} checks: {counts[PASS]} passed, {counts[FAIL]} "
                 f"failed, {counts[SKIP]} skipped"]
        cut = [f"{r.name} ({', '.join(r.data[BUDGET_SKIPPED])})" for r in self.results
               if r.data.get(BUDGET_SKIPPED)]
        if cut:
            lines.append(f"skipped for the time budget: {'; '.join(cut)} (a larger --budget "
                         f"runs them)")
        return lines

    def to_dict(self) -> dict:
        return {"model": self.model, "passed": self.passed,
                "results": [r.to_dict() for r in self.results]}

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2)


def _plain(value):
    """JSON-friendly copy: NumPy scalars and arrays, tuples and SymPy numbers to plain types."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if hasattr(value, "tolist"):
        return value.tolist()
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    try:
        return float(value)
    except (TypeError, ValueError):
        return str(value)
