"""Check ``structure`` (issue 5, item 6): the step map preserves the symplectic form (pair
groupoid) or the Poisson structure (Lie groups, action groupoids, products), first and
second order; deliberately broken step maps are caught with the sample point and the size
of the defect; constrained models are skipped."""
from __future__ import annotations

import dataclasses
from functools import lru_cache

import numpy as np
import pytest
import sympy as sp

from symvi import SO3, ActionGroupoid, Model, PairGroupoid, ProductGroupoid
from symvi.checks import check
from symvi.checks.runner import Context
from symvi.checks.structure import (TOLERANCE, StepMap, canonical_poisson, linear_poisson,
                                    poisson_defect, run, symplectic_defect)
from symvi.models import get


@lru_cache(maxsize=None)
def _context(name: str) -> Context:
    """One derivation per bundled model for the whole module."""
    return Context(get(name))


def _passes(ctx: Context, structure: str):
    result = run(ctx)
    assert result.status == "pass", (result.summary, result.details)
    assert structure in result.data["structure"]
    assert len(result.data["defects"]) == 3
    assert result.data["max_defect"] < TOLERANCE
    return result


def _with_residual(name: str, make) -> Context:
    """A fresh context of bundled model ``name`` whose step residual is ``make(z, h)``."""
    derived = _context(name).derived
    step = derived.kernel("step")
    R = sp.Matrix(make(step.z, derived.step))
    unknown = step.z[-derived.fibre_dim:]
    broken = dataclasses.replace(step, outputs=(("residual", R),
                                                ("jacobian", R.jacobian(unknown))))
    ctx = Context(get(name))
    ctx.derived = dataclasses.replace(
        derived, kernels=tuple(broken if k.name == "step" else k for k in derived.kernels))
    return ctx


def _caught(ctx: Context, at_least: float = 1e-5):
    result = run(ctx)
    assert result.status == "fail", result.summary
    assert result.data["max_defect"] > at_least
    assert "does not preserve" in result.summary
    assert result.details
    for line in result.details:
        assert "at the sample point s = (x₀, f₀" in line
        assert "relative defect" in line and "defect norm" in line and "worst entry" in line
    return result


# -- correct models pass ----------------------------------------------------------------
@pytest.mark.parametrize("name", ["harmonic_oscillator", "pendulum", "double_pendulum"])
def test_pair_first_order_is_symplectic(name):
    _passes(_context(name), "canonical symplectic form of T*Q")


@pytest.mark.parametrize("name", ["cubic_spline", "spline_potential"])
def test_pair_second_order_preserves_the_form_on_T_star_QxQ(name):
    _passes(_context(name), "canonical symplectic form of T*(Q×Q)")


@pytest.mark.parametrize("name", ["rigid_body", "rigid_body_exp", "planar_body"])
def test_lie_first_order_is_lie_poisson(name):
    _passes(_context(name), "Lie–Poisson structure")


def test_lie_second_order_preserves_the_structure_of_A_star_PG():
    _passes(_context("so3_cubic"), "𝔤* × T*G")


@pytest.mark.parametrize("name", ["heavy_top", "spherical_pendulum"])
def test_action_groupoid_first_order_preserves_the_linear_poisson_structure(name):
    _passes(_context(name), "linear Poisson structure of A*G")


def test_action_groupoid_second_order_and_the_sign_is_pinned_down():
    H = SO3()
    G = ActionGroupoid(H, "Gamma1 Gamma2 Gamma3", lambda q, W: W.T * q, label="S2xSO3")
    Om, dOm, Ga = sp.Matrix(G.xi), sp.Matrix(G.xidot), sp.Matrix(G.q)
    L = dOm.dot(dOm) / 2 + (Om.T * sp.diag(1, 2, 3) * Om)[0] / 2 - Ga[2] / 2 + Ga[0] * Om[1] / 4
    ctx = Context(Model(name="top2", groupoid=G, lagrangian=L))
    _passes(ctx, "A*G × T*H")
    _other_sign_fails(ctx)


def test_products_first_and_second_order():
    H, P = SO3(), PairGroupoid("th")
    G = ProductGroupoid(P, H)
    Om, th, thd = sp.Matrix(H.xi), P.q[0], P.qdot[0]
    first = thd**2 / 2 + (Om.T * sp.diag(1, 2, 3) * Om)[0] / 2 + sp.cos(th) * Om[2] \
        + thd * Om[0] / 3
    second = P.qddot[0]**2 / 2 + sp.Matrix(H.xidot).dot(sp.Matrix(H.xidot)) / 2 \
        + sp.cos(th) * Om[2]**2 + thd * Om[0] / 3
    _passes(Context(Model(name="p1", groupoid=G, lagrangian=first)), "linear Poisson")
    _passes(Context(Model(name="p2", groupoid=G, lagrangian=second)), "A*(P^αG)")


def test_through_the_runner():
    report = check(get("pendulum"), only=["structure"])
    assert report.passed and report["structure"].status == "pass"
    assert "structure" in report.format()


# -- the structure is the right one: the other relative sign fails ------------------------
def _other_sign_fails(ctx: Context):
    step = StepMap(ctx.derived, ctx.model.groupoid, sign=+1.0)
    rng = np.random.default_rng(3)
    defects = [step.defect(step.sample(rng)).relative for _ in range(2)]
    assert min(defects) > 1e-4, defects


@pytest.mark.parametrize("name", ["so3_cubic", "heavy_top"])
def test_other_sign_of_the_bracket_fails(name):
    _other_sign_fails(_context(name))


def test_lie_group_alone_is_blind_to_the_sign():
    # N Π Nᵀ = Π' is homogeneous in Π: on 𝔤* alone ±Lie–Poisson are the same condition.
    ctx = _context("rigid_body")
    step = StepMap(ctx.derived, ctx.model.groupoid, sign=+1.0)
    assert step.defect(step.sample(np.random.default_rng(3))).relative < TOLERANCE


# -- broken step maps are caught --------------------------------------------------------
def test_non_variational_pendulum_is_caught():
    # q₂ − 2q₁ + q₀ + h²V′(q₀) = 0: explicit, looks like Störmer–Verlet, is not symplectic.
    def residual(z, h):
        q0, q1, q2 = z
        return [q2 - 2 * q1 + q0 + h**2 * 9.81 * sp.sin(q0)]
    result = _caught(_with_residual("pendulum", residual))
    assert "T*Q" in result.summary
    assert 1e-4 < result.data["max_defect"] < 1e-1


def test_non_variational_second_order_is_caught():
    # Fourth difference plus a force at the first node only (spline_potential's V′): a
    # consistent but non-variational step; its defect is O(h⁴V″), ~1e-6 at h = 0.1.
    def residual(z, h):
        n = 2
        nodes = [sp.Matrix(z[k * n:(k + 1) * n]) for k in range(5)]
        q0 = nodes[0]
        force = q0 + q0 * (q0.dot(q0)) / 2
        return nodes[4] - 4 * nodes[3] + 6 * nodes[2] - 4 * nodes[1] + nodes[0] + h**4 * force
    result = _caught(_with_residual("spline_potential", residual), at_least=1e-7)
    assert "T*(Q×Q)" in result.summary


def test_explicit_euler_poincare_is_caught():
    inertia = sp.diag(1, 2, 3)

    def residual(z, h):
        w0, w1 = sp.Matrix(z[:3]), sp.Matrix(z[3:])
        return inertia * (w1 - w0) / h - (inertia * w0).cross(w0)
    result = _caught(_with_residual("rigid_body", residual))
    assert "Lie–Poisson" in result.summary


def test_swapped_euler_poincare_signs_are_the_inverse_map_and_pass():
    # ERRATA.md item 7: with the ± swapped the residual is F⁻L_d(ξ_k) = F⁺L_d(ξ_{k+1}), the
    # inverse of the correct Hamiltonian map — Poisson too, so this check cannot see it.
    G, inertia = get("rigid_body").groupoid, sp.diag(1, 2, 3)

    def residual(z, h):
        w0, w1 = sp.Matrix(z[:3]), sp.Matrix(z[3:])
        return (G.dtau_inv(list(h * w0)).T * inertia * w0
                - G.dtau_inv(list(-h * w1)).T * inertia * w1)
    assert run(_with_residual("rigid_body", residual)).status == "pass"


# -- the plain functions ----------------------------------------------------------------
def test_symplectic_defect_of_plain_maps():
    h = 0.1
    # Symplectic Euler for the pendulum: symplectic.
    q = 0.4
    M = np.array([[1 - h**2 * np.cos(q), h], [-h * np.cos(q), 1]])
    assert symplectic_defect(M).relative < 1e-15
    # Explicit Euler: det = 1 + h² cos q ≠ 1.
    M = np.array([[1, h], [-h * np.cos(q), 1]])
    d = symplectic_defect(M)
    assert d.relative > 1e-3 and d.worst in ((0, 1), (1, 0))
    assert abs(abs(d.value) - h**2 * np.cos(q)) < 1e-14
    # In two degrees of freedom with a form given explicitly.
    J = canonical_poisson(2)
    S = np.block([[np.eye(2), np.zeros((2, 2))], [np.array([[1, 2], [2, 3]]), np.eye(2)]])
    assert symplectic_defect(S, J).relative < 1e-15
    assert poisson_defect(S, J, J).relative < 1e-15


def test_poisson_defect_on_so3_star():
    C = [np.zeros((3, 3)) for _ in range(3)]
    for a, b, c in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        C[c][a, b], C[c][b, a] = 1.0, -1.0
    mu = np.array([0.3, -1.0, 0.5])
    P = linear_poisson(mu, np.zeros((0, 3)), C)
    # {μ_a, μ_b} = −ε_abc μ_c: the matrix of μ× (hat map).
    assert np.allclose(P, [[0, -mu[2], mu[1]], [mu[2], 0, -mu[0]], [-mu[1], mu[0], 0]])
    t = 0.7
    R = np.array([[np.cos(t), -np.sin(t), 0], [np.sin(t), np.cos(t), 0], [0, 0, 1]])
    assert poisson_defect(R, P, linear_poisson(R @ mu, np.zeros((0, 3)), C)).relative < 1e-15
    # μ ↦ 2μ is not Poisson: 4Π(μ) ≠ Π(2μ).
    d = poisson_defect(2 * np.eye(3), P, linear_poisson(2 * mu, np.zeros((0, 3)), C))
    assert d.relative > 0.1 and d.norm == pytest.approx(2 * np.linalg.norm(P))


# -- skips ------------------------------------------------------------------------------
def test_constrained_models_are_skipped():
    result = run(Context(get("cart_pole_oc")))
    assert result.status == "skip"
    assert "constrained" in result.summary and "no step map" in result.summary


def test_groupoids_without_a_known_structure_are_skipped(monkeypatch):
    """A groupoid that does not declare ``structure_check`` (its Poisson structure is not
    implemented in :mod:`symvi.checks.stepmap`) is skipped, naming it."""
    model = get("pendulum")
    monkeypatch.setattr(model.groupoid, "structure_check", False)
    result = run(Context(model))
    assert result.status == "skip" and "PairGroupoid(['theta'])" in result.summary
