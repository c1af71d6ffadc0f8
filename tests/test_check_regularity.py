"""Check ``regularity``: the step-defining matrix is generically non-singular (paper §4.3)."""
from __future__ import annotations


from symvi import Model, PairGroupoid, h
from symvi.checks import check
from symvi.models import get


def test_pendulum_singular_locus_is_stated():
    result = check(get("pendulum"), only=["regularity"])["regularity"]
    assert result.summary.startswith("D₁₂L_d (1×1) has full rank 1")
    # D₁₂L_d = −m l²/h + (h m g l/4) cos((θ₁+θ₂)/2): singular where 4l + g h² cos(…) = 0.
    assert "g*h**2*cos(theta_1/2 + theta_2/2) + 4*l" in result.summary


def test_a_degenerate_direction_is_caught_and_named():
    G = PairGroupoid("x y")
    (x0, y0), (x1, y1) = G.nodes(2)
    # y never couples two nodes: D₁₂L_d = diag(−1/h, 0).
    model = Model(name="degenerate", groupoid=G, order=1,
                  discrete_lagrangian=(x1 - x0)**2 / (2 * h) - h * y0**2)
    result = check(model, only=["regularity"])["regularity"]
    assert result.status == "fail"
    assert "rank 1 < 2" in result.summary
    assert "y_2" in result.details[0] and "x_2" not in result.details[0]
