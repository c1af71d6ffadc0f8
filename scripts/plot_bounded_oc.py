"""The bounded optimal-control problems of issue 21 with plots: controls against their
bounds, states and the bound multipliers, beside the problems without limits; the
near-minimum-time slew; the cart-pole swing-up with force and track limits.

``spacecraft_slew`` (rest to rest through a quarter turn about (1,1,1)/√3 in T = 1,
I = diag(1, 2, 3), N = 1000) is solved for τ_max = 11 and 13 and, for comparison, for
τ_max = 100 (no bound active: the unbounded optimum). The script prints each outcome
and writes ``spacecraft_slew.png`` into the output directory (default ``paper_figures/``):
torques τ_k per window with ±τ_max, Ω_k, and the multipliers z_k/h of the active
bounds (per unit time, so they do not scale with N); and ``minimum_time_slew.png``: the torques
of the free-horizon slew (min ½∫|τ/I|² + 100·T) for τ_max = 11 and 16 over their optimal
horizons; and ``cart_pole_swing_up.png``: the swing-up's force against ±u_max, the
cart against its track ±d, the pole angle and the multipliers, beside the swing-up without
limits; and ``planar_flyer.png``: the flyer's path around the keep-out disc with its
heading, and its controls, for two disc radii. Needs matplotlib (``pip install '.[plots]'``).

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
    plot_swing_up(out, plt)
    plot_flyer(out, plt)


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


def plot_swing_up(out: Path, plt) -> None:
    """The cart-pole swing-up with force and track limits beside the one without: the
    force against ±u_max, the cart against ±d, the pole angle, and the multipliers of
    the force bounds and of the track bound (per unit time), and the pole equation's λ."""
    name = "cart_pole_swing_up"
    model = get(name)
    ex, steps = model.example, model.example.n_steps
    module = compile_model(model, out / "generated")
    limits = {"u_max = 14, d = 0.8": dict(u_max=14.0, d=0.8),
              "no limits": dict(u_max=100.0, d=100.0)}
    fig, axes = plt.subplots(5, 1, figsize=(8, 11), sharex=True)
    for (label, params), colour in zip(limits.items(), ("C0", "0.5")):
        r = module.solve_bvp(ex.start, ex.end, steps, ex.h, params=params)
        r.raise_for_status()
        print(f"{name}, {label}: cost {r.cost:.10g}, {r.iterations} iterations, "
              f"max |u| {abs(r.controls).max():.4g}, max |x| {abs(r.x[:, 0]).max():.4g}")
        t = midpoints(r.t)
        axes[0].plot(t, r.controls[:, 0], color=colour, label=label)
        axes[1].plot(r.t, r.x[:, 0], color=colour, label=label)
        axes[2].plot(r.t, r.x[:, 1], color=colour, label=label)
        axes[4].plot(t, r.multipliers[:, 0], color=colour, label=f"{label}: λ")
        if colour == "C0":
            z = r.bound_multipliers / ex.h
            axes[3].plot(t, z[:, 0] - z[:, 1], color="C0", label="force: z₊ − z₋")
            axes[3].plot(t, z[:, 2] - z[:, 3], color="C3", label="track: z₊ − z₋")
            for ax, bound in ((axes[0], params["u_max"]), (axes[1], params["d"])):
                for sign in (1, -1):
                    ax.axhline(sign * bound, color="C0", ls=":", lw=0.8)
    for ax, what in zip(axes, ("force u", "cart x", "pole angle θ", "bound multipliers / h",
                               "pole equation's multiplier")):
        ax.set_ylabel(what)
    # the track bound's multiplier is an impulse where the cart touches the end (a
    # second-order state constraint); the force bound's is two orders smaller
    axes[3].set_yscale("symlog", linthresh=1.0)
    finish(fig, list(axes), f"{name}: swing-up, min ½∫u², N = {steps}", out / f"{name}.png")
    print(f"wrote {out / f'{name}.png'}")


def plot_flyer(out: Path, plt) -> None:
    """The planar flyer's path around the keep-out disc, with its heading every few
    steps, and its controls (the main thrust against its lower bound 0), for the
    example's disc (r = 0.7) and a smaller one (r = 0.4)."""
    from symvi.models.planar_flyer import CENTRE

    name = "planar_flyer"
    model = get(name)
    ex, steps = model.example, model.example.n_steps
    module = compile_model(model, out / "generated")
    fig = plt.figure(figsize=(11, 7))
    path_ax = fig.add_subplot(1, 2, 1)
    control_axes = [fig.add_subplot(3, 2, 2 * i + 2) for i in range(3)]
    for radius, colour in ((0.7, "C0"), (0.4, "C1")):
        r = module.solve_bvp(ex.start, ex.end, steps, ex.h, params=dict(r=radius))
        r.raise_for_status()
        print(f"{name}, r = {radius}: cost {r.cost:.10g}, {r.iterations} iterations, main "
              f"thrust at its bound 0 on {int(r.active[:, 3].sum())} of {len(r.active)} "
              f"windows")
        label = f"disc r = {radius}"
        path_ax.add_patch(plt.Circle(CENTRE, radius, color=colour, alpha=0.15))
        xy, heading = r.g[:, :2, 2], r.g[:, :2, 0]
        path_ax.plot(xy[:, 0], xy[:, 1], color=colour, label=label)
        every = slice(0, None, max(1, steps // 20))
        path_ax.quiver(xy[every, 0], xy[every, 1], heading[every, 0], heading[every, 1],
                       color=colour, scale=25, width=0.004)
        for ax, u in zip(control_axes, r.controls.T):
            ax.plot(midpoints(r.t), u, color=colour, label=label)
    path_ax.set_aspect("equal")
    path_ax.set_xlabel("x")
    path_ax.set_ylabel("y (arrows: heading)")
    path_ax.legend(fontsize=8)
    control_axes[1].axhline(0.0, color="k", ls=":", lw=0.8)
    for ax, what in zip(control_axes, ("torque τ", "main thrust f₁ ≥ 0", "side thrust f₂")):
        ax.set_ylabel(what)
    finish(fig, control_axes, f"{name}: rest to rest around a keep-out disc, forward-only "
           f"main thruster, N = {steps}", out / f"{name}.png")
    print(f"wrote {out / f'{name}.png'}")


if __name__ == "__main__":
    main()
