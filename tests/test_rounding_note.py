"""The step map's rounding note bounds the error from the run's measured growth, not only
from its polynomial part (issue 53, item 4; ``_runtime/step/stepping.py``).

L = ½q̈² + ½q̇² (three-point rule): its Euler–Lagrange equation q'''' = q̈ has the modes
1, t, e^{t}, e^{−t}. Started on the decaying mode e^{−t}, 5000 steps of h = 0.003 (T = 15):
rounding excites e^{t}, which grows by e^{15} ≈ 3e6 while the path decays. The polynomial
part of the note, ε·n³/3!, is 4.6e-6; a run from the same data one unit in their last
place off ends 2e-2 of the path's size away — the measured bound must cover that.
"""
from __future__ import annotations

import numpy as np
import pytest

from symvi import Model, PairGroupoid
from symvi.build import compile_model

H, STEPS = 0.003, 5000


@pytest.fixture(scope="module")
def unstable(build_dir):
    G = PairGroupoid("q")
    model = Model(name="unstable_quartic", groupoid=G,
                  lagrangian=G.qddot[0]**2 / 2 + G.qdot[0]**2 / 2,
                  discretisation="three_point")
    return compile_model(model, build_dir)


def test_the_note_covers_what_one_ulp_of_the_data_does_on_unstable_dynamics(unstable):
    initial = np.exp(-H * np.arange(4.0))[:, None]
    result = unstable.integrate(initial, STEPS, H)
    note = result.message.split("; note: ", 1)[1]
    assert note.startswith("rounding accumulates along this order-2 step map — its free "
                           "part amplifies it like n^3/3! (4.6e-06 relative over these "
                           "steps) and, measured by a second run from initial data one unit "
                           "in their last place off, up to ")
    stated = float(note.split("up to ", 1)[1].split(" relative", 1)[0])
    off = np.random.default_rng(1).choice((-1.0, 1.0), initial.shape)
    other = unstable.integrate(initial * (1 + np.finfo(float).eps * off), STEPS, H)
    seen = np.abs(other.x - result.x).max() / np.abs(result.x).max()
    assert 1e-3 < seen <= stated < 100 * seen, (seen, stated)


def test_no_second_run_where_no_note_is_due(unstable):
    """Below the note's threshold (ε·n³/3! ≤ 1e-6) there is neither note nor second run."""
    result = unstable.integrate(np.exp(-H * np.arange(4.0))[:, None], 500, H)
    assert result.message == "integrated 500 steps (the first 3 given)"
