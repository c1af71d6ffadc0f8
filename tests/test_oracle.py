"""The variational oracle of DESIGN.md §5 on every bundled model.

A path computed by the step map must make the action sum S = Σ_w L_d(window w)
stationary with respect to every node whose discrete Euler–Lagrange equation the step map
enforced. The oracle knows nothing of the engine's residual, its signs or its slot
conventions: it only perturbs nodes and re-evaluates the compiled ``lagrangian`` kernel.

Which nodes. A path of E elements has nodes q_0 … q_E. For order r, each step solves the
residual at the middle node of the stencil q_{j−r} … q_{j+r} for q_{j+r}; the first step
gives q_{2r} (equation at node r), the last q_E (equation at node E − r). So the nodes
r … E − r are stationary; the first and last r nodes are not (their windows are cut off).

A node variation on the pair groupoid is σ_a(ε) = ε e_a at the shared node: element
(q_{j−1}, q_j) becomes (q_{j−1}, q_j + ε e_a) and (q_j, q_{j+1}) becomes
(q_j + ε e_a, q_{j+1}); in the arrays of a StepResult that is x[j] and f[j−1].

Error analysis (central differences with step ε_{j,c} = 1e-5·max(1, |q_{j,c}|)):

* rounding: S(+ε) − S(−ε) is summed window by window (``math.fsum`` of the window
  differences). The windows that do not contain q_j are bitwise unchanged and drop out,
  so the size of S adds no rounding (differencing two totals would add u|S|/ε, which
  for the spline, |S| ≈ 900, is 5e-10 of the gradient scale); each window that does
  contain q_j is evaluated to a few ulp, so |error| ≲ 4u·Σ_{w∋j}|L_w|/ε (u = 2.2e-16) —
  the "noise" computed below;
* truncation: ε²/6·|∂³S/∂q_j³| ≈ 2e-11·|∂³S/∂q_j³|; the bundled Lagrangians are
  polynomial or trigonometric in q with O(1) coefficients (the 1/h of kinetic terms
  multiplies differences, which makes their third derivatives O(1) too), so this is
  ~1e-10 of the gradient scale;
* ε ≈ (3u|S|/|∂³S|)^{1/3} ≈ 1e-5 balances the two for |S|, |∂³S| = O(1).

The scale of a node is Σ_w |∂L_w/∂q_j|, the sizes of the individual terms whose sum the
discrete Euler–Lagrange equation says cancels (for first order |D2 L_d| + |D1 L_d|, i.e.
about 2|p|). The relative gradient |∂S/∂q_j|/scale is then ~1e-11 on a solution
(measured ≤ 3e-11), limited by the noise above and by Newton's stopping tolerance
(xtol = 1e-12 on the update, which leaves at most ‖D12 L_d‖·1e-12 in the residual).
TOL = 1e-8 leaves a factor of 300 above that, and each test also checks that the noise
bound of every node is below TOL/10 (it is largest, 5e-10, at node 1 of the pendulums,
which start at rest: there the velocity terms vanish and the scale is only h|∂L/∂q|),
so a gradient of size TOL would be resolved.
The negative control perturbs one node by 1e-3: that leaves a gradient of about
1e-3·‖D11 L_d + D22 L_d‖ ≈ 1e-3·2m/h for first order and 1e-3·6/h³ for the spline, i.e.
≥ 1e-3 relative, five orders of magnitude above TOL.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from conftest import PAIR
from symvi.models import get

TOL = 1e-8
N_STEPS = 50
U = np.finfo(float).eps


@dataclass(frozen=True)
class Oracle:
    """Per-node outcome of the oracle: nodes j, relative gradients and noise floors."""

    nodes: np.ndarray
    relative: np.ndarray  # max_c |∂S/∂q_{j,c}| / scale_j
    noise: np.ndarray     # FD rounding bound / scale_j


def _window_values(mod, x, f, h):
    return mod.model.along("lagrangian", x, f, h)[:, 0]


def _vary(x, f, j, c, delta):
    """The node variation σ: move node j along coordinate c, in both elements holding it."""
    x, f = x.copy(), f.copy()
    x[j, c] += delta
    if j >= 1:
        f[j - 1, c] += delta
    return x, f


def oracle(mod, x, f, h, nodes) -> Oracle:
    values = _window_values(mod, x, f, h)
    rel, noise = [], []
    for j in nodes:
        gradient, scale, floor = [], [], []
        for c in range(x.shape[1]):
            eps = 1e-5 * max(1.0, abs(x[j, c]))
            plus = _window_values(mod, *_vary(x, f, j, c, +eps), h)
            minus = _window_values(mod, *_vary(x, f, j, c, -eps), h)
            # S(+ε) − S(−ε) summed window by window: the windows without node j are
            # bitwise equal and drop out, so |S| itself adds no rounding.
            terms = (plus - minus) / (2 * eps)  # ∂L_w/∂q_{j,c}; zero off the windows of j
            gradient.append(math.fsum(terms))
            scale.append(np.abs(terms).sum())
            touched = np.abs(values[terms != 0]).sum()
            floor.append(4 * U * touched / eps)
        s = max(scale)
        rel.append(max(abs(g) for g in gradient) / s)
        noise.append(max(floor) / s)
    return Oracle(np.asarray(nodes), np.asarray(rel), np.asarray(noise))


def _path(mod, model):
    ex = model.example
    result = mod.integrate(ex.initial, N_STEPS, ex.h)
    assert result.success, result.message
    # Pair groupoid: element k is (q_k, q_{k+1}), so the fibres are the later nodes.
    np.testing.assert_array_equal(result.f, result.x[1:])
    return result.x, result.f, ex.h


def _enforced(model, x):
    r, E = model.order, x.shape[0] - 1
    return list(range(r, E - r + 1))


@pytest.mark.parametrize("name", PAIR)
def test_computed_path_is_stationary(name, compiled):
    model, mod = get(name), compiled(name)
    x, f, h = _path(mod, model)
    nodes = _enforced(model, x)
    assert len(nodes) >= 40
    out = oracle(mod, x, f, h, nodes)
    assert out.noise.max() < TOL / 10, f"FD noise floor {out.noise.max():.2e} too high"
    worst = int(np.argmax(out.relative))
    assert out.relative.max() < TOL, (
        f"{name}: action not stationary at node {out.nodes[worst]}: relative gradient "
        f"{out.relative[worst]:.3e}")


@pytest.mark.parametrize("name", PAIR)
def test_oracle_detects_a_perturbed_node(name, compiled):
    """Negative control: moving one node by 1e-3 breaks stationarity there (and only near)."""
    model, mod = get(name), compiled(name)
    x, f, h = _path(mod, model)
    r, nodes = model.order, _enforced(model, x)
    j0 = nodes[len(nodes) // 2]
    bad_x, bad_f = _vary(x, f, j0, 0, 1e-3)
    out = oracle(mod, bad_x, bad_f, h, nodes)
    by_node = dict(zip(out.nodes.tolist(), out.relative))
    assert by_node[j0] > 1e3 * TOL, f"{name}: oracle missed the moved node ({by_node[j0]:.2e})"
    # The windows of node j reach nodes j − r … j + r: the moved node spoils the equations
    # of the nodes within r of it and of no other.
    for j in range(j0 - r, j0 + r + 1):
        assert by_node[j] > 1e3 * TOL, (j, by_node[j])
    far = [rel for j, rel in by_node.items() if abs(j - j0) > r]
    assert max(far) < TOL


@pytest.mark.parametrize("name", PAIR)
def test_boundary_nodes_are_not_stationary(name, compiled):
    """The first and last r nodes lack windows, so the full action sum is not stationary
    there: this shows the oracle measures the sum, not a quantity that is always small.
    (For order 1 the boundary nodes have a single window and the ratio is 1 by
    construction; for order 2 node 1 has two windows whose terms do not cancel.)"""
    model, mod = get(name), compiled(name)
    x, f, h = _path(mod, model)
    r, E = model.order, x.shape[0] - 1
    boundary = list(range(0, r)) + list(range(E - r + 1, E + 1))
    out = oracle(mod, x, f, h, boundary)
    assert out.relative.min() > 1e-3, dict(zip(out.nodes.tolist(), out.relative))
