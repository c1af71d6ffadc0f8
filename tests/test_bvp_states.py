"""States (position, velocity) as boundary data of the whole-trajectory solve (issue 22).

Each State fixes the element whose midpoint it is, so the windows are centred at
(k + ½)h and the discrete cost is the midpoint rule on [0, T]. The tests measure what
that buys against exact optima: order 2 in h for the cost, the path and the controls,
where nodes given directly (the velocity pinned at h/2, the sum over [h/2, T − h/2])
give order 1.
"""
import pickle

import numpy as np
import pytest
import sympy as sp

from symvi import SE2, State, optimal_control
from symvi.models import get
from symvi.models.rigid_body_oc import quarter_turn

STEPS = (25, 50, 100, 200)


def orders(errors) -> np.ndarray:
    """Observed orders between successive halvings of h."""
    errors = np.asarray(errors, dtype=float)
    return np.log2(errors[:-1] / errors[1:])


def se2(theta: float, x: float, y: float) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s, x], [s, c, y], [0.0, 0.0, 1.0]])


@pytest.fixture(scope="module")
def planar_body_oc(build_dir):
    """The fully actuated planar body on SE(2): L = ½(ω² + v₁² + v₂²), body-frame torque
    and forces u, cost ½∫|u|². The world-frame motion is ẍ = R(θ)(f₁, f₂), θ̈ = τ and
    |R f| = |f|, so the optimum decouples into three rest-to-rest cubics."""
    from symvi.build import compile_model
    G = SE2()
    omega, v1, v2 = G.xi
    u = sp.symbols("tau f1 f2", real=True)
    model = optimal_control("planar_body_oc", G, (omega**2 + v1**2 + v2**2) / 2,
                            sum(c**2 for c in u) / 2, u)
    return compile_model(model, build_dir)


def test_planar_body_rest_to_rest_converges_at_order_two(planar_body_oc):
    """Rest to rest in T = 2 to (θ, x, y) = (π/2, 2, 1): each coordinate is the cubic
    d(3s² − 2s³), s = t/T, with ∫q̈² = 12d²/T³, so J* = ½·12/T³·(π²/4 + 2² + 1²)."""
    T, target = 2.0, np.array([np.pi / 2, 2.0, 1.0])
    exact_cost = 0.5 * 12 / T**3 * float(target @ target)
    costs, paths, controls, node_costs = [], [], [], []
    for N in STEPS:
        r = planar_body_oc.solve_bvp(State(g=np.eye(3), v=np.zeros(3)),
                                     State(g=se2(*target), v=np.zeros(3)), N, T=T)
        assert r.success, r.message
        assert r.T == T and r.t_states.shape == (N + 1,) and r.t_states[-1] == T
        s = r.t_states / T
        theta, x, y = target[:, None] * (3 * s**2 - 2 * s**3)
        exact = np.stack([se2(*c) for c in zip(theta, x, y)])
        paths.append(np.abs(r.states.g - exact).max())
        costs.append(abs(r.cost - exact_cost))
        # the torque and the body-frame forces R(θ)ᵀ ẍ at the windows' centres
        sc = r.t_controls / T
        acc = target[:, None] * (6 - 12 * sc) / T**2
        th = target[0] * (3 * sc**2 - 2 * sc**3)
        body = np.stack([acc[0], np.cos(th) * acc[1] + np.sin(th) * acc[2],
                         -np.sin(th) * acc[1] + np.cos(th) * acc[2]], axis=1)
        controls.append(np.abs(r.controls - body).max())
        nodes = planar_body_oc.solve_bvp([np.eye(3)] * 2, [se2(*target)] * 2, N, T=T)
        node_costs.append(abs(nodes.cost - exact_cost))
    for name, errors in (("cost", costs), ("path", paths), ("controls", controls)):
        assert np.all(np.abs(orders(errors) - 2) < 0.1), (name, errors, orders(errors))
    assert costs[-1] < 2e-3 * exact_cost
    # the node form, on the same grid, is first order: what the States repair
    assert np.all(np.abs(orders(node_costs) - 1) < 0.15), orders(node_costs)


def test_rigid_body_slew_cost_converges_at_order_two(compiled):
    """The paper's slew (§3.3.4) from rest to rest: the cost against its Richardson
    extrapolation, and the node form's for contrast."""
    mod, end = compiled("rigid_body_oc"), quarter_turn()
    steps = STEPS + (400,)
    states, nodes = [], []
    for N in steps:
        r = mod.solve_bvp(State(g=np.eye(3), v=np.zeros(3)), State(g=end, v=np.zeros(3)),
                          N, T=1.0)
        assert r.success, r.message
        np.testing.assert_allclose(r.states.g[-1], end, rtol=0, atol=1e-14)
        states.append(r.cost)
        nodes.append(mod.solve_bvp([np.eye(3)] * 2, [end] * 2, N, T=1.0).cost)
    assert np.all(np.abs(orders(np.diff(states)) - 2) < 0.1), orders(np.diff(states))
    first = orders(np.diff(nodes))      # 1.12, 1.06, 1.03: the h² term fading
    assert abs(first[-1] - 1) < 0.05 and np.all(first < 1.2), first
    extrapolated = states[-1] + (states[-1] - states[-2]) / 3
    assert abs(states[-1] - extrapolated) < 1e-4 * extrapolated


def hermite(t, q0, v0, q1, v1, T):
    """The cubic q0 + v0 t + a t² + b t³ from (q0, v0) at 0 to (q1, v1) at T, and its
    ∫½|q̈|² = ½ Σ (4a²T + 12ab T² + 12b²T³)."""
    a = (3 * (q1 - q0) / T - 2 * v0 - v1) / T
    b = (-2 * (q1 - q0) / T + v0 + v1) / T**2
    t = np.asarray(t)[:, None]
    q = q0 + v0 * t + a * t**2 + b * t**3
    return q, 0.5 * float(np.sum(4 * a * a * T + 12 * a * b * T**2 + 12 * b * b * T**3))


def test_cubic_spline_between_states_with_velocities(compiled):
    """L = ½|q̈|² between two general states: the Hermite cubic is the optimum. Cost,
    states and velocities converge at order 2; the given states are the solution's
    first and last states; the node form with the nodes the States fix is the same
    solve, bit for bit."""
    from symvi._runtime.bvp import boundary_states
    mod, T = compiled("cubic_spline"), 1.5
    q0, v0, q1, v1 = (np.array(a) for a in ([0.0, 1.0], [1.0, -1.0], [1.0, 0.0], [0.5, 2.0]))
    costs, paths = [], []
    for N in STEPS:
        r = mod.solve_bvp(State(x=q0, v=v0), State(x=q1, v=v1), N, T=T)
        assert r.success, r.message
        q, cost = hermite(r.t_states, q0, v0, q1, v1, T)
        costs.append(abs(r.cost - cost))
        paths.append(np.abs(r.states.x - q).max())
        for k, (q_k, v_k) in ((0, (q0, v0)), (-1, (q1, v1))):
            np.testing.assert_allclose(r.states.x[k], q_k, rtol=0, atol=1e-15)
            np.testing.assert_allclose(r.states.v[k], v_k, rtol=0, atol=1e-13)
    for errors in (costs, paths):
        assert np.all(np.abs(orders(errors) - 2) < 0.1), (errors, orders(errors))
    h = T / STEPS[-1]
    p = mod.model.params(None)
    start = boundary_states.element_nodes(mod.model, State(x=q0, v=v0), h, p, "start")
    end = boundary_states.element_nodes(mod.model, State(x=q1, v=v1), h, p, "end")
    nodes = mod.solve_bvp(start, end, STEPS[-1] + 1, h)
    np.testing.assert_array_equal(nodes.x, r.x)
    assert nodes.cost == r.cost
    np.testing.assert_allclose(r.t, (np.arange(STEPS[-1] + 2) - 0.5) * h, rtol=0, atol=1e-15)


def test_group_states_with_velocities_are_recovered_and_warm_start(compiled, tmp_path):
    """Moving end states on SO(3) are the solution's own first and last states; a warm
    start from a States result (other inertia) agrees with the cold solve; the states
    are saved and pickled."""
    mod = compiled("rigid_body_oc_exp")
    start = State(g=np.eye(3), v=[0.3, -0.2, 0.1])
    end = State(g=quarter_turn(), v=[-0.1, 0.4, 0.2])
    r = mod.solve_bvp(start, end, 60, T=1.0)
    assert r.success, r.message
    for k, state in ((0, start), (-1, end)):
        np.testing.assert_allclose(r.states.g[k], state.g, rtol=0, atol=1e-14)
        np.testing.assert_allclose(r.states.v[k], state.v, rtol=0, atol=1e-13)
    again = mod.solve_bvp(start, end, 60, T=1.0, guess=r)
    assert again.success and again.iterations <= 1 and again.cost == pytest.approx(r.cost)
    params = {"I2": 2.5}
    warm = mod.solve_bvp(start, end, 60, T=1.0, params=params, guess=r)
    cold = mod.solve_bvp(start, end, 60, T=1.0, params=params)
    assert warm.success and cold.success, (warm.message, cold.message)
    assert warm.cost == pytest.approx(cold.cost, rel=1e-11)
    np.testing.assert_allclose(warm.states.g, cold.states.g, rtol=0, atol=1e-9)
    r.save(tmp_path / "r.npz")
    with np.load(tmp_path / "r.npz") as saved:
        np.testing.assert_array_equal(saved["states_g"], r.states.g)
        np.testing.assert_array_equal(saved["t_states"], r.t_states)
    again = pickle.loads(pickle.dumps(r))
    np.testing.assert_array_equal(again.states.v, r.states.v)
    assert again.T == 1.0


def test_underactuated_and_bounded_problems_take_states(compiled):
    """The cart-pole's constraints (its unactuated pole) and the bounded slew's interior
    point both run on the States' grid: the cost's Richardson differences fall at order
    2, and the bounded solve keeps its end states."""
    mod = compiled("cart_pole_oc")
    rest = State(x=[0.0, 0.0], v=[0.0, 0.0])
    costs = []
    for N in (40, 80, 160, 320):
        r = mod.solve_bvp(rest, State(x=[1.0, 0.0], v=[0.0, 0.0]), N, T=2.0)
        assert r.success, r.message
        costs.append(r.cost)
    assert np.all(np.abs(orders(np.diff(costs)) - 2) < 0.15), orders(np.diff(costs))
    ex = get("spacecraft_slew").example
    end = State(g=np.asarray(ex.end[-1]), v=np.zeros(3))
    r = compiled("spacecraft_slew").solve_bvp(State(g=np.asarray(ex.start[0]), v=np.zeros(3)),
                                              end, ex.n_steps, T=ex.n_steps * ex.h)
    assert r.success, r.message
    np.testing.assert_allclose(r.states.g[-1], end.g, rtol=0, atol=1e-13)


@pytest.mark.parametrize("name, start, end, match", [
    ("cubic_spline", State(x=[0, 0], v=[0, 0]), np.zeros((2, 2)), "States at both ends"),
    ("cubic_spline", State(x=[0, 0], v=[0, 0, 0]), State(x=[1, 0], v=[0, 0]),
     r"start state's velocity v.*shape"),
    ("cubic_spline", State(x=[0, np.nan], v=[0, 0]), State(x=[1, 0], v=[0, 0]),
     "start state's position x"),
    ("rigid_body_oc", State(g=2 * np.eye(3), v=[0, 0, 0]), State(g=np.eye(3), v=[0, 0, 0]),
     "start state's configuration g.*not on SO"),
    ("rigid_body_oc_exp", State(g=np.eye(3), v=[0, 0, 0]), State(g=np.eye(3), v=[900, 0, 0]),
     "end state's velocity is outside the retraction's chart"),
    ("cart_pole_catch", State(x=[0, 0.3], v=[0, 0]), State(x=[0, 0], v=[0, 0]),
     "end is free or given by end conditions"),
    ("planar_flyer", State(x=[2, 0.2], v=[0, 0, 0]), State(x=[-2, 0.2], v=[0, 0, 0]),
     r"inconsistent boundary data or guess: the base point of node 20 differs by 4\.000e\+00"),
    ("pendulum", State(x=[0], v=[0]), State(x=[1], v=[0]), "order-1 problem fixes its end"),
])
def test_bad_state_boundary_data_are_named(compiled, name, start, end, match):
    with pytest.raises(ValueError, match=match):
        compiled(name).solve_bvp(start, end, 20, T=1.0)


def test_batches_and_continuations_take_states(compiled):
    """A batch of States (a leading batch axis on each array) is the single solves, and a
    continuation along a parameter from States warm-starts each point."""
    mod = compiled("cubic_spline")
    starts = State(x=np.zeros((2, 2)), v=np.array([[0.0, 1.0], [1.0, 0.0]]))
    ends = State(x=np.array([[1.0, 0.0], [0.0, 2.0]]), v=np.zeros((2, 2)))
    batch = mod.solve_bvp_many(starts, ends, 40, T=1.0, workers=2, progress=False)
    for b in range(2):
        alone = mod.solve_bvp(State(x=starts.x[b], v=starts.v[b]),
                              State(x=ends.x[b], v=ends.v[b]), 40, T=1.0)
        np.testing.assert_array_equal(batch[b].states.x, alone.states.x)
        assert batch[b].T == 1.0
    slew = compiled("rigid_body_oc")
    rest = np.zeros(3)
    path = slew.continuation(State(g=np.eye(3), v=rest), State(g=quarter_turn(), v=rest), 50,
                             T=1.0, path={"I3": [3.0, 3.2, 3.4]}, progress=False)
    assert path.success, path.message
    cold = slew.solve_bvp(State(g=np.eye(3), v=rest), State(g=quarter_turn(), v=rest), 50,
                          T=1.0, params={"I3": 3.4})
    assert path[-1].cost == pytest.approx(cold.cost, rel=1e-11)


def test_repr_counts_the_states(compiled):
    r = compiled("cubic_spline").solve_bvp(State(x=[0, 0], v=[0, 0]), State(x=[1, 0], v=[0, 0]),
                                           10, T=1.0)
    assert "10 steps, 11 states, 12 nodes" in repr(r)


def test_failed_and_mismatched_results_from_states(compiled):
    """A failed States solve keeps T = N·h; a States result with other steps starts a
    solve from States resampled (the optimum from the default guess); a non-finite path
    attaches no states, without error."""
    import numpy as np
    from dataclasses import replace as replaced
    from symvi._runtime.bvp import boundary_states
    mod = compiled("rigid_body_oc")
    rest = np.zeros(3)
    failed = mod.solve_bvp(State(g=np.eye(3), v=rest), State(g=quarter_turn(), v=rest), 20,
                           T=1.0, maxiter=1)
    assert not failed.success and failed.T == 1.0
    r = mod.solve_bvp(State(g=np.eye(3), v=rest), State(g=quarter_turn(), v=rest), 20, T=1.0)
    ends = State(g=np.eye(3), v=rest), State(g=quarter_turn(), v=rest)
    warm, cold = mod.solve_bvp(*ends, 30, T=1.0, guess=r), mod.solve_bvp(*ends, 30, T=1.0)
    assert warm.success and np.abs(warm.g - cold.g).max() <= 1e-12
    nodes = replaced(r, t=r.t + 0.5 * r.t_states[1], g=np.full_like(r.g, np.nan),
                     states=None, t_states=None)
    again = boundary_states.attach(mod.model, nodes, r.t_states[1], mod.model.params(None))
    assert again.states is None and again.T == 1.0


def test_states_on_an_action_groupoid_times_a_pair_groupoid(compiled):
    """The heavy top with rotors (SO(3) acting on the direction of gravity Γ, times the
    rotor angles' pair groupoid) from States at rest: each end's element has the State at
    its midpoint — Γ moved by the action, θ by ∓hθ̇/2, the attitude by τ(∓hξ/2) — and the
    optimal cost converges at order 2 (against N = 1280; from nodes it is order 1)."""
    from symvi.models.heavy_top_rotors_oc import _rotation_x
    mod = compiled("heavy_top_rotors_oc")
    e3, R = np.array([0.0, 0.0, 1.0]), _rotation_x(0.2)
    ends = (State(x=np.r_[e3, 0.0, 0.0], g=np.eye(3), v=np.zeros(5)),
            State(x=np.r_[R.T @ e3, -1.0, 0.0], g=R, v=np.zeros(5)))
    costs = []
    for N in (40, 80, 160, 1280):
        r = mod.solve_bvp(*ends, N, T=2.0)
        assert r.success, r.message
        costs.append(r.cost)
    errors = np.abs(np.array(costs[:-1]) - costs[-1])
    assert np.all(np.abs(np.log2(errors[:-1] / errors[1:]) - 2) < 0.1), errors
    assert np.abs(r.states.x[[0, -1]] - [ends[0].x, ends[1].x]).max() <= 1e-13
    assert np.abs(r.states.g[-1] - R).max() <= 1e-13 and np.abs(r.states.v[-1]).max() <= 1e-13


def test_a_bad_example_is_refused_when_declared():
    """The Example's boundary data are checked by the declaration itself, before any
    build: a State whose velocity has the wrong size, a configuration off SO(3)."""
    import sympy as sp
    from symvi import SO3, Example, ModelError, optimal_control
    G = SO3()
    u = sp.symbols("tau1 tau2 tau3", real=True)

    def declare(start):
        return optimal_control(name="refused", groupoid=G,
                               lagrangian=sum(w**2 for w in G.xi) / 2,
                               cost=sum(x**2 for x in u) / 2, controls=u,
                               example=Example(h=0.1, n_steps=10, start=start,
                                               end=State(g=np.eye(3), v=np.zeros(3))))
    with pytest.raises(ModelError, match=r"example of model 'refused': the start state's "
                                         r"velocity v has shape \(2,\), expected \(3,\)"):
        declare(State(g=np.eye(3), v=np.zeros(2)))
    with pytest.raises(ModelError, match=r"the start state's configuration g is not on SO3"):
        declare(State(g=2 * np.eye(3), v=np.zeros(3)))
