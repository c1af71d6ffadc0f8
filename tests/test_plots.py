"""Issue 53, plots: ``res.plot()`` returns a matplotlib Figure, read back here — its
curves named by the declared symbols (controls by their declared names), a world-frame
position and an attitude panel for group configurations, legends beside the axes, an
offset on the ticks of a 0.1 % variation; ``symvi run --plot`` writes that figure.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from symvi.cli import main
from symvi.models import get

pytest.importorskip("matplotlib")
from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: E402


def _curves(fig) -> dict[str, list[str]]:
    """Per panel (its y-label), the names of its curves."""
    return {ax.get_ylabel(): [line.get_label() for line in ax.get_lines()]
            for ax in fig.axes}


def test_a_pair_groupoid_plot_names_the_declared_symbols(compiled):
    pendulum = compiled("double_pendulum")
    ex = get("double_pendulum").example
    res = pendulum.integrate(ex.run_from, 200, ex.h)
    fig = res.plot()
    assert type(fig).__name__ == "Figure"
    x, v = pendulum.INFO.coordinate_names, pendulum.INFO.velocity_names
    curves = _curves(fig)
    assert curves["configuration"] == list(x) and curves["velocity"] == list(v)
    assert "E − E₀" in curves and fig.axes[-1].get_xlabel() == "t"
    assert x == ("theta1", "theta2") and v == ("theta1_dot", "theta2_dot")


def test_controls_are_labelled_with_their_declared_names(compiled):
    oc = compiled("rigid_body_oc")
    ex = get("rigid_body_oc").example
    res = oc.solve_bvp(ex.start, ex.end, 60, T=1.0)
    curves = _curves(res.plot())
    assert curves["controls"] == ["tau1", "tau2", "tau3"]
    assert curves["velocity"] == ["Omega1", "Omega2", "Omega3"]
    assert curves["attitude (SO3), rad"] == ["roll", "pitch", "yaw"]
    assert not any(name.startswith("position") for name in curves)     # SO(3): no position


def test_a_group_model_has_world_position_and_attitude_panels(compiled):
    """SE(2): the world position is g's translation, the attitude its heading; SE(3)
    (``se3_snap``) the same in space, roll, pitch and yaw, not body-frame quantities."""
    planar = compiled("planar_body")
    ex = get("planar_body").example
    res = planar.integrate(ex.run_from, 100, ex.h)
    fig = res.plot()
    curves = _curves(fig)
    assert curves["position (world, SE2)"] == ["x", "y"]
    assert curves["attitude (SE2), rad"] == ["heading"]
    position = next(ax for ax in fig.axes if ax.get_ylabel().startswith("position"))
    np.testing.assert_allclose(position.get_lines()[0].get_ydata(), res.g[:, 0, 2])
    heading = next(ax for ax in fig.axes if ax.get_ylabel().startswith("attitude"))
    np.testing.assert_allclose(np.cos(heading.get_lines()[0].get_ydata()), res.g[:, 0, 0],
                               atol=1e-12)
    snap, ex = compiled("se3_snap"), get("se3_snap").example
    curves = _curves(snap.integrate(ex.run_from, 40, ex.h).plot())
    assert curves["position (world, SE3)"] == ["x", "y", "z"]
    assert curves["attitude (SE3), rad"] == ["roll", "pitch", "yaw"]


def test_legends_sit_outside_the_data_and_small_variations_take_an_offset(compiled):
    pendulum = compiled("pendulum")
    res = pendulum.integrate(pendulum.State(x=[1.0], v=[0.0]), 300, 0.01)
    # a coordinate varying by 0.1 % about 1: its ticks must read as an offset
    x = 1.0 + 1e-3 * np.sin(res.t)[:, None]
    fig = dataclasses.replace(res, x=x).plot()
    FigureCanvasAgg(fig).draw()
    for ax in fig.axes:
        legend = ax.get_legend()
        assert legend is not None
        assert legend.get_window_extent().x0 >= ax.get_window_extent().x1
    configuration = next(ax for ax in fig.axes if ax.get_ylabel() == "configuration")
    assert configuration.yaxis.get_major_formatter().get_offset() != ""


def test_batches_plot_one_member_at_a_time(compiled):
    pendulum = compiled("pendulum")
    batch = pendulum.integrate_many(pendulum.State(x=[[1.0], [0.5]], v=[[0.0], [0.0]]),
                                    20, 0.01)
    with pytest.raises(TypeError, match=r"result\[b\]\.plot\(\)"):
        batch.plot()
    assert _curves(batch[1].plot())["configuration"] == ["theta"]


def test_the_cli_plot_writes_the_results_figure(compiled, build_dir, tmp_path, capsys):
    """``symvi run --plot`` goes through ``result.plot()``: the image has the figure's
    size (three panels of the planar body and the energy: four)."""
    compiled("planar_body")
    png = tmp_path / "p.png"
    code = main(["run", "planar_body", "--build-dir", str(build_dir), "--steps", "50",
                 "--plot", str(png)])
    assert code == 0 and f"plot       {png}" in capsys.readouterr().out
    import matplotlib.image
    image = matplotlib.image.imread(png)
    assert image.shape[0] > image.shape[1]          # four panels stacked: taller than wide
