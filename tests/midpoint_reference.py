"""An extended-precision solution of the midpoint rule's discrete Euler–Lagrange
equations on a pair groupoid, derived with SymPy from the model's Lagrangian and solved
with mpmath: the independent reference of tests/test_step_loop.py and
scripts/bench_step.py."""
from __future__ import annotations

import mpmath as mp
import numpy as np
import sympy as sp


def reference_path(model, initial: np.ndarray, h: float, steps: int) -> np.ndarray:
    """The nodes of the midpoint rule's discrete path from the first two nodes, in 25
    digits: D₂L_d(q_{k−1}, q_k) + D₁L_d(q_k, q_{k+1}) = 0, L_d(a, b) = h L((a+b)/2, (b−a)/h),
    each step by Newton's method to convergence."""
    G = model.groupoid
    n = G.fibre_dim
    a, b, c = (sp.symbols(f"{s}0:{n}", real=True) for s in "abc")
    step = sp.Rational(str(h))
    params = {s: sp.nsimplify(v) for s, v in model.parameters}

    def Ld(u, v):
        point = dict(zip(G.q, [(x + y) / 2 for x, y in zip(u, v)]))
        point |= dict(zip(G.qdot, [(y - x) / step for x, y in zip(u, v)]))
        return step * model.lagrangian.xreplace(point).xreplace(params)
    R = sp.Matrix([sp.diff(Ld(a, b), bi) + sp.diff(Ld(b, c), bi) for bi in b])
    residual = sp.lambdify([*a, *b, *c], R, "mpmath")
    jacobian = sp.lambdify([*a, *b, *c], R.jacobian(c), "mpmath")
    with mp.workdps(25):
        nodes = [[mp.mpf(float(v)) for v in row] for row in initial]
        for _ in range(steps - 1):
            q0, q1 = nodes[-2], nodes[-1]
            x = mp.matrix([2 * u - v for u, v in zip(q1, q0)])
            for _ in range(5):
                x -= mp.lu_solve(jacobian(*q0, *q1, *x), residual(*q0, *q1, *x))
            nodes.append(list(x))
        return np.array([[float(v) for v in row] for row in nodes])
