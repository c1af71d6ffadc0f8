"""Regularity is decided relative to the scale of the model (issue 19): a Lagrangian in
small units is as regular as in large ones, an identically singular one is refused in
any units, and the step map's kernel is found by name."""
from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

import symvi.derivation.derive as derive_module
from symvi import Example, Model, PairGroupoid, compile_model
from symvi.derivation.derive import derive
from symvi.discretisation.discretise import discretise
from symvi.errors import ModelError
from symvi.models import get
from symvi.declaration.rank import generic_rank

SMALL = 1e-11


def pendulum(mass: float, name: str = "pendulum_small_mass") -> Model:
    """The bundled pendulum, L = m l² θ̇²/2 + m g l cos θ, with another default mass."""
    G = PairGroupoid("theta")
    (theta,), (omega,) = G.q, G.qdot
    m, l, g = sp.symbols("m l g", positive=True)
    return Model(name=name, groupoid=G,
                 lagrangian=m * l**2 * omega**2 / 2 + m * g * l * sp.cos(theta),
                 discretisation="midpoint", parameters={m: mass, l: 1.0, g: 9.81},
                 example=Example(initial=[[1.0], [1.0]], h=0.01, n_steps=10_000))


def relative_energy_error(result) -> float:
    return float(np.abs(result.energy - result.energy[0]).max() / abs(result.energy[0]))


def test_pendulum_with_a_tiny_mass_compiles_and_conserves_energy(compiled, tmp_path):
    """m factors out of L: the path is the one of m = 1, and the energy m·E₁."""
    small = compile_model(pendulum(SMALL), tmp_path)
    unit = compiled("pendulum")
    initial, h = [[1.0], [1.0]], 0.01
    a, b = small.integrate(initial, 10_000, h), unit.integrate(initial, 10_000, h)
    assert a.success and b.success, (a.message, b.message)
    np.testing.assert_allclose(a.x, b.x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(a.energy, SMALL * b.energy, rtol=1e-9)
    assert relative_energy_error(b) < 1e-3
    assert relative_energy_error(a) == pytest.approx(relative_energy_error(b), rel=1e-3)


@pytest.mark.parametrize("mass", [1.0, SMALL])
def test_identically_singular_hessian_is_refused_in_any_units(mass):
    """(sin²θ + cos²θ − 1)·m θ̇²/2 has ∂²L/∂θ̇² ≡ 0, which SymPy does not see: its samples
    are rounding noise of terms of size ~m, not a small-unit Hessian."""
    G = PairGroupoid("theta")
    (theta,), (omega,) = G.q, G.qdot
    m = sp.Symbol("m", positive=True)
    hidden_zero = sp.sin(theta)**2 + sp.cos(theta)**2 - 1
    L = m * hidden_zero * omega**2 / 2 + m * sp.cos(theta)
    with pytest.raises(ModelError, match=r"not regular: .* has rank 0 < 1 everywhere"):
        Model("hidden_degenerate", G, lagrangian=L, parameters={m: mass})


def test_generic_rank_is_relative_to_the_matrix_scale():
    x, m = sp.symbols("x m")
    fixed = {m: SMALL}
    assert generic_rank(sp.Matrix([[m, 0], [0, m * (1 + x**2)]]), [x], fixed) == 2
    assert generic_rank(sp.Matrix([[m, m * x], [m * x, m * x**2]]), [x], fixed) == 1
    assert generic_rank(sp.zeros(2, 2), [x], fixed) == 0
    assert generic_rank(sp.Matrix([[m, 0], [0, m * x]]), [x], {m: 0.0}) == 0
    huge = {m: 1e11}
    assert generic_rank(sp.Matrix([[m, m * x], [m * x, m * x**2]]), [x], huge) == 1


# -- the step kernel is looked up by name -------------------------------------------------
def singular_discrete_model(name: str) -> Model:
    """L_d = q₁ − q₀: D₁₂L_d ≡ 0."""
    G = PairGroupoid("x")
    (q0,), (q1,) = G.nodes(2)
    return Model(name, G, discrete_lagrangian=q1 - q0, order=1)


def test_regularity_is_checked_on_the_step_kernel_wherever_it_is(monkeypatch):
    kernels = derive_module._kernels

    def step_last(dm):
        found = kernels(dm)
        return tuple(k for k in found if k.name != "step") + tuple(
            k for k in found if k.name == "step")
    monkeypatch.setattr(derive_module, "_kernels", step_last)
    with pytest.raises(ModelError, match=r"not regular: the step Jacobian .* rank 0 < 1"):
        derive(discretise(singular_discrete_model("singular_step_last")))


def test_a_derivation_without_a_step_kernel_fails_clearly(monkeypatch):
    kernels = derive_module._kernels
    monkeypatch.setattr(derive_module, "_kernels",
                        lambda dm: tuple(k for k in kernels(dm) if k.name != "step"))
    model = pendulum(1.0, name="pendulum_without_step")
    with pytest.raises(ModelError, match=r"model 'pendulum_without_step': no 'step' kernel was "
                                         r"derived \(kernels: \['predict', "):
        derive(discretise(model))


def test_bundled_pendulum_is_unchanged():
    """The copy above is the bundled model but for its name, mass and example."""
    bundled = get("pendulum")
    copy = pendulum(1.0)
    assert sp.srepr(copy.lagrangian) == sp.srepr(bundled.lagrangian)
    assert [(str(s), v) for s, v in copy.parameters] == \
        [(str(s), v) for s, v in bundled.parameters]
