"""``symvi sweep`` and progress bars (issue 24, item 4).

The sweep's archive is checked against the single calls it stands for — each trajectory
the single ``integrate`` at its step bit for bit, each energy error recomputed from it,
each optimal cost the single ``solve_bvp``'s — and its fitted order of the midpoint
rule's energy error against the theory (2); a sweep over steps too large for Newton's
method keeps its failures apart and exits 1; bad sweeps are refused before anything runs.
"""
from __future__ import annotations

import sys

import numpy as np
import pytest

from symvi.cli import main, parser
from symvi.models import get


@pytest.fixture(scope="module")
def pendulum(compiled):
    return compiled("pendulum")


def _sweep(build_dir, *arguments) -> int:
    return main(["sweep", *arguments, "--build-dir", str(build_dir), "--quiet"])


def test_a_step_sweep_is_the_single_runs_and_measures_the_order_of_the_energy_error(
        pendulum, build_dir, tmp_path, capsys):
    npz, png = tmp_path / "s.npz", tmp_path / "s.png"
    code = _sweep(build_dir, "pendulum", "--h", "0.002:0.05:6", "--spacing", "log",
                  "--steps", "3000", "-o", str(npz), "--plot", str(png))
    out = capsys.readouterr().out
    assert code == 0, out
    saved = np.load(npz)
    steps = np.geomspace(0.002, 0.05, 6)
    np.testing.assert_array_equal(saved["values"], steps)
    assert str(saved["swept"]) == "h" and (saved["statuses"] == "SUCCESS").all()
    errors = []
    for b, h in enumerate(steps):
        single = pendulum.integrate(get("pendulum").example.run_from, 3000, h)
        np.testing.assert_array_equal(saved["x"][b], single.x)
        np.testing.assert_array_equal(saved["energy"][b], single.energy)
        errors.append(np.abs(single.energy - single.energy[0]).max())
    np.testing.assert_array_equal(saved["measure"], errors)
    # the midpoint rule's energy error is O(h²): the fitted exponent, and the printed one
    order = np.polyfit(np.log(steps), np.log(errors), 1)[0]
    assert 1.9 < order < 2.1, order
    assert f"∝ h^{order:.2f}" in out
    _assert_a_real_plot(png)


def test_a_sweep_keeps_the_runs_that_fail_apart_and_exits_1(pendulum, build_dir, tmp_path,
                                                            capsys):
    npz = tmp_path / "f.npz"
    code = _sweep(build_dir, "pendulum", "--h", "0.1:4:8", "--steps", "200", "-o", str(npz))
    out = capsys.readouterr().out
    saved = np.load(npz)
    failed = saved["statuses"] != "SUCCESS"
    assert code == 1 and failed.any() and (~failed).any(), out
    for b, h in enumerate(np.linspace(0.1, 4, 8)):
        single = pendulum.integrate(get("pendulum").example.run_from, 200, h)
        assert str(saved["statuses"][b]) == single.status.name
        assert str(saved["messages"][b]) == single.message
        n = saved["lengths_x"][b]
        np.testing.assert_array_equal(saved["x"][b, :n], single.x)
        assert np.isnan(saved["x"][b, n:]).all()
    assert f"{(~failed).sum()} of 8 trajectories succeeded" in out


def test_an_optimal_control_sweep_is_the_single_solves(compiled, build_dir, tmp_path,
                                                      capsys):
    """A continuation over the inertia I1 of the rigid-body slew: each cost equals the
    cold single solve's (the same minimum, reached from the previous solution)."""
    module, npz = compiled("rigid_body_oc"), tmp_path / "oc.npz"
    code = _sweep(build_dir, "rigid_body_oc", "--param", "I1=0.5:1.5:3", "--param",
                  "I3=2.5", "--steps", "60", "-o", str(npz))
    assert code == 0, capsys.readouterr()
    saved = np.load(npz)
    ex = get("rigid_body_oc").example
    for b, inertia in enumerate([0.5, 1.0, 1.5]):
        single = module.solve_bvp(ex.start, ex.end, 60, 1 / 60, {"I1": inertia, "I3": 2.5})
        assert single.success
        assert saved["cost"][b] == pytest.approx(single.cost, rel=1e-9)
        np.testing.assert_allclose(saved["controls"][b], single.controls, atol=1e-7)
    assert np.all(np.diff(saved["cost"]) != 0)     # the parameter did reach the solves


@pytest.mark.parametrize("arguments, message", [
    (["pendulum", "--param", "m=1:2:3", "--h", "0.1:0.2:3"], "sweep one quantity"),
    (["pendulum", "--param", "m=1:2:3", "--param", "l=1:2:3"], "sweep one quantity"),
    (["pendulum", "--param", "m=1:2:1"], "must be an integer ≥ 2, got '1'"),
    (["pendulum", "--param", "m=1:2"], "expected start:stop:count, got '1:2'"),
    (["pendulum", "--param", "m=-1:2:3", "--spacing", "log"], "positive end points"),
    (["pendulum", "--param", "mass=1:2:3"], "has no parameter 'mass'"),
    (["rigid_body_oc", "--h", "0.01:0.02:3"], "an optimal-control sweep varies a parameter"),
])
def test_a_bad_sweep_is_refused_before_anything_runs(arguments, message, build_dir,
                                                    tmp_path, capsys):
    npz = tmp_path / "bad.npz"
    code = _sweep(build_dir, *arguments, "-o", str(npz))
    captured = capsys.readouterr()
    assert code == 2 and message in captured.err, captured.err
    assert not npz.exists() and "sweep " not in captured.out


def test_every_flag_of_symvi_sweep_is_documented():
    sweep = parser()._subparsers._group_actions[0].choices["sweep"]
    assert all(action.help for action in sweep._actions)


def test_a_progress_bar_counts_the_batch_and_can_be_switched_off(pendulum, capsys,
                                                                 monkeypatch):
    start = pendulum.State(x=np.ones((5, 1)), v=np.zeros((5, 1)))
    pendulum.integrate_many(start, 50, 0.01, progress=True, workers=2)
    assert "5/5" in capsys.readouterr().err
    pendulum.integrate_many(start, 50, 0.01, progress=False)
    assert capsys.readouterr().err == ""
    with pytest.raises(ValueError, match="progress must be True, False or None"):
        pendulum.integrate_many(start, 50, 0.01, progress="yes")
    monkeypatch.setitem(sys.modules, "tqdm.auto", None)       # tqdm not installed
    with pytest.raises(ValueError, match=r"progress=True needs tqdm \(pip install tqdm\)"):
        pendulum.integrate_many(start, 50, 0.01, progress=True)
    assert pendulum.integrate_many(start, 50, 0.01).success    # None: quietly without


def _assert_a_real_plot(png) -> None:
    plt = pytest.importorskip("matplotlib.pyplot")
    image = plt.imread(png)
    ink = (image[..., :3] < 0.5).any(axis=-1).mean()
    assert image.shape[0] >= 400 and 0.005 < ink < 0.5, ink
