"""Inequalities on matrix Lie group configurations (issue 50, item 4):
``ActionGroupoid.on_itself(G)``, the action groupoid of G's right multiplication on itself,
whose base points are the configurations' entries — so a path inequality may use the
world-frame position or the attitude, with its derivative along the group variation.

Each optimum is checked against the same discrete problem written independently: the
world-frame keep-out disc against the bundled planar flyer's body-frame one (base point
g⁻¹·centre), the pointing cone on SO(3) against the sun direction seen from the body
(base point Rᵀs on S², the heavy top's action); and the cone's values from the returned
configurations in NumPy.
"""
from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

from symvi import SE2, SE3, SO3, ActionGroupoid, Example, Model, optimal_control
from symvi.errors import ModelError
from symvi.models import get
from symvi.models.planar_flyer import CENTRE, pose
from symvi.models.rigid_body_oc import quarter_turn

BORESIGHT = np.array([1.0, 0.0, 0.0])
#: The sun midway between the boresight's directions at the ends (35.3° from both):
#: without the cone the boresight passes within 5.8° of it.
SUN = (BORESIGHT + quarter_turn() @ BORESIGHT) / np.linalg.norm(BORESIGHT + quarter_turn() @ BORESIGHT)
CONE = np.radians(25.0)


def _world_flyer_model(name: str, end="fixed"):
    """The planar flyer with its keep-out disc on the world position (g13, g23); ``end``
    as :func:`symvi.optimal_control` takes it."""
    flyer = get("planar_flyer")
    G = ActionGroupoid.on_itself(SE2())
    X, (omega, v1, v2) = G.configuration, G.xi
    I, m, r, tau_max, f_max, side = sp.symbols("I m r tau_max f_max side", positive=True)
    tau, f1, f2 = sp.symbols("tau f1 f2", real=True)
    ends = [np.stack([pose(x, 0.0, 0.0)] * 2) for x in (0.0, 4.0)]
    return optimal_control(
        name=name, groupoid=G,
        lagrangian=(I * omega**2 + m * (v1**2 + v2**2)) / 2,
        cost=(tau**2 + f1**2 + f2**2) / 2, controls=[tau, f1, f2], actuated=[0, 1, 2],
        parameters={I: 0.5, m: 1.0, r: 0.7, tau_max: 10.0, f_max: 10.0, side: 5.0},
        bounds={tau: (-tau_max, tau_max), f1: (0, f_max), f2: (-side, side)},
        inequalities={"keep-out": r**2 - ((X[0, 2] - CENTRE[0])**2
                                          + (X[1, 2] - CENTRE[1])**2)},
        end=end, example=Example(h=flyer.example.h, n_steps=flyer.example.n_steps,
                                 start=ends[0], end=None if end != "fixed" else ends[1]))


@pytest.fixture(scope="module")
def world_flyer(build_dir):
    """The planar flyer with its keep-out disc on the world position (g13, g23)."""
    from symvi import compile_model
    ends = [np.stack([pose(x, 0.0, 0.0)] * 2) for x in (0.0, 4.0)]
    return compile_model(_world_flyer_model("world_flyer"), build_dir), ends


def _slew_with_cone(G, cone, name: str, start, end):
    """The rigid_body_oc slew (inertia diag(1, 2, 3), T = 1) with the inequality
    ``cone`` ≤ 0 on the groupoid ``G``."""
    I = sp.symbols("I1 I2 I3", positive=True)
    u = sp.symbols("tau1 tau2 tau3", real=True)
    Omega = sp.Matrix(G.xi)
    return optimal_control(
        name=name, groupoid=G, lagrangian=(Omega.T * sp.diag(*I) * Omega)[0] / 2,
        cost=sum((ui / Ii) ** 2 for ui, Ii in zip(u, I)) / 2, controls=u,
        parameters=dict(zip(I, (1.0, 2.0, 3.0))), inequalities={"sun": cone},
        example=Example(h=1 / 40, n_steps=40, start=start, end=end))


def test_configuration_entries_of_the_groups():
    """The base coordinates are the entries that vary over the group, in row-major order;
    ``configuration`` puts them in g with the identity's constant entries."""
    for group, entries in ((SE2(), range(6)), (SO3(), range(9)), (SE3(), range(12))):
        G = ActionGroupoid.on_itself(group)
        assert G.configuration_entries == tuple(entries)
        d = group.matrix_dim
        flat = list(G.configuration)
        assert [flat[i] for i in entries] == list(G.q)
        assert flat[len(G.q):] == ([] if group.label == "SO3" else [0] * (d - 1) + [1])
    assert str(ActionGroupoid.on_itself(SE2()).configuration[0, 2]) == "g13"
    with pytest.raises(ModelError, match="only the action of a group on itself"):
        ActionGroupoid(SO3(), "G1 G2 G3", lambda q, W: W.T * q).configuration
    group, position = SE2(), sp.Symbol("x")
    torques = sp.symbols("tau f1 f2", real=True)
    with pytest.raises(ModelError, match=r"uses \['x'\]; .* is written on "
                                         r"ActionGroupoid\.on_itself\(group\)"):
        optimal_control(name="box", groupoid=group, lagrangian=sum(v**2 for v in group.xi),
                        cost=sum(u**2 for u in torques), controls=torques,
                        inequalities=[position - 1])


def test_world_frame_obstacle_is_the_body_frame_one(world_flyer, compiled):
    """The keep-out disc r² − |t − centre|² ≤ 0 on the world position is the planar
    flyer's r² − |g⁻¹·centre|² ≤ 0 (|Rᵀ(centre − t)| = |centre − t|): the same discrete
    problem on another groupoid, so the same optimum — configurations, controls and cost
    to rounding. The base points returned are the configurations' entries."""
    mod, (start, end) = world_flyer
    ex = get("planar_flyer").example
    N = 100
    world = mod.solve_bvp(start, end, N, 4.0 / N)        # configurations alone
    body = compiled("planar_flyer").solve_bvp(ex.start, ex.end, N, 4.0 / N)
    assert world.success and body.success, (world.message, body.message)
    assert np.abs(world.g - body.g).max() <= 1e-9
    assert np.abs(world.controls - body.controls).max() <= 1e-7
    assert world.cost == pytest.approx(body.cost, rel=1e-10)
    assert np.abs(world.x - world.g[:, :2, :].reshape(N + 1, 6)).max() <= 1e-13
    distance = np.hypot(world.g[:, 0, 2] - CENTRE[0], world.g[:, 1, 2] - CENTRE[1])
    assert distance.min() == pytest.approx(0.7, abs=1e-9)   # on the disc, not inside


def test_base_points_must_be_their_configurations(world_flyer):
    """(x, g) pairs are accepted where x is g's entries; a base point that is not, is
    refused by name and node before any work."""
    mod, (start, end) = world_flyer
    x = start[:, :2, :].reshape(2, 6)
    paired, alone = mod.solve_bvp((x, start), end, 20, 0.2), mod.solve_bvp(start, end, 20, 0.2)
    assert paired.success and np.array_equal(paired.g, alone.g)
    shifted = x.copy()
    shifted[1, 2] += 0.5
    with pytest.raises(ValueError, match=r"start base point g13 of node 1 is 0\.5, but the "
                                         r"configuration's entry it stands for is 0"):
        mod.solve_bvp((shifted, start), end, 20, 0.2)


def test_pointing_cone_on_so3(build_dir, compiled):
    """A boresight b that must stay 25° from the sun s, (R b)·s ≤ cos 25°, on SO(3)
    acting on itself, against the same cone written as b·Γ ≤ cos 25° with Γ = Rᵀs on S²
    (Γ·W = WᵀΓ): the same optimum at N = 40 and 400; the cone holds at every node from
    the returned attitudes and touches; the slew without it crosses the cone."""
    from symvi import compile_model
    cos_cone = float(np.cos(CONE))
    A = ActionGroupoid.on_itself(SO3())
    attitude = compile_model(_slew_with_cone(
        A, (A.configuration * sp.Matrix(BORESIGHT)).dot(sp.Matrix(SUN)) - cos_cone,
        "cone_on_attitude", *(np.stack([R] * 2) for R in (np.eye(3), quarter_turn()))),
        build_dir)
    B = ActionGroupoid(SO3(), "G1 G2 G3", lambda q, W: W.T * q)
    sun_ends = [(np.stack([R.T @ SUN] * 2), np.stack([R] * 2))
                for R in (np.eye(3), quarter_turn())]
    sun = compile_model(_slew_with_cone(B, sp.Matrix(BORESIGHT).dot(sp.Matrix(B.q)) - cos_cone,
                                        "cone_on_sun", *sun_ends), build_dir)
    for N in (40, 400):
        a = attitude.solve_bvp(np.stack([np.eye(3)] * 2), np.stack([quarter_turn()] * 2),
                               N, 1 / N)
        b = sun.solve_bvp(*sun_ends, N, 1 / N)
        assert a.success and b.success, (a.message, b.message)
        assert np.abs(a.g - b.g).max() <= 1e-9 and a.cost == pytest.approx(b.cost, rel=1e-10)
        cone = np.einsum("kij,j,i->k", a.g, BORESIGHT, SUN) - cos_cone
        assert cone.max() <= 1e-12 and cone.max() >= -1e-4, cone.max()
    free = compiled("rigid_body_oc").solve_bvp(np.stack([np.eye(3)] * 2),
                                               np.stack([quarter_turn()] * 2), 40, 1 / 40)
    assert (np.einsum("kij,j,i->k", free.g, BORESIGHT, SUN) - cos_cone).max() > 0.05


def _heavy_top_on_itself():
    """The bundled heavy top with its potential on the world height of the centre of
    mass, e₃·Rχ, on SO(3) acting on itself: the bundled S²×SO(3) top's χ·Γ with
    Γ = Rᵀe₃, so the same step map from the same R₀ and ξ₀."""
    G = ActionGroupoid.on_itself(SO3())
    Omega, X = sp.Matrix(G.xi), G.configuration
    I1, I2, I3, mgl = sp.symbols("I1 I2 I3 mgl", positive=True)
    chi = sp.Matrix(sp.symbols("chi1 chi2 chi3", real=True))
    return Model(name="heavy_top_on_itself", groupoid=G,
                 lagrangian=(Omega.T * sp.diag(I1, I2, I3) * Omega)[0] / 2 - mgl * (X * chi)[2],
                 parameters={I1: 1.0, I2: 2.0, I3: 3.0, mgl: 1.0,
                             chi[0]: 0.6, chi[1]: 0.0, chi[2]: 0.8})


def test_step_map_base_points_are_their_configurations(build_dir, compiled):
    """The step map moves x₀ and g₀ by the same increments; on a group acting on itself
    x is g's entries, so initial data whose x₀ is not g₀'s entries would make a path
    whose base points (which the dynamics reads) are not its configurations — returned
    as SUCCESS before: (x₀, f) with g₀ the identity by default, 0.63 apart after 1000
    steps. Such data are refused by coordinate; (g₀, f) and State(v, g) fill x₀ from g₀,
    and give the bundled S²×SO(3) top's attitudes exactly."""
    from symvi import State, compile_model
    mod = compile_model(_heavy_top_on_itself(), build_dir)
    top = compiled("heavy_top")
    c, s = 0.8, 0.6
    R0 = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])      # R₀ᵀe₃ = (0, .6, .8)
    xi = [[0.5, 0.3, 2.0]]
    reference = top.integrate(([0.0, 0.6, 0.8], R0, xi), 200, 0.01)
    for initial in ((R0, xi), (R0.reshape(-1), R0, xi)):
        res = mod.integrate(initial, 200, 0.01)
        assert res.success and np.abs(res.g - reference.g).max() <= 1e-13
        assert np.abs(res.x - res.g.reshape(-1, 9)).max() <= 1e-13
    by_state = mod.integrate(State(v=xi[0], g=R0), 200, 0.01)
    assert np.abs(by_state.g - top.integrate(State(v=xi[0], x=[0.0, 0.6, 0.8], g=R0),
                                             200, 0.01).g).max() <= 1e-13
    with pytest.raises(ValueError, match=r"initial base point g23 of node 0 is -0\.6, but the "
                                         r"configuration's entry it stands for is 0: give "
                                         r"\(g_0, f\)"):
        mod.integrate((R0.reshape(-1), xi), 200, 0.01)          # g₀ the identity
    with pytest.raises(ValueError, match=r"initial base point g23 of node 0 is 0, but"):
        mod.integrate((np.eye(3).reshape(-1), R0, xi), 200, 0.01)
    with pytest.raises(ValueError, match=r"the state's base point g23 of node 0 is -0\.6"):
        mod.integrate(State(v=xi[0], x=R0.reshape(-1)), 200, 0.01)
    with pytest.raises(ValueError, match=r"trajectory 1: initial base point g23"):
        mod.integrate_many((np.stack([R0.reshape(-1)] * 2), np.stack([R0, np.eye(3)]),
                            np.array([xi, xi])), 20, 0.01)


def _kinetic_control(name: str, groupoid):
    """min ½∫|u|² for L = ½|y|², every direction actuated, on ``groupoid``."""
    y = [s for f in groupoid.factors
         for s in (f.xi if hasattr(f, "xi") else f.qdot)]
    u = sp.symbols(f"u1:{len(y) + 1}", real=True)
    return optimal_control(name=name, groupoid=groupoid, lagrangian=sum(v**2 for v in y) / 2,
                           cost=sum(v**2 for v in u) / 2, controls=u)


def test_products_with_a_group_acting_on_itself(build_dir):
    """On SE(2) acting on itself × SE(3) every base coordinate is an SE(2) entry: an
    (x, (g_SE2, g_SE3)) pair — configurations 3×3 and 4×4 — is a pair (it raised NumPy's
    'inhomogeneous shape' from the test for one), the same solve as the configurations
    alone. With a pair factor (θ not an entry) configurations alone are no nodes, and
    the refusal of a base point off its entry does not offer them."""
    from symvi import PairGroupoid, ProductGroupoid, compile_model
    A = ActionGroupoid.on_itself(SE2())
    ragged = compile_model(_kinetic_control("se2_on_itself_se3", ProductGroupoid(A, SE3())),
                           build_dir)
    s0, s1 = (np.stack([np.array([[1.0, 0.0, x], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])] * 2)
              for x in (0.0, 1.0))
    e = np.stack([np.eye(4)] * 2)
    alone = ragged.solve_bvp((s0, e), (s1, e), 20, 0.05)
    paired = ragged.solve_bvp((s0[:, :2].reshape(2, 6), (s0, e)),
                              (s1[:, :2].reshape(2, 6), (s1, e)), 20, 0.05)
    assert alone.success and paired.success
    assert np.abs(paired.g[0] - alone.g[0]).max() == 0.0
    with_pair = compile_model(_kinetic_control("se2_on_itself_theta",
                                               ProductGroupoid(A, PairGroupoid("theta"))),
                              build_dir)
    x = np.hstack([s0[:, :2].reshape(2, 6), np.zeros((2, 1))])
    x[1, 2] = 0.5
    with pytest.raises(ValueError, match=r"start base point g13 of node 1 is 0\.5, but the "
                                         r"configuration's entry it stands for is 0: give "
                                         r"base points equal to their entries$"):
        with_pair.solve_bvp((x, s0), (np.hstack([s1[:, :2].reshape(2, 6), np.ones((2, 1))]),
                                      s1), 20, 0.05)


def test_end_conditions_on_the_configuration(build_dir, world_flyer):
    """End conditions on the configuration's entries (world position, heading's sine)
    and ξ = 0 are the fixed end where they coincide: the same optimum to rounding, from
    the end's guess or from none (the interior point's step where no inertia correction
    up to 10³ descends is not solved with an infinite shift, whose inf·0 NaN warned).
    Nine conditions, all six entries and ξ, are dependent (SE(2) has three directions):
    the interior point's singular matrix says which, as the solve without bounds does."""
    import warnings
    from symvi import compile_model
    fixed, (start, end) = world_flyer
    X, (omega, v1, v2) = ActionGroupoid.on_itself(SE2()).configuration, \
        ActionGroupoid.on_itself(SE2()).xi
    at_rest = {"x": X[0, 2] - 4, "y": X[1, 2], "s": X[1, 0], "w": omega, "v1": v1, "v2": v2}
    six = compile_model(_world_flyer_model("world_flyer_end", at_rest), build_dir)
    nine = compile_model(_world_flyer_model("world_flyer_end9", at_rest | {
        "c": X[0, 0] - 1, "c2": X[1, 1] - 1, "s2": X[0, 1]}), build_dir)
    reference = fixed.solve_bvp(start, end, 40, 0.1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for guess in (end, None):
            res = six.solve_bvp(start, guess, 40, 0.1)
            assert res.success, res.message
            assert np.abs(res.g - reference.g).max() <= 1e-12
            assert res.cost == pytest.approx(reference.cost, rel=1e-12)
    res = nine.solve_bvp(start, end, 40, 0.1)
    assert res.status.name == "SINGULAR_JACOBIAN"
    assert "the end conditions 's', 'c', 'c2', 's2' are dependent" in res.message


def test_the_step_map_of_a_bounded_model_says_it_ignores_the_inequalities(compiled):
    """integrate on a model with inequalities steps the equations without them (a hunt:
    from the flyer's optimum the run entered its keep-out disc with SUCCESS and no word):
    its message says so."""
    mod = compiled("planar_flyer")
    ex = get("planar_flyer").example
    best = mod.solve_bvp(ex.start, ex.end, 100, 0.04)
    run = mod.integrate((best.x[0], best.g[0], best.f[:3]), 100, 0.04)
    assert "without the 7 inequalities, which bind solve_bvp only" in run.message
