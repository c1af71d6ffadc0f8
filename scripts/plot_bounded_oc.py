"""The torque-limited slews of issue 21 with plots: controls against their bounds, angular
velocity and the bound multipliers, beside the slew without limits; and the
near-minimum-time slew.

``spacecraft_slew`` (rest to rest through a quarter turn about (1,1,1)/√3 in T = 1,
I = diag(1, 2, 3), N = 1000) is solved for τ_max = 11 and 13 and, for comparison, for
τ_max = 100 (no bound active: the unbounded optimum). The script prints each outcome
and writes ``spacecraft_slew.png`` into the output directory (default ``paper_figures/``):
torques τ_k per window with ±τ_max, Ω_k, and the multipliers z_k/h of the active
bounds (per unit time, so they do not scale with N); and ``minimum_time_slew.png``: the torques
of the free-horizon slew (min ½∫|τ/I|² + 100·T) for τ_max = 11 and 16 over their optimal
horizons. Needs matplotlib (``pip install '.[plots]'``).

Run from the repository root: ``python scripts/plot_bounded_oc.py [-o DIR]``.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from reproduce_paper import finish, midpoints  # noqa: E402
from symvi.build import compile_model  # noqa: E402
from symvi.models import get  # noqa: E402

NAME, N, T, LIMITS = "spacecraft_slew", 1000, 1.0, (11.0, 13.0, 100.0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--output", default="paper_figures", help="output directory")
    out = Path(parser.parse_args().output)
    out.mkdir(parents=True, exist_ok=True)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    model = get(NAME)
    module = compile_model(model, out / "generated")
    results = {}
    for limit in LIMITS:
        r = module.solve_bvp(model.example.start, model.example.end, N, T / N,
                             params=dict(tau_max=limit))
        print(f"τ_max = {limit:5g}: {r.status.name}: cost {r.cost:.10g}, {r.iterations} "
              f"iterations, active windows {int(r.active.any(axis=1).sum())} of "
              f"{r.active.shape[0]}")
        r.raise_for_status()
        results[limit] = r
    fig, axes = plt.subplots(3, 3, figsize=(12, 8), sharex=True)
    colours = dict(zip(LIMITS, ("C0", "C1", "0.5")))
    for i in range(3):
        for limit, r in results.items():
            label = "no limit" if limit == LIMITS[-1] else f"τ_max = {limit:g}"
            t = midpoints(r.t)
            axes[0, i].plot(t, r.controls[:, i], color=colours[limit], label=label)
            axes[1, i].plot(r.t[:-1] + T / N / 2, r.f[:, i], color=colours[limit], label=label)
            if limit != LIMITS[-1]:
                z = r.bound_multipliers[:, 2 * i:2 * i + 2] * N / T
                axes[2, i].plot(t, z[:, 0] - z[:, 1], color=colours[limit],
                                label=f"{label}: z₊ − z₋")
                for sign in (1, -1):
                    axes[0, i].axhline(sign * limit, color=colours[limit], ls=":", lw=0.8)
        axes[0, i].set_ylabel(f"τ{i + 1}")
        axes[1, i].set_ylabel(f"Ω{i + 1}")
        axes[2, i].set_ylabel(f"bound multiplier {i + 1} / h")
    finish(fig, axes.ravel(), f"{NAME}: torque-limited rest-to-rest slew, N = {N}",
           out / f"{NAME}.png")
    print(f"wrote {out / f'{NAME}.png'}")
    plot_minimum_time(out, plt)


def plot_minimum_time(out: Path, plt) -> None:
    """The free-horizon slew's torques for two limits, over their optimal horizons."""
    name, steps = "minimum_time_slew", 400
    model = get(name)
    module = compile_model(model, out / "generated")
    fig, axes = plt.subplots(3, 1, figsize=(8, 7), sharex=True)
    for limit, colour in ((11.0, "C0"), (16.0, "C1")):
        r = module.solve_bvp(model.example.start, model.example.end, steps, 1.0 / steps,
                             params=dict(tau_max=limit))
        r.raise_for_status()
        print(f"{name}, τ_max = {limit:g}: T* = {r.t[-1]:.6f}, cost {r.cost:.8g}")
        for i, ax in enumerate(axes):
            ax.plot(midpoints(r.t), r.controls[:, i], color=colour,
                    label=f"τ_max = {limit:g}, T* = {r.t[-1]:.4f}")
            for sign in (1, -1):
                ax.axhline(sign * limit, color=colour, ls=":", lw=0.8)
            ax.set_ylabel(f"τ{i + 1}")
    finish(fig, list(axes), f"{name}: min ½∫|τ/I|² + 100·T, free horizon, N = {steps}",
           out / f"{name}.png")
    print(f"wrote {out / f'{name}.png'}")


if __name__ == "__main__":
    main()
