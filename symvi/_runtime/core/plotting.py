"""A result drawn as a matplotlib ``Figure``: ``StepResult.plot()`` and
``BVPResult.plot()`` (and ``symvi run --plot``, which writes that figure).

Panels against time, each labelled with the model's declared names (the result's
``labels``, from the package's ``INFO``): the base coordinates; per matrix-group factor of
the configuration its world-frame position (the translation of an affine group such as
SE(2), SE(3)) and its attitude (roll, pitch and yaw of a 3 × 3 rotation, the heading of a
2 × 2 one; else the distance ‖g₀⁻¹g − I‖ from the start); the velocities (difference
quotients of the nodes a pair factor's fibres copy, else the fibres ξ); and what judges
the run: the controls (by their declared names, the windows with an active bound marked),
the energy error, the conserved quantities' drift or the Newton iterations.

Legends sit beside the axes, outside the data; tick labels use an offset (``+1.0001``)
as soon as it saves two digits, so that a 0.1 % variation reads as such. matplotlib is
optional: without it :func:`figure` raises ImportError. The figure is made without
pyplot (no backend is chosen or changed, nothing is registered): save it with
``fig.savefig(...)``; a notebook shows it.
"""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np

#: Tick labels switch to an offset when it saves at least this many digits
#: (matplotlib's default, 4, leaves 1.0000, 1.0002, … on a 0.1 % variation).
OFFSET_DIGITS = 2
#: Height of one panel, inches.
PANEL_HEIGHT = 2.2
#: A rotation block whose columns are orthonormal to this accuracy is drawn as angles.
ORTHONORMAL = 1e-6


def figure(result: Any):
    """The figure of ``result`` (a ``StepResult`` or ``BVPResult``): one panel per
    quantity (see the module's docstring), time on the shared x-axis."""
    try:
        import matplotlib
        from matplotlib.figure import Figure
    except ImportError:
        raise ImportError("plot() needs matplotlib: pip install matplotlib "
                          "(or 'symvi[plots]')") from None
    labels = result.labels or {}
    panels = _panels(result, labels)
    with matplotlib.rc_context({"axes.formatter.offset_threshold": OFFSET_DIGITS}):
        fig = Figure(figsize=(8.5, PANEL_HEIGHT * len(panels) + 0.6), layout="constrained")
        axes = np.atleast_1d(fig.subplots(len(panels), 1, sharex=True, squeeze=False)[:, 0])
        for ax, (ylabel, t, values, names, marks) in zip(axes, panels):
            _draw(ax, ylabel, t, values, names, marks)
    axes[-1].set_xlabel("t")
    fig.suptitle(f"{labels.get('model', type(result).__name__)}: {result.status.name}")
    return fig


def _panels(result, labels: dict) -> list[tuple]:
    """(y-label, times, values (T, k), the k names, marks) of each panel, in order."""
    panels = []
    x = result.x
    if x is not None and x.ndim == 2 and x.shape[1]:
        panels.append(("configuration", result.t[:len(x)], x, labels.get("x", ()), None))
    g = result.g
    factors = g if isinstance(g, tuple) else (() if g is None else (g,))
    groups = labels.get("groups", ())
    for i, gi in enumerate(factors):
        label, affine = groups[i] if i < len(groups) else ("g", False)
        panels += _group_panels(result.t[:len(gi)], np.asarray(gi), label, affine)
    if result.f is not None and len(result.f):
        panels.append(_velocities(result, labels))
    panels.append(_judge(result, labels))
    return panels


def _group_panels(t: np.ndarray, g: np.ndarray, label: str, affine: bool) -> list[tuple]:
    """The world-frame position (an affine group's translation g[:-1, -1]) and the
    attitude of one group factor's configurations g (T, d, d)."""
    panels = []
    rotation = g[:, :-1, :-1] if affine else g
    if affine:
        position = g[:, :-1, -1]
        names = ("x", "y", "z")[:position.shape[1]] if position.shape[1] <= 3 else ()
        panels.append((f"position (world, {label})", t, position, names, None))
    angles = _attitude(rotation)
    if angles is not None:
        panels.append((f"attitude ({label}), rad", t, *angles, None))
    else:
        d = g.shape[-1]
        distance = np.linalg.norm(np.linalg.solve(g[0], g) - np.eye(d), axis=(1, 2))
        panels.append((f"configuration ({label})", t, distance[:, None],
                       ("‖g₀⁻¹g − I‖",), None))
    return panels


def _attitude(R: np.ndarray) -> tuple[np.ndarray, tuple[str, ...]] | None:
    """Angles of rotations R (T, k, k), unwrapped in time: the heading of a planar
    rotation, roll, pitch and yaw (Z-Y-X, body to world) of a spatial one; None for
    matrices that are not rotations."""
    k = R.shape[-1]
    if k not in (2, 3) or not len(R) or \
            np.abs(R[0].T @ R[0] - np.eye(k)).max() > ORTHONORMAL:
        return None
    if k == 2:
        return np.unwrap(np.arctan2(R[:, 1, 0], R[:, 0, 0]))[:, None], ("heading",)
    roll = np.arctan2(R[:, 2, 1], R[:, 2, 2])
    pitch = -np.arcsin(np.clip(R[:, 2, 0], -1.0, 1.0))
    yaw = np.arctan2(R[:, 1, 0], R[:, 0, 0])
    return np.unwrap(np.stack([roll, pitch, yaw], axis=1), axis=0), ("roll", "pitch", "yaw")


def _velocities(result, labels: dict) -> tuple:
    """The velocities at the elements' midpoints: per fibre coordinate that copies the
    next node's coordinate j (``labels["fibre_nodes"]``), the difference quotient of x_j;
    an increment (ξ on a group) is the velocity itself."""
    t = result.t
    h = float(t[1] - t[0]) if len(t) > 1 else 1.0
    values = np.array(result.f, dtype=float, copy=True)
    nodes = np.asarray(labels.get("fibre_nodes", ()), dtype=int)
    copies = nodes >= 0 if nodes.size == values.shape[1] else np.zeros(values.shape[1], bool)
    if copies.any() and result.x is not None:
        x = np.asarray(result.x, dtype=float)[:len(values) + 1, nodes[copies]]
        values = values[:len(x) - 1]
        values[:, copies] = (x[1:] - x[:-1]) / h
    return ("velocity", t[:len(values)] + h / 2, values, labels.get("v", ()), None)


def _judge(result, labels: dict) -> tuple:
    """The last panel: controls, energy error, conserved quantities' drift or Newton
    iterations, whichever the result has first."""
    controls = getattr(result, "controls", None)
    energy = getattr(result, "energy", None)
    noether = getattr(result, "noether", None)
    if controls is not None:
        t = result.t_controls
        active = result.active.any(axis=1) if result.active is not None else None
        return ("controls", t, controls, labels.get("controls", ()), active)
    if energy is not None and len(energy):
        return ("E − E₀", result.t[:len(energy)], (energy - energy[0])[:, None], ("E − E₀",),
                None)
    if noether is not None and len(noether):
        names = tuple(f"{s} − {s}(0)" for s in labels.get("symmetries", ()))
        return ("drift", result.t[:len(noether)], noether - noether[0], names, None)
    iterations = getattr(result, "newton_iterations", None)
    if iterations is None:
        iterations = result.residual_norms
        return ("residual norm", np.arange(len(iterations)), iterations[:, None],
                ("‖R‖∞ per iteration",), None)
    return ("Newton iterations", result.t[len(result.t) - len(iterations):],
            np.asarray(iterations, float)[:, None], ("per step",), None)


def _draw(ax, ylabel: str, t: np.ndarray, values: np.ndarray, names: Sequence[str],
          marks: np.ndarray | None) -> None:
    """One panel: a line per column named by ``names`` (else ``ylabel[i]``), the legend
    beside the axes, an offset on the y ticks where it saves digits; ``marks``: where a
    bound is active, marked along the bottom."""
    values = np.asarray(values, dtype=float).reshape(len(values), -1)
    for i in range(values.shape[1]):
        name = names[i] if i < len(names) else f"{ylabel}[{i}]"
        ax.plot(t[:len(values)], values[:, i], label=name)
    if marks is not None and marks.any():
        low = np.nanmin(values) if values.size else 0.0
        ax.plot(t[:len(marks)][marks], np.full(int(marks.sum()), low), "|", color="k",
                label="bound active")
    ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.3)
    ax.ticklabel_format(axis="y", style="sci", scilimits=(-3, 4), useOffset=True)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0,
              fontsize="small", frameon=False)
