"""Check ``noether`` and the compiled conserved quantities F_Z (paper §4.4)."""
from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

from symvi import SO3, Example, Model, PairGroupoid, Symmetry, compile_model
from symvi.checks import check
from symvi.errors import ModelError
from symvi.models import get

B = sp.Symbol("B", positive=True)


def magnetic(potential, name="magnetic") -> Model:
    """A charged particle in a uniform magnetic field B e_z, L = ½|q̇|² + (B/2)(x ẏ − y ẋ):
    rotations leave it invariant, translation along x only quasi-invariant (f = B y/2)."""
    G = PairGroupoid("x y")
    (x, y), (vx, vy) = G.q, G.qdot
    return Model(name=name, groupoid=G, lagrangian=(vx**2 + vy**2) / 2 + B * (x * vy - y * vx) / 2,
                 parameters={B: 1.5},
                 symmetries=[Symmetry("rotation", [-y, x]),
                             Symmetry("x_translation", [1, 0], potential=potential(G))])


def test_heavy_top_vertical_momentum_is_an_exact_symmetry():
    result = check(get("heavy_top"), only=["noether"])["noether"]
    assert result.status == "pass"
    assert result.data["vertical_momentum"]["relative_defect"] < 1e-14


def _tilted_top(name: str) -> list[str]:
    top = get(name)
    G = top.groupoid
    broken = Model(name="tilted", groupoid=G, lagrangian=top.lagrangian,
                   parameters=dict(top.parameters),
                   symmetries=[Symmetry("tilted", [G.q[0], G.q[1], 0])])
    result = check(broken, only=["noether"])["noether"]
    assert result.status == "fail"
    assert result.data["tilted"]["relative_defect"] > 1e-3
    return result.details


def _leading(details: list[str]) -> sp.Expr:
    text = "\n".join(details)
    return sp.sympify(text.split("leading term: δL_d − Δf = ")[1].split(" + …")[0])


def test_wrong_section_is_caught_and_its_terms_named():
    """The leading term in h of the defect is the continuous one, so the same for both
    retractions (τ_exp − τ_Cayley = O(ξ³) changes L_d at O(h³), the defect leads at
    O(h)); with the exponential it once came out as 0/0, or with the coefficients
    unevaluated at 0."""
    cayley, exponential = _tilted_top("heavy_top"), _tilted_top("heavy_top_exp")
    text = "\n".join(cayley)
    assert "tilted: L_d is not invariant" in text and "leading term" in text
    assert "mgl" in text and "Gamma3" in text       # gravity breaks it, through Γ₃
    lead = _leading(cayley)
    assert lead.free_symbols >= {sp.Symbol("mgl"), sp.Symbol("h")} and "nan" not in text
    assert sp.expand(_leading(exponential) - lead) == 0, (exponential, cayley)


def test_quasi_invariance_needs_its_potential():
    good = check(magnetic(lambda G: B * G.q[1] / 2), only=["noether"])["noether"]
    assert good.status == "pass", good.details
    assert good.data["x_translation"]["kind"] == "quasi-invariant"
    bad = check(magnetic(lambda G: 0, name="no_potential"), only=["noether"])["noether"]
    assert bad.status == "fail"
    assert "x_translation" in bad.details[0] and "rotation" not in "".join(bad.details)
    leading = sp.sympify(bad.details[1].split("=")[1].replace("+ …", ""))
    b, y0, y1 = sp.symbols("B y_0 y_1")                       # as parsed from the text
    assert sp.expand(leading - b * (y1 - y0) / 2) == 0       # the missing Δf, exactly


def test_magnetic_momenta_are_conserved_to_round_off(tmp_path):
    model = magnetic(lambda G: B * G.q[1] / 2)
    mod = compile_model(model, tmp_path)
    h = 0.05
    q0 = np.array([[0.3, -0.2], [0.33, -0.15]])
    result = mod.integrate(q0, 2000, h)
    assert result.success
    F = result.noether
    assert F.shape == (result.q.shape[0] - 1, 2)
    assert np.abs(F - F[0]).max() < 1e-12 * (1 + np.abs(F).max())
    # F_x = ⟨p, e_x⟩ − B y/2 at every node with the discrete Legendre momenta.
    p, q = result.momenta[:-1], result.q[:-1]
    np.testing.assert_allclose(F[:, 1], p[:, 0] - 1.5 * q[:, 1] / 2, atol=1e-13)
    np.testing.assert_allclose(F[:, 0], q[:, 0] * p[:, 1] - q[:, 1] * p[:, 0], atol=1e-13)
    assert mod.INFO.symmetries == ("rotation", "x_translation")


def test_second_order_translations_and_rotations_of_a_spline(tmp_path):
    spline = get("cubic_spline")
    G = spline.groupoid
    x, y = G.q
    model = Model(name="spline_symmetries", groupoid=G, lagrangian=spline.lagrangian,
                  symmetries=[Symmetry("px", [1, 0]), Symmetry("angular", [-y, x])])
    assert check(model, only=["noether"])["noether"].status == "pass"
    mod = compile_model(model, tmp_path)
    t = 0.1 * np.arange(4)                  # nodes of a cubic: an exact discrete solution
    nodes = np.stack([1 + t - 0.3 * t**2 + 0.1 * t**3, 0.5 * t + 0.2 * t**3], axis=1)
    result = mod.integrate(nodes, 40, 0.1)
    F = result.noether
    assert result.success and F.shape == (38, 2)
    # Momenta are third differences / h³ of nodes up to |q| ≈ 10: rounding of 1e-13 in F.
    assert np.abs(F - F[0]).max() < 1e-10
    assert np.abs(F[0]).min() > 0.1                        # not trivially zero


def test_symmetric_rigid_body_conserves_its_axial_momentum(tmp_path):
    G = SO3()
    Omega = sp.Matrix(G.xi)
    a, c = sp.symbols("a c", positive=True)
    model = Model(name="symmetric_top", groupoid=G,
                  lagrangian=(Omega.T * sp.diag(a, a, c) * Omega)[0] / 2,
                  parameters={a: 1.0, c: 2.5}, symmetries=[Symmetry("axial", [0, 0, 1])])
    assert check(model, only=["noether"])["noether"].status == "pass"
    result = compile_model(model, tmp_path).integrate((np.eye(3), [[0.4, -0.3, 1.1]]), 1000, 0.02)
    F = result.noether[:, 0]
    np.testing.assert_allclose(F, result.momenta[:-1, 2], atol=1e-14)
    assert np.ptp(F) < 1e-13 and abs(F[0] - 2.5 * 1.1) < 0.05
    tilted = Model(name="tilted_top", groupoid=G, lagrangian=model.lagrangian,
                   parameters={a: 1.0, c: 2.5}, symmetries=[Symmetry("transverse", [1, 0, 0])])
    assert check(tilted, only=["noether"])["noether"].status == "fail"


def test_models_without_symmetries_skip():
    assert check(get("pendulum"), only=["noether"])["noether"].status == "skip"


@pytest.mark.parametrize("section, message", [([1], "has 1 coefficients"),
                                               ([sp.Symbol("k"), 0], "undeclared symbol(s) k")])
def test_bad_symmetry_declarations(section, message):
    G = PairGroupoid("x y")
    with pytest.raises(ModelError, match=message.replace("(", r"\(").replace(")", r"\)")):
        Model(name="bad", groupoid=G, lagrangian=sum(v**2 for v in G.qdot) / 2,
              symmetries=[Symmetry("z", section)], example=Example(initial=None, h=0.1,
                                                                   n_steps=1))
