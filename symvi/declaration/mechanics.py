"""Models from ``sympy.physics.mechanics`` (issue 23, item 3).

Users of PyDy and SymPy mechanics build multibody systems from frames, bodies and joints,
with generalised coordinates as ``dynamicsymbols`` q(t). :func:`from_system` turns such a
system into a :class:`~symvi.declaration.model.Model` on the pair groupoid Q×Q: its
Lagrangian L = Σ T − V, the generalised speeds eliminated through the system's kinematic
differential equations (u = q̇ for joints), each q(t) and q̇(t) renamed to the groupoid's
``q`` and ``q_dot`` symbols, and the remaining symbols as parameters.

The potential V is each body's ``potential_energy`` plus that of the system's constant
forces (``System.apply_uniform_gravity``): a force F fixed in the inertial frame at a
point P is conservative with V = −F·r_P. Any other load (a torque, a force that depends
on the state or on time) is not a Lagrangian system and is refused by name, as are
holonomic constraints (the coordinates must be independent) and nonholonomic ones (not
variational).
"""
from __future__ import annotations

from typing import Any, Mapping, Sequence

import sympy as sp

from ..errors import ModelError
from ..groupoids import PairGroupoid
from .model import Model


def from_system(system, *, name: str, parameters: Mapping[Any, float],
                **options) -> Model:
    """The :class:`Model` of a ``sympy.physics.mechanics.System`` on Q×Q.

    ``parameters`` gives a default value to every symbol of the Lagrangian other than the
    coordinates (masses, lengths, g), by Symbol or name; ``options`` go to :class:`Model`
    (``example``, ``description``, ``discretisation``, ``symmetries``).
    """
    from sympy.physics.mechanics import System, dynamicsymbols
    if not isinstance(system, System):
        raise ModelError(f"{name}: system must be a sympy.physics.mechanics.System, got "
                         f"{type(system).__name__}")
    coordinates = list(system.q)
    if not coordinates:
        raise ModelError(f"{name}: the system has no generalised coordinates")
    t = dynamicsymbols._t
    _check_unconstrained(system, name)
    speeds = _speeds(system, t, name)
    frame, origin = system.frame, system.fixed_point
    kinetic = sum((body.kinetic_energy(frame) for body in system.bodies), sp.S.Zero)
    # actuators become loads only inside form_eoms: theirs are checked like the others
    loads = list(system.loads) + [load for actuator in system.actuators
                                  for load in actuator.to_loads()]
    potential = sum((getattr(body, "potential_energy", 0) for body in system.bodies),
                    sp.S.Zero) + _load_potential(loads, frame, origin, t, name)
    return from_lagrangian((kinetic - potential).xreplace(speeds), coordinates, name=name,
                           parameters=parameters, **options)


def from_lagrangian(lagrangian, coordinates: Sequence, *, name: str,
                    parameters: Mapping[Any, float], **options) -> Model:
    """The :class:`Model` on Q×Q of a Lagrangian L(q(t), q̇(t)) written in
    ``dynamicsymbols`` ``coordinates``; see :func:`from_system`."""
    from sympy.physics.mechanics import dynamicsymbols
    t = dynamicsymbols._t
    lagrangian, coordinates = _lagrangian(lagrangian, name), _sequence(coordinates, name)
    parameters = _mapping(parameters, name)
    names = []
    for q in coordinates:
        if not (isinstance(q, sp.Function) and q.args == (t,)):
            raise ModelError(f"{name}: coordinate {q} is not a dynamicsymbol q(t)")
        names.append(str(q.func))
    G = PairGroupoid(names)
    rates = {q.diff(t): v for q, v in zip(coordinates, G.qdot)}
    L = lagrangian.xreplace(rates).xreplace(dict(zip(coordinates, G.q)))
    left = L.atoms(sp.Derivative) | {f for f in L.atoms(sp.Function) if t in f.free_symbols}
    if left:
        raise ModelError(f"{name}: the Lagrangian still holds {sorted(map(str, left))} after "
                         f"the coordinates {names} and their rates are substituted (an "
                         f"acceleration, a speed without a kinematic equation, or another "
                         f"function of time)")
    if t in L.free_symbols:
        raise ModelError(f"{name}: the Lagrangian depends on time {t} explicitly")
    given = {(k if isinstance(k, str) else k.name): v for k, v in parameters.items()}
    symbols = {s.name: s for s in L.free_symbols - set(G.q) - set(G.qdot)}
    missing, unused = sorted(set(symbols) - set(given)), sorted(set(given) - set(symbols))
    if missing or unused:
        raise ModelError(f"{name}: parameters must give a value to each symbol of the "
                         f"Lagrangian besides the coordinates"
                         + (f"; missing: {', '.join(missing)}" if missing else "")
                         + (f"; not in the Lagrangian: {', '.join(unused)}" if unused else ""))
    return Model(name=name, groupoid=G, lagrangian=L,
                 parameters={symbols[n]: given[n] for n in sorted(symbols)}, **options)


def _lagrangian(value: Any, name: str) -> sp.Expr:
    """``from_lagrangian``'s ``lagrangian`` as a SymPy expression (text is parsed, as
    :class:`Model` parses it); anything else, None included, is refused by the
    argument's name."""
    try:
        L = sp.sympify(value)
    except (sp.SympifyError, TypeError):
        L = None
    if not isinstance(L, sp.Expr):
        raise ModelError(f"{name}: lagrangian must be a SymPy expression in the coordinates "
                         f"q(t) and their rates, got {type(value).__name__}")
    return L


def _sequence(value: Any, name: str) -> list:
    """``from_lagrangian``'s ``coordinates``: a list or tuple of dynamicsymbols."""
    if not isinstance(value, (list, tuple, sp.MatrixBase)):
        raise ModelError(f"{name}: coordinates must be a list of dynamicsymbols q(t), got "
                         f"{value!r}")
    return list(value)


def _mapping(value: Any, name: str) -> Mapping:
    """``parameters``: a mapping from each parameter (Symbol or name) to its default."""
    if not isinstance(value, Mapping):
        raise ModelError(f"{name}: parameters must be a mapping symbol or name → default "
                         f"value, got {type(value).__name__}")
    return value


def _check_unconstrained(system, name: str) -> None:
    """Refuse constraints between the coordinates or speeds: the pair groupoid's path has
    independent coordinates, and a nonholonomic system is not variational (its
    Lagrange–d'Alembert equations are not Euler–Lagrange equations of any L)."""
    if len(system.nonholonomic_constraints) or len(system.u_dep):
        raise ModelError(f"{name}: the system has nonholonomic constraints "
                         f"{list(system.nonholonomic_constraints)}: its motion obeys "
                         f"Lagrange–d'Alembert, not a variational principle symvi can "
                         f"discretise from a Lagrangian")
    if len(system.holonomic_constraints) or len(system.q_dep):
        raise ModelError(f"{name}: the system has holonomic constraints "
                         f"{list(system.holonomic_constraints)} between its coordinates: "
                         f"choose independent coordinates (a minimal set) for the pair "
                         f"groupoid")


def _speeds(system, t, name: str) -> dict:
    """Each generalised speed u(t) as the rates q̇ through the kinematic equations."""
    speeds = list(system.u)
    if not speeds:
        return {}
    solution = sp.solve(list(system.kdes), speeds, dict=True)
    if len(solution) != 1 or set(solution[0]) != set(speeds):
        raise ModelError(f"{name}: the kinematic differential equations do not give the "
                         f"speeds {speeds} as functions of the coordinates and their rates")
    return solution[0]


def _load_potential(loads, frame, origin, t, name: str) -> sp.Expr:
    """V of the constant forces among ``loads``; any other load refused."""
    from sympy.physics.mechanics import Force
    total = sp.S.Zero
    for load in loads:
        if not isinstance(load, Force):
            raise ModelError(f"{name}: load {load} is not a force: a Lagrangian system "
                             f"takes no torques (give it a potential energy instead)")
        force = load.force.to_matrix(frame)
        if any(t in c.free_symbols or c.atoms(sp.Function) for c in force):
            raise ModelError(f"{name}: the force {load.force} on {load.point} is not "
                             f"constant in {frame}: not conservative")
        total -= load.force.dot(load.point.pos_from(origin))
    return total
