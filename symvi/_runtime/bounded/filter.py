"""The filter line search of the interior point (issue 50; Wächter & Biegler 2006, §2.3):
a trial point is accepted when it reduces the infeasibility θ or the barrier objective φ
enough against the current point and no point of the filter dominates it — no penalty
parameter weighs one against the other.

θ = ‖Φ_d‖₁ + ‖c + s‖₁ (the equalities and the slacked inequalities), φ = S − μh Σ log s
(the cost and the barrier, μ per unit time). Near feasibility (θ ≤ θ_min) a step along
which φ descends fast enough (the switching condition) must decrease φ by Armijo's rule
and leaves the filter unchanged (an f-type step); every other accepted step enlarges the
filter by the current point's (θ, φ), moved by the margins.
"""
from __future__ import annotations

from dataclasses import dataclass, field

#: Margins and exponents of Wächter & Biegler 2006 (their defaults, IPOPT's): sufficient
#: decrease of θ and φ (γ_θ, γ_φ), the switching condition's δ, s_θ, s_φ, Armijo's η_φ,
#: θ_max and θ_min as factors on max(1, θ at the start), and γ_α of the smallest step.
GAMMA_THETA, GAMMA_PHI = 1e-5, 1e-8
DELTA, S_THETA, S_PHI, ETA_PHI = 1.0, 1.1, 2.3, 1e-8
THETA_MAX, THETA_MIN, GAMMA_ALPHA = 1e4, 1e-4, 0.05


@dataclass
class Filter:
    """The filter of one barrier problem: pairs (θ, φ) no accepted point may dominate."""

    theta_start: float
    entries: list[tuple[float, float]] = field(default_factory=list)

    @property
    def theta_max(self) -> float:
        return THETA_MAX * max(1.0, self.theta_start)

    @property
    def theta_min(self) -> float:
        return THETA_MIN * max(1.0, self.theta_start)

    def reset(self) -> None:
        """Empty, for a new barrier parameter (its φ is another function)."""
        self.entries.clear()

    def admits(self, theta: float, phi: float) -> bool:
        """Whether (θ, φ) is below θ_max and not dominated by an entry."""
        return theta <= self.theta_max and all(theta < t or phi < f for t, f in self.entries)

    def augment(self, theta: float, phi: float) -> None:
        """Add the current point's corner, moved by the margins."""
        self.entries.append(((1.0 - GAMMA_THETA) * theta, phi - GAMMA_PHI * theta))

    def switching(self, alpha: float, slope: float, theta: float) -> bool:
        """Whether the step α along a direction of φ-slope ``slope`` is a φ step: it
        descends, by more than θ^s_θ can explain."""
        return slope < 0.0 and alpha * (-slope) ** S_PHI > DELTA * theta ** S_THETA

    def verdict(self, alpha: float, slope: float, theta: float, phi: float,
                trial_theta: float, trial_phi: float, noise: float) -> str | None:
        """"f" (accepted by Armijo, the filter kept), "h" (accepted by sufficient decrease,
        the filter to be augmented) or None (rejected), for a trial (θ, φ) at step α from
        the current (θ, φ); ``noise``: φ's rounding level."""
        if not self.admits(trial_theta, trial_phi):
            return None
        if theta <= self.theta_min and self.switching(alpha, slope, theta):
            armijo = trial_phi <= phi + ETA_PHI * alpha * slope + noise
            return "f" if armijo else None
        if trial_theta <= (1.0 - GAMMA_THETA) * theta \
                or trial_phi <= phi - GAMMA_PHI * theta + noise:
            return "h"
        return None

    def smallest_step(self, slope: float, theta: float) -> float:
        """α_min (Wächter & Biegler 2006, eq. 23): below it no step can be accepted and the
        line search gives up."""
        if slope < 0.0 and theta <= self.theta_min:
            return GAMMA_ALPHA * min(GAMMA_THETA, GAMMA_PHI * theta / -slope,
                                     DELTA * theta ** S_THETA / (-slope) ** S_PHI)
        if slope < 0.0:
            return GAMMA_ALPHA * min(GAMMA_THETA, GAMMA_PHI * theta / -slope)
        return GAMMA_ALPHA * GAMMA_THETA
