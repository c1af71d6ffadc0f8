"""Plots for ``symvi run --plot`` and ``symvi sweep --plot`` (needs matplotlib: ``pip
install 'symvi[plots]'``).

A result's figure is its own ``plot()`` (the run time's ``_runtime/core/plotting.py``:
declared names, world position and attitude of group configurations, the controls or
energy error); this module writes it, and draws the sweep's summary.
"""
from __future__ import annotations

import os
import secrets
from typing import Any

import numpy as np

#: Why ``--plot`` cannot run: the one message of the CLI's early check and of a late import.
MISSING = "--plot needs matplotlib: pip install 'symvi[plots]'"
#: Formats matplotlib lists but cannot write without more software: PGF measures its text
#: with a LaTeX installation, found missing only when the figure is written.
UNWRITABLE = ("pgf",)
#: The formats named first where a message lists them.
COMMON = (".png", ".pdf", ".svg")


def plot_result(result: Any, file: str | os.PathLike) -> None:
    """Write ``result.plot()`` (a ``StepResult`` or ``BVPResult``: its matplotlib
    figure) to the image ``file`` (its format from the suffix, e.g. ``.png``)."""
    plt = _pyplot()
    try:
        fig = result.plot()
    except ImportError:
        raise ValueError(MISSING) from None
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
