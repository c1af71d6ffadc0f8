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

from symvi import SE2, SE3, SO3, ActionGroupoid, Example, optimal_control
from symvi.errors import ModelError
from symvi.models import get
from symvi.models.planar_flyer import CENTRE, pose
from symvi.models.rigid_body_oc import quarter_turn

BORESIGHT = np.array([1.0, 0.0, 0.0])
#: The sun midway between the boresight's directions at the ends (35.3° from both):
#: without the cone the boresight passes within 5.8° of it.
SUN = (BORESIGHT + quarter_turn() @ BORESIGHT) / np.linalg.norm(BORESIGHT + quarter_turn() @ BORESIGHT)
CONE = np.radians(25.0)


@pytest.fixture(scope="module")
def world_flyer(build_dir):
    """The planar flyer with its keep-out disc on the world position (g13, g23)."""
    from symvi import compile_model
    flyer = get("planar_flyer")
    G = ActionGroupoid.on_itself(SE2())
    X, (omega, v1, v2) = G.configuration, G.xi
    I, m, r, tau_max, f_max, side = sp.symbols("I m r tau_max f_max side", positive=True)
    tau, f1, f2 = sp.symbols("tau f1 f2", real=True)
    ends = [np.stack([pose(x, 0.0, 0.0)] * 2) for x in (0.0, 4.0)]
    model = optimal_control(
        name="world_flyer", groupoid=G,
        lagrangian=(I * omega**2 + m * (v1**2 + v2**2)) / 2,
        cost=(tau**2 + f1**2 + f2**2) / 2, controls=[tau, f1, f2], actuated=[0, 1, 2],
        parameters={I: 0.5, m: 1.0, r: 0.7, tau_max: 10.0, f_max: 10.0, side: 5.0},
        bounds={tau: (-tau_max, tau_max), f1: (0, f_max), f2: (-side, side)},
        inequalities={"keep-out": r**2 - ((X[0, 2] - CENTRE[0])**2
                                          + (X[1, 2] - CENTRE[1])**2)},
        example=Example(h=flyer.example.h, n_steps=flyer.example.n_steps,
                        start=ends[0], end=ends[1]))
    return compile_model(model, build_dir), ends


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
