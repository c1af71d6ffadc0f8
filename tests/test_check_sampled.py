"""The ``equations`` check: a sampled-point verdict first, the symbolic location after,
within the check's budget (issue 53, item 3).

The triple pendulum of ``sympy.physics.mechanics`` (three uniform links on pin joints,
the model by :func:`symvi.mechanics.from_system`) against ``LagrangesMethod``'s equations:
a verdict (pass) within the default budget, a doubled gravity term of link 3 located as
exactly that term, and with no budget left the sampled verdict alone with a note. The
same display against a model written with cos(q₁ − q₂) (trigsimp's form) agrees — it
took 25 s and failed before, the symbolic solve of the 3×3 mass matrix. The Chaplygin
sled: its derived constraints hold (sin²θ + cos²θ)·m·u̇, simplified so that a sign slip in
the unactuated equation and a spurious term are located term by term; the constraints
target wants the kinematic constraints too, and says so.
"""
from __future__ import annotations

import pytest
import sympy as sp
import sympy.physics.mechanics as me

from symvi.checks import check
from symvi.checks.equations import HandDerived, compare
from symvi.checks.equivalence import show, simplified
from symvi.checks.sampled import sampled_equations
from symvi.mechanics import from_lagrangian, from_system
from symvi.models import get

m = sp.symbols("m1:4", positive=True)
l = sp.symbols("l1:4", positive=True)
g = sp.Symbol("g", positive=True)
PARAMETERS = {**{s: 1.0 for s in m + l}, g: 9.81}


@pytest.fixture(scope="module")
def pendulum():
    """(model, LagrangesMethod's three equations, q(t)) of the triple pendulum: uniform
    links of mass m_i, length l_i, inertia m_i l_i²/12, joined by pins; gravity −g·y."""
    q, u = me.dynamicsymbols("q1:4"), me.dynamicsymbols("u1:4")
    ground = me.RigidBody("ground")
    links = []
    for i in range(3):
        link = me.RigidBody(f"link{i + 1}", frame=me.ReferenceFrame(f"L{i + 1}"), mass=m[i])
        link.inertia = (me.inertia(link.frame, 0, 0, m[i] * l[i]**2 / 12), link.masscenter)
        links.append(link)
    system = me.System.from_newtonian(ground)
    parent = ground
    for i, link in enumerate(links):
        joint = me.PinJoint(f"J{i + 1}", parent, link, coordinates=q[i], speeds=u[i],
                            parent_point=(0 if i == 0 else -l[i - 1] / 2) * parent.frame.x,
                            child_point=l[i] / 2 * link.frame.x, joint_axis=ground.frame.z)
        system.add_joints(joint)
        parent = link
    system.apply_uniform_gravity(-g * ground.frame.y)
    model = from_system(system, name="triple_pendulum", parameters=PARAMETERS)
    for link in links:
        link.potential_energy = link.mass * g * link.masscenter.pos_from(
            ground.masscenter).dot(ground.frame.y)
    L = me.Lagrangian(ground.frame, *links).xreplace(
        {ui: qi.diff() for ui, qi in zip(u, q)})
    return model, list(me.LagrangesMethod(L, q).form_lagranges_equations()), q, L


def test_lagranges_method_display_passes_within_the_default_budget(pendulum):
    """The verdict is the sampled points', inside the default budget whatever the load;
    the term-by-term pairing follows where the budget leaves time (unloaded, 2 s of 20),
    and with no budget it always does."""
    model, equations, _, _ = pendulum
    display = [HandDerived("LagrangesMethod", "euler_lagrange", equations)]
    result = check(model, only="equations", equations=display)["equations"]
    assert result.status == "pass", result.details
    rows = [r["message"] for r in result.data["comparisons"][0]["equations"]]
    paired = [f"= derived eq. {i}" for i in (1, 2, 3)]
    assert rows == paired if "skipped_for_budget" not in result.data else \
        rows == ["agrees at 4 random points"] * 3
    unlimited = check(model, only="equations", equations=display, budget=None)["equations"]
    assert [r["message"] for r in unlimited.data["comparisons"][0]["equations"]] == paired


def _plain(expr, q):
    """``expr`` with q_i(t) written as the plain symbols q_i of the messages."""
    return expr.xreplace({qi: sp.Symbol(str(qi.func)) for qi in q})


def test_doubled_gravity_of_link_3_is_located_exactly(pendulum):
    """Link 3's gravity term G = ∂V₃/∂q₃ in the third equation, written twice: the row is
    paired with derived eq. 3 and differs in G alone, 2G where G is right."""
    model, equations, q, _ = pendulum
    gravity = sp.expand(equations[2] - equations[2].subs(g, 0))
    assert gravity.free_symbols >= {g, l[2], m[2]} and not gravity.has(l[0], l[1])
    slip = equations[:2] + [equations[2] + gravity]
    result = compare(HandDerived("LagrangesMethod", "euler_lagrange", slip), model)
    assert [r.ok for r in result.equations] == [True, True, False]
    G = _plain(gravity, q)
    assert result.equations[2].message == (
        f"vs derived eq. 3: {show(sp.factor(2 * G))} where {show(sp.factor(G))} is right "
        f"(2 times the right one)")


def test_without_budget_the_sampled_verdict_stands_with_a_note(pendulum):
    """No budget left for the location: the rows are still judged (at sampled points) and
    the report says that, and why, where is not told."""
    model, equations, _, _ = pendulum
    slip = equations[:2] + [2 * equations[2] - equations[2].subs(g, 0)]
    report = check(model, only="equations", budget=1e-6,
                   equations=[HandDerived("display", "euler_lagrange", slip)])
    result = report["equations"]
    assert result.status == "fail"
    label = "location of the differences in display"
    assert result.data["skipped_for_budget"] == (label,)
    note = f"{label} skipped: over the check's time budget of 1e-06 s (--budget)"
    assert result.details == (
        f"display, eq. 3: differs from the derived euler_lagrange at 4 random points; "
        f"where is not located: {note}", f"display: {note}", "agree: display (eq. 1, eq. 2)")
    assert f"skipped for the time budget: equations ({label})" in report.format()


def test_a_model_in_sines_of_differences_agrees_with_the_expanded_display():
    """Point masses on absolute angles, the model's Lagrangian trigsimp'd to cos(q_i − q_j)
    and the display LagrangesMethod's, in products sin q_i sin q_j + cos q_i cos q_j:
    the same equations, found so term by term once the sums are expanded."""
    q = me.dynamicsymbols("q1:4")
    N, O = me.ReferenceFrame("N"), me.Point("O")
    O.set_vel(N, 0)
    points, particles = [O], []
    for i in range(3):
        frame = N.orientnew(f"A{i}", "Axis", [q[i], N.z])
        P = points[-1].locatenew(f"P{i}", l[i] * frame.x)
        P.v2pt_theory(points[-1], N, frame)
        particle = me.Particle(f"p{i}", P, m[i])
        particle.potential_energy = -m[i] * g * P.pos_from(O).dot(N.x)
        points.append(P)
        particles.append(particle)
    L = me.Lagrangian(N, *particles)
    model = from_lagrangian(sp.trigsimp(L), q, name="triple", parameters=PARAMETERS)
    assert model.lagrangian.has(sp.cos(model.groupoid.q[0] - model.groupoid.q[1]))
    equations = me.LagrangesMethod(L, q).form_lagranges_equations()
    result = compare(HandDerived("LagrangesMethod", "euler_lagrange", list(equations)), model)
    assert result.ok, result.details()


# -- the Chaplygin sled ------------------------------------------------------------------
SLED = get("chaplygin_sled")
x, y, th, v, w, x_dot, y_dot, th_dot, v_dot, w_dot = SLED.groupoid.continuous_symbols(1)
M, I, a = sp.symbols("m I a", positive=True)
KINEMATIC = [x_dot - v * sp.cos(th) + a * w * sp.sin(th),
             y_dot - v * sp.sin(th) - a * w * sp.cos(th), th_dot - w]


def test_sin_squared_plus_cos_squared_is_one_in_the_derived_constraints():
    forward = SLED.constraints[3]
    assert forward.has(sp.sin(th)**2)
    assert simplified(forward) == M * (v_dot - a * w**2)
    assert simplified(sp.sin(th)**2 * v_dot) == sp.sin(th)**2 * v_dot     # not shorter


@pytest.mark.parametrize("row, located", [
    (M * v_dot + a * M * w**2, "a*m*omega**2 where -a*m*omega**2 is right (wrong sign)"),
    (M * v_dot - a * M * w**2 + M * v * w, "spurious m*omega*u"),
])
def test_sled_slips_in_the_unactuated_equation_are_located_term_by_term(row, located):
    result = compare(HandDerived("sled", "constraints", KINEMATIC + [row]), SLED)
    assert [r.ok for r in result.equations] == [True, True, True, False]
    assert result.equations[3].message == f"vs derived eq. 4: {located}"


def test_sled_control_sign_slip_is_one_term():
    row = sp.Symbol("u1") - (I + M * a**2) * w_dot + M * a * v * w
    (line,) = compare(HandDerived("sled", "controls", [row]), SLED).details()
    assert line == ("sled, eq. 1: vs derived eq. 1 × -1: a*m*omega*u where -a*m*omega*u is "
                    "right (wrong sign)")


def test_constraints_target_names_the_kinematic_constraints_it_also_wants():
    result = compare(HandDerived("sled", "constraints", [M * v_dot - a * M * w**2]), SLED)
    assert result.equations[0].ok and not result.ok
    message = result.equations[1].message
    assert message.startswith("determines only 1 of the 4 unknowns")
    assert ("no row is eq. 1: a*omega*sin(theta) - u*cos(theta) + x_dot = 0; eq. 2: "
            "-a*omega*cos(theta) - u*sin(theta) + y_dot = 0; eq. 3: -omega + theta_dot = 0. "
            "The constraints target is every constraint of the model") in message
    assert compare(HandDerived("sled", "constraints", [M * v_dot - a * M * w**2],
                               select=[3]), SLED).ok


# -- the sampled verdict itself ----------------------------------------------------------
def test_sampled_verdict_on_recombined_slipped_and_missing_equations():
    """D: ẍ + k y = 0, ÿ − x = 0 in the unknowns ẍ, ÿ. A recombination with coefficients
    in the state agrees; a slip in one term is that row; one row alone determines one
    unknown."""
    X, Y, Xdd, Ydd, k = sp.symbols("X Y Xdd Ydd k")
    D = [Xdd + k * Y, Ydd - X]
    unknowns, variables = [Xdd, Ydd], [X, Y, Xdd, Ydd]
    mixed = [(1 + X**2) * D[0] + sp.sin(Y) * D[1], k * D[1]]
    verdict = sampled_equations(mixed, D, unknowns, variables)
    assert verdict.ok and verdict.rank == 2
    slip = sampled_equations([D[0] + 1e-3 * X, D[1]], D, unknowns, variables)
    assert slip.rows == (False, True) and not slip.ok
    alone = sampled_equations([D[1]], D, unknowns, variables)
    assert alone.rows == (True,) and alone.rank == 1 and not alone.ok
    paired = sampled_equations([k * D[1], 3 * D[0]], D, None, variables)
    assert paired.rows == (True, True) and paired.pairs == (1, 0)
