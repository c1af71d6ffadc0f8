"""Symbolic derivation: discrete Euler–Lagrange residuals, momenta and Jacobians.

One engine for every groupoid (DESIGN.md §2). A discrete path is a sequence of composable
elements E_0, E_1, … with E_i = (x_i, f_i) and x_{i+1} = β(x_i, f_i). Node ν_j is the
base point shared by E_{j−1} and E_j. Hamilton's principle varies ν_j by
E_{j−1} → E_{j−1}·σ(ε), E_j → σ(ε)⁻¹·E_j; the variation of the action term
L_d(E_w, …, E_{w+r−1}) (order r) is ``right(E_{j−1})ᵀ ∇_slot L_d + left(E_j)ᵀ ∇_slot L_d``
for the slots that hold E_{j−1}, E_j. Summing over the windows that contain ν_j gives the
discrete Euler–Lagrange residual (paper §2.2 for r = 1; §3.1, eq. ``delelg`` for r = 2).

The same sum over the windows that lie entirely before (after) a node gives the discrete
Legendre transforms F⁺L_d (−F⁻L_d) — the momenta of Appendix B for r = 1 and of §4.3 for
r = 2; on a solution the two agree, which is the residual vanishing.

Kernels are described on a *stencil* of K consecutive elements, with coordinates
z = (x_0, f_0, …, f_{K−1}). Later base points x_j = β(x_{j−1}, f_{j−1}) are substituted
when β is a plain coordinate (the pair groupoid) and otherwise kept as named intermediate
quantities of the kernel (``definitions``), with the chain rule applied through them:
substituting a nonlinear β (an action through τ(hξ)) into every derivative makes the
expressions grow many-fold.
"""
from __future__ import annotations

import threading
from collections import OrderedDict
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import sympy as sp

from ..discretisation.discretise import DiscreteModel
from ..errors import ModelError
from ..groupoids.analytic import used_coefficients
from ..groupoids.base import CContext
from .._runtime.core.model_info import Kernel as KernelName
from ..declaration.rank import generic_rank
from .differentiate import (_UNTRANSLATABLE, _Translation, engine_function, gradient,
                            gradient_and_hessian, jacobian)


@dataclass(frozen=True)
class Kernel:
    """One function to compile: z, parameters and h in; named arrays out.

    ``outputs`` maps names to SymPy matrices (row-major flattening in C).
    """

    name: KernelName | str
    z: tuple[sp.Symbol, ...]
    outputs: tuple[tuple[str, sp.Matrix], ...]
    doc: str
    #: Intermediate quantities (symbol, expression), in evaluation order; outputs and
    #: later definitions may use the symbols.
    definitions: tuple[tuple[sp.Symbol, sp.Expr], ...] = ()
    #: Whether z is a window of consecutive elements (x_0, f_0, …), so that the kernel
    #: can be evaluated along a path.
    along: bool = True

    def __post_init__(self) -> None:
        # named by the run time's enum (a string only for an end stencil stencil_end<j>)
        if isinstance(self.name, KernelName):
            object.__setattr__(self, "name", self.name.value)


@dataclass(frozen=True, eq=False)
class DerivedModel:
    """Everything the C emitter needs, as data (no reference back to the Model)."""

    name: str
    kind: str
    order: int
    source_dim: int
    fibre_dim: int
    parameters: tuple[sp.Symbol, ...]
    defaults: tuple[float, ...]
    step: sp.Symbol
    kernels: tuple[Kernel, ...]
    whole_trajectory: bool
    has_energy: bool
    #: How initial data are laid out: "nodes" or "elements"
    #: (:meth:`Groupoid.initial_layout`).
    initial_layout: str
    fingerprint: str
    c_context: CContext
    #: Analytic coefficient functions (exponential retraction) the C must define.
    coefficients: tuple = ()
    #: Number s of constraints per window (multipliers λ^k ∈ R^s) and of controls.
    constraint_count: int = 0
    control_count: int = 0
    #: The declared names of the base coordinates, of the velocities (one per fibre
    #: coordinate, :meth:`Groupoid.state_symbols`) and of the controls.
    coordinate_names: tuple[str, ...] = ()
    velocity_names: tuple[str, ...] = ()
    control_names: tuple[str, ...] = ()
    #: :attr:`DiscreteModel.constraint_names`.
    constraint_names: tuple[str, ...] = ()
    unactuated: tuple[int, ...] = ()
    #: :attr:`DiscreteModel.end_free` and :attr:`DiscreteModel.end_names`.
    end_free: bool = False
    end_names: tuple[str, ...] = ()
    #: :attr:`DiscreteModel.pure_minimum_time`.
    pure_minimum_time: bool = False
    #: The inequalities c ≤ 0 per window (their count is the ``inequality`` kernel's rows).
    inequality_names: tuple[str, ...] = ()
    #: The control-free inequalities on one element (the ``boundary`` kernel's rows).
    boundary_names: tuple[str, ...] = ()
    #: Pairs (i, j) of inequality rows whose sum c_i + c_j depends on the parameters
    #: alone — a bound's two sides, c_i + c_j = lower − upper (:func:`interval_pairs`).
    intervals: tuple[tuple[int, int], ...] = ()
    #: Per fibre coordinate: an increment divided by h (a group factor's ξ).
    step_scaled: tuple[bool, ...] = ()
    #: Names of the conserved quantities F_Z of the ``noether`` kernel.
    symmetries: tuple[str, ...] = ()
    #: Names of the symmetries on which the constraints depend exactly (the ``gauge``
    #: kernel's rows).
    gauges: tuple[str, ...] = ()
    #: For the lifted whole-trajectory solve (:func:`fibre_sources`): per fibre
    #: coordinate, the base coordinate it is measured from (a pair factor's q_{k+1}) or
    #: −1 (a group increment); empty when the model has no lifted solve.
    fibre_sources: tuple[int, ...] = ()
    #: :meth:`Groupoid.configuration_base`.
    configuration_base: tuple[int, ...] = ()

    @property
    def stencil_elements(self) -> int:
        """K = 2r: elements in the stencil of one residual."""
        return 2 * self.order

    def kernel(self, name: KernelName | str) -> Kernel:
        """The kernel ``name``: a :class:`~symvi._runtime.core.model_info.Kernel` (the
        names the run time calls), or the name of an end stencil ``stencil_end<j>``."""
        key = name.value if isinstance(name, KernelName) else name
        return next(k for k in self.kernels if k.name == key)


@dataclass(frozen=True)
class _Stencil:
    z: tuple[sp.Symbol, ...]
    xs: tuple[tuple[sp.Expr, ...], ...]
    fs: tuple[tuple[sp.Symbol, ...], ...]
    #: Named base points x_j = β(x_{j−1}, f_{j−1}), then the entries of their Jacobians.
    definitions: tuple[tuple[sp.Symbol, sp.Expr], ...]
    jacobian_definitions: tuple[tuple[sp.Symbol, sp.Expr], ...]
    #: dx_j/dz for every base point (entries are expressions or definition symbols).
    source_jacobians: tuple[sp.Matrix, ...]
    #: Multipliers λ^w of the windows w = 0, 1, … starting at the stencil's elements
    #: (constrained models; the last coordinates of z).
    multipliers: tuple[tuple[sp.Symbol, ...], ...] = ()

    def total_jacobian(self, R: sp.Matrix, wrt: Sequence[sp.Symbol] | None = None) -> sp.Matrix:
        """dR/dz, or dR/d(wrt) for ``wrt`` a part of z, with the chain rule through the
        named base points."""
        wrt = self.z if wrt is None else tuple(wrt)
        columns = [self.z.index(s) for s in wrt]
        named = {s for s, _ in self.definitions}
        return jacobian(R, wrt, [(x, D.extract(list(range(D.rows)), columns))
                                 for x, D in zip(self.xs[1:], self.source_jacobians[1:])
                                 if x and x[0] in named])


def _on_element(dm: DiscreteModel, st: _Stencil, element: int) -> dict:
    """The first slot's coordinates (x, f) ↦ those of ``element`` of the stencil: an
    expression on one element (a boundary inequality, an end condition) placed there."""
    (x, f), = dm.slots[:1]
    return dict(zip(x, st.xs[element])) | dict(zip(f, st.fs[element]))


def _selector(symbols, z) -> sp.Matrix:
    return sp.Matrix(len(symbols), len(z), lambda i, j: int(z[j] == symbols[i]))


def _name_entries(E: sp.Matrix, prefix: str, out: list) -> sp.Matrix:
    """Replace the non-constant entries of E by fresh symbols recorded in ``out``."""
    def entry(i, j):
        if E[i, j].is_number:
            return E[i, j]
        symbol = sp.Dummy(f"{prefix}_{i}_{j}", real=True)
        out.append((symbol, E[i, j]))
        return symbol
    return sp.Matrix(E.shape[0], E.shape[1], entry)


def _stencil(dm: DiscreteModel, elements: int, windows: int = 0,
             extra: tuple[sp.Symbol, ...] = ()) -> _Stencil:
    g = dm.groupoid
    x0 = tuple(sp.Dummy(f"x_{i}", real=True) for i in range(g.source_dim))
    fs = tuple(tuple(sp.Dummy(f"f{k}_{i}", real=True) for i in range(g.fibre_dim))
               for k in range(elements))
    lams = tuple(tuple(sp.Dummy(f"lam{w}_{a}", real=True)
                       for a in range(len(dm.window_multipliers))) for w in range(windows))
    z = x0 + tuple(s for f in fs for s in f) + tuple(s for lam in lams for s in lam) + extra
    xs, definitions, jacobian_definitions = [x0], [], []
    D = [_selector(x0, z)]
    for k in range(elements - 1):
        if not x0:
            xs.append(())
            D.append(D[0])
            continue
        beta = sp.Matrix(g.target(xs[-1], fs[k], dm.step))
        E = beta.jacobian(xs[-1]) * D[-1] + beta.jacobian(fs[k]) * _selector(fs[k], z)
        if all(isinstance(v, sp.Symbol) for v in beta):
            xs.append(tuple(beta))
            D.append(E)
            continue
        named = tuple(sp.Dummy(f"x{k + 1}_{i}", real=True) for i in range(len(x0)))
        definitions += list(zip(named, beta))
        xs.append(named)
        D.append(_name_entries(E, f"Dx{k + 1}", jacobian_definitions))
    return _Stencil(z, tuple(xs), fs, tuple(definitions), tuple(jacobian_definitions),
                    tuple(D), lams)


class _Engine:
    """Node variations of the (augmented) action sum of one discrete model.

    With constraints the varied function is L_d + λ_A Φ^A_d, λ the multipliers of the
    window (paper §3.2, eq. ``constrainedso``), and with inequalities c ≤ 0 also + z·c
    (the Lagrangian of the interior-point solve).
    """

    def __init__(self, dm: DiscreteModel):
        self.dm = dm
        augmented = dm.lagrangian + sum(
            l * c for l, c in zip(dm.window_multipliers, dm.window_constraints))
        # kept in SymEngine: each variation substitutes a window's symbols into them there
        # (SymPy's xreplace of the 20-link chain's gradients took 3 s). In SymPy where
        # SymEngine cannot take the Lagrangian, or where it holds analytic coefficients
        # c(s): their stand-ins do not see a substitution into s.
        t = _Translation()
        try:
            gradients = tuple(gradient(augmented, x + f, t) for x, f in dm.slots)
        except _UNTRANSLATABLE:
            t, gradients = None, tuple(sp.Matrix([sp.diff(augmented, s) for s in x + f])
                                       for x, f in dm.slots)
        if t is not None and t.applications:
            gradients = tuple(t.sympy(G) for G in gradients)
            t = None
        self.translation, self.gradients = t, gradients

    def _window_mapping(self, st: _Stencil, w: int) -> dict:
        own = self.dm.window_multipliers
        lams = st.multipliers[w] if w < len(st.multipliers) else (0,) * len(own)
        mapping = dict(zip(own, lams))
        for j, (X, F) in enumerate(self.dm.slots):
            mapping.update(zip(X, st.xs[w + j]))
            mapping.update(zip(F, st.fs[w + j]))
        return mapping

    def variation(self, st: _Stencil, node: int, windows) -> sp.Matrix:
        """Σ over ``windows`` of d/dε of L_d(window) when node ν_node is varied."""
        g, r, t = self.dm.groupoid, self.dm.order, self.translation
        engine = (lambda M: M) if t is None else t.engine
        total = None
        for w in windows:
            mapping = self._window_mapping(st, w)
            if t is not None:
                mapping = dict(zip((t.stand_in(k) for k in mapping),
                                   engine(sp.Matrix(list(mapping.values())))))
            for element, side in ((node - 1, g.right), (node, g.left)):
                slot = element - w
                if 0 <= slot < r:
                    grad = self.gradients[slot].xreplace(mapping)
                    term = engine(side(st.xs[element], st.fs[element], self.dm.step).T) * grad
                    total = term if total is None else total + term
        if total is None:
            return sp.zeros(g.fibre_dim, 1)
        return total if t is None else t.sympy(total)

    def element_variation(self, st: _Stencil, node: int, element: int,
                          F: sp.Expr) -> sp.Matrix:
        """d/dε of F on one element (an expression in the first slot's coordinates)
        when node ν_node is varied: zero unless the element meets the node."""
        g, (X, Fs) = self.dm.groupoid, self.dm.slots[0]
        side = g.right if node == element + 1 else g.left if node == element else None
        if side is None:
            return sp.zeros(g.fibre_dim, 1)
        grad = sp.Matrix([sp.diff(F, s) for s in tuple(X) + tuple(Fs)])
        return side(st.xs[element], st.fs[element], self.dm.step).T \
            * grad.xreplace(_on_element(self.dm, st, element))

    def lagrangian(self, st: _Stencil, w: int) -> sp.Expr:
        return self.dm.lagrangian.xreplace(self._window_mapping(st, w))

    def window_values(self, st: _Stencil, w: int, exprs) -> sp.Matrix:
        """Slot expressions (constraints, controls) on window w of the stencil."""
        mapping = self._window_mapping(st, w)
        return sp.Matrix([e.xreplace(mapping) for e in exprs])


def _stack(vectors) -> sp.Matrix:
    return sp.Matrix.vstack(*vectors)


def _kernels(dm: DiscreteModel) -> tuple[Kernel, ...]:
    engine, r, g = _Engine(dm), dm.order, dm.groupoid
    constrained, windowed = bool(dm.constraints), bool(dm.window_constraints)
    sources, lifted = increment_sources(dm), fibre_sources(dm)
    full = _stencil(dm, 2 * r, windows=r + 1 if windowed else 0)
    residual = engine.variation(full, r, range(r + 1))
    one = _stencil(dm, 1)
    window = _stencil(dm, r)
    target = sp.Matrix(g.target(one.xs[0], one.fs[0], dm.step))
    # with inequalities only, the step map is that of the unbounded problem (z = 0)
    plain = _stencil(dm, 2 * r) if windowed else full
    kernels = [] if constrained else _step_kernels(
        dm, engine, plain, engine.variation(plain, r, range(r + 1)) if windowed else residual)
    kernels += [
        Kernel(KernelName.TARGET, one.z, (("target", target),), "β(x, f)"),
        Kernel(KernelName.VARIATIONS, one.z, (("right", g.right(one.xs[0], one.fs[0], dm.step)),
                                     ("left", g.left(one.xs[0], one.fs[0], dm.step))),
               "node variations of one element: d(x, f)/dε of g·σ_a(ε) and σ_a(ε)⁻¹·g"),
        _in_increments(Kernel(KernelName.LAGRANGIAN, window.z,
                              (("value", sp.Matrix([engine.lagrangian(window, 0)])),),
                              "L_d on one window of r elements", window.definitions),
                       window, sources),
    ]
    manifold = g.manifold(one.xs[0])
    if manifold:
        kernels.append(Kernel(KernelName.MANIFOLD, one.xs[0], (("value", sp.Matrix(manifold)),),
                              "equations F(x) = 0 of the base manifold at a base point",
                              along=False))
    if g.whole_trajectory:
        eta = tuple(sp.Dummy(f"eta_{a}", real=True) for a in range(g.fibre_dim))
        kernels += [
            _in_increments(Kernel(
                KernelName.STENCIL, full.z,
                (("residual", residual), ("jacobian", full.total_jacobian(residual))),
                "residual and its Jacobian with respect to every stencil coordinate "
                "(multipliers of the r+1 windows last)",
                full.definitions + full.jacobian_definitions, along=not windowed),
                full, sources),
            Kernel(KernelName.MOVE, one.xs[0] + eta, (("x", sp.Matrix(g.move(one.xs[0], eta))),),
                   "base point of a node after the variation g -> g tau(eta)", along=False)]
    for name, exprs, what in (
            (KernelName.CONSTRAINT, dm.constraints, "discrete constraints Phi_d"),
            (KernelName.INEQUALITY, dm.inequalities, "inequalities c <= 0")):
        if exprs:
            values = engine.window_values(window, 0, exprs)
            kernels.append(Kernel(
                name, window.z, (("value", values), ("jacobian", window.total_jacobian(values))),
                f"{what} on one window and their Jacobian",
                window.definitions + window.jacobian_definitions))
    if dm.boundary_inequalities:
        on_one = _on_element(dm, one, 0)
        kernels.append(Kernel(
            KernelName.BOUNDARY, one.z,
            (("value", sp.Matrix([c.xreplace(on_one) for c in dm.boundary_inequalities])),),
            "the inequalities without controls on one element (first-order rule): the "
            "check of the fixed boundary elements"))
    if dm.end_free:
        kernels += _end_kernels(dm, engine, sources)
    if lifted:
        kernels += _lifted_kernels(dm, engine, window, one)
    if dm.gauges:
        sections = [c for _, z in dm.gauges for c in z]
        kernels.append(Kernel(
            KernelName.GAUGE, window.z, (("value", engine.window_values(window, 0, sections)),),
            "sections Z of the symmetries on which the constraints depend exactly, at the "
            "window's middle node (one row of constraint components per symmetry)",
            window.definitions))
    if dm.controls:
        kernels.append(Kernel(KernelName.CONTROLS, window.z,
                              (("value", engine.window_values(window, 0, dm.controls)),),
                              "controls u at the window's quadrature point", window.definitions))
    if dm.time_cost is not None:
        parts = [engine.lagrangian(window, 0)] + list(engine.window_values(
            window, 0, dm.window_constraints))
        derivative = [_at_fixed_elements(dm, e, window.fs) for e in parts]
        kernels.append(Kernel(
            KernelName.HORIZON, window.z, (("value", sp.Matrix(derivative + [dm.time_cost])),),
            "∂/∂h at fixed elements of L_d, Φ_d and c on one window, then ρ (a free "
            "horizon: dJ/dT by the envelope theorem)", window.definitions))
    if dm.symmetries and not constrained:
        half = _stencil(dm, 2 * r - 1)
        kernels.append(Kernel(KernelName.NOETHER, half.z, (("value", noether_quantities(dm, engine, half)),),
                              "conserved F_Z of the declared symmetries at node r−1 (§4.4)",
                              half.definitions))
    if r == 1:
        energy = _energy(dm, engine.lagrangian(one, 0), one.fs[0])
        kernels.append(Kernel(KernelName.ENERGY, one.z, (("value", sp.Matrix([energy])),),
                              "discrete energy E_d = −∂L_d/∂h (Kane, Marsden & Ortiz)"))
    return tuple(kernels)


def fibre_sources(dm: DiscreteModel) -> tuple[int, ...]:
    """Which fibre coordinates are increments, for the lifted solve (``templates/lifted.c.j2``).

    The lifted Newton system takes the increments u_k of the elements as unknowns beside
    the nodes: a group factor's fibre hξ is one (−1), a pair factor's fibre q_{k+1} is
    measured from its base coordinate q_k (its index; u = q_{k+1} − q_k). It exists for
    second-order whole-trajectory models, with or without constraints and inequalities
    (the bound multipliers weigh the inequalities in the window Hessians; the barrier's
    GᵀΣG joins the node rows at run time, ``symvi_lifted_barrier``), whose fibres are
    each a group increment or the target of a base coordinate (pair, matrix-group and
    action factors: an action's base point Γ_{k+1} = Γ_k·τ(hξ_k) is the source of no
    fibre, so the change of coordinates to increments stays linear); () otherwise,
    and with end conditions other than fixed (their unknown end nodes have no lifted rows
    yet: the node system solves them at every N), for orders above 2 (the lifted rows
    are written for windows of two elements), and for pure minimum time (a zero
    Lagrangian: the lifted rows would hold the barrier's weights alone, and its interior
    point, verified at a vertex on the node system, reached SUCCESS in 50 iterations at
    N = 10⁴ on the node system against a SADDLE short of the vertex on the lifted one).
    """
    if dm.order != 2 or dm.end_free or dm.pure_minimum_time:
        return ()
    return increment_sources(dm)


def increment_sources(dm: DiscreteModel) -> tuple[int, ...]:
    """:func:`fibre_sources` whether or not the model has inequalities: the coordinates
    whose differences the residual is evaluated from (:func:`_in_increments`), for every
    order from 2 (an order-k residual rounds like ε|q|/h^{2k−1} from the nodes). A bounded
    model's residual needs the differences as much as its lifted solve: evaluated from
    the nodes, the cart-pole swing-up's rounded like the unbounded cart-pole's times 10³ at
    N = 1000 in the directions its Newton matrix amplifies (rounding floors 1e-7 against
    1e-10), and its solves ended ILL_CONDITIONED there."""
    g = dm.groupoid
    if dm.order < 2 or not g.whole_trajectory:
        return ()
    one = _stencil(dm, 1)
    fibre = {s: i for i, s in enumerate(one.fs[0])}
    sources = [-1 if scaled else None for scaled in g.step_scaled()]
    for j, t in enumerate(g.target(one.xs[0], one.fs[0], dm.step)):
        if t in fibre:
            sources[fibre[t]] = j
    return () if None in sources else tuple(sources)


def _end_kernels(dm: DiscreteModel, engine: "_Engine", sources) -> list[Kernel]:
    """The residuals of the last r nodes when they are unknowns (end conditions other
    than fixed), and the end conditions ψ = 0 on the last element.

    Node N − j (j = 0 … r − 1) meets only the windows N − j − r … N − r: its residual is
    the variation of those windows' augmented L_d, plus ν·ψ(last element) — the
    stencil of r + j elements from element N − j − r, the multipliers of its j + 1
    windows, then ν, the end conditions' multipliers (``stencil_end{j}``). Without ψ
    (a free end) these are the natural boundary conditions: the discrete momenta at the
    end vanish."""
    r, windowed = dm.order, bool(dm.window_constraints)
    nu = tuple(sp.Dummy(f"nu_{a}", real=True) for a in range(len(dm.end_conditions)))
    weighted = sum((v * psi for v, psi in zip(nu, dm.end_conditions)), sp.S.Zero)
    kernels = []
    for j in range(r):
        st = _stencil(dm, r + j, windows=j + 1 if windowed else 0, extra=nu)
        R = engine.variation(st, r, range(j + 1)) \
            + engine.element_variation(st, r, r + j - 1, weighted)
        kernels.append(_in_increments(Kernel(
            f"stencil_end{j}", st.z, (("residual", R), ("jacobian", st.total_jacobian(R))),
            f"residual of node N - {j} (an unknown end node) and its Jacobian: windows "
            f"N - {j} - r ... N - r, then nu . psi on the last element",
            st.definitions + st.jacobian_definitions, along=False), st, sources))
    if dm.end_conditions:
        one = _stencil(dm, 1)
        values = sp.Matrix([psi.xreplace(_on_element(dm, one, 0)) for psi in dm.end_conditions])
        kernels.append(Kernel(
            KernelName.END_CONDITION, one.z, (("value", values), ("jacobian", one.total_jacobian(values))),
            "end conditions psi = 0 on the last element and their Jacobian",
            one.definitions + one.jacobian_definitions, along=False))
        if dm.time_cost is not None:    # ν·∂ψ/∂h enters dJ*/dT (a ξ = τ⁻¹(w)/h moves with h)
            kernels.append(Kernel(
                KernelName.END_HORIZON, one.z,
                (("value", values.applyfunc(lambda e: _at_fixed_elements(dm, e, one.fs))),),
                "d psi/dh at a fixed last element (a free horizon's dJ/dT)", one.definitions,
                along=False))
    return kernels


def _in_increments(kernel: Kernel, st: _Stencil, sources: Sequence[int]) -> Kernel:
    """``kernel`` evaluated from differences: the increments d_k = q_{k+1} − q_k of its
    pair coordinates, and the changes d_k = f_k − f_{k−1} of its group increments.

    SymPy's derivatives expand differences of nodes into sums like 8q₂ − 4q₁ − 4q₃ whose
    rounding, ε|q|/h³ in a second-order residual, is noise the Newton matrix amplifies
    (cubic_spline: errors of 4e-5 at N = 10⁵); a group increment f = hξ differenced the
    same way rounds like ε|ξ|/h² instead of ε|ξ̇|/h. The differences of stored numbers
    are exact (Sterbenz), so in them the expressions round like the quantities they
    approximate. Every output (a Jacobian still with respect to z) is rewritten with each
    such coordinate as its predecessor plus the difference, which SymPy's automatic
    simplification cancels in the linear combinations; the differences are the kernel's
    first definitions. Unchanged without ``sources`` (:func:`fibre_sources`) and for
    kernels with named base points (an action's).
    """
    if not sources or kernel.definitions:
        return kernel
    substitution, definitions = {}, []
    for i, j in enumerate(sources):
        # a pair coordinate from its base point, a group increment from the one before
        first = 0 if j >= 0 else 1
        previous = running = st.xs[0][j] if j >= 0 else st.fs[0][i]
        for k, f in enumerate(st.fs[first:], start=first):
            d = sp.Dummy(f"d{k}_{i}", real=True)
            definitions.append((d, f[i] - previous))
            running = running + d
            substitution[f[i]] = running
            previous = f[i]
    outputs = tuple((name, M.xreplace(substitution)) for name, M in kernel.outputs)
    return Kernel(kernel.name, kernel.z, outputs, kernel.doc, tuple(definitions), kernel.along)


def _lifted_kernels(dm: DiscreteModel, engine: "_Engine", window: _Stencil,
                    one: _Stencil) -> list[Kernel]:
    """The window Hessian of ℓ = L_d + λ·Φ_d + z·c (the window's multipliers last; the
    bound multipliers z, eliminated from the Newton system, are inputs only) and the
    derivatives of the node variations contracted with a covector: with them the lifted
    system is assembled (``templates/lifted.c.j2``). The window's named base points
    (an action's x_{w+1} = β(x_w, f_w)) are substituted, so that the Hessian carries
    their chain rule."""
    g = dm.groupoid
    lams = tuple(sp.Dummy(f"mult_{a}", real=True) for a in range(len(dm.multipliers)))
    zs = tuple(sp.Dummy(f"bound_{a}", real=True) for a in range(len(dm.inequalities)))
    weighed = engine.window_values(window, 0, dm.window_constraints)
    augmented = engine.lagrangian(window, 0) + sum(
        (l * c for l, c in zip(lams + zs, weighed)), sp.S.Zero)
    for symbol, value in reversed(window.definitions):
        augmented = augmented.xreplace({symbol: value})
    z = window.z + lams
    gradient, hessian = gradient_and_hessian(augmented, z)
    c = tuple(sp.Dummy(f"c_{i}", real=True) for i in range(len(one.z)))
    cv = sp.Matrix(c)
    duals = tuple((name, jacobian(side(one.xs[0], one.fs[0], dm.step).T * cv, one.z))
                  for name, side in (("left", g.left), ("right", g.right)))
    return [Kernel(KernelName.WINDOW_HESSIAN, z + zs,
                   (("gradient", gradient), ("hessian", hessian)),
                   "gradient and Hessian of L_d + lambda.Phi_d + z.c on one window along "
                   "(x_w, f_w, f_{w+1}, lambda_w), the bound multipliers z_w given last",
                   along=False),
            Kernel(KernelName.VARIATIONS_DUAL, one.z + c, duals,
                   "d/d(x, f) of left(x, f)^T c and right(x, f)^T c: the curvature of the node "
                   "variations along a covector c", along=False)]


def _section(symmetry, groupoid, x) -> sp.Matrix:
    """Z(x): the symmetry's coefficients at base point x."""
    return sp.Matrix(symmetry.section).xreplace(dict(zip(groupoid.algebroid().q, x)))


def _potential(symmetry, dm: DiscreteModel, st: _Stencil, first: int) -> sp.Expr:
    """f on the r−1 elements from element ``first`` (first order: f at base point ``first``)."""
    g = dm.groupoid
    if dm.order == 1:
        mapping = dict(zip(g.algebroid().q, st.xs[first]))
    else:
        mapping = g.discrete_mapping(1, [st.xs[first]], [st.fs[first]])
    return symmetry.potential.xreplace(mapping)


def noether_quantities(dm: DiscreteModel, engine: "_Engine", half: _Stencil) -> sp.Matrix:
    """F_Z = ⟨p, Z⟩ − f at node r−1 of 2r−1 elements, one per declared symmetry (§4.4).

    ⟨p, Z⟩ is minus the change of the windows 0 … r−1 that straddle node r−1 when the
    nodes 0 … r−1 move along Z (for r = 1, ⟨−D₁L_d, Z⟩ = ⟨F⁻L_d, Z⟩); f is the potential
    on elements 0 … r−2. Moving the node on by one changes F_Z by −Z·(residual there),
    the windows' own changes cancelling by (quasi-)invariance, so F_Z is conserved.
    """
    r, g = dm.order, dm.groupoid
    values = []
    for z in dm.symmetries:
        change = sum(((_section(z, g, half.xs[i]).T * engine.variation(half, i, range(r)))[0, 0]
                      for i in range(r)), sp.S.Zero)
        values.append(-change - _potential(z, dm, half, 0))
    return sp.Matrix(values)


def invariance_defect(dm: DiscreteModel, symmetry) -> tuple[tuple[sp.Expr, ...], _Stencil]:
    """The terms of δL_d − (f(last r−1 elements) − f(first r−1 elements)) on one window of
    r elements — the change of L_d when each node i = 0 … r moves along Z, then minus the
    potential difference — with the stencil whose symbols (and named base points) they
    use. Their sum vanishes identically for a (quasi-)invariant L_d (paper §4.4)."""
    engine, r, g = _Engine(dm), dm.order, dm.groupoid
    window = _stencil(dm, r)
    nodes = list(window.xs) + [tuple(g.target(window.xs[-1], window.fs[-1], dm.step))]
    terms = [(_section(symmetry, g, nodes[i]).T * engine.variation(window, i, [0]))[0, 0]
             for i in range(r + 1)]
    if r == 1:
        base = g.algebroid().q
        terms += [symmetry.potential.xreplace(dict(zip(base, nodes[0]))),
                  -symmetry.potential.xreplace(dict(zip(base, nodes[1])))]
    else:
        terms += [_potential(symmetry, dm, window, 0), -_potential(symmetry, dm, window, 1)]
    return tuple(terms), window


def _step_kernels(dm: DiscreteModel, engine: _Engine, full: _Stencil,
                  residual: sp.Matrix) -> list[Kernel]:
    """The step map and the discrete Legendre transforms (unconstrained models)."""
    r, g = dm.order, dm.groupoid
    unknown = full.fs[-1]
    guess = sp.Matrix(g.predictor(full.xs[:-1], full.fs[:-1]))
    half = _stencil(dm, 2 * r - 1)
    p_plus = _stack([engine.variation(half, j, range(r)) for j in range(r, 2 * r)])
    p_minus = -_stack([engine.variation(half, j, range(r)) for j in range(r)])
    return [
        Kernel(KernelName.STEP, full.z, (("residual", residual), ("jacobian", jacobian(residual, unknown))),
               "discrete Euler–Lagrange residual at the middle node and ∂R/∂f_{K−1}",
               full.definitions),
        Kernel(KernelName.PREDICT, full.z, (("guess", guess),),
               "explicit guess of f_{K−1} from the earlier elements", full.definitions),
        Kernel(KernelName.MOMENTUM_PLUS, half.z, (("momentum", p_plus),),
               "F⁺L_d: momenta at the last r nodes from the 2r−1 elements before them",
               half.definitions),
        Kernel(KernelName.MOMENTUM_MINUS, half.z, (("momentum", p_minus),)
               + ((("jacobian", half.total_jacobian(p_minus, half.fs[0])),) if r == 1 else ()),
               "F⁻L_d: momenta at the first r nodes from the 2r−1 elements after them "
               "(first order: and ∂/∂f₀, for the discrete Legendre transform of a state)",
               half.definitions + (half.jacobian_definitions if r == 1 else ())),
    ] + _legendre(dm, r)


def _legendre(dm: DiscreteModel, r: int) -> list[Kernel]:
    """The continuous Legendre transform p = ∂L/∂v at a state (x, v) of a first-order
    model — the groupoid's first-order symbols: base coordinates, then the velocity (q̇,
    or ξ on a group) — whose matching F⁻L_d(x₀, f₀) = p gives the first element of a run
    started from a state (:meth:`.compiled.CompiledModel.initial_state`)."""
    L = dm.continuous_lagrangian
    if r != 1 or L is None:
        return []
    base, velocity = dm.groupoid.state_symbols()
    symbols = (*base, *velocity)
    momentum = sp.Matrix([sp.diff(L, v) for v in velocity])
    return [Kernel(KernelName.LEGENDRE, symbols, (("momentum", momentum),),
                   "∂L/∂v at a state (base coordinates, velocity)", along=False)]


def step_jacobian(dm: DiscreteModel) -> tuple[sp.Matrix, _Stencil]:
    """The matrix that must be invertible for the step map to exist (paper §4.3), with the
    stencil whose symbols it uses.

    Unconstrained: ∂R/∂f_{K−1} of the residual at the middle node of 2r elements (D₁₂L_d,
    resp. D₁₃L_d, on the pair groupoid). Constrained: the bordered matrix
    [[∂R/∂f_{K−1}, ∂R/∂λ^r], [∂Φ_d/∂f_{K−1}, 0]] of the last element and the last window's
    multipliers λ^r, Φ_d on that window. With inequalities, the step map of the problem
    without them (z = 0), as the ``step`` kernels.
    """
    engine, r, s = _Engine(dm), dm.order, len(dm.constraints)
    constrained = bool(dm.constraints)
    full = _stencil(dm, 2 * r, windows=r + 1 if constrained else 0)
    unbounded = {z: 0 for window in full.multipliers for z in window[s:]}
    residual = engine.variation(full, r, range(r + 1)).xreplace(unbounded)
    unknown = full.fs[-1]
    J = jacobian(residual, unknown)
    if constrained:
        phi = engine.window_values(full, r, dm.constraints)
        J = sp.Matrix.vstack(sp.Matrix.hstack(J, jacobian(residual, full.multipliers[r][:s])),
                             sp.Matrix.hstack(jacobian(phi, unknown),
                                              sp.zeros(len(phi), len(phi))))
    return J, full


def _energy(dm: DiscreteModel, Ld: sp.Expr, f: Sequence[sp.Symbol]) -> sp.Expr:
    """E_d = −∂L_d/∂h at a fixed groupoid element (Kane, Marsden & Ortiz)."""
    return -_at_fixed_elements(dm, Ld, [f])


def _at_fixed_elements(dm: DiscreteModel, expr: sp.Expr, fibres) -> sp.Expr:
    """∂expr/∂h with the groupoid elements of ``fibres`` (one tuple per element) held
    fixed: where fibre coordinates are scaled by h (ξ = τ⁻¹(w)/h on a Lie group), that
    means holding h·ξ fixed. Named base points count as fixed too (they are β of fixed
    elements)."""
    eta = sp.Dummy("eta", positive=True)
    flags = dm.groupoid.step_scaled()
    scaled = {v: v * dm.step / eta for f in fibres for v, s in zip(f, flags) if s}
    moved = expr.xreplace({dm.step: eta} | scaled)
    return sp.diff(moved, eta).xreplace({eta: dm.step})


def _check_regular(dm: DiscreteModel, step: Kernel) -> None:
    """Refuse an L_d whose step Jacobian (D₁₂L_d, D₁₃L_d, …: :func:`step_matrix`) is
    identically singular."""
    jac = dict(step.outputs)["jacobian"]
    rng = np.random.default_rng(7)
    fixed = dict(zip(dm.parameters, dm.defaults)) | {dm.step: float(rng.uniform(0.05, 0.2))}
    rank = generic_rank(jac, step.z, fixed, definitions=step.definitions, engine=engine_function)
    n = jac.shape[0]
    if rank is not None and rank < n:
        which = dm.groupoid.step_matrix_name(dm.order)
        raise ModelError(
            f"model {dm.name!r} is not regular: the step Jacobian ∂R/∂f ({which}) has rank "
            f"{rank} < {n} at every sample point, so the discrete "
            f"Lagrangian does not define a step map (is the Lagrangian degenerate?)")


class DerivationCache:
    """Derived models kept in memory by fingerprint, the ``size`` most recently used:
    a model derived again in one process (a forced rebuild, a symbolic check of a
    compiled model) is derived once. Its own lock makes it safe to share between threads
    (the builds of a batch of models); a derivation runs outside the lock, so two threads
    asking for one new model may both derive it (the result is the same)."""

    def __init__(self, size: int = 32):
        self.size = size
        self._models: OrderedDict[str, DerivedModel] = OrderedDict()
        self._lock = threading.Lock()

    def get(self, fingerprint: str) -> DerivedModel | None:
        """The model derived under ``fingerprint``, now the most recently used; or None."""
        with self._lock:
            if fingerprint not in self._models:
                return None
            self._models.move_to_end(fingerprint)
            return self._models[fingerprint]

    def put(self, fingerprint: str, derived: DerivedModel) -> None:
        """Keep ``derived``, forgetting the least recently used beyond :attr:`size`."""
        with self._lock:
            self._models[fingerprint] = derived
            while len(self._models) > self.size:
                self._models.popitem(last=False)


def interval_pairs(inequalities, parameters) -> tuple[tuple[int, int], ...]:
    """The pairs (i, j), i < j, of the window inequalities c ≤ 0 whose sum is free of
    the path: the two sides of a bound (u − upper and lower − u sum to lower − upper),
    which the run time checks for an empty interval once the parameters are known
    (:func:`symvi._runtime.bounded.barrier.check_intervals`), before any iteration."""
    allowed = set(parameters)
    return tuple((i, j) for i in range(len(inequalities))
                 for j in range(i + 1, len(inequalities))
                 if sp.expand(inequalities[i] + inequalities[j]).free_symbols <= allowed)


#: The cache :func:`derive` uses unless handed another: the one every caller in a process
#: shares by default (the build, the checks, the test session, which enlarges it), passed
#: as :func:`derive`'s default argument. A caller that wants derivations of its own (or
#: none kept: ``DerivationCache(0)``) passes its own.
PROCESS_CACHE = DerivationCache()


def derive(dm: DiscreteModel, cache: DerivationCache = PROCESS_CACHE) -> DerivedModel:
    """Derive every kernel of ``dm`` and check that its step map is regular.

    Constrained models have no step map (they are solved as whole trajectories); their
    regularity is that of the bordered Hessian, checked on the continuous model. The
    result depends on ``dm.fingerprint`` only: ``cache`` (:class:`DerivationCache`) keeps
    it for the next call with the same fingerprint.
    """
    derived = cache.get(dm.fingerprint)
    if derived is None:
        derived = _derive(dm)
        cache.put(dm.fingerprint, derived)
    return derived


def _step_kernel(dm: DiscreteModel, kernels: Sequence[Kernel]) -> Kernel:
    """The kernel of the step map's residual, by name (its place in the list is not fixed)."""
    step = next((k for k in kernels if k.name == KernelName.STEP.value), None)
    if step is None:
        raise ModelError(f"model {dm.name!r}: no 'step' kernel was derived (kernels: "
                         f"{[k.name for k in kernels]}), so its step map cannot be checked "
                         f"for regularity")
    return step


def _derive(dm: DiscreteModel) -> DerivedModel:
    kernels = _kernels(dm)
    if not dm.constraints and not dm.pure_minimum_time:
        _check_regular(dm, _step_kernel(dm, kernels))
    g = dm.groupoid
    expressions = [e for k in kernels for _, M in k.outputs for e in M] \
        + [e for k in kernels for _, e in k.definitions]
    coefficients = set(used_coefficients(expressions)) | set(g.coefficient_functions())
    return DerivedModel(name=dm.name, kind=g.kind, order=dm.order, source_dim=g.source_dim,
                        fibre_dim=g.fibre_dim, parameters=dm.parameters, defaults=dm.defaults,
                        step=dm.step, kernels=kernels, whole_trajectory=g.whole_trajectory,
                        has_energy=dm.order == 1, fingerprint=dm.fingerprint,
                        initial_layout=g.initial_layout,
                        constraint_count=len(dm.constraints), control_count=len(dm.controls),
                        coordinate_names=tuple(map(str, g.state_symbols()[0])),
                        velocity_names=tuple(map(str, g.state_symbols()[1])),
                        control_names=dm.control_names,
                        constraint_names=dm.constraint_names, unactuated=dm.unactuated,
                        end_free=dm.end_free, end_names=dm.end_names,
                        pure_minimum_time=dm.pure_minimum_time,
                        inequality_names=dm.inequality_names,
                        boundary_names=dm.boundary_names,
                        intervals=interval_pairs(dm.inequalities, dm.parameters),
                        step_scaled=tuple(g.step_scaled()),
                        symmetries=tuple(z.name for z in dm.symmetries)
                        if any(k.name == KernelName.NOETHER.value for k in kernels) else (),
                        gauges=tuple(name for name, _ in dm.gauges), c_context=g.c_context(),
                        fibre_sources=fibre_sources(dm),
                        configuration_base=tuple(g.configuration_base()),
                        coefficients=tuple(sorted(coefficients, key=lambda c: c.__name__)))
