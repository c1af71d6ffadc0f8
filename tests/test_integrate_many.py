"""Batches of trajectories: ``integrate_many`` (``symvi/_runtime/step/batch.py``, issue 24).

Each trajectory must be the single ``integrate`` call bit for bit, on one thread or two;
a trajectory whose Newton step fails must keep its own status, message and partial path
while the others complete; bad batches are refused naming the problem.
"""
from __future__ import annotations

import math
import pickle
import threading

import numpy as np
import pytest

from symvi.build import compile_model
from test_errors import fold_model

FIELDS = ("t", "x", "f", "momenta", "energy", "newton_iterations")


def assert_bitwise(batch_result, b: int, single) -> None:
    """Trajectory b of a batch equals the single call's result exactly."""
    mine = batch_result[b]
    assert mine.status == single.status and mine.message == single.message
    for name in FIELDS + ("g", "noether"):
        a, s = getattr(mine, name), getattr(single, name)
        assert (a is None) == (s is None), name
        if a is not None:
            assert a.shape == s.shape and np.array_equal(a, s), (b, name)


def states(module, B: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    return module.State(x=rng.uniform(-1, 1, (B, 2)), v=rng.uniform(-1, 1, (B, 2)))


def test_each_trajectory_is_the_single_call_bit_for_bit(compiled):
    """Double pendulum, 12 states, a length l1 and a step h per trajectory: on 2 threads
    and on 1 every trajectory equals ``integrate`` from its own data exactly."""
    mod = compiled("double_pendulum")
    B, rng = 12, np.random.default_rng(1)
    start, l1, h = states(mod, B), rng.uniform(0.5, 2.0, B), rng.uniform(0.002, 0.01, B)
    two = mod.integrate_many(start, 300, h, {"l1": l1, "m2": 1.5}, workers=2)
    one = mod.integrate_many(start, 300, h, {"l1": l1, "m2": 1.5}, workers=1)
    assert two.success and two.message == "12 of 12 trajectories succeeded"
    assert two.x.shape == (B, 301, 2) and two.energy.shape == (B, 300) and len(two) == B
    for b in range(B):
        single = mod.integrate(mod.State(x=start.x[b], v=start.v[b]), 300, h[b],
                               {"l1": l1[b], "m2": 1.5})
        assert_bitwise(two, b, single)
        assert_bitwise(one, b, single)


def test_lie_group_batches_from_states_and_from_increments(compiled):
    """Rigid body: States (ξ₀ per trajectory, a configuration each) and the node form
    (g₀, ξ) batched on both arrays — configurations bit for bit as the single calls."""
    mod = compiled("rigid_body")
    rng, B = np.random.default_rng(2), 6
    v = rng.uniform(-1, 1, (B, 3))
    g0 = np.stack([_rotation(a) for a in rng.uniform(-1, 1, (B, 3))])
    from_states = mod.integrate_many(mod.State(v=v, g=g0), 200, 0.01)
    from_nodes = mod.integrate_many((g0, v[:, None, :]), 200, 0.01)
    assert from_states.g.shape == (B, 201, 3, 3)
    for b in range(B):
        assert_bitwise(from_states, b, mod.integrate(mod.State(v=v[b], g=g0[b]), 200, 0.01))
        assert_bitwise(from_nodes, b, mod.integrate((g0[b], v[b][None]), 200, 0.01))


def test_a_failing_trajectory_does_not_stop_the_others(tmp_path):
    """L_d = (q₁ − q₀)³/h² − h q₀: d_{k+1}² = d_k² − h³/3, so from d₀² = 0.0105 (h = 0.1)
    the step map has no solution at step 33 and from d₀² = 0.0095 at step 30; d₀ = 0.5
    lasts 750 steps. The failed trajectories keep their statuses, messages and partial
    paths (equal to the single calls'), NaN after them; the third completes."""
    mod = compile_model(fold_model(), tmp_path)
    d0 = np.array([math.sqrt(0.0105), 0.5, math.sqrt(0.0095)])
    nodes = np.stack([np.zeros(3), d0], axis=1)[:, :, None]          # (3, 2, 1)
    r = mod.integrate_many(nodes, 100, 0.1)
    assert not r.success and r.status == mod.Status.MAX_ITERATIONS, r.message
    assert list(r.succeeded) == [False, True, False]
    assert r.message.startswith("1 of 3 trajectories succeeded; failed: trajectory 0 (")
    assert "step 33 of 100" in r.messages[0] and "step 30 of 100" in r.messages[2]
    assert list(r.lengths["x"]) == [33, 101, 30]
    assert np.isnan(r.x[0, 33:]).all() and np.isfinite(r.x[1]).all()
    assert (r.newton_iterations[0, 31:] == -1).all()
    for b in range(3):
        assert_bitwise(r, b, mod.integrate(nodes[b], 100, 0.1))


def test_thinned_and_final_only_batches_keep_the_single_calls_nodes(compiled):
    mod = compiled("double_pendulum")
    start = states(mod, 5, seed=3)
    thinned = mod.integrate_many(start, 1000, 0.005, keep_every=10)
    final = mod.integrate_many(start, 1000, 0.005, final_only=True)
    assert thinned.x.shape == (5, 101, 2) and final.x.shape == (5, 2, 2)
    for b in range(5):
        state = mod.State(x=start.x[b], v=start.v[b])
        assert_bitwise(thinned, b, mod.integrate(state, 1000, 0.005, keep_every=10))
        assert np.array_equal(final.x[b, -1], mod.integrate(state, 1000, 0.005).x[-1])
        assert final.t[b, -1] == pytest.approx(5.0)


def test_results_pickle_and_save(compiled, tmp_path):
    mod = compiled("double_pendulum")
    r = mod.integrate_many(states(mod, 3), 20, 0.01)
    again = pickle.loads(pickle.dumps(r))
    # a pickle loads as symvi's class, which counts as the package's (issue 49)
    assert type(again).__module__ == "symvi._runtime.core.results" and isinstance(again, type(r))
    assert np.array_equal(again.x, r.x)
    assert list(again.statuses) == list(r.statuses) and again.messages == r.messages
    r.save(tmp_path / "batch.npz")
    with np.load(tmp_path / "batch.npz") as saved:
        assert np.array_equal(saved["x"], r.x) and str(saved["status"]) == "SUCCESS"


@pytest.mark.parametrize("call, pattern", [
    (lambda m: m.integrate_many(m.State(x=np.zeros((4, 2)), v=np.zeros((5, 2))), 10, 0.01),
     r"initial: the arrays disagree on the batch size \(the leading axis\): initial\.v has "
     r"5, initial\.x has 4"),
    (lambda m: m.integrate_many(states(m, 4), 10, 0.01, params={"l1": [1.0, 2.0, 3.0]}),
     r"params\['l1'\]: shape \(3,\) does not broadcast against the batch of 4 trajectories"),
    (lambda m: m.integrate_many(states(m, 4), 10, np.full(3, 0.01)),
     r"h: shape \(3,\) does not broadcast against the batch of 4"),
    (lambda m: m.integrate_many(m.State(x=np.zeros(2), v=np.zeros((1, 2))), 10, 0.01),
     r"initial\.x: a batch needs a leading batch axis|disagree on the batch size"),
    (lambda m: m.integrate_many(states(m, 4), 10, 0.01, params={"l1": np.array([1, 1, 0, 1.])}),
     r"trajectory 2: .*l1"),
    (lambda m: m.integrate_many(states(m, 2), 10, 0.01, workers=0), r"workers must be at least 1"),
])
def test_bad_batches_are_refused_naming_the_problem(compiled, call, pattern):
    mod = compiled("double_pendulum")
    with pytest.raises(ValueError, match=pattern):
        call(mod)
    assert not [t for t in threading.enumerate() if t.name.startswith("symvi")]


def test_a_rotation_off_the_group_names_its_trajectory(compiled):
    mod = compiled("rigid_body")
    g0 = np.repeat(np.eye(3)[None], 4, axis=0)
    g0[2, 0, 0] = 1.01
    with pytest.raises(ValueError, match=r"trajectory 2: .*(rotation|orthogonal|SO\(3\))"):
        mod.integrate_many(mod.State(v=np.ones((4, 3)), g=g0), 10, 0.01, workers=2)
    assert not [t for t in threading.enumerate() if t.name.startswith("symvi")]


@pytest.mark.parametrize("B, n_steps, keep", [(4, 3_000_000, 1000), (20_000, 1000, 1000)],
                         ids=["long runs one by one", "short runs in C slices"])
def test_ctrl_c_stops_every_worker_promptly(compiled, B, n_steps, keep, ctrl_c):
    """Ctrl-C 0.2 s into a batch of about 4 s of work — four 3·10⁶-step runs (the chunked
    single loop), or 2·10⁴ runs of 10³ steps (the batch loop in C, slice by slice): the
    batch raises KeyboardInterrupt within half a second and no worker thread is left."""
    import time

    mod = compiled("double_pendulum")
    start = states(mod, B)
    began = ctrl_c()
    with pytest.raises(KeyboardInterrupt):
        mod.integrate_many(start, n_steps, 0.001, workers=2, keep_every=keep)
    assert time.perf_counter() - began < 0.7
    assert not [t for t in threading.enumerate() if t.name.startswith("symvi")]


def test_a_singular_legendre_transform_names_its_trajectory(build_dir):
    """The transforms of a slice are solved together; where one is singular (m = 0 for
    trajectory 2 of a pendulum whose parameters may vanish) the error names it and says
    what the single call says."""
    import sympy as sp
    from symvi import Model, PairGroupoid

    G = PairGroupoid("theta")
    (theta,), (omega,) = G.q, G.qdot
    m, l, g = sp.symbols("m l g", real=True)
    mod = compile_model(Model("pendulum_unsigned", G, lagrangian=m * l**2 * omega**2 / 2
                              + m * g * l * sp.cos(theta), parameters={m: 1.0, l: 1.0, g: 9.81}),
                        build_dir)
    with pytest.raises(ValueError) as batch:
        mod.integrate_many(mod.State(x=np.zeros((4, 1)), v=np.ones((4, 1))), 10, 0.1,
                           {"m": np.array([1.0, 2.0, 0.0, 1.0])})
    with pytest.raises(ValueError) as single:
        mod.integrate(mod.State(x=[0.0], v=[1.0]), 10, 0.1, {"m": 0.0})
    assert "singular" in str(single.value)
    assert str(batch.value) == f"trajectory 2: {single.value}"


def _rotation(a: np.ndarray) -> np.ndarray:
    """exp of the skew matrix of a (Rodrigues)."""
    theta = np.linalg.norm(a)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]]) / theta
    return np.eye(3) + np.sin(theta) * K + (1 - np.cos(theta)) * K @ K


def test_overflowing_outputs_are_never_a_success(compiled):
    """Trajectories whose energies overflow (|x| = 1e160, 1e300) end NON_FINITE in a batch
    as alone — same status and message as the single call — beside one that succeeds."""
    mod = compiled("harmonic_oscillator")
    x = np.array([[1.0], [1e160], [1e300]])
    batch = mod.integrate_many(mod.State(x=x, v=np.zeros((3, 1))), 10, 0.1)
    assert [mod.Status(s).name for s in batch.statuses] == ["SUCCESS", "NON_FINITE",
                                                            "NON_FINITE"]
    assert not batch.success
    for b in range(3):
        single = mod.integrate(mod.State(x=x[b], v=[0.0]), 10, 0.1)
        assert (batch.statuses[b], batch.messages[b]) == (single.status, single.message)
    assert "overflow double precision" in batch.messages[2]
