"""The iteration log of the whole-trajectory solvers (issue 50, item 7): one row per
iteration, printed like IPOPT's with ``verbose`` and kept as the result's ``history``.

Columns: the barrier parameter μ (per unit time; the interior point's, "-" for the
equality Newton), the cost S (+ ρT with a free horizon), the primal infeasibility (max
of |Φ_d|, and |c + s| with inequalities), the dual infeasibility (max node residual),
the complementarity max s·z ("-" without inequalities), the Newton correction (for the
interior point the μ = 0 one the SUCCESS rule reads), the step α taken (0 where none),
the inertia correction's shift (relative to W's largest diagonal entry), the line
search's trial points, and the horizon T where it is an unknown.
"""
from __future__ import annotations

import math
import sys

import numpy as np

from . import progress

#: The columns, in the order printed; those a step sets come last.
MEASURED = ("mu", "objective", "primal", "dual", "complementarity", "correction", "T")
STEP = ("alpha", "shift", "trials")
HEADER = (" iter   objective      inf_pr   inf_du   lg(mu)  compl    KKT corr  alpha     "
          "lg(shift)  ls")


class IterationLog:
    """The rows of one solve's iterations (``title`` names it on the header), and their
    printing."""

    def __init__(self, title: str, verbose: bool):
        self.title, self.verbose = title, verbose
        self.rows: dict[str, list] = {k: [] for k in MEASURED + STEP}
        self._step: dict[str, float] = {}
        self._reported = 0      # rows printed

    def measured(self, **values: float) -> None:
        """The start of an iteration: its measured columns (a correction may follow)."""
        self._close()
        for k in MEASURED:
            self.rows[k].append(values.get(k, math.nan))
        self._step = {"alpha": 0.0, "shift": 0.0, "trials": 0}

    def correction(self, value: float) -> None:
        """The iteration's Newton (for the interior point, KKT) correction."""
        self.rows["correction"][-1] = value

    def horizon(self, value: float | None) -> None:
        """The horizon T after the iteration's step, where it is an unknown."""
        if value is not None and self.rows["T"]:
            self.rows["T"][-1] = value

    def trial(self) -> None:
        """One more trial point of the line search."""
        self._step["trials"] = self._step.get("trials", 0) + 1

    def step(self, alpha: float | None = None, shift: float | None = None,
             trials: int | None = None) -> None:
        """The step taken (α), the inertia correction's shift used and the line search's
        trial points (where not counted one by one with :meth:`trial`)."""
        if alpha is not None:
            self._step["alpha"] = alpha
        if shift is not None:
            self._step["shift"] = shift
        if trials is not None:
            self._step["trials"] = trials

    def report(self, it: int, verdict: str = "") -> None:
        """Print the iteration's row (with ``verbose``), the header first; without it,
        update the call's progress line (:mod:`.progress`), if it has one."""
        if not self.verbose:
            progress.report(lambda: self._progress(it))
        if not self.verbose or not self.rows["mu"]:
            return
        if len(self.rows["mu"]) == self._reported:      # no new row: the verdict alone
            print(f"{it:5d}  {verdict.lstrip(': ')}", file=sys.stderr, flush=True)
            return
        self._reported = len(self.rows["mu"])
        if it == 0:
            print(f"symvi: {self.title}\n{HEADER}", file=sys.stderr)
        r = {k: v[-1] for k, v in self.rows.items() if v}
        s = self._step
        shift = f"{math.log10(s['shift']):6.1f}" if s.get("shift", 0.0) > 0 else "     -"
        mu = f"{math.log10(r['mu']):6.1f}" if r["mu"] > 0 else "     -"
        complementarity = f"{r['complementarity']:8.2e}" if r["complementarity"] == \
            r["complementarity"] else "       -"
        horizon = f"  T {r['T']:.10g}" if r["T"] == r["T"] else ""
        print(f"{it:5d}  {r['objective']:14.7e} {r['primal']:8.2e} {r['dual']:8.2e} "
              f"{mu}  {complementarity} {r['correction']:8.2e}  {s.get('alpha', 0.0):8.2e}  "
              f"{shift}   {s.get('trials', 0):3d}{horizon}{verdict}", file=sys.stderr,
              flush=True)

    def _progress(self, it: int) -> str:
        """The progress line's text at iteration ``it``."""
        correction = self.rows["correction"][-1] if self.rows["correction"] else math.nan
        return f"{self.title}, iteration {it + 1}, correction {correction:.1e}"

    def history(self) -> dict[str, np.ndarray]:
        """The columns as arrays, one entry per iteration."""
        self._close()
        return {k: np.array(v, dtype=float) for k, v in self.rows.items()}

    def _close(self) -> None:
        """Write the last iteration's step columns (once)."""
        if self._step and len(self.rows["alpha"]) < len(self.rows["mu"]):
            for k in STEP:
                self.rows[k].append(self._step.get(k, 0.0))
