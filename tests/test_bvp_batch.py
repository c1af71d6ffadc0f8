"""Many whole-trajectory solves: ``solve_bvp_many`` and ``continuation``
(``symvi/_runtime/bvp/bvp_batch.py``, issue 24, item 2).

Each solve of a batch must be the single ``solve_bvp`` call; a solve that fails (an
infeasible torque limit) keeps its status while the others succeed; a continuation must
reach the cold solves' optima through warm starts, and step over a failed point.
"""
from __future__ import annotations

import numpy as np
import pytest

from symvi.models import get
from so3 import cay, hat

N = 60


@pytest.fixture(scope="module")
def slew(compiled):
    module = compiled("spacecraft_slew")
    ex = get("spacecraft_slew").example
    return module, np.asarray(ex.start, float), np.asarray(ex.end, float), 1.0 / N


def test_each_solve_is_the_single_call(slew):
    """Three end attitudes (the example's, turned further by 0.2 rad about two axes) and a
    torque limit per solve, on two threads: each result is the single solve's (nodes to
    1e-12, cost to 1e-12 relative), all SUCCESS."""
    module, start, end, h = slew
    turns = [np.zeros(3), [0.2, 0.0, 0.0], [0.0, -0.2, 0.1]]
    ends = np.stack([np.array([g @ cay(hat(np.asarray(v, float))) for g in end]) for v in turns])
    limits = np.array([11.0, 12.0, 14.0])
    batch = module.solve_bvp_many(np.repeat(start[None], 3, axis=0), ends, N, h,
                                  {"tau_max": limits}, workers=2)
    assert batch.success and batch.message == "3 of 3 solves succeeded", batch.message
    assert batch.stack("g").shape == (3, N + 1, 3, 3) and batch.cost.shape == (3,)
    for b in range(3):
        single = module.solve_bvp(start, ends[b], N, h, {"tau_max": limits[b]})
        assert np.abs(batch[b].g - single.g).max() <= 1e-12
        assert batch.cost[b] == pytest.approx(single.cost, rel=1e-12)


def test_an_infeasible_solve_does_not_stop_the_others(slew):
    """τ_max = 3 admits no quarter turn in T = 1 (below about 9): that solve says
    INFEASIBLE and the batch names it; the other two succeed."""
    module, start, end, h = slew
    starts, ends = (np.repeat(a[None], 3, axis=0) for a in (start, end))
    batch = module.solve_bvp_many(starts, ends, N, h, {"tau_max": [11.0, 3.0, 13.0]})
    assert list(batch.succeeded) == [True, False, True]
    assert batch.status.name == "INFEASIBLE" and not batch.success
    assert batch.message.startswith("2 of 3 solves succeeded; failed: solve 1 (INFEASIBLE: ")
    assert np.isfinite(batch.cost[[0, 2]]).all()


def test_continuation_warm_starts_and_steps_over_a_failure(slew):
    """τ_max along 11 → 3 → 11.5 → 13: the solve at 3 fails (warm-started from 11's
    optimum it stalls, saying the bounds may admit no solution; cold it is INFEASIBLE);
    11.5 starts warm from 11's result, 13 from 11.5's, and both reach the cold solves'
    costs (1e-9 relative) through the active-set Newton of a warm start."""
    module, start, end, h = slew
    path = module.continuation(start, end, N, h, path={"tau_max": [11.0, 3.0, 11.5, 13.0]})
    assert list(path.succeeded) == [True, False, True, True], path.message
    assert "solve 1 (STALLED" in path.message and "may admit no solution" in path[1].message
    for k, tau in ((2, 11.5), (3, 13.0)):
        assert "warm start" in path[k].message, path[k].message
        cold = module.solve_bvp(start, end, N, h, {"tau_max": tau})
        assert path.cost[k] == pytest.approx(cold.cost, rel=1e-9)


@pytest.mark.parametrize("call, pattern", [
    (lambda m, s, e, h: m.solve_bvp_many(np.repeat(s[None], 3, 0), np.repeat(e[None], 2, 0),
                                         N, h), r"ends: 2 given for a batch of 3 starts"),
    (lambda m, s, e, h: m.solve_bvp_many(np.repeat(s[None], 2, 0), np.repeat(e[None], 2, 0),
                                         N, h, guesses=[None]),
     r"guesses: 1 given for a batch of 2 solves"),
    (lambda m, s, e, h: m.solve_bvp_many(np.repeat(s[None], 2, 0), np.repeat(e[None], 2, 0),
                                         N, h, {"tau_max": [11.0, -1.0]}),
     r"solve 1: .*tau_max"),
    (lambda m, s, e, h: m.continuation(s, e, N, h, path={"tau_max": [11, 12], "omega_max": [9]}),
     r"path: the sequences differ in length"),
    (lambda m, s, e, h: m.continuation(s, e, N, h), r"continuation needs a path"),
])
def test_bad_batches_are_refused(slew, call, pattern):
    module, start, end, h = slew
    with pytest.raises(ValueError, match=pattern):
        call(module, start, end, h)


def test_ctrl_c_stops_a_batch_of_solves_promptly(slew, ctrl_c):
    """Ctrl-C 0.2 s into about 4 s of solves: KeyboardInterrupt once the solves under way
    end (each a few milliseconds here), and no worker thread left."""
    import threading
    import time

    module, start, end, h = slew
    B = 400
    began = ctrl_c()
    with pytest.raises(KeyboardInterrupt):
        module.solve_bvp_many(np.repeat(start[None], B, 0), np.repeat(end[None], B, 0), N, h,
                              workers=2)
    assert time.perf_counter() - began < 0.7
    assert not [t for t in threading.enumerate() if t.name.startswith("symvi")]
