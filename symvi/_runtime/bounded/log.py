"""The interior point's iteration log (issue 50, item 7): one row per iteration, printed
like IPOPT's with ``verbose`` and kept as the result's ``history``.

Columns: the barrier parameter μ (per unit time), the cost S, the primal infeasibility
(max of |Φ_d| and |c + s|), the dual infeasibility (max node residual), the
complementarity max s·z, the KKT correction (the μ = 0 Newton correction the SUCCESS
rule reads), the step α taken (0 where none), the inertia correction's shift (relative
to W's largest diagonal entry) and the line search's trial points.
"""
from __future__ import annotations

import math
import sys

import numpy as np

#: The columns, in the order printed; those a step sets come last.
MEASURED = ("mu", "objective", "primal", "dual", "complementarity", "correction")
STEP = ("alpha", "shift", "trials")
HEADER = (" iter   objective      inf_pr   inf_du   lg(mu)  compl    KKT corr  alpha     "
          "lg(shift)  ls")


class IterationLog:
    """The rows of one interior point, and its printing."""

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
        """The iteration's KKT correction."""
        self.rows["correction"][-1] = value

    def trial(self) -> None:
        """One more trial point of the line search."""
        self._step["trials"] = self._step.get("trials", 0) + 1

    def step(self, alpha: float | None = None, shift: float | None = None) -> None:
        """The step taken (α) and the inertia correction's shift used."""
        if alpha is not None:
            self._step["alpha"] = alpha
        if shift is not None:
            self._step["shift"] = shift

    def report(self, it: int, verdict: str = "") -> None:
        """Print the iteration's row (with ``verbose``), the header first."""
        if not self.verbose or not self.rows["mu"]:
            return
        if len(self.rows["mu"]) == self._reported:      # no new row: the verdict alone
            print(f"{it:5d}  {verdict.lstrip(': ')}", file=sys.stderr, flush=True)
            return
        self._reported = len(self.rows["mu"])
        if it == 0:
            print(f"symvi: interior point {self.title}\n{HEADER}", file=sys.stderr)
        r = {k: v[-1] for k, v in self.rows.items() if v}
        s = self._step
        shift = f"{math.log10(s['shift']):6.1f}" if s.get("shift", 0.0) > 0 else "     -"
        print(f"{it:5d}  {r['objective']:14.7e} {r['primal']:8.2e} {r['dual']:8.2e} "
              f"{math.log10(r['mu']):6.1f}  {r['complementarity']:8.2e} "
              f"{r['correction']:8.2e}  {s.get('alpha', 0.0):8.2e}  {shift}   "
              f"{s.get('trials', 0):3d}{verdict}", file=sys.stderr, flush=True)

    def history(self) -> dict[str, np.ndarray]:
        """The columns as arrays, one entry per iteration."""
        self._close()
        return {k: np.array(v, dtype=float) for k, v in self.rows.items()}

    def _close(self) -> None:
        """Write the last iteration's step columns (once)."""
        if self._step and len(self.rows["alpha"]) < len(self.rows["mu"]):
            for k in STEP:
                self.rows[k].append(self._step.get(k, 0.0))
