"""Consistency of discrete Euler–Lagrange residuals with the continuous equations (DESIGN.md §5).

The discrete residual at the middle node of a stencil, R(z; h), is expanded in h along a
smooth curve. The coefficient of the lowest power of h that survives must be the continuous
Euler–Lagrange (Euler–Poincaré, Lagrange–Poincaré) expression; the power of the next
surviving term measures how well the residual approximates it.

Conventions. Every expected expression is the *variational derivative* of the action,
E = δS/δ(node), with one sign for every groupoid and order:

* pair groupoid, :func:`euler_lagrange`: E(L) = ∂L/∂q − d/dt ∂L/∂q̇ + d²/dt² ∂L/∂q̈,
  which is minus the usual first-order expression d/dt ∂L/∂q̇ − ∂L/∂q and equal to the
  usual second-order one; for a Lagrangian of order r, E(L) = Σ_{j=0}^{r} (−d/dt)^j
  ∂L/∂q⁽ʲ⁾;
* on a Lie algebroid (q, y; anchor ρ, structure functions C), E = −EL_r(L) with
  the operator of Appendix C.2 (:func:`symvi.declaration.control.euler_lagrange_operator`)

      EL₁(L)_α = d/dt ∂L/∂y^α − ρ^i_α ∂L/∂q^i + C^γ_{αβ} y^β ∂L/∂y^γ

  and its second-order version (paper eq. ``ecuacionesvakonomoalgebroides2``, times −1),
  with P_γ = ∂L̃/∂y^γ − d/dt ∂L̃/∂ẏ^γ,

      EL₂(L̃)_α = d/dt P_α − ρ^i_α ∂L̃/∂q^i + C^γ_{αβ} y^β P_γ,

  where d/dt F = ∂F/∂q^i ρ^i_β y^β + Σ_k ∂F/∂y^{(k)} y^{(k+1)}. Of order r (a Lagrangian
  L(q, y, …, y⁽ʳ⁻¹⁾)), EL_r has the same form with P_γ = Σ_{j=0}^{r−1} (−d/dt)^j
  ∂L/∂y⁽ʲ⁾_γ (r − 1 integrations by parts of δy⁽ʲ⁾ = (d/dt)^j (η̇ + [y, η])). It is the first-order
  operator with ∂L/∂y replaced by the second-order momentum P (δy = η̇ + [y, η] enters the
  action through P after one integration by parts). On TQ (ρ = I, C = 0) EL_r = −E(L) of
  the pair groupoid; on so(3) with L̃ = ½|Ω̇ − f(Ω)|² it is −(d/dt + Ω×)(u̇ + Df(Ω)ᵀu),
  u = Ω̇ − f(Ω) (ERRATA.md, "Agree"). With constraints Φ^A and multipliers λ_A(t) the
  expected expression is E(L̃ + λ_A Φ^A) with λ a function of time, so that d/dt acts on
  it (the corrected form of ERRATA.md item 8: −d/dt(∂L̃/∂y^α + λ_A ∂Φ^A/∂y^α)).

With these the residual is ∂S_d/∂(node) and a node carries a time span h of the action, so
R = h·E(t_node) + O(h²). For a symmetric rule (midpoint, trapezoid, three-point, the Lie
rules with a symmetric retraction τ(−x) = τ(x)⁻¹) the residual is odd in h and the next
term is O(h³): the relative consistency error is O(h²).

Sampling. The stencil of the residual at node c (the middle one) is K = 2r consecutive
elements (x_0, f_0, …, f_{K−1}) with node j at time t + (j − c)h:

* pair groupoid (and pair factors of products): the fibre part of element i is its target
  node, f_i = q(t + (i + 1 − c)h), and x_0 = q(t − ch);
* Lie groups and action groupoids (and their factors): f_i = ξ_i, the group increment
  divided by h, sampled at the middle of the element, ξ_i = y(t + (i + ½ − c)h) (for a
  symmetric retraction τ⁻¹(g(t_i)⁻¹g(t_{i+1}))/h = y(t_i + h/2) + O(h²), so either choice
  has the same leading term and the same parity in h);
* the base point of an action groupoid is x_0 = q(t − ch); the later base points follow
  from the kernel's definitions x_j = β(x_{j−1}, f_{j−1}) = φ(x_{j−1}, τ(hξ_{j−1}));
* multipliers λ^w of window w (constrained models) are sampled at the window's middle
  node, λ^w = λ(t + (w + r/2 − c)h).

Jets: the pair groupoid's expansion uses the derivatives q^{(k)}(t) as symbols. On an
algebroid the independent quantities are the base point q(t) and the derivatives y^{(k)}(t)
of the fibre curve; derivatives of q follow from the anchor, q̇ = ρ(q) y (for a pair factor
y = q̇, so q^{(k+1)} = y^{(k)}). Results are reported as functions of t: base coordinates
q_i(t), fibre coordinates y_α(t) and their derivatives (a pair factor's y^{(k)} as q^{(k+1)}).

Method. The expansion is a small truncated Laurent-series arithmetic over the residual's
expression tree (sums, products, integer powers, analytic functions of one argument — the
exponential retraction's coefficient functions through their exact Taylor series) that
tracks up to which power every intermediate result is exact. It never calls
``sympy.series`` on the substituted residual, which is slow for trigonometric Lagrangians,
and derivatives are plain *jet* symbols until the result is reported, so the identities
needed are polynomial ones. The coefficients are sparse Laurent polynomials with rational
coefficients in the atoms they contain (jets, parameters, values such as sin(q)) rather
than SymPy expressions — ``sympy.expand`` of products of large sums was the cost — and are
tested for zero as expressions at the end (:func:`_is_zero`: random points, then
``simplify`` when small). The series arithmetic lives in :mod:`symvi.checks.series`, the jets and
the continuous operators in :mod:`symvi.checks.jets`; this module samples stencils, expands them
and compares the result with the continuous equations.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import sympy as sp
from sympy.core.function import AppliedUndef

from ..derivation.derive import DerivedModel, derive
from ..discretisation.discretise import discretise
from ..errors import ModelError
from .jets import (TIME, _AlgebroidJets, _Jets, _layout, _variational_derivative, component_names,
                   constraint_functions, euler_lagrange_algebroid, unsupported)
from ..declaration.model import Model
from .series import (_EXACT, _QQ, _Expander, _is_zero, _Poly, _Series, _series_of, _truncate,
                     expansion_scope)
from .._runtime.core.model_info import Kernel as KernelName

__all__ = ["TIME", "ResidualExpansion", "ConsistencyReport", "check_consistency", "compact",
           "euler_lagrange", "euler_lagrange_algebroid", "constraint_functions",
           "expand_residual", "expand_stencil", "sample_stencil", "residual_expansion",
           "constraint_expansion", "unsupported", "component_names"]


# --------------------------------------------------------------------------------------
# Public API
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ResidualExpansion:
    """The Taylor expansion in h of a discrete residual (or any kernel output) along a
    smooth curve.

    Attributes
    ----------
    step, time : the symbols h and t.
    terms : the non-zero coefficients, ((power, column matrix), …) in increasing power,
        in terms of functions of t and their derivatives (module doc).
    through : every power ≤ ``through`` has been computed (absent powers vanish).
    """

    step: sp.Symbol
    time: sp.Symbol
    terms: tuple[tuple[int, sp.Matrix], ...]
    through: int
    _jets: object
    _jet_terms: tuple[tuple[int, sp.Matrix], ...]

    @property
    def leading_power(self) -> int | None:
        return self.terms[0][0] if self.terms else None

    @property
    def leading(self) -> sp.Matrix | None:
        return self.terms[0][1] if self.terms else None

    @property
    def next_power(self) -> int | None:
        return self.terms[1][0] if len(self.terms) > 1 else None

    @property
    def next_term(self) -> sp.Matrix | None:
        return self.terms[1][1] if len(self.terms) > 1 else None

    @property
    def order(self) -> int | None:
        """Consistency order: next power − leading power (the relative error is O(h^order))."""
        if self.leading_power is None or self.next_power is None:
            return None
        return self.next_power - self.leading_power

    def sign_against(self, expected: sp.Matrix) -> int | None:
        """+1 if the leading coefficient equals ``expected``, −1 if it equals −expected,
        None otherwise (``expected`` as returned by :func:`euler_lagrange` with the same
        ``time``)."""
        sign, rows = self.compare(expected)
        return sign if sign is not None and not rows else None

    def compare(self, expected: sp.Matrix) -> tuple[int | None, list[int]]:
        """(s, rows): the sign s = ±1 for which the leading coefficient agrees with
        s·``expected`` in the most components, and the components where it does not
        ((None, every row) when there is no leading term)."""
        expected = sp.Matrix(expected)
        if not self._jet_terms:
            return None, list(range(expected.rows))
        lead = self._jet_terms[0][1]
        target = _to_jets(expected, self._jets, self.time)
        if lead.rows != target.rows:
            raise ModelError(f"the residual has {lead.rows} components, the expected "
                             f"expression {target.rows}")
        best = None
        for sign in (1, -1):
            rows = [i for i, (a, b) in enumerate(zip(lead, target)) if not _is_zero(a - sign * b)]
            if best is None or len(rows) < len(best[1]):
                best = (sign, rows)
            if not rows:
                break
        return best


def _to_jets(expr: sp.Matrix, jets, t: sp.Symbol) -> sp.Matrix:
    """Inverse of the jets' ``to_functions`` (derivatives beyond the jet depth are kept)."""
    return sp.Matrix(expr).applyfunc(lambda e: jets.from_functions(e, t))


@expansion_scope
def euler_lagrange(model: Model, t: sp.Symbol = TIME, *, multipliers: bool = True) -> sp.Matrix:
    """The variational derivative E of the action along functions of ``t`` (module doc).

    Pair groupoid: E(L) = ∂L/∂q − d/dt ∂L/∂q̇ + d²/dt² ∂L/∂q̈ along q_c(t) (of order r,
    Σ_{j≤r} (−d/dt)^j ∂L/∂q⁽ʲ⁾). Other groupoids:
    E = −EL_r(L) on the algebroid (:func:`euler_lagrange_algebroid`). For a constrained
    model with ``multipliers``, E(L̃ + λ_A(t) Φ^A), the multipliers being functions
    ``lambda0(t)``, … Needs a model declared with a continuous Lagrangian.
    """
    if model.lagrangian is None:
        raise ModelError(f"model {model.name!r} has no continuous Lagrangian")
    constraints = tuple(model.constraints) if multipliers else ()
    if model.groupoid.elements_are_node_pairs and not constraints:
        jets = _Jets.make(model.groupoid.names, 2 * model.order)
        return _variational_derivative(model.groupoid, model.lagrangian, model.order,
                                       jets).applyfunc(lambda e: jets.to_functions(e, t))
    return -euler_lagrange_algebroid(model.groupoid, model.lagrangian, model.order, t,
                                     constraints)


def _collect(columns: Sequence[_Series], jets, step, t, through) -> ResidualExpansion:
    powers = sorted({p for s in columns for p in s.terms})
    jet_terms = []
    for p in powers:
        entries = [s.coefficient(p) for s in columns]
        entries = [sp.Integer(0) if _is_zero(c) else sp.expand(c) for c in entries]
        if any(c != 0 for c in entries):
            jet_terms.append((p, sp.Matrix(entries)))
    terms = tuple((p, M.applyfunc(lambda e: jets.to_functions(e, t))) for p, M in jet_terms)
    return ResidualExpansion(step=step, time=t, terms=terms, through=through, _jets=jets,
                             _jet_terms=tuple(jet_terms))


@expansion_scope
def expand_residual(residual: sp.Matrix, nodes: Sequence[Sequence[sp.Symbol]],
                    step: sp.Symbol, names: Sequence[str], *, centre: int,
                    through: int, t: sp.Symbol = TIME) -> ResidualExpansion:
    """Expand ``residual`` in ``step`` with node i set to q(t + (i − centre)·h).

    ``nodes[i]`` are the coordinate symbols of node i; ``names`` name the coordinate
    functions. Every power of h up to ``through`` is computed; the node Taylor polynomials
    are lengthened until that precision is reached.
    """
    residual = sp.Matrix(residual)
    # Lower bound of the residual's order with O(1) nodes: a pole h^{-p} (the 1/h² of
    # the three-point rule's acceleration) costs p orders of the Taylor polynomials.
    probe = _Expander(step, {s: _series_of({0: s}, _EXACT) for node in nodes for s in node})
    first = through + 1 - min([0] + [probe.valuation(e) for e in residual])

    def sample(degree):
        jets = _Jets.make(names, degree)
        atoms = {s: _series_of({k: sp.Rational((i - centre)**k, math.factorial(k))
                                * jets.symbols[c][k] for k in range(degree + 1)}, degree)
                 for i, node in enumerate(nodes) for c, s in enumerate(node)}
        return jets, atoms
    return _expand_until(residual, step, through, t, range(first, first + 11), sample)


def _expand_until(outputs: sp.Matrix, step: sp.Symbol, through: int, t: sp.Symbol,
                  degrees, sample, definitions=None) -> ResidualExpansion:
    """Lengthen the Taylor polynomials (``sample(degree)`` → jets and the series of each
    stencil symbol) until every power of h through ``through`` is exact."""
    for degree in degrees:
        jets, atoms = sample(degree)
        expander = _Expander(step, atoms, definitions)
        columns = [expander.series(e, through) for e in outputs]
        if min(c.prec for c in columns) >= through:
            return _collect(columns, jets, step, t, through)
    raise ModelError(f"could not reach precision h^{through} in the residual expansion")


def _taylor(values: Sequence, offset: sp.Rational, degree: int) -> _Series:
    """Σ_k (offset·h)^k/k! values[k] (expressions or coefficient polynomials), exact
    through h^degree."""
    return _truncate({k: (v if isinstance(v, _Poly) else _Poly.of(v)).scale(
        _QQ(int((offset**k).p), int((offset**k).q) * math.factorial(k)))
        for k, v in enumerate(values[:degree + 1])}, degree)


def _stencil_atoms(jets: _AlgebroidJets, groupoid, z: Sequence[sp.Symbol], *, elements: int,
                   centre: int | sp.Rational, order: int, degree: int, windows: int,
                   multipliers: int,
                   with_multipliers: bool) -> dict[sp.Symbol, _Series]:
    """The sampled stencil coordinates as Taylor polynomials of degree ``degree``."""
    m, n = groupoid.source_dim, groupoid.fibre_dim
    size = m + elements * n + windows * multipliers
    if len(z) != size:
        raise ModelError(f"a stencil of {elements} elements and {windows} windows of "
                         f"{multipliers} multipliers has {size} coordinates, the kernel "
                         f"has {len(z)}")
    x0 = tuple(z[:m])
    fs = [tuple(z[m + i * n:m + (i + 1) * n]) for i in range(elements)]
    start = m + elements * n
    lams = [tuple(z[start + w * multipliers:start + (w + 1) * multipliers])
            for w in range(windows)]
    layout = _layout(groupoid)
    base = [[jets.base_derivative_poly(i, k) for k in range(degree + 1)] for i in range(m)]
    centre = sp.sympify(centre)     # a half-integer: the middle of an odd window
    atoms = {s: _taylor(base[i], -centre, degree) for i, s in enumerate(x0)}
    for i, f in enumerate(fs):
        for c, s in enumerate(f):
            b = layout[c]
            if b is not None:       # a pair factor: the target node q(t + (i + 1 − c)h)
                atoms[s] = _taylor(base[b], i + 1 - centre, degree)
            else:                   # a group increment: y at the element's middle
                atoms[s] = _taylor(jets.y[c], i - centre + sp.S.Half, degree)
    for w, lam in enumerate(lams):  # multipliers at the window's middle (node or element)
        offset = w - centre + sp.Rational(order, 2)
        for a, s in enumerate(lam):
            atoms[s] = (_taylor(jets.lam[a], offset, degree) if with_multipliers
                        else _Series({}, _EXACT))
    return atoms


@expansion_scope
def sample_stencil(groupoid, z: Sequence[sp.Symbol], step: sp.Symbol, *, elements: int,
                   centre: int | sp.Rational, order: int, degree: int, windows: int = 0,
                   multipliers: int = 0, t: sp.Symbol = TIME) -> dict[sp.Symbol, sp.Expr]:
    """The values :func:`expand_stencil` gives the stencil coordinates ``z``: polynomials
    of degree ``degree`` in ``step`` whose coefficients are functions of ``t`` (module doc;
    later base points follow from the kernel's definitions)."""
    jets = _AlgebroidJets(groupoid, degree + 2 * order + 1, multipliers)
    atoms = _stencil_atoms(jets, groupoid, z, elements=elements, centre=centre, order=order,
                           degree=degree, windows=windows, multipliers=multipliers,
                           with_multipliers=True)
    return {s: jets.to_functions(sp.Add(*[c.as_expr() * step**p for p, c in a.terms.items()]), t)
            for s, a in atoms.items()}


@expansion_scope
def expand_stencil(outputs: sp.Matrix, z: Sequence[sp.Symbol], groupoid, step: sp.Symbol, *,
                   elements: int, centre: int | sp.Rational, order: int, through: int,
                   definitions: Sequence[tuple[sp.Symbol, sp.Expr]] = (),
                   windows: int = 0, multipliers: int = 0, with_multipliers: bool = True,
                   t: sp.Symbol = TIME) -> ResidualExpansion:
    """Expand kernel ``outputs`` in ``step`` along a smooth curve on any groupoid.

    ``z`` = (x_0, f_0, …, f_{K−1}, λ^0, …, λ^{W−1}) is a stencil of K = ``elements``
    consecutive elements (and the ``multipliers`` multipliers of each of W = ``windows``
    windows of ``order`` elements); ``definitions`` are the kernel's named base points.
    Node j is at time t + (j − ``centre``)·h; the sampling is that of the module doc.
    Without ``with_multipliers`` the multipliers are set to zero. Every power through
    h^``through`` is computed.
    """
    outputs = sp.Matrix(outputs)
    definitions = dict(definitions)
    # Lower bound of the outputs' order in h with O(1) coordinates: a pole h^{-p} costs
    # p orders of the Taylor polynomials.
    probe = _Expander(step, {s: _series_of({0: s}, _EXACT) for s in z}, definitions)
    lowest = min([0] + [probe.valuation(e) for e in outputs])
    first = max(through + 1 - lowest, 1)

    def sample(degree):
        jets = _AlgebroidJets(groupoid, degree + 2 * order + 1,
                              multipliers if with_multipliers else 0)
        return jets, _stencil_atoms(jets, groupoid, z, elements=elements, centre=centre,
                                    order=order, degree=degree, windows=windows,
                                    multipliers=multipliers, with_multipliers=with_multipliers)
    return _expand_until(outputs, step, through, t, range(first, first + 8), sample,
                         definitions)


def _stencil_kernel(model: Model, dm: DerivedModel):
    """(residual, coordinates, definitions, windows, multipliers per window) of the
    residual at the middle node: the step kernel, or the stencil kernel of a constrained
    model — with a bounded model's inequality multipliers z set to zero (the residual of
    the problem without its inequalities, which is what the continuous equations
    describe)."""
    if not model.constraints:
        kernel = dm.kernel(KernelName.STEP)
        return dict(kernel.outputs)["residual"], kernel.z, kernel.definitions, 0, 0
    if "stencil" not in [k.name for k in dm.kernels]:
        raise ModelError(f"model {model.name!r} has constraints but no stencil kernel")
    kernel, windows, s = dm.kernel(KernelName.STENCIL), dm.order + 1, dm.constraint_count
    per = s + len(dm.inequality_names)
    head = len(kernel.z) - windows * per
    bound = {kernel.z[head + w * per + k]: sp.S.Zero
             for w in range(windows) for k in range(s, per)}
    z = [c for c in kernel.z if c not in bound]
    definitions = tuple((d, e.xreplace(bound)) for d, e in kernel.definitions)
    return (dict(kernel.outputs)["residual"].xreplace(bound), z, definitions, windows, s)


@expansion_scope
def residual_expansion(model: Model, *, derived: DerivedModel | None = None,
                       terms: int = 2, max_power: int = 7, t: sp.Symbol = TIME,
                       multipliers: bool = True) -> ResidualExpansion:
    """Expand the discrete Euler–Lagrange residual of ``model`` in h.

    The residual is the ``step`` kernel of ``derive(discretise(model))`` (pass ``derived``
    to reuse one): on the pair groupoid its stencil is the nodes q_{j−r} … q_{j+r}, on
    other groupoids the 2r elements around the node (module doc). A constrained model has
    no step kernel: its ``stencil`` kernel's residual is expanded, with the multipliers of
    its r+1 windows sampled from smooth λ_A(t) (set to zero without ``multipliers``).
    Powers are computed until ``terms`` non-zero coefficients are found or ``max_power``
    is reached.
    """
    dm = derived if derived is not None else derive(discretise(model))
    if model.groupoid.elements_are_node_pairs and not model.constraints:
        kernel = dm.kernel(KernelName.STEP)
        residual = dict(kernel.outputs)["residual"]
        n, r = dm.fibre_dim, dm.order
        nodes = [kernel.z[i * n:(i + 1) * n] for i in range(2 * r + 1)]
        through = min(3, max_power)
        while True:
            expansion = expand_residual(residual, nodes, dm.step, model.groupoid.names,
                                        centre=r, through=through, t=t)
            if len(expansion.terms) >= terms or through >= max_power:
                return expansion
            through = min(max_power, through + 2)
    residual, z, definitions, windows, count = _stencil_kernel(model, dm)
    r = dm.order
    through = min(3, max_power)
    while True:
        expansion = expand_stencil(residual, z, model.groupoid, dm.step,
                                   elements=2 * r, centre=r, order=r, through=through,
                                   definitions=definitions, windows=windows,
                                   multipliers=count, with_multipliers=multipliers, t=t)
        if len(expansion.terms) >= terms or through >= max_power:
            return expansion
        through = min(max_power, through + 2)


@expansion_scope
def constraint_expansion(model: Model, *, derived: DerivedModel | None = None,
                         terms: int = 2, max_power: int = 5,
                         t: sp.Symbol = TIME) -> ResidualExpansion:
    """Expand the discrete constraints Φ_d of a constrained ``model`` on one window of r
    elements centred at t (its middle: a node, or an element's midpoint for r = 1);
    consistent ones give h·Φ(t) + O(h³)."""
    if not model.constraints:
        raise ModelError(f"model {model.name!r} has no constraints")
    dm = derived if derived is not None else derive(discretise(model))
    kernel = dm.kernel(KernelName.CONSTRAINT)
    value = dict(kernel.outputs)["value"]
    r = dm.order
    through = min(3, max_power)
    while True:
        expansion = expand_stencil(value, kernel.z, model.groupoid, dm.step, elements=r,
                                   centre=sp.Rational(r, 2), order=r, through=through,
                                   definitions=kernel.definitions, t=t)
        if len(expansion.terms) >= terms or through >= max_power:
            return expansion
        through = min(max_power, through + 2)


@dataclass(frozen=True)
class ConsistencyReport:
    """Outcome of :func:`check_consistency`.

    ``sign`` is +1 when R = h^power·E + …, −1 for −E, None when the leading term is not ±E
    (the residual is inconsistent); ``order`` is the consistency order; ``expected`` is E
    (:func:`euler_lagrange`). For a constrained model ``constraints`` reports the discrete
    constraints Φ_d against h·Φ in the same way.
    """

    model: str
    power: int | None
    sign: int | None
    order: int | None
    expansion: ResidualExpansion
    expected: sp.Matrix | None = None
    constraints: "ConsistencyReport | None" = None

    @property
    def consistent(self) -> bool:
        return self.sign is not None and (self.constraints is None
                                          or self.constraints.consistent)


@expansion_scope
def check_consistency(model: Model, *, derived: DerivedModel | None = None,
                      lagrangian_model: Model | None = None, multipliers: bool = True,
                      max_power: int = 7) -> ConsistencyReport:
    """Compare the leading term of ``model``'s residual with the continuous equations.

    ``lagrangian_model`` supplies the continuous Lagrangian (and constraints) when
    ``model`` was declared with a discrete one (default: ``model`` itself). For a
    constrained model the residual with smooth multipliers is compared with
    E(L̃ + λ_A Φ^A) (``multipliers=False``: multipliers zero, against E(L̃)), and its
    discrete constraints with h·Φ.
    """
    reference = lagrangian_model if lagrangian_model is not None else model
    dm = derived if derived is not None else derive(discretise(model))
    expansion = residual_expansion(model, derived=dm, multipliers=multipliers,
                                   max_power=max_power)
    expected = euler_lagrange(reference, expansion.time, multipliers=multipliers)
    sign = expansion.sign_against(expected)
    constraints = None
    if model.constraints and reference.constraints:
        c = constraint_expansion(model, derived=dm, t=expansion.time)
        target = constraint_functions(reference, expansion.time)
        constraints = ConsistencyReport(model=model.name, power=c.leading_power,
                                        sign=c.sign_against(target), order=c.order,
                                        expansion=c, expected=target)
    return ConsistencyReport(model=model.name, power=expansion.leading_power, sign=sign,
                             order=expansion.order, expansion=expansion, expected=expected,
                             constraints=constraints)


def compact(expr, t: sp.Symbol = TIME, width: int = 300) -> str:
    """A short text of a coefficient: f(t) → f and its derivatives → f', f'', f''', f^(4), …;
    cut at ``width`` characters."""
    expr = sp.sympify(expr)
    mapping = {}
    for d in expr.atoms(sp.Derivative):
        if isinstance(d.expr, AppliedUndef):
            k = d.derivative_count
            mark = "'" * k if k <= 3 else f"^({k})"
            mapping[d] = sp.Symbol(d.expr.func.__name__ + mark)
    for f in expr.atoms(AppliedUndef):
        if f.args == (t,):
            mapping[f] = sp.Symbol(f.func.__name__)
    text = sp.sstr(expr.xreplace(mapping))
    return text if len(text) <= width else text[:width - 1] + "…"
