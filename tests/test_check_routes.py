"""Check "routes" (issue 5, item 2): the Σ_{L_d} route of paper §4.2 against the variational
residual of the derivation engine."""
from __future__ import annotations

import mpmath
import sympy as sp

from symvi import SO3, ActionGroupoid, Model, PairGroupoid
from symvi.checks import routes
from symvi.checks.runner import Context, run_check
from symvi.groupoids.lie import MatrixLieGroup
from symvi.models import get


def _routes(model):
    return run_check("routes", Context(model))


# -- the paper's pair-groupoid example (§4.2) ----------------------------------------------
def _coefficients_close(expression, expected, symbols):
    difference = sp.expand(sp.sympify(expression) - expected)
    return all(abs(c) < 1e-25 for c in sp.Poly(difference, *symbols).coeffs()) \
        if difference != 0 else True


def test_paper_pair_example_source_and_target_maps():
    """α̃(μ₀, μ₁, μ̄₁, μ₂) = (−μ₀, −μ₁), β̃ = (μ̄₁, μ₂) in the natural basis
    (∂_{q₀}, ∂_{q₁}) = (−Z₁, Z₂) of A(P^α(Q×Q))."""
    G = PairGroupoid("q")
    q0, q1, q2 = sp.Rational(3, 10), sp.Rational(-1, 7), sp.Rational(5, 4)
    mu0, mu1, mubar1, mu2 = symbols = sp.symbols("mu0 mu1 mubar1 mu2")
    point = (((q0,), (q1,)), ((q0,), (q1,)), ((q1,), (q2,)))      # i(g₁, g₂) = (g₁, g₁, g₂)
    alpha, beta, problems = routes.cotangent_maps(G, point, [mu0, mu1, mubar1, mu2],
                                                  sp.Rational(1, 5))
    assert not problems
    natural = lambda v: (-v[0], v[1])                               # noqa: E731
    for got, want in zip(natural(alpha), (-mu0, -mu1)):
        assert _coefficients_close(got, want, symbols)
    for got, want in zip(natural(beta), (mubar1, mu2)):
        assert _coefficients_close(got, want, symbols)


def test_first_order_cotangent_groupoid_of_the_pair():
    """T*(Q×Q) ⇉ T*Q: α̃(μ₀, μ₁) = −μ₀, β̃ = μ₁, so β̃ = α̃ is D₂L_d + D₁L_d = 0."""
    G = PairGroupoid("q")
    mu0, mu1 = sp.symbols("mu0 mu1")
    alpha, beta = routes.first_order_maps(G, ((sp.Rational(1, 3),), (sp.Rational(2, 3),)),
                                          [mu0, mu1], sp.Rational(1, 10))
    assert _coefficients_close(alpha[0], -mu0, (mu0, mu1))
    assert _coefficients_close(beta[0], mu1, (mu0, mu1))


def test_lemma_defsection_from_the_prolongation_structure_maps():
    """Z⃖, Z⃗ of Lemma defsection equal d/dt p·c(t) and −d/dt c(t)⁻¹·p computed from the
    prolongation groupoid's own product (g, h, r)(r, h', r') = (g, hh', r') and inverse
    (r, h⁻¹, g), on the action groupoid of the heavy top (where sources move)."""
    G = get("heavy_top").groupoid
    h = sp.Rational(1, 5)
    with mpmath.workdps(routes.DPS):
        geo = routes._Geometry(G, routes._num(h))
        num = lambda *v: tuple(routes._num(s) for s in v)          # noqa: E731
        g = (num(0.3, -0.5, 0.8), num(0.2, -0.4, 0.7))
        hh = (g[0], num(-0.6, 0.1, 0.3))
        r = (geo.target(hh), num(0.5, 0.9, -0.2))
        p = (g, hh, r)

        def coords(point):
            (x, fg), (_, fh), (_, fr) = point
            return tuple(x) + tuple(fg) + tuple(fh) + tuple(fr)

        def times(p, c):              # p·c, c = (r, h', r')
            (g, hh, _), (_, h2, r2) = p, c
            return (g, G.multiply(*hh, *h2, h), r2)

        def inverse(c):
            b, hh, r2 = c
            return (r2, G.inverse(*hh, h), b)

        def curve(base, k, a, t):     # c(t) at base b for Z₁ (k = 1) or Z₂ (k = 2)
            if k == 1:
                s = G.basis_curve(base[0], a, -t, h)
                return (base, s, G.multiply(*G.inverse(*s, h), *base, h))
            y = geo.target(base)
            return (base, G.identity(base[0]), G.multiply(*base, *G.basis_curve(y, a, t, h), h))

        pro = routes._Prolongation(geo, routes.TOLERANCE)
        lemma_left, lemma_right = pro.fields(p, "left"), pro.fields(p, "right")
        assert not pro.problems
        for k in (1, 2):
            for a in range(3):
                left = routes._derivative(lambda t: coords(times(p, curve(r, k, a, t))))
                right = -routes._derivative(
                    lambda t: coords(times(inverse(curve(g, k, a, t)), p)))
                for ours, (label, lemma) in ((left, lemma_left[3 * (k - 1) + a]),
                                             (right, lemma_right[3 * (k - 1) + a])):
                    assert max(abs(u - v) for u, v in zip(ours, lemma)) < 1e-25, label


# -- negative: a deliberately broken groupoid is caught, the direction named ---------------
class TransposedSO3(MatrixLieGroup):
    """SO(3) whose left() uses the transpose of dτ⁻¹ (a plausible slip)."""

    def left(self, x, f, h):
        return -self.dtau_inv([h * v for v in f]).T / h


def test_transposed_dtau_in_left_is_caught():
    good = SO3()
    G = TransposedSO3(good.basis, "Omega1 Omega2 Omega3", "SO3")
    I = (1, 2, 3)
    model = Model(name="broken_rigid_body", groupoid=G,
                  lagrangian=sum(i * w**2 for i, w in zip(I, G.xi)) / 2)
    result = _routes(model)
    assert result.status == "fail"
    text = "\n".join(result.details)
    assert "left()" in text and "right-invariant field −X⃗" in text
    assert "direction e_1 (Omega1)" in text
    assert "variational residual R_1" in text


class SignSlipPair(PairGroupoid):
    """A pair groupoid whose right() has the wrong sign."""

    def right(self, x, f, h):
        return -super().right(x, f, h)


def test_sign_slip_in_right_is_caught_at_second_order():
    G = SignSlipPair("x y")
    model = Model(name="broken_spline", groupoid=G,
                  lagrangian=sum(a**2 for a in G.qddot) / 2 + G.q[0] * G.q[1])
    result = _routes(model)
    assert result.status == "fail"
    text = "\n".join(result.details)
    assert "left-invariant field X⃖_1 from m(g, σ_a(ε))" in text
    assert "the groupoid's right()[:, 0]" in text
    assert "direction e_2 (y)" in text


class WrongActionSign(ActionGroupoid):
    """An action groupoid whose left() moves the source the wrong way."""

    def left(self, x, f, h):
        M = super().left(x, f, h)
        M[:self.source_dim, :] = -M[:self.source_dim, :]
        return M


def _broken_planar_top(groupoid_class, name: str):
    """Check ``routes`` on a planar top, SO(2) acting on (u, v), with a broken groupoid."""
    SO2 = MatrixLieGroup([[[0, -1], [1, 0]]], "omega", "SO2")
    G = groupoid_class(SO2, "u v", lambda q, W: W.T * q)
    (omega,), (u, v) = G.xi, G.q
    return _routes(Model(name=name, groupoid=G, lagrangian=omega**2 / 2 - u - v**2))


def test_wrong_infinitesimal_action_is_caught():
    result = _broken_planar_top(WrongActionSign, "broken_planar_top")
    assert result.status == "fail"
    text = "\n".join(result.details)
    assert "the groupoid's left()[:, 0]" in text and "direction e_1 (omega)" in text
    assert "variational residual R_1" in text


class WrongTarget(ActionGroupoid):
    """target() acts by W instead of Wᵀ: β ≠ α∘i."""

    def target(self, x, f, h):
        return tuple(self.group.tau([h * v for v in f]) * sp.Matrix(x))


def test_target_inconsistent_with_inverse_is_caught():
    result = _broken_planar_top(WrongTarget, "broken_target")
    assert result.status == "fail"
    assert any(d.startswith("target(): β(g_0)") for d in result.details), result.details


def test_groupoid_without_structure_maps_is_skipped():
    class Opaque(PairGroupoid):
        def inverse(self, x, f, h):
            raise NotImplementedError("no inverse")

    G = Opaque("q")
    model = Model(name="opaque", groupoid=G, lagrangian=G.qdot[0]**2 / 2 - G.q[0]**2 / 2)
    result = _routes(model)
    assert result.status == "skip" and "structure maps" in result.summary
