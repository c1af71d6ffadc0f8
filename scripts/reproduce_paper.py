"""Reproduce the two optimal-control examples of the paper (§3.3.4 and §3.3.5) with plots.

1. Rigid body on SO(3) (``rigid_body_oc``): R_0 = I to a quarter-turn about (1,1,1)/√3,
   at rest at both ends, T = 1, inertia diag(1, 2, 3), N = 1000: attitude (the rotation
   vector of R_k), angular velocity Ω_k and the torques τ_k.
2. Heavy top with two internal rotors (``heavy_top_rotors_oc``, underactuated): from
   rest upright to a tilt of 0.2 rad, T = 2, N = 400: the direction of gravity Γ_k, Ω_k and
   rotor rates, the rotor torques u_k and the multipliers λ_k of the three constraints.

Both are solved as one whole-trajectory Newton problem from the default initial guess; the
script prints the outcome, the optimal discrete cost and how well the discrete
constraints hold, and writes ``rigid_body_oc.png`` and ``heavy_top_rotors_oc.png`` into
the output directory (default ``paper_figures/``). Needs matplotlib
(``pip install '.[plots]'``).

Run from the repository root: ``python scripts/reproduce_paper.py [-o DIR]``.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from symvi.build import compile_model  # noqa: E402
from symvi.models import get  # noqa: E402
from symvi.models.heavy_top_rotors_oc import boundary  # noqa: E402


def rotation_vector(R: np.ndarray) -> np.ndarray:
    """Axis times angle of rotation matrices (K, 3, 3)."""
    angle = np.arccos(np.clip((np.trace(R, axis1=1, axis2=2) - 1) / 2, -1.0, 1.0))
    axis = np.stack([R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]],
                    axis=1)
    scale = np.where(angle > 1e-12, angle / (2 * np.sin(np.maximum(angle, 1e-12))), 0.5)
    return axis * scale[:, None]


def solve(name: str, out: Path, N: int, start, end, T: float):
    module = compile_model(get(name), out / "generated")
    result = module.solve_bvp(start, end, N, T / N)
    print(f"{name}: {result.status.name}: {result.message}; discrete cost {result.cost:.10g}")
    if result.multipliers is not None:
        phi = module.model.along("constraint", result.x, result.f, T / N)
        print(f"  max |Φ_d| over the windows: {np.abs(phi).max():.2e}")
    result.raise_for_status()
    return module, result


def midpoints(t: np.ndarray) -> np.ndarray:
    """Times of the windows' quadrature points (the middle node of each window)."""
    return t[1:-1]


def finish(fig, axes, title: str, path: Path) -> None:
    """Legends, grids, the time axis and the title; write the PNG."""
    import matplotlib.pyplot as plt

    for ax in axes:
        ax.legend(loc="best", fontsize=8)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("t")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_rigid_body(result, path: Path) -> None:
    import matplotlib.pyplot as plt

    t = result.t
    fig, axes = plt.subplots(3, 1, figsize=(7, 8), sharex=True)
    axes[0].plot(t, rotation_vector(result.g), label=["$\\phi_1$", "$\\phi_2$", "$\\phi_3$"])
    axes[0].set_ylabel("rotation vector of $R_k$")
    axes[1].plot(t[:-1], result.f, label=["$\\Omega_1$", "$\\Omega_2$", "$\\Omega_3$"])
    axes[1].set_ylabel("angular velocity $\\xi_k$")
    axes[2].plot(midpoints(t), result.controls, label=["$\\tau_1$", "$\\tau_2$", "$\\tau_3$"])
    axes[2].set_ylabel("torques $\\tau_k$")
    finish(fig, axes, f"Rigid body optimal control on SO(3), cost {result.cost:.6g}", path)


def plot_heavy_top(result, path: Path) -> None:
    import matplotlib.pyplot as plt

    t, x, f = result.t, result.x, result.f
    fig, axes = plt.subplots(4, 1, figsize=(7, 10), sharex=True)
    axes[0].plot(t, x[:, :3], label=["$\\Gamma_1$", "$\\Gamma_2$", "$\\Gamma_3$"])
    axes[0].set_ylabel("gravity direction $\\Gamma_k$")
    h = t[1] - t[0]
    rotor_rates = np.diff(x[:, 3:], axis=0) / h
    axes[1].plot(t[:-1], f[:, :3], label=["$\\Omega_1$", "$\\Omega_2$", "$\\Omega_3$"])
    axes[1].plot(t[:-1], rotor_rates, "--", label=["$\\dot\\theta_1$", "$\\dot\\theta_2$"])
    axes[1].set_ylabel("velocities")
    axes[2].plot(midpoints(t), result.controls, label=["$u_1$", "$u_2$"])
    axes[2].set_ylabel("rotor torques $u_k$")
    axes[3].plot(midpoints(t), result.multipliers,
                 label=["$\\lambda_1$", "$\\lambda_2$", "$\\lambda_3$"])
    axes[3].set_ylabel("multipliers $\\lambda_k$")
    finish(fig, axes, f"Heavy top with two rotors (underactuated), cost {result.cost:.6g}", path)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--output", default="paper_figures", help="output directory")
    args = parser.parse_args(argv)
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)

    ex = get("rigid_body_oc").example
    _, rigid = solve("rigid_body_oc", out, ex.n_steps, ex.start, ex.end, ex.n_steps * ex.h)
    N, T = 400, 2.0
    start, end = boundary(T / N)
    _, top = solve("heavy_top_rotors_oc", out, N, start, end, T)
    plot_rigid_body(rigid, out / "rigid_body_oc.png")
    plot_heavy_top(top, out / "heavy_top_rotors_oc.png")
    print(f"wrote {out / 'rigid_body_oc.png'} and {out / 'heavy_top_rotors_oc.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
