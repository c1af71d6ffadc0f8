"""The Groupoid contract in one place (issue 49, item 4).

A groupoid written against :mod:`symvi.groupoids.base` alone
(:mod:`example_groupoid`: the pair groupoid in source–velocity coordinates) compiles,
integrates — from its first element and from a State — and passes the variational oracle
of DESIGN.md §5, with no file of symvi touched; with its own midpoint rule it computes the
pair groupoid's midpoint path. And every method the engine, the rules, the templates and
the run time call on a groupoid is declared in base.py.
"""
from __future__ import annotations

import ast
import inspect
import math
import re
from pathlib import Path

import numpy as np
import pytest
import sympy as sp

from example_groupoid import VelocityPairGroupoid
from symvi import Example, Model, PairGroupoid, State
from symvi.build import compile_model
from symvi.discretisation import rules
from symvi.groupoids.base import CContext, Groupoid

ROOT = Path(__file__).resolve().parent.parent
TOL, N_STEPS, H = 1e-8, 60, 0.05
U = np.finfo(float).eps
X0, V0 = [0.4, -0.2], [0.3, 0.5]


def _lagrangian(q, v):
    """Two coupled oscillators, one of them a pendulum."""
    return (v[0] ** 2 + v[1] ** 2) / 2 - (1 - sp.cos(q[0])) - q[1] ** 2 / 2 - q[0] * q[1] / 10


def _velocity_model(discretisation: str) -> Model:
    G = VelocityPairGroupoid("a b")
    return Model(name=f"velocity_pair_{discretisation}", groupoid=G,
                 lagrangian=_lagrangian(G.q, G.v), discretisation=discretisation,
                 example=Example(initial=(X0, [V0]), h=H, n_steps=N_STEPS))


@pytest.fixture(scope="module")
def velocity_modules(tmp_path_factory):
    out = tmp_path_factory.mktemp("contract")
    return {rule: compile_model(_velocity_model(rule), out)
            for rule in ("velocity_midpoint", "lie")}


def _vary(x, f, h, j, c, delta):
    """The node variation σ_c(δ) at node j in this groupoid's coordinates: element j − 1
    becomes g·σ (its f moves by δ/h: ``right``), element j becomes σ⁻¹·g (its source
    moves by δ, its f by −δ/h: ``left``)."""
    x, f = x.copy(), f.copy()
    x[j, c] += delta
    if j >= 1:
        f[j - 1, c] += delta / h
    if j < len(f):
        f[j, c] -= delta / h
    return x, f


def _oracle(mod, x, f, h, nodes) -> tuple[np.ndarray, np.ndarray]:
    """Relative gradients of the action sum at ``nodes`` and their rounding floors
    (tests/test_oracle.py, with this groupoid's variations)."""
    def values(x, f):
        return mod.model.along("lagrangian", x, f, h)[:, 0]
    base = values(x, f)
    relative, noise = [], []
    for j in nodes:
        gradient, scale, floor = [], [], []
        for c in range(x.shape[1]):
            eps = 1e-5 * max(1.0, abs(x[j, c]))
            terms = (values(*_vary(x, f, h, j, c, eps))
                     - values(*_vary(x, f, h, j, c, -eps))) / (2 * eps)
            gradient.append(math.fsum(terms))
            scale.append(np.abs(terms).sum())
            floor.append(4 * U * np.abs(base[terms != 0]).sum() / eps)
        relative.append(max(map(abs, gradient)) / max(scale))
        noise.append(max(floor) / max(scale))
    return np.array(relative), np.array(noise)


@pytest.mark.parametrize("rule", ["velocity_midpoint", "lie"])
def test_example_groupoid_integrates_and_passes_the_oracle(rule, velocity_modules):
    mod = velocity_modules[rule]
    assert mod.INFO.kind == "velocity_pair" and mod.INFO.fibre_nodes == (-1, -1)
    result = mod.integrate((X0, [V0]), N_STEPS, H)
    assert result.success, result.message
    x, f = np.asarray(result.x), np.asarray(result.f)
    assert x.shape == (N_STEPS + 1, 2) and f.shape == (N_STEPS, 2)
    np.testing.assert_allclose(x[1:], x[:-1] + H * f, rtol=0, atol=1e-12)   # β(x, f)
    relative, noise = _oracle(mod, x, f, H, range(1, N_STEPS))
    assert noise.max() < TOL / 10
    assert relative.max() < TOL, f"not stationary: {relative.max():.2e}"
    # negative control: one node moved by 1e-3 breaks stationarity there
    bad = _vary(x, f, H, N_STEPS // 2, 0, 1e-3)
    assert _oracle(mod, *bad, H, [N_STEPS // 2])[0][0] > 1e3 * TOL


def test_example_groupoid_starts_from_a_state(velocity_modules):
    """A State (x₀, v₀) through the discrete Legendre transform: every fibre coordinate an
    increment (``step_scaled``), so the explicit guess is f₀ = v₀ and Newton matches
    the momentum −D₁L_d(x₀, f₀) = ∂L/∂v(x₀, v₀)."""
    mod = velocity_modules["velocity_midpoint"]
    result = mod.integrate(State(v=V0, x=X0), N_STEPS, H)
    assert result.success, result.message
    a, b = X0[0] + H * result.f[0][0] / 2, X0[1] + H * result.f[0][1] / 2
    # −D₁L_d of the midpoint rule: f + h/2 ∂V/∂q at the middle; ∂L/∂v = v₀
    grad = np.array([math.sin(a) + b / 10, b + a / 10])
    np.testing.assert_allclose(result.f[0] + H / 2 * grad, V0, rtol=0, atol=1e-12)


def test_example_groupoid_computes_the_pair_midpoint_path(velocity_modules, tmp_path):
    """Its midpoint L_d is the pair groupoid's h L((q₀ + q₁)/2, (q₁ − q₀)/h): the same
    nodes, to Newton's tolerance."""
    P = PairGroupoid("a b")
    pair = compile_model(Model(name="pair_reference", groupoid=P,
                               lagrangian=_lagrangian(P.q, P.qdot), discretisation="midpoint"),
                         tmp_path)
    q1 = np.add(X0, H * np.asarray(V0))
    nodes = pair.integrate([X0, q1], N_STEPS, H).x
    ours = velocity_modules["velocity_midpoint"].integrate((X0, [V0]), N_STEPS, H).x
    np.testing.assert_allclose(ours, nodes, rtol=0, atol=1e-10)


# -- the contract is declared in base.py ----------------------------------------------------
def _called_on(path: Path, names: set[str]) -> set[str]:
    """Attributes read on the variables ``names`` in a module's source."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) \
                and node.value.id in names:
            found.add(node.attr)
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Attribute) \
                and node.value.attr in names:
            found.add(node.attr)
    return found


def test_every_method_the_engine_and_rules_call_is_declared_in_base():
    """What the declaration, the engine, the rules, the emitter and the checks read of a
    groupoid (a variable ``g``, ``groupoid``, ``factor`` or ``….groupoid``) is a member of
    :class:`Groupoid` (nonholonomic.py reads the pair groupoid it builds itself)."""
    modules = [ROOT / "symvi" / name for name in (
        "derivation/derive.py", "discretisation/discretise.py", "discretisation/rules.py",
        "codegen/emit.py", "build/package.py")]
    modules += sorted((ROOT / "symvi" / "checks").glob("*.py"))
    modules += [p for p in sorted((ROOT / "symvi" / "declaration").glob("*.py"))
                if p.name != "nonholonomic.py"]
    used = set()
    for module in modules:
        used |= _called_on(module, {"g", "groupoid", "factor"})
    # SymPy and NumPy objects that share the variable names
    used -= {"free_symbols", "xreplace", "subs", "T", "shape", "reshape", "copy"}
    missing = sorted(name for name in used if not hasattr(Groupoid, name))
    assert not missing, f"called on a groupoid but not declared in base.py: {missing}"


def test_rules_take_a_groupoid():
    source = inspect.getsource(rules)
    assert "Any" not in re.sub(r"#.*", "", source)
    for quadrature in (rules._midpoint, rules._lie, rules._product, rules._central):
        assert inspect.signature(quadrature).parameters["g"].annotation == "Groupoid"


def test_the_template_context_is_typed_data():
    """c_context is a :class:`CContext` for every groupoid, with no kind in it."""
    from symvi import SO3, ActionGroupoid, ProductGroupoid
    top = ActionGroupoid(SO3(retraction="exp"), "G1 G2 G3", lambda q, W: W.T * q)
    for G in (PairGroupoid("a b"), SO3(), top, ProductGroupoid(top, PairGroupoid("phi")),
              VelocityPairGroupoid("a b")):
        context = G.c_context()
        assert isinstance(context, CContext)
        assert "kind" not in str(context)
    product = ProductGroupoid(top, PairGroupoid("phi")).c_context()
    assert [(c.x_offset, c.f_offset, c.dim) for c in product.node_copies] == [(3, 3, 1)]
    assert [G.retraction.log_macro for G in product.groups] == ["exponential_log"]


def test_initial_layouts_read_as_the_compiled_model_does(velocity_modules, tmp_path):
    """The layouts of initial data the package names (``INFO.initial_layout``,
    ``_runtime/core/paths.py``) read what :meth:`CompiledModel.initial_state` reads: the
    first K nodes on the pair groupoid, (x₀, f) here."""
    import importlib
    P = PairGroupoid("a b")
    pair = compile_model(Model(name="pair_layout", groupoid=P,
                               lagrangian=_lagrangian(P.q, P.qdot)), tmp_path)
    for mod, initial, name in ((pair, [X0, [0.5, 0.1]], "nodes"),
                               (velocity_modules["lie"], (X0, [V0]), "elements")):
        paths = importlib.import_module(f"{mod.__name__}._runtime.core.paths")
        assert mod.INFO.initial_layout == name
        read = paths.initial_layout(mod.model).read(mod.model, initial)
        for ours, theirs in zip(read, mod.model.initial_state(initial)):
            np.testing.assert_array_equal(ours, theirs)


def test_a_cayley_group_without_closed_form_emits():
    """The retraction names its C (``cayley_solve``: τ by a linear solve, no θ²); a group
    whose algebra has no minimal-polynomial structure (Heisenberg) emits (the templates
    once read a closed form it does not have)."""
    from symvi.codegen.emit import emit
    from symvi.derivation.derive import derive
    from symvi.discretisation.discretise import discretise
    from symvi.groupoids import MatrixLieGroup
    G = MatrixLieGroup([[[0, 1, 0], [0, 0, 0], [0, 0, 0]], [[0, 0, 0], [0, 0, 1], [0, 0, 0]],
                        [[0, 0, 1], [0, 0, 0], [0, 0, 0]]], label="Heisenberg")
    assert G.minimal_structure is None
    assert G.retraction.c_context().retract_macro == "cayley_solve"
    x = G.xi
    source = emit(derive(discretise(Model(name="heisenberg", groupoid=G,
                                          lagrangian=sum(v**2 for v in x) / 2
                                          + x[0] * x[1] / 5)))).c_source
    assert "static int retract_0(" in source and "theta_squared_0" not in source


def test_a_product_of_pair_groupoids_starts_from_a_state(tmp_path):
    """Every fibre coordinate of Q₁×Q₁ copies a node (``INFO.fibre_nodes``), so a State
    starts it as it starts the pair groupoid of both coordinates: the same path."""
    from symvi import ProductGroupoid
    A, B, P = PairGroupoid("a"), PairGroupoid("b"), PairGroupoid("a b")
    both = ProductGroupoid(A, B)
    product = compile_model(Model(name="pair_product_state", groupoid=both,
                                  lagrangian=_lagrangian(A.q + B.q, A.qdot + B.qdot)),
                            tmp_path)
    pair = compile_model(Model(name="pair_state", groupoid=P,
                               lagrangian=_lagrangian(P.q, P.qdot)), tmp_path)
    assert product.INFO.fibre_nodes == (0, 1)
    ours = product.integrate(State(v=V0, x=X0), N_STEPS, H)
    theirs = pair.integrate(State(v=V0, x=X0), N_STEPS, H)
    assert ours.success and theirs.success
    np.testing.assert_allclose(ours.x, theirs.x, rtol=0, atol=1e-10)
