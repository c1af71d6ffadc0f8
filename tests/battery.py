"""The robustness battery of the whole-trajectory solve (issue 20, item 3).

For a bundled optimal-control problem at N steps: the chord guess, the zero guess (every
free node at the last start node: at rest at the start configuration throughout) and
seeded perturbed guesses — the default cubic guess moved by a smooth random variation
η(t) = Σ_{k=1}^{3} a_k sin(kπ t/T), a_k uniform in [−½, ½]^n per node coordinate (radians
on a group), zero at the fixed ends. Smooth, because white noise of that size would put
accelerations of order 1/h² into the guess, which no user would start from.
Used by ``tests/test_robustness.py`` and ``scripts/robustness_bvp.py``.
"""
from __future__ import annotations

import numpy as np

from symvi.models import get
from test_bvp_merit import dense_jacobian
from test_bvp_merit import runtime_of as runtime




def free_nodes(module, path, N: int):
    """The free nodes of a runtime Path in the layout of ``solve_bvp(..., guess=...)``."""
    r, model = module.model.order, module.model
    free = slice(r, N + 1 - r)
    g = model.configurations(path.g[free]) if model.matrix_dims else None
    if not model.matrix_dims:
        return path.x[free]
    return g if model.m == 0 else (path.x[free], g)


def guesses(module, name: str, N: int, count: int = 20, amplitude: float = 0.5) -> dict:
    """{label: guess} for the battery: "chord", "zero" and ``count`` perturbed ones."""
    model, ex = module.model, get(name).example
    h = ex.h * ex.n_steps / N
    p = model.params()
    base = runtime(module, "core.paths").initial_path(model, ex.start, ex.end, N, None, p, h)
    problem = runtime(module, "bvp.assembly").Problem(model, p, h)
    blocks = problem._blocks(base)
    out = {"chord": "chord", "zero": zero_guess(module, name, N)}
    t = blocks / N
    for seed in range(count):
        a = np.random.default_rng(seed).uniform(-amplitude, amplitude, (3, model.n))
        eta = sum(np.outer(np.sin((k + 1) * np.pi * t), a[k]) for k in range(3))
        eta[(blocks < model.order) | (blocks > N - model.order)] = 0.0
        delta = np.concatenate([eta, np.zeros((len(blocks), model.constraints))], axis=1)
        moved = problem.moved(base, np.r_[delta.reshape(-1), np.zeros(model.end_count)], 1.0)
        if moved is not None:
            out[f"perturbed {seed}"] = free_nodes(module, moved, N)
    return out


def zero_guess(module, name: str, N: int):
    """Every free node equal to the last start node."""
    model, start = module.model, get(name).example.start
    count = N + 1 - 2 * model.order

    def held(nodes):
        nodes = np.asarray(nodes, dtype=float)
        return np.repeat(nodes[-1:], count, axis=0)
    if isinstance(start, tuple):
        return tuple(held(part) for part in start)
    return held(start)


def run(module, name: str, N: int, count: int = 20, **options) -> dict:
    """{label: result} over the battery at N steps (the example's horizon)."""
    ex = get(name).example
    h = ex.h * ex.n_steps / N
    return {label: module.solve_bvp(ex.start, ex.end, N, h, guess=guess, **options)
            for label, guess in guesses(module, name, N, count).items()}


def newton_matrix(module, name: str, N: int, result):
    """The dense Newton (KKT) matrix at a result's path and the mask of its constraint
    rows, through the runtime's own assembly."""
    problem, path, ab, bw = assembled(module, name, N, result)
    return dense_jacobian(ab, bw), problem.constraint_rows(path)


def assembled(module, name: str, N: int, result, lifted: bool | None = None):
    """(problem, path, band, bw): the runtime's Newton system at a result's path (with the
    lifted system too when ``lifted``)."""
    model, ex = module.model, get(name).example
    h = ex.h * ex.n_steps / N
    paths, nodes = runtime(module, "core.paths"), N + 1
    g = paths.flat_configurations(model, result.g, nodes, "g") if model.matrix_dims \
        else np.zeros((nodes, 0))
    x = np.zeros((nodes, 0)) if result.x is None else result.x
    lam = np.zeros((0, 0)) if result.multipliers is None else result.multipliers
    path = paths.Path(*(np.ascontiguousarray(a, dtype=float) for a in (x, g, result.f, lam)))
    problem = runtime(module, "bvp.assembly").Problem(model, model.params(), h, lifted=lifted)
    _, ab, bw, _ = problem.assemble(path, True)
    return problem, path, ab, bw
