"""First guesses a user can give (issue 53, item 2; ``_runtime/bvp/guesses.py``): a function
t ↦ State on any groupoid, and a previous result at another number of steps, resampled
on the groupoid. Each solve is checked against the optimum from the default guess or the
exact discrete solution, never against itself.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm, logm

from symvi import State
from symvi.models import get
from symvi.models.rigid_body_oc import quarter_turn


def _geodesic(end: np.ndarray, T: float):
    """t ↦ the State on the one-parameter subgroup from I to ``end`` over [0, T]."""
    A = np.real(logm(end)) / T
    return lambda t: State(g=expm(t * A), v=np.zeros(3 if end.shape[0] == 3 else 6))


def test_a_function_of_time_on_so3_and_se3(compiled):
    """guess=lambda t: State(g=…): on SO(3) the slew's optimum from the default guess to
    rounding; on SE(3) the minimum-snap path between four fixed poses at each end is the
    exact discrete solution the step map integrates (a quintic ξ), reached from a
    one-parameter subgroup through the end pose."""
    slew = compiled("rigid_body_oc")
    ex = get("rigid_body_oc").example
    default = slew.solve_bvp(ex.start, ex.end, 100, 0.01)
    guessed = slew.solve_bvp(ex.start, ex.end, 100, 0.01, guess=_geodesic(quarter_turn(), 1.0))
    assert default.success and guessed.success
    assert np.abs(guessed.g - default.g).max() <= 1e-12
    snap, sx = compiled("se3_snap"), get("se3_snap").example
    exact = snap.integrate(sx.run_from, 40, sx.h).g
    solved = snap.solve_bvp(exact[:4], exact[-4:], 40, sx.h,
                            guess=_geodesic(exact[-1], 40 * sx.h))
    assert solved.success, solved.message
    assert np.abs(solved.g - exact).max() <= 1e-11


def test_a_function_of_time_reads_its_states_at_the_nodes(compiled):
    """From States the nodes lie at the half steps, t_j = (j − ½)h: the optimum's own
    configurations, looked up by time, start the solve at the optimum, which Newton
    confirms in one iteration (read at j·h instead, half a step off, it took 7)."""
    mod = compiled("rigid_body_oc")
    ends = State(g=np.eye(3), v=np.zeros(3)), State(g=quarter_turn(), v=np.zeros(3))
    fixed = mod.solve_bvp(*ends, 50, 1 / 50)
    assert fixed.success and fixed.t[0] == pytest.approx(-0.01)

    def along(t: float) -> State:
        return State(g=fixed.g[np.argmin(np.abs(fixed.t - t))], v=np.zeros(3))
    again = mod.solve_bvp(*ends, 50, 1 / 50, guess=along)
    assert again.success and again.iterations == 1, again.message
    assert np.abs(again.g - fixed.g).max() <= 1e-12


def test_a_previous_result_at_another_n(compiled):
    """The slew with torque limits at N = 50 warm-starts the solve at N = 400 with its
    nodes, multipliers and active set resampled: the optimum from the default guess, in
    fewer iterations; from States with the horizon free, the double integrator at N = 20
    starts N = 80 and T is 2 again."""
    mod = compiled("spacecraft_slew")
    ex = get("spacecraft_slew").example
    coarse = mod.solve_bvp(ex.start, ex.end, 50, 1 / 50)
    default = mod.solve_bvp(ex.start, ex.end, 400, 1 / 400)
    warm = mod.solve_bvp(ex.start, ex.end, 400, 1 / 400, guess=coarse)
    assert coarse.success and default.success and warm.success, warm.message
    assert np.abs(warm.g - default.g).max() <= 1e-9
    assert warm.iterations < default.iterations
    timed = compiled("minimum_time_double_integrator")
    tx = get("minimum_time_double_integrator").example
    first = timed.solve_bvp(tx.start, tx.end, 20, 0.05)
    finer = timed.solve_bvp(tx.start, tx.end, 80, 0.02, guess=first)
    assert first.success and finer.success and abs(finer.T - 2.0) <= 1e-9


def test_guesses_that_cannot_be_read(compiled):
    """A function that returns no State, a State without the configuration a Lie group
    needs, and a previous result from nodes for a solve from States are refused by name."""
    slew = compiled("rigid_body_oc")
    ex = get("rigid_body_oc").example
    with pytest.raises(ValueError, match=r"must return a State, got ndarray at t = 0\.02"):
        slew.solve_bvp(ex.start, ex.end, 100, 0.01, guess=lambda t: np.eye(3))
    with pytest.raises(ValueError, match="needs its configuration g"):
        slew.solve_bvp(ex.start, ex.end, 100, 0.01, guess=lambda t: State(v=np.zeros(3)))
    timed = compiled("minimum_time_double_integrator")
    tx = get("minimum_time_double_integrator").example
    nodes = timed.solve_bvp(np.array([[0.0], [0.0]]), np.array([[1.0], [1.0]]), 20, 0.1)
    with pytest.raises(ValueError, match="boundary data are of its own kind"):
        timed.solve_bvp(tx.start, tx.end, 40, 0.05, guess=nodes)
