"""The nonholonomic optimal-control problems of issue 25 with plots: the paths in the
plane with the heading along them, and the controls.

``unicycle_parking`` (sideways by 1 at rest, T = 4), ``chaplygin_sled`` (from rest to the
state a wiggling torque reaches, only the turning actuated) and ``rolling_coin`` (a
quarter turn to (1, 1)), each solved from its example's first path at its example's N.
The script prints each outcome and the largest constraint defect (the discrete kinematic
constraints (q₁ − q₀)/h − ρ(q̄)ȳ and the unactuated equations), and writes ``nonholonomic.png`` into the output directory (default
``paper_figures/``): per problem, the path (x, y) with arrows for the heading θ, and the
controls per element against time. Needs matplotlib (``pip install '.[plots]'``).

Run from the repository root: ``python scripts/plot_nonholonomic.py [-o DIR]``.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from symvi.build import compile_model  # noqa: E402
from symvi.models import NONHOLONOMIC, get  # noqa: E402


def solve(name: str, build_dir: str):
    """The example's solve, and the largest constraint defect |Φ_d|/h over the elements
    (the kinematic constraints and the unactuated equations), recomputed from the path
    through the compiled ``constraint`` kernel."""
    model = get(name)
    module = compile_model(model, build_dir)
    ex = model.example
    result = module.solve_bvp(ex.start, ex.end, ex.n_steps, ex.h, guess=ex.guess_nodes())
    values = module.model.along("constraint", result.x, result.f, ex.h)
    return result, float(np.abs(values).max()) / ex.h


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--output", default="paper_figures", help="output directory")
    out = Path(parser.parse_args().output)
    out.mkdir(parents=True, exist_ok=True)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, len(NONHOLONOMIC), figsize=(5 * len(NONHOLONOMIC), 8))
    with tempfile.TemporaryDirectory(prefix="symvi-nonholonomic-") as build_dir:
        for column, name in enumerate(NONHOLONOMIC):
            result, defect = solve(name, build_dir)
            print(f"{name}: {result.status.name} in {result.iterations} iterations, cost "
                  f"{result.cost:.10g}, max constraint defect {defect:.1e}")
            x, y, theta = result.x[:, 0], result.x[:, 1], result.x[:, 2]
            path = axes[0, column]
            path.plot(x, y, "-", lw=1.5)
            every = max(len(x) // 16, 1)
            path.quiver(x[::every], y[::every], np.cos(theta[::every]),
                        np.sin(theta[::every]), angles="xy", scale=12, width=0.006,
                        color="C1")
            path.plot(x[[0, -1]], y[[0, -1]], "ko", ms=4)
            path.set_aspect("equal", adjustable="datalim")
            path.set_title(f"{name}: cost {result.cost:.4g}")
            path.set_xlabel("x")
            path.set_ylabel("y")
            controls = axes[1, column]
            t = (result.t[1:] + result.t[:-1]) / 2
            for k in range(result.controls.shape[1]):
                controls.step(t, result.controls[:, k], where="mid", label=f"u{k + 1}")
            controls.set_xlabel("t")
            controls.legend(loc="best", fontsize=8)
            for ax in (path, controls):
                ax.grid(alpha=0.3)
    fig.suptitle("Nonholonomic optimal control on D⁽²⁾: paths with headings, controls")
    fig.tight_layout()
    fig.savefig(out / "nonholonomic.png", dpi=120)
    plt.close(fig)
    print(f"wrote {out / 'nonholonomic.png'}")


if __name__ == "__main__":
    main()
