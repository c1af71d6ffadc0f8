"""Route 2 of the check ``routes``: Σ_{L_d} in the cotangent groupoid T*(P^αG), rebuilt
from a groupoid's structure maps (paper §2.1, §4.2; :mod:`symvi.checks.routes` compares it
with the variational residual).

Nothing here uses the groupoid's hand-written ``right``/``left``: from its structure maps in
element coordinates (:meth:`~symvi.groupoids.base.Groupoid.multiply`, ``inverse``,
``identity``, ``basis_curve``; paper §2.1) the invariant fields are obtained by
differentiation (:class:`_Geometry`),

    X⃖_a(g) = d/dε m(g, σ_a(ε))|₀          (σ_a at β(g)),
    X⃗_a(g) = −d/dε m(i(σ_a(ε)), g)|₀      (σ_a at α(g); paper eq. right-invariant-vf),

β(g) is taken as α(i(g)) and the pulled-back L_d differentiated through it
(:class:`_Route`).

* First order (L_d : G → R; :func:`first_order_maps`): Σ_{L_d} = Im dL_d ⊂ T*G ⇉ A*G with
  ⟨α̃(μ), e_a⟩ = ⟨μ, X⃗_a(g)⟩, ⟨β̃(μ), e_a⟩ = ⟨μ, X⃖_a(g)⟩ (paper §2.1, eq.
  cotangent:groupoid); the dynamics is β̃(dL_d(g_k)) = α̃(dL_d(g_{k+1})).
* Second order (L_d : G₂ → R; §4.2, Theorems teoremagroupoides1, teoremagroupoides2;
  :func:`cotangent_maps`, :class:`_Prolongation`, :func:`_second_order`):
  P^αG = {(g, h, r) : α(g) = α(h), β(h) = α(r)} in coordinates (x, f_g, f_h, f_r),
  r's source being β(h); i(g₁, g₂) = (g₁, g₁, g₂). A covector γ at i(g₁, g₂) lies in
  Σ_{L_d} iff i*γ = dL̂_d, L̂_d(x₀, f₀, f₁) = L_d(x₀, f₀, β(x₀, f₀), f₁): its x and f_r
  parts are fixed and the f_g, f_h parts are a free split μ, ∂L̂_d/∂f₀ − μ. The invariant
  fields of the basis Z₁ = (−X, X⃗), Z₂ = (0, X⃖) are those of Lemma defsection,

      Z⃗₁ = (−X⃗(g), −X⃗(h), 0),  Z⃗₂ = (−X⃖(g), 0, 0),
      Z⃖₁ = (0, −X⃖(h), X⃗(r)),  Z⃖₂ = (0, 0, X⃖(r))

  (re-derived: Z⃖(p) = d/dt p·c(t), Z⃗(p) = −d/dt c(t)⁻¹·p for the curves
  c(t) = (b, σ(−t), σ(−t)⁻¹b) and (b, ε, bσ(t)) of the prolongation groupoid, whose
  product is (g, h, r)(r, h', r') = (g, hh', r') and inverse (r, h⁻¹, g)), and
  ⟨α̃(γ), Z⟩ = ⟨γ, Z⃗⟩, ⟨β̃(γ), Z⟩ = ⟨γ, Z⃖⟩ (eqs. Zsections, Zsections2). With the
  stencil g₀, …, g₃ of the engine: the Z₂ components of β̃(γ_k) = α̃(γ_{k+1}) (k = 0, 1)
  fix the splits μ₁, μ₂, and then the Z₁ component of β̃(γ₁) − α̃(γ₂) is
  **−R** at the node β(g₁) shared by g₁ and g₂ (the engine's middle node). In the
  pair groupoid's natural basis (∂_{q₀}, ∂_{q₁}) = (−Z₁, Z₂) this is the paper's example:
  α̃(μ₀, μ₁, μ̄₁, μ₂) = (−μ₀, −μ₁), β̃ = (μ̄₁, μ₂).

Arithmetic: every quantity is evaluated with SymPy/mpmath numbers at ``DPS`` digits and
the ε-derivatives are central differences with step ``STEP`` (error ≈ 1e-32 relative);
the exponential retraction's τ, τ⁻¹ are mpmath's expm/logm. :func:`cotangent_maps` and
:func:`first_order_maps` set ``mpmath.workdps(DPS)`` themselves; the rest expects to be
called inside it.
"""
from __future__ import annotations

import mpmath
import sympy as sp

from ..errors import ModelError

#: Working precision (decimal digits) of route 2 and of the evaluation of route 1.
DPS = 50
#: Step of the central differences d/dε (truncation ~STEP², round-off ~10^−DPS/STEP).
STEP = sp.Float("1e-16", DPS)
#: Largest accepted |route 2 − route 1| relative to max(|route 1|, |route 2|); also the
#: tolerance of the tangency checks of :class:`_Prolongation`.
TOLERANCE = 1e-20


# -- numbers -------------------------------------------------------------------------------
def _num(v) -> sp.Float:
    """A number at DPS digits (raises ModelError on a leftover symbol)."""
    value = sp.sympify(v).evalf(DPS)
    if not value.is_number:
        raise ModelError(f"route 2: cannot evaluate {value} (free symbols "
                         f"{sorted(map(str, value.free_symbols))})")
    if value.is_real is False or (value.is_real is None and abs(sp.im(value)) > 1e-30):
        raise ModelError(f"route 2: complex value {value}")
    return sp.Float(sp.re(value), DPS)


def _vector(values) -> sp.Matrix:
    return sp.Matrix([_num(v) for v in values])


def _derivative(F) -> sp.Matrix:
    """d/dε F(ε) at ε = 0 by a central difference (F returns a sequence)."""
    plus, minus = _vector(F(STEP)), _vector(F(-STEP))
    return (plus - minus) / (2 * STEP)


def _fmt(values, digits: int = 12) -> str:
    return "[" + ", ".join(sp.sstr(sp.Float(v, digits)) for v in values) + "]"


def _flat(element) -> tuple:
    return tuple(element[0]) + tuple(element[1])


# -- invariant fields from the structure maps ----------------------------------------------
class _Geometry:
    """Invariant fields and target map of one groupoid at one h, from its structure maps."""

    def __init__(self, groupoid, h):
        self.G, self.h = groupoid, h
        self.m, self.n = groupoid.source_dim, groupoid.fibre_dim
        self._cache: dict = {}

    def _memo(self, key, compute):
        if key not in self._cache:
            self._cache[key] = compute()
        return self._cache[key]

    def element(self, x, f) -> tuple[tuple, tuple]:
        return tuple(_num(v) for v in x), tuple(_num(v) for v in f)

    def target(self, g) -> tuple:
        """β(g) = α(i(g))."""
        if not self.m:
            return ()
        return self._memo(("beta", _flat(g)),
                          lambda: tuple(_num(v) for v in self.G.inverse(*g, self.h)[0]))

    def left_invariant(self, g) -> sp.Matrix:
        """(m+n)×n, column a = X⃖_a(g) = d/dε m(g, σ_a(ε))."""
        def compute():
            y = self.target(g)
            return sp.Matrix.hstack(*[_derivative(
                lambda e, a=a: _flat(self.G.multiply(*g, *self.G.basis_curve(y, a, e, self.h),
                                                     self.h)))
                for a in range(self.n)])
        return self._memo(("left", _flat(g)), compute)

    def right_invariant(self, g) -> sp.Matrix:
        """(m+n)×n, column a = X⃗_a(g) = −d/dε m(i(σ_a(ε)), g)."""
        def compute():
            def curve(e, a):
                s = self.G.inverse(*self.G.basis_curve(g[0], a, e, self.h), self.h)
                return _flat(self.G.multiply(*s, *g, self.h))
            return -sp.Matrix.hstack(*[_derivative(lambda e, a=a: curve(e, a))
                                       for a in range(self.n)])
        return self._memo(("right", _flat(g)), compute)

    def target_jacobian(self, g) -> sp.Matrix:
        """m×(m+n): d β(x, f) / d(x, f), differentiating β = α∘i."""
        if not self.m:
            return sp.zeros(0, self.n)

        def compute():
            x, f = g
            columns = []
            for i in range(self.m + self.n):
                def moved(e, i=i):
                    xs = tuple(v + e if j == i else v for j, v in enumerate(x))
                    fs = tuple(v + e if self.m + j == i else v for j, v in enumerate(f))
                    return self.G.inverse(xs, fs, self.h)[0]
                columns.append(_derivative(moved))
            return sp.Matrix.hstack(*columns) if columns else sp.zeros(self.m, 0)
        return self._memo(("dbeta", _flat(g)), compute)


class _Prolongation:
    """P^αG in coordinates (x, f_g, f_h, f_r); invariant fields of Lemma defsection."""

    def __init__(self, geometry: _Geometry, tolerance: float):
        self.geo, self.tol = geometry, tolerance
        self.problems: list[str] = []

    def _coordinates(self, point, triple, label: str) -> sp.Matrix:
        """Tangent vector (δg, δh, δr) of G³ at (g, h, r) → (δx, δf_g, δf_h, δf_r),
        checking that it is tangent to P^αG (Tα δg = Tα δh, Tβ δh = Tα δr)."""
        geo, h = self.geo, point[1]
        m = geo.m
        dg, dh, dr = triple
        scale = max([abs(v) for v in list(dg) + list(dh) + list(dr)] + [sp.Float(1)])
        if m:
            if max(abs(a - b) for a, b in zip(dg[:m], dh[:m])) > self.tol * scale:
                self.problems.append(f"{label}: Tα of its g and h parts differ "
                                     f"({_fmt(dg[:m])} vs {_fmt(dh[:m])})")
            moved = geo.target_jacobian(h) * sp.Matrix(dh)
            if max(abs(a - b) for a, b in zip(moved, dr[:m])) > self.tol * scale:
                self.problems.append(
                    f"{label}: Tβ of its h part {_fmt(moved)} ≠ Tα of its r part "
                    f"{_fmt(dr[:m])} (β = α∘i and the invariant fields disagree)")
        return sp.Matrix(list(dg[:m]) + list(dg[m:]) + list(dh[m:]) + list(dr[m:]))

    def fields(self, point, which: str) -> list[tuple[str, sp.Matrix]]:
        """[(name, vector)] for Z₁_a, Z₂_a (a = 1…n): which = 'right' (Z⃗) or 'left' (Z⃖)."""
        geo, (g, h, r) = self.geo, point
        n, zero = geo.n, sp.zeros(geo.m + geo.n, 1)
        out = []
        for k, name in ((1, "Z1"), (2, "Z2")):
            for a in range(n):
                if which == "right" and k == 1:
                    triple = (-geo.right_invariant(g)[:, a], -geo.right_invariant(h)[:, a], zero)
                elif which == "right":
                    triple = (-geo.left_invariant(g)[:, a], zero, zero)
                elif k == 1:
                    triple = (zero, -geo.left_invariant(h)[:, a], geo.right_invariant(r)[:, a])
                else:
                    triple = (zero, zero, geo.left_invariant(r)[:, a])
                arrow = "⃗" if which == "right" else "⃖"
                label = f"{name}{arrow}_{a + 1}"
                out.append((label, self._coordinates(point, triple, label)))
        return out


def cotangent_maps(groupoid, point, covector, h, tolerance: float = TOLERANCE):
    """α̃(γ), β̃(γ) of a covector γ = (γ_x, γ_g, γ_h, γ_r) on P^αG at point = (g, h, r)
    (elements as (x, f)), in the basis (Z₁_1…Z₁_n, Z₂_1…Z₂_n) of Lemma defsection.

    Entries of γ may be symbols (the result is then linear in them). Returns
    (alpha, beta, problems) with problems the tangency failures found.
    """
    with mpmath.workdps(DPS):
        geo = _Geometry(groupoid, _num(h))
        pro = _Prolongation(geo, tolerance)
        point = tuple(geo.element(*e) for e in point)
        gamma = sp.Matrix(covector)
        alpha = [sp.expand((gamma.T * v)[0]) for _, v in pro.fields(point, "right")]
        beta = [sp.expand((gamma.T * v)[0]) for _, v in pro.fields(point, "left")]
        return alpha, beta, pro.problems


def first_order_maps(groupoid, element, covector, h):
    """α̃(μ), β̃(μ) ∈ A*G of a covector μ on G at element = (x, f) (paper §2.1)."""
    with mpmath.workdps(DPS):
        geo = _Geometry(groupoid, _num(h))
        g = geo.element(*element)
        mu = sp.Matrix(covector)
        alpha = [sp.expand(v) for v in (mu.T * geo.right_invariant(g))]
        beta = [sp.expand(v) for v in (mu.T * geo.left_invariant(g))]
        return alpha, beta


# -- Σ_{L_d}: the pulled-back L_d and its second-order dynamics ----------------------------
class _Route:
    """Route 2 on one discrete model at one sample point."""

    def __init__(self, dm, h, fixed: dict, lams, tolerance: float):
        self.dm, self.h, self.fixed, self.lams = dm, h, fixed, lams
        self.geo = _Geometry(dm.groupoid, h)
        self.tol = tolerance
        augmented = dm.lagrangian + sum(l * c for l, c in zip(dm.multipliers, dm.constraints))
        self.slot_symbols = [s for x, f in dm.slots for s in tuple(x) + tuple(f)]
        self.gradient = [sp.diff(augmented, s) for s in self.slot_symbols]

    def slot_gradient(self, window: int, elements) -> list[sp.Float]:
        """∇ of L_d + λ^w Φ_d in slot coordinates at elements g_w, …, g_{w+r−1}."""
        values = dict(self.fixed)
        values.update(zip(self.dm.multipliers, self.lams[window]))
        for (X, F), (x, f) in zip(self.dm.slots, elements):
            values.update(zip(X, x))
            values.update(zip(F, f))
        return [_num(g.xreplace(values)) for g in self.gradient]

    def pulled_back(self, window: int, elements):
        """dL̂ on G (r = 1) or on G₂ in coordinates (x₀, f₀, f₁) (r = 2), through β."""
        grad = self.slot_gradient(window, elements)
        m, n = self.geo.m, self.geo.n
        if self.dm.order == 1:
            return sp.Matrix(grad)
        g0x, g0f = sp.Matrix(m, 1, grad[:m]), sp.Matrix(n, 1, grad[m:m + n])
        g1x, g1f = sp.Matrix(m, 1, grad[m + n:2 * m + n]), sp.Matrix(n, 1, grad[2 * m + n:])
        D = self.geo.target_jacobian(elements[0])
        through = D.T * g1x if m else sp.zeros(m + n, 1)
        return sp.Matrix.vstack(g0x + through[:m, :], g0f + through[m:, :], g1f)


def _second_order(route: _Route, elements):
    """Z₁ part of β̃(γ₁) − α̃(γ₂) with the splits fixed by the Z₂ parts (see module doc)."""
    geo, n, m = route.geo, route.geo.n, route.geo.m
    pro = _Prolongation(geo, route.tol)
    gammas, points = [], []
    for w in range(3):
        d = route.pulled_back(w, elements[w:w + 2])
        gammas.append((d[:m, :], d[m:m + n, :], d[m + n:, :]))  # γ_x, ∂L̂/∂f₀, γ_r
        points.append((elements[w], elements[w], elements[w + 1]))

    def pair(w, vector, mu):
        """⟨γ_w, v⟩ = γ_x·δx + μ·(δf_g − δf_h) + s·δf_h + γ_r·δf_r → (coefficient of μ,
        value with the given μ or None)."""
        gx, s, gr = gammas[w]
        dx, dg, dh, dr = (vector[:m, :], vector[m:m + n, :], vector[m + n:m + 2 * n, :],
                          vector[m + 2 * n:, :])
        base = ((gx.T * dx)[0] if m else 0) + (s.T * dh)[0] + (gr.T * dr)[0]
        coefficient = dg - dh
        value = None if mu is None else base + (coefficient.T * mu)[0]
        return coefficient, base, value

    mus = {0: None}
    for w in (0, 1):
        beta = pro.fields(points[w], "left")[n:]                 # Z⃖₂ at i(g_w, g_{w+1})
        alpha = pro.fields(points[w + 1], "right")[n:]           # Z⃗₂ at i(g_{w+1}, g_{w+2})
        rows, rhs = [], []
        for (_, vb), (_, va) in zip(beta, alpha):
            cb, kb, value = pair(w, vb, mus[w])
            if value is None:
                if max(abs(c) for c in cb) > route.tol:
                    raise ModelError("route 2: the Z₂ equations involve the split μ₀ of the "
                                     "first window, which the stencil does not fix")
                value = kb
            ca, ka, _ = pair(w + 1, va, None)
            rows.append(list(ca))
            rhs.append(value - ka)
        mus[w + 1] = sp.Matrix(rows).LUsolve(sp.Matrix(rhs))
    beta = pro.fields(points[1], "left")[:n]                      # Z⃖₁ at i(g_1, g_2)
    alpha = pro.fields(points[2], "right")[:n]                    # Z⃗₁ at i(g_2, g_3)
    composed = sp.Matrix([pair(1, vb, mus[1])[2] - pair(2, va, mus[2])[2]
                          for (_, vb), (_, va) in zip(beta, alpha)])
    return composed, pro.problems
