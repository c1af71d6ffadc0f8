"""What a user hands to the ``equations`` check: :class:`HandDerived` and its targets.

Its own module so that the comparison (:mod:`.equations`), the equivalence tests
(:mod:`.equivalence`) and the symbol spaces (:mod:`.spaces`) all use it without importing
one another.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import sympy as sp

#: target → the derived object it names (paper reference).
TARGETS: dict[str, str] = {
    "controls": "controlled equations u_a = EL(L)_a, the model's controls (§3.3, eq. costLtilde)",
    "constraints": "every constraint Φ^A = 0 of the model, in its order (§3.3.2): the "
                   "unactuated equations EL(L)_A = 0 and, on a nonholonomic model, first the "
                   "kinematic constraints q̇ = ρ(q)y (the velocities in the distribution); "
                   "``select`` compares some of them",
    "euler_lagrange": "continuous Euler–Lagrange equations EL_r(L + λ_AΦ^A) = 0 followed by "
                      "the constraints Φ^A = 0 (§3.3.2, Appendix C.2)",
    "lagrangian": "continuous Lagrangian L̃ = C(q, y, EL(L)_a) (eq. costLtilde, LagCont)",
    "discrete_lagrangian": "L_d on one window (DESIGN.md §3, eq. sdfinal)",
    "discrete_constraints": "Φ^A_d = h Σ w Φ^A(point) on one window (§3.2, eq. constrainedso)",
    "discrete_action": "discrete cost Σ_k L_d over the windows of a trajectory of `elements` "
                       "elements (§2.2, eq. hamprinc)",
    "target_map": "target β(g) of one element (action groupoid: φ(q, τ(hξ)))",
    "residual": "discrete Euler–Lagrange / Euler–Poincaré residual at a stencil's middle node "
                "(§2.2, eq. delelg)",
    "anchor": "q̇ = ρ(q) y, the anchor applied to the fibre velocities (§3.3.1)",
    "structure_functions": "⟦a, b⟧^γ = C^γ_{αβ}(q) a^α b^β, the bracket of two sections "
                           "with constant coefficients a, b (§3.3.1)",
    "variation": "δ(q, y) = η^C, the complete lift of a time-dependent section η: "
                 "δq^i = ρ^i_α η^α, δy^α = η̇^α + C^α_{βγ} y^β η^γ (§3.3.1)",
    "lift": "the complete lift η^C (as ``variation``) and then the vertical lift "
            "η^V = (0, η) of a section η, in the coordinates (q, y) (§3.3.1); "
            "``select`` picks components",
}
_VALUE_ONLY = ("lagrangian", "discrete_lagrangian", "discrete_action", "target_map",
               "anchor", "structure_functions", "variation", "lift")


@dataclass(frozen=True, eq=False)
class HandDerived:
    """Hand-derived equations (or expressions) claimed to reproduce one derived object.

    Parameters
    ----------
    name:
        Where they come from (``"paper eq. CuerpoRigido"``); failures are located by it.
    target:
        Which derived object they claim to be (:data:`TARGETS`), all of it unless
        ``select`` names some of its expressions: a display of fewer equations than
        the target holds fails with the ones it lacks written out (``constraints`` on
        the Chaplygin sled is its three kinematic constraints and its forward equation).
    expressions:
        The hand equations: expressions meaning ``= 0``, ``sympy.Eq`` or a Matrix of them
        (``mode="equations"``), or the claimed values (``mode="value"``, one per derived
        expression, in order).
    symbols:
        The user's own symbols (names or Symbols) → expressions in the model's symbols,
        e.g. ``{"u1": tau1/I1, "P1": I1/(I2 - I3), "xi1[k]": "Omega1_0"}``; values may use
        other keys. Symbols are matched by name. Model symbols: continuous targets use the
        groupoid's continuous symbols (``Omega1``, ``Omega1_dot``, ``theta1_ddot``, …),
        the parameters and the control symbols ``controls``; discrete targets and
        ``target_map`` the groupoid's discrete symbols of one window
        (``groupoid.discrete_symbols(order)``: ``Omega1_0``, ``Omega1_1`` the ξ of its two
        elements, ``theta1_0 … theta1_2`` the pair nodes, ``Gamma1`` the first base point)
        plus ``Gamma1_j`` for the base point at node j, the parameters and ``h``;
        ``residual`` the discrete symbols of the 2r elements of its stencil,
        ``discrete_action`` those of its ``elements`` elements; ``euler_lagrange`` the
        jets of :func:`symvi.checks.jets.continuous_equations` (``Omega1_dddot``, ``theta1_d4``,
        ``lambda1_dot``), or functions of time (``Omega1(t)``, ``lambda1(t)``, their
        derivatives; the base point's follow from the anchor). The algebroid's targets
        use its base coordinates and fibre velocities (``Omega1``), ``anchor`` nothing
        else, ``structure_functions`` the sections' coefficients ``a1 … an``,
        ``b1 … bn``, ``variation`` and ``lift`` the section ``eta1 … etan`` and its
        rates ``eta1_dot … etan_dot``; each compares values, in the order (δq, δy).
    mode:
        ``"equations"`` (same solution set) or ``"value"`` (equal); default ``"value"``
        for Lagrangians and the target map, ``"equations"`` otherwise.
    labels:
        A name per expression (default ``eq. 1``, ``eq. 2``, …).
    select:
        Indices of the derived expressions compared (default all), e.g. the first three
        coordinates of the target map.
    controls:
        Names of the symbols standing for the model's controls (default ``u1 … um``): in
        ``"controls"`` they are the unknowns of EL(L)_a − u_a = 0, elsewhere a hand
        expression in them is compared with the derived one written in them.
    unknowns:
        Unknowns to solve the derived equations for (default: chosen automatically).
    model:
        The model these equations describe, when it is not the checked one.
    elements:
        Number of elements of the trajectory of ``discrete_action`` (its symbols are those
        of ``elements`` slots: ``Omega1_0`` … ``Omega1_{elements-1}``, pair nodes
        ``theta1_0`` … ``theta1_{elements}``).
    """

    name: str
    target: str
    expressions: Any
    symbols: Mapping[Any, Any] = field(default_factory=dict)
    mode: str | None = None
    labels: Sequence[str] = ()
    select: Sequence[int] | None = None
    controls: Sequence[Any] = ()
    unknowns: Sequence[Any] = ()
    model: Any = None
    elements: int = 4

    def __post_init__(self) -> None:
        if self.target not in TARGETS:
            raise ValueError(f"{self.name}: unknown target {self.target!r}; targets: "
                             f"{', '.join(TARGETS)}")
        mode = self.mode or ("value" if self.target in _VALUE_ONLY else "equations")
        if mode not in ("equations", "value"):
            raise ValueError(f"{self.name}: mode must be 'equations' or 'value', got {mode!r}")
        if mode == "equations" and self.target in _VALUE_ONLY:
            raise ValueError(f"{self.name}: target {self.target!r} compares values; use "
                             f"mode='value'")
        exprs = self.expressions
        if isinstance(exprs, (sp.Basic, str)) and not isinstance(exprs, sp.MatrixBase):
            exprs = [exprs]
        exprs = tuple(_as_expression(e) for e in list(exprs))
        labels = tuple(self.labels) or tuple(f"eq. {i + 1}" for i in range(len(exprs)))
        if len(labels) != len(exprs):
            raise ValueError(f"{self.name}: {len(labels)} labels for {len(exprs)} expressions")
        symbols = {_name(k): sp.sympify(v) for k, v in dict(self.symbols).items()}
        object.__setattr__(self, "mode", mode)
        object.__setattr__(self, "expressions", exprs)
        object.__setattr__(self, "labels", labels)
        object.__setattr__(self, "symbols", symbols)
        object.__setattr__(self, "controls", tuple(_name(c) for c in self.controls))
        object.__setattr__(self, "unknowns", tuple(_name(u) for u in self.unknowns))
        if self.select is not None:
            object.__setattr__(self, "select", tuple(int(i) for i in self.select))


def _name(symbol) -> str:
    return symbol if isinstance(symbol, str) else symbol.name


def _as_expression(e) -> sp.Expr:
    e = sp.sympify(e)
    return e.lhs - e.rhs if isinstance(e, sp.Equality) else e
