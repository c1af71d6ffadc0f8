"""Models from ``sympy.physics.mechanics`` (issue 23, item 3): the bundled robot arm's
Lagrangian gives SymPy mechanics' own equations of motion (Kane's method on the same
System), its discrete flow converges at order 2 to their solution, and systems that are
not Lagrangian, or symbols without values, are refused by name."""
import numpy as np
import pytest
import sympy as sp
from scipy.integrate import solve_ivp
from sympy.physics.mechanics import (PinJoint, RigidBody, System, Torque, dynamicsymbols,
                                     inertia)

from symvi import ModelError, State, euler_lagrange_operator
from symvi.mechanics import from_lagrangian, from_system
from symvi.models import robot_arm


@pytest.fixture(scope="module")
def kane():
    """M(q, u) u̇ = F(q, u) of the arm from SymPy mechanics itself, as functions."""
    system = robot_arm.arm()
    system.form_eoms()
    values = {robot_arm.sp.Symbol(s.name, positive=True): v
              for s, v in robot_arm.model.parameters}
    q, u = list(system.q), list(system.u)
    args = q + u
    M = sp.lambdify(args, system.mass_matrix.xreplace(values), "numpy")
    F = sp.lambdify(args, system.forcing.xreplace(values), "numpy")
    return M, F


def test_arm_lagrangian_gives_sympy_mechanics_equations(kane):
    """EL(L) of the model = M q̈ − F at random states and accelerations."""
    model = robot_arm.model
    A = model.groupoid.algebroid()
    EL = euler_lagrange_operator(A, model.lagrangian).xreplace(dict(model.parameters))
    f = sp.lambdify(list(A.q) + list(A.y) + list(A.ydot), EL, "numpy")
    M, F = kane
    rng = np.random.default_rng(7)
    for _ in range(5):
        q, v, a = rng.uniform(-1.5, 1.5, (3, 3))
        expected = np.asarray(M(*q, *v), dtype=float) @ a - np.asarray(F(*q, *v), dtype=float).ravel()
        np.testing.assert_allclose(np.asarray(f(*q, *v, *a), dtype=float).ravel(), expected,
                                   rtol=1e-11, atol=1e-11)


def test_arm_flow_converges_at_order_two_to_sympy_mechanics(compiled, kane):
    """From State(q₀, q̇₀), the discrete path at T = 0.5 against DOP853 on Kane's
    equations: the error falls by 4 per halving of h; the vertical angular momentum
    (q₁ cyclic) is conserved to the Newton tolerance."""
    mod, (M, F) = compiled("robot_arm"), kane
    q0, v0, T = np.array([0.0, -0.5, 0.8]), np.array([1.0, 0.3, -0.4]), 0.5

    def rhs(_, z):
        q, v = z[:3], z[3:]
        return np.concatenate([v, np.linalg.solve(np.asarray(M(*q, *v), dtype=float),
                                                  np.asarray(F(*q, *v), dtype=float).ravel())])
    exact = solve_ivp(rhs, (0, T), np.concatenate([q0, v0]), method="DOP853", rtol=1e-12,
                      atol=1e-12).y[:3, -1]
    errors = []
    for N in (50, 100, 200):
        r = mod.integrate(State(x=q0, v=v0), N, T / N)
        assert r.success, r.message
        errors.append(np.abs(r.q[-1] - exact).max())
        assert np.abs(r.noether - r.noether[0]).max() < 1e-9
    orders = np.log2(np.array(errors[:-1]) / errors[1:])
    assert np.all(np.abs(orders - 2) < 0.1), (errors, orders)


def pendulum_system(load=None):
    """A particle on a massless rod pinned at the origin, in the vertical plane."""
    theta, omega = dynamicsymbols("theta omega")
    m, l, g = sp.symbols("m l g", positive=True)
    ground = RigidBody("ground")
    bob = RigidBody("bob", mass=m)            # a point mass: no inertia about itself
    bob.inertia = (inertia(bob.frame, 0, 0, 0), bob.masscenter)
    system = System.from_newtonian(ground)
    system.add_joints(PinJoint("pin", ground, bob, coordinates=theta, speeds=omega,
                               joint_axis=ground.frame.z, child_point=-l * bob.frame.x))
    system.apply_uniform_gravity(-g * ground.frame.y)
    if load is not None:
        system.add_loads(load(system, bob, theta))
    return system, theta, (m, l, g)


def test_a_pendulum_from_joints_is_the_pendulum():
    """L = ½ m l² θ̇² − V with V from the uniform gravity force: EL gives
    m l² θ̈ + m g l sin-type terms; compared with the textbook Lagrangian directly."""
    system, theta, (m, l, g) = pendulum_system()
    model = from_system(system, name="pin", parameters={"m": 1.0, "l": 2.0, "g": 9.81})
    q, v = model.groupoid.q[0], model.groupoid.qdot[0]
    M, L_, G_ = (sp.Symbol(n, positive=True) for n in ("m", "l", "g"))
    textbook = M * L_ ** 2 * v ** 2 / 2 - M * G_ * L_ * sp.sin(q)   # bob at l(cos θ, sin θ)
    assert sp.simplify(model.lagrangian - textbook) == 0
    again = from_lagrangian(M * L_ ** 2 * theta.diff() ** 2 / 2, [theta], name="free",
                            parameters={"m": 1.0, "l": 2.0})
    assert again.groupoid.names == ("theta",)


@pytest.mark.parametrize("load, match", [
    (lambda s, bob, th: Torque(s.frame, sp.Symbol("tau") * s.frame.z), "not a force"),
    (lambda s, bob, th: (bob.masscenter, th * s.frame.x), "not constant"),
])
def test_non_lagrangian_loads_are_refused(load, match):
    system, _, _ = pendulum_system(load)
    with pytest.raises(ModelError, match=match):
        from_system(system, name="bad", parameters={"m": 1.0, "l": 2.0, "g": 9.81})


def test_bad_parameters_and_coordinates_are_named():
    system, theta, _ = pendulum_system()
    with pytest.raises(ModelError, match="missing: g; not in the Lagrangian: k"):
        from_system(system, name="bad", parameters={"m": 1.0, "l": 2.0, "k": 3.0})
    x = sp.Symbol("x")
    with pytest.raises(ModelError, match="not a dynamicsymbol"):
        from_lagrangian(x ** 2, [x], name="bad", parameters={})
    with pytest.raises(ModelError, match="still holds"):
        from_lagrangian(theta.diff().diff() ** 2, [theta], name="bad", parameters={})


def double_pendulum_system():
    """The bundled double pendulum's system in SymPy mechanics: absolute angles θ₁, θ₂
    from the downward vertical, point masses on massless rods."""
    from sympy.physics.mechanics import Particle, Point, ReferenceFrame
    th, om = dynamicsymbols("theta1:3"), dynamicsymbols("omega1:3")
    m1, m2, l1, l2, g = sp.symbols("m1 m2 l1 l2 g", positive=True)
    N, O = ReferenceFrame("N"), Point("O")
    O.set_vel(N, 0)
    A, B = N.orientnew("A", "Axis", (th[0], N.z)), N.orientnew("B", "Axis", (th[1], N.z))
    P1 = O.locatenew("P1", l1 * A.x)
    P2 = P1.locatenew("P2", l2 * B.x)
    P1.v2pt_theory(O, N, A)
    P2.v2pt_theory(P1, N, B)
    bobs = [Particle("b1", P1, m1), Particle("b2", P2, m2)]
    system = System(N, O)
    system.add_coordinates(*th)
    system.add_speeds(*om)
    system.add_kdes(*[w - q.diff() for w, q in zip(om, th)])
    system.add_bodies(*bobs)
    system.apply_uniform_gravity(g * N.x)          # N.x points down
    return system


def test_double_pendulum_from_mechanics_is_the_bundled_one(compiled, build_dir):
    """Same Lagrangian, same coordinates: the compiled trajectories agree to 1e-12 over
    2000 steps (the two expression trees round differently, nothing more)."""
    from symvi.build import compile_model
    from symvi.models import get
    bundled = get("double_pendulum")
    model = from_system(double_pendulum_system(), name="mechanics_double_pendulum",
                        parameters={str(s): v for s, v in bundled.parameters})
    assert sp.simplify(model.lagrangian.xreplace(
        {a: b for a, b in zip(model.groupoid.q + model.groupoid.qdot,
                              bundled.groupoid.q + bundled.groupoid.qdot)})
        - bundled.lagrangian) == 0
    ours, theirs = compile_model(model, build_dir), compiled("double_pendulum")
    start = State(x=[0.5, -0.3], v=[0.0, 0.0])
    a, b = ours.integrate(start, 2000, 0.005), theirs.integrate(start, 2000, 0.005)
    assert a.success and b.success
    np.testing.assert_allclose(a.q, b.q, rtol=0, atol=1e-12)


def test_arm_energy_stays_bounded_over_1e5_steps(compiled):
    """The midpoint rule's energy error oscillates without drift: over 10⁵ steps
    (T = 500) it stays within the bound the first 10⁴ steps reach, and within
    O(h²) (0.065 at h = 0.005 over the example's 10⁴ steps)."""
    mod = compiled("robot_arm")
    r = mod.integrate(State(x=[0.0, -0.5, 0.8], v=[1.0, 0.0, 0.0]), 100_000, 0.005)
    assert r.success, r.message
    error = np.abs(r.energy - r.energy[0])
    early, late = error[:10_000].max(), error[-10_000:].max()
    assert early < 0.1 and late < 1.5 * early, (early, late)


def test_constrained_systems_are_refused():
    system, theta, _ = pendulum_system()
    system.add_holonomic_constraints(theta - 1)
    with pytest.raises(ModelError, match="holonomic constraints"):
        from_system(system, name="bad", parameters={"m": 1.0, "l": 2.0, "g": 9.81})
    system, theta, _ = pendulum_system()
    omega = system.u[0]
    system.add_nonholonomic_constraints(omega - 1)
    with pytest.raises(ModelError, match="nonholonomic"):
        from_system(system, name="bad", parameters={"m": 1.0, "l": 2.0, "g": 9.81})


def test_actuators_are_refused_like_loads():
    """SymPy adds actuators' loads only in form_eoms: a torque actuator is refused, not
    silently dropped from the Lagrangian."""
    from sympy.physics.mechanics import TorqueActuator
    system, theta, (m, l, g) = pendulum_system()
    ground = system.bodies[0]
    system.add_actuators(TorqueActuator(-sp.Symbol("k") * theta, ground.frame.z,
                                        system.bodies[1], ground))
    with pytest.raises(ModelError, match="not a force"):
        from_system(system, name="bad", parameters={"m": 1.0, "l": 2.0, "g": 9.81})


def test_arguments_that_are_not_a_lagrangian_or_a_system_are_refused_by_name():
    """``from_lagrangian(None, ...)`` raised ``AttributeError: 'NoneType' object has no
    attribute 'xreplace'``; each argument of the wrong kind is refused by its name."""
    system, theta, _ = pendulum_system()
    rate = theta.diff() ** 2 / 2
    for call, message in [
            (lambda: from_lagrangian(None, [theta], name="bad", parameters={}),
             "bad: lagrangian must be a SymPy expression in the coordinates q(t) and their "
             "rates, got NoneType"),
            (lambda: from_lagrangian(rate, None, name="bad", parameters={}),
             "bad: coordinates must be a list of dynamicsymbols q(t), got None"),
            (lambda: from_lagrangian(rate, theta, name="bad", parameters={}),
             "bad: coordinates must be a list of dynamicsymbols q(t), got theta(t)"),
            (lambda: from_lagrangian(rate, [theta], name="bad", parameters=None),
             "bad: parameters must be a mapping symbol or name → default value, got "
             "NoneType"),
            (lambda: from_system(None, name="bad", parameters={}),
             "bad: system must be a sympy.physics.mechanics.System, got NoneType")]:
        with pytest.raises(ModelError) as info:
            call()
        assert str(info.value) == message
    assert from_lagrangian(rate, (theta,), name="free", parameters={}).order == 1
