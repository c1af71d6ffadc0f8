"""Plots of a result for ``symvi run --plot`` (needs matplotlib: ``pip install 'symvi[plots]'``).

Three panels against time: the configuration (a pair groupoid's nodes, an action
groupoid's base points, or on a Lie group over a point the distance ‖g₀⁻¹g − I‖_F of the
configuration from the start), the velocities (difference quotients of the nodes, or the
fibres ξ), and what judges the run: the energy error of a first-order integration, the
conserved quantities' drift, or the controls of an optimal-control solve with the
windows where a bound is active marked.
"""
from __future__ import annotations

import os
import secrets
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

if TYPE_CHECKING:
    from ._runtime.core.model_info import ModelInfo

#: Why ``--plot`` cannot run: the one message of the CLI's early check and of a late import.
MISSING = "--plot needs matplotlib: pip install 'symvi[plots]'"
#: Formats matplotlib lists but cannot write without more software: PGF measures its text
#: with a LaTeX installation, found missing only when the figure is written.
UNWRITABLE = ("pgf",)
#: The formats named first where a message lists them.
COMMON = (".png", ".pdf", ".svg")


def plot_result(result: Any, model: Any, info: ModelInfo, file: str | os.PathLike) -> None:
    """Write the plot of ``result`` (a ``StepResult`` or ``BVPResult``) of the declared
    ``model`` (a :class:`symvi.Model`, for the coordinates' names) compiled with metadata
    ``info`` (the generated package's ``INFO``) to the image ``file`` (its format from the
    suffix, e.g. ``.png``)."""
    plt = _pyplot()
    names = [str(s) for s in model.groupoid.continuous_symbols(1)]
    n = info.fibre_dim
    fig, axes = plt.subplots(3, 1, figsize=(8, 8), sharex=True, constrained_layout=True)
    _configuration(axes[0], result, info, names[:len(names) - n])
    _velocities(axes[1], result, info, names[-n:])
    _judge(axes[2], result, info)
    axes[-1].set_xlabel("t")
    fig.suptitle(f"{info.name}: {result.status.name}")
    _save(plt, fig, file)


def formats() -> tuple[str, ...]:
    """The file suffixes a plot can be written to (``.png``, ``.pdf``, ``.svg``, then the
    others alphabetically): what matplotlib's file-only Agg canvas writes;
    :data:`MISSING` without matplotlib."""
    _pyplot()
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    suffixes = {f".{name}" for name in FigureCanvasAgg.get_supported_filetypes()
                if name not in UNWRITABLE}
    return tuple(sorted(suffixes, key=lambda s: (COMMON.index(s) if s in COMMON
                                                 else len(COMMON), s)))


def _save(plt, fig, file: str | os.PathLike) -> None:
    """Write ``fig`` to ``file`` in the format its suffix names (matplotlib's default,
    PNG, without one; the name kept as given), as results are written: beside it, then
    renamed over it — whole or not at all, and an existing symlink is replaced, never
    written through. The figure is closed either way."""
    target = os.path.abspath(os.fspath(file))
    temporary = f"{target}.{os.getpid()}.{secrets.token_hex(4)}.tmp"
    # the temporary's suffix is not the format's: name it
    kind = os.path.splitext(target)[1][1:].lower() or plt.rcParams["savefig.format"]
    try:
        fig.savefig(temporary, format=kind, dpi=100)
        os.replace(temporary, target)
    except BaseException:
        if os.path.exists(temporary):
            os.unlink(temporary)
        raise
    finally:
        plt.close(fig)


def _pyplot():
    """matplotlib's pyplot on the file-only Agg backend; :data:`MISSING` without it."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise ValueError(MISSING) from None
    return plt


def _configuration(ax, result, info: ModelInfo, names: Sequence[str]) -> None:
    if result.x is not None and result.x.shape[1]:
        _lines(ax, result.t[:len(result.x)], result.x, names, "configuration")
        return
    g = result.g[0] if isinstance(result.g, tuple) else result.g
    d = g.shape[-1]
    distance = np.linalg.norm(np.linalg.solve(g[0], g) - np.eye(d), axis=(1, 2))
    ax.plot(result.t[:len(g)], distance, label="‖g₀⁻¹g − I‖")
    ax.set_ylabel("configuration")
    ax.legend(loc="best", fontsize="small")


def _velocities(ax, result, info: ModelInfo, names: Sequence[str]) -> None:
    h = float(result.t[1] - result.t[0])
    # per fibre coordinate (INFO.fibre_nodes): a copy of the next node's coordinate j
    # (a pair factor) has the difference quotient of x_j as its velocity, an increment (ξ
    # on a group) is the velocity itself
    nodes = np.asarray(info.fibre_nodes, dtype=int)
    copies = nodes >= 0
    values = np.array(result.f, dtype=float, copy=True)
    if copies.any():
        x = np.asarray(result.x, dtype=float)[:len(values) + 1, nodes[copies]]
        values[:, copies] = (x[1:] - x[:-1]) / h
    _lines(ax, result.t[:len(values)] + h / 2, values, names, "velocity")


def _judge(ax, result, info: ModelInfo) -> None:
    controls = getattr(result, "controls", None)
    energy = getattr(result, "energy", None)
    noether = getattr(result, "noether", None)
    if controls is not None:
        t = result.t[1:1 + len(controls)]
        _lines(ax, t, controls, [f"u{i + 1}" for i in range(controls.shape[1])], "controls")
        if result.active is not None and result.active.any():
            active = result.active.any(axis=1)
            ax.plot(t[active], np.zeros(active.sum()), "|", color="k", label="bound active")
            ax.legend(loc="best", fontsize="small")
    elif energy is not None and len(energy):
        ax.plot(result.t[:len(energy)], energy - energy[0])
        ax.set_ylabel("E − E₀")
    elif noether is not None and len(noether):
        _lines(ax, result.t[:len(noether)], noether - noether[0],
               [f"F{i + 1} − F{i + 1}(0)" for i in range(noether.shape[1])], "drift")
    else:
        iterations = getattr(result, "newton_iterations", getattr(result, "step_norms", None))
        ax.plot(np.arange(len(iterations)), iterations, ".")
        ax.set_ylabel("Newton iterations")


def _lines(ax, t: np.ndarray, values: np.ndarray, names: Sequence[str], label: str) -> None:
    for i in range(values.shape[1]):
        ax.plot(t, values[:, i], label=names[i] if i < len(names) else f"{label}[{i}]")
    ax.set_ylabel(label)
    ax.legend(loc="best", fontsize="small")


def plot_sweep(sweep: Any, title: str, file: str | os.PathLike, log_x: bool = False) -> None:
    """Write the summary plot of a ``symvi sweep`` (a :class:`symvi.sweep.Sweep`): what
    judges each member (the energy error, a drift, the Newton iterations or the cost)
    against the swept values, on a logarithmic axis where it spans decades; members that
    failed marked with a cross at the bottom of the axes."""
    plt = _pyplot()
    ok = sweep.succeeded
    fig, ax = plt.subplots(figsize=(7, 4.5), constrained_layout=True)
    ax.plot(sweep.values[ok], sweep.measure[ok], "o-", ms=4, label="succeeded")
    positive = sweep.measure[ok][np.isfinite(sweep.measure[ok])]
    if positive.size and (positive > 0).all() and positive.max() > 10 * positive.min():
        ax.set_yscale("log")
    if log_x:
        ax.set_xscale("log")
    if (~ok).any():
        low = np.nanmin(positive) if positive.size else 0.0
        ax.plot(sweep.values[~ok], np.full((~ok).sum(), low), "x", color="C3", ms=8,
                label=f"failed ({(~ok).sum()})")
    slope = sweep.slope()
    if slope is not None:
        ax.set_title(f"{title}\nfitted order: {sweep.measure_name} ∝ h^{slope:.2f}")
    else:
        ax.set_title(title)
    ax.set_xlabel(sweep.name)
    ax.set_ylabel(sweep.measure_name)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    _save(plt, fig, file)
