"""Data that must lie on a group or manifold is checked (issue 20, item 4).

Before, ``so3_cubic.solve_bvp`` to end configurations 2·I returned SUCCESS after 0
iterations, ``rigid_body.integrate`` from g₀ = 0 or 2·I and ``heavy_top.integrate`` from
Γ = (0, 0, 2) or Γ = 0 returned SUCCESS, and small step counts raised LAPACK's or NumPy's
own errors. Each case is now a ValueError naming the argument, the node and the defect, or
a failed status; data on the group (to rounding) is still accepted.
"""
from __future__ import annotations

import numpy as np
import pytest
import sympy as sp
from scipy.linalg import expm
from scipy.spatial.transform import Rotation

from symvi import SE2, SE3, SO3, ActionGroupoid, ModelError
from symvi._runtime.core.geometry import TOLERANCE, group_defect
from symvi.models import get

I3 = np.eye(3)
SHEAR = np.array([[1.0, 0.2, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])


def random_element(group, rng) -> np.ndarray:
    basis = [np.array(E, dtype=float) for E in group.basis]
    return expm(sum(c * E for c, E in zip(rng.normal(size=len(basis)), basis)))


@pytest.mark.parametrize("make", [SO3, SE2, SE3])
def test_invariants_accept_the_group_and_refuse_what_is_off_it(make):
    """exp of random algebra elements lies on the group to rounding; a perturbation of
    1e-6 in any entry of the rotation block, a reflection, and a changed last row do not."""
    group, rng = make(), np.random.default_rng(7)
    invariants, d = group.invariants(), group.matrix_dim
    for _ in range(20):
        g = random_element(group, rng)
        if d == 4:
            g[:3, 3] *= 1e6             # a far translation hides nothing
        assert group_defect(g, invariants)[0] < 1e-12
        for i in range(min(d, 3) if d > 3 else d - (d == 3 and make is SE2)):
            for j in range(i + 1):
                off = g.copy()
                off[i, j] += 1e-6
                assert group_defect(off, invariants)[0] > 100 * TOLERANCE, (i, j)
    reflection = np.eye(d)
    reflection[0, 0] = -1.0
    assert "det g > 0" in group_defect(reflection, invariants)[1]
    if d > 3 or make is SE2:
        bad_row = np.eye(d)
        bad_row[-1, 0] = 0.5
        assert group_defect(bad_row, invariants)[0] > 0.1


@pytest.mark.parametrize("end, condition", [(2 * I3, "gᵀJg = J"), (SHEAR, "gᵀJg = J"),
                                            (np.diag([1.0, 1.0, -1.0]), "det g > 0")])
def test_whole_trajectory_refuses_off_group_ends(compiled, end, condition):
    mod = compiled("so3_cubic")
    R = Rotation.from_rotvec([0.3, -0.2, 0.1]).as_matrix()
    with pytest.raises(ValueError, match=rf"^end configurations: the configuration of node 20 is not on "
                                         rf"SO3: {condition}"):
        mod.solve_bvp([I3, R], [R @ R, end], 20, 0.05)
    ok = mod.solve_bvp([I3, R], [R @ R @ R, R @ R @ R @ R], 20, 0.05)     # on the group
    assert ok.success, ok.message


def test_guess_off_the_group_is_refused_with_its_node(compiled):
    mod = compiled("so3_cubic")
    R = Rotation.from_rotvec([0.3, -0.2, 0.1]).as_matrix()
    guess = np.tile(I3, (17, 1, 1))
    guess[5] = SHEAR
    with pytest.raises(ValueError, match=r"guess of the free configurations: the "
                                         r"configuration of node 7 is not on SO3"):
        mod.solve_bvp([I3, R], [R, R], 20, 0.05, guess=guess)


@pytest.mark.parametrize("g0", [np.zeros((3, 3)), 2 * I3, SHEAR, np.diag([1.0, -1.0, 1.0])])
def test_step_map_refuses_an_off_group_start(compiled, g0):
    with pytest.raises(ValueError, match=r"initial configuration g_0: the configuration of "
                                         r"node 0 is not on SO3"):
        compiled("rigid_body").integrate((g0, [[0.1, 0.2, 0.3]]), 10, 0.01)


def test_step_map_accepts_a_rotation_built_in_floating_point(compiled):
    g0 = Rotation.from_euler("zyx", [0.3, 1.1, -2.0]).as_matrix()
    g0 = np.linalg.multi_dot([g0] * 7)      # rounding of a few products: ~1e-15
    assert compiled("rigid_body").integrate((g0, [[0.1, 0.2, 0.3]]), 10, 0.01).success


@pytest.mark.parametrize("gamma", [[0.0, 0.0, 2.0], [0.0, 0.0, 0.0], [0.6, 0.8, 1e-4]])
def test_heavy_top_refuses_gravity_directions_off_the_sphere(compiled, gamma):
    with pytest.raises(ValueError, match=r"initial base point x_0: the base point of node 0"
                                         r".* is not on the model's manifold"):
        compiled("heavy_top").integrate((gamma, [[0.5, 0.3, 2.0]]), 10, 0.01)
    unit = np.array([0.36, 0.48, 0.8]) / np.linalg.norm([0.36, 0.48, 0.8])
    assert compiled("heavy_top").integrate((unit, [[0.5, 0.3, 2.0]]), 10, 0.01).success


def test_se3_body_checks_both_base_point_and_configuration(compiled):
    mod = compiled("se3_body")
    f = [[0.5, 0.3, 1.0, 0.2, 0.0, 0.4]]
    with pytest.raises(ValueError, match=r"is not on the model's manifold"):
        mod.integrate(([0.0, 0.0, 0.6, 0.9], f), 10, 0.01)
    g = np.eye(4)
    g[3, 0] = 0.5
    with pytest.raises(ValueError, match=r"not on SE3"):
        mod.integrate(([0.0, 0.0, 0.6, 0.8], g, f), 10, 0.01)
    g = np.eye(4)
    g[:3, 3] = [1e6, -2e6, 3e6]            # any translation is on SE(3)
    assert mod.integrate(([5.0, 0.0, 0.6, 0.8], g, f), 10, 0.01).success


def test_a_manifold_must_be_invariant_and_use_base_coordinates_only():
    with pytest.raises(ModelError, match=r"not invariant under the action"):
        ActionGroupoid(SO3(), "q1 q2 q3", lambda q, W: W.T * q, manifold=lambda q: [q[2] - 1])
    with pytest.raises(ModelError, match=r"base coordinates only, not \['r'\]"):
        ActionGroupoid(SO3(), "q1 q2 q3", lambda q, W: W.T * q,
                       manifold=lambda q: [q.dot(q) - sp.Symbol("r") ** 2])


@pytest.mark.parametrize("name", ["rigid_body_oc", "double_pendulum_oc",
                                  "heavy_top_rotors_oc_variational", "cart_pole_oc"])
def test_few_steps_give_a_status_or_a_named_error(compiled, name):
    """n_steps below the stencil is refused with the reason; 4 and 5 steps (which raised
    LAPACK's 'dgbsv: singular' or a NumPy broadcast error) return a result whose status
    says what happened."""
    mod, ex = compiled(name), get(name).example
    with pytest.raises(ValueError, match=r"n_steps must be at least 4 \(2 fixed nodes at "
                                         r"each end of an order-2 problem"):
        mod.solve_bvp(ex.start, ex.end, 3, ex.h)
    for N in (4, 5):
        result = mod.solve_bvp(ex.start, ex.end, N, ex.h)
        assert isinstance(result.status, mod.Status) and result.message
        assert "use fewer steps" not in result.message, result.message   # it needs more


def test_group_conditions_are_described_for_any_group():
    """The conditions a configuration must meet are named by what they are (an invariant
    co-form, an invariant covector), with SE(n)'s reading beside (a hunt: a custom
    Heisenberg group's check spoke of 'the rotation block'): the Heisenberg group of
    upper unitriangular 3×3 matrices fixes e₁ and the covector e₃ᵀ."""
    import sympy as sp
    from symvi import MatrixLieGroup
    from symvi._runtime.core.geometry import group_defects
    E = [sp.zeros(3) for _ in range(3)]
    E[0][0, 1], E[1][1, 2], E[2][0, 2] = 1, 1, 1
    heisenberg = MatrixLieGroup(E, "a b c", "H3")
    off = np.eye(3)
    off[2, 0] = 0.5                                 # below the diagonal: off the group
    defects, conditions = group_defects(off[None], heisenberg.invariants())
    violated = [c for c, d in zip(conditions, defects[0]) if d > 1e-12]
    assert "gKgᵀ = K (an invariant co-form: on SE(n) the rotation block's orthogonality)" \
        in violated
    assert "wᵀg = wᵀ for w = [0.0, 0.0, 1.0] (an invariant covector: on SE(n) the last row)" \
        in violated
    assert "g v = v for v = [1.0, 0.0, 0.0]" in violated
