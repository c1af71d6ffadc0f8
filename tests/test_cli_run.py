"""``symvi run`` and the generated packages as a new user meets them (issue 22, items 3, 4
and 6): every option of the generated functions in their signatures and help, every flag
of ``symvi run`` documented, ``--param``, ``--output`` and ``--plot``, and an
optimal-control example that keeps its horizon when ``--steps`` changes.
"""
from __future__ import annotations

import inspect
import pydoc
import re

import numpy as np
import pytest

from symvi._runtime.step.batch import integrate_many
from symvi._runtime.bvp.bvp import solve_bvp
from symvi._runtime.bvp.bvp_batch import continuation, solve_bvp_many
from symvi._runtime.step.stepping import integrate
from symvi.cli import main, parser
from symvi.models import get

PUBLIC = ("integrate", "integrate_many", "solve_bvp", "solve_bvp_many", "continuation",
          "evaluate", "momenta", "noether")


@pytest.fixture(scope="module")
def pendulum(compiled):
    return compiled("pendulum")


@pytest.mark.parametrize("name", ["pendulum", "rigid_body_oc"])
def test_generated_functions_name_every_option(compiled, name):
    """``inspect.signature`` of each public function of a generated package lists the
    runtime function's every parameter (the model bound), with its default, and the
    ``help()`` text names each of them."""
    module = compiled(name)
    runtime = {"integrate": integrate, "integrate_many": integrate_many, "solve_bvp": solve_bvp,
               "solve_bvp_many": solve_bvp_many, "continuation": continuation}
    for public in PUBLIC:
        function = getattr(module, public)
        parameters = inspect.signature(function).parameters
        if public in runtime:
            expected = list(inspect.signature(runtime[public]).parameters.values())[1:]
            assert list(parameters.values()) == expected, public
        doc = inspect.getdoc(function)
        assert doc.splitlines()[0] in pydoc.render_doc(function, renderer=pydoc.plaintext)
        for parameter in parameters:       # in the docstring, not only in the signature
            assert re.search(rf"(?<![\w_]){parameter}(?![\w_])", doc), (public, parameter)
    assert inspect.signature(module.integrate).parameters["xtol"].default == 1e-12
    assert inspect.signature(module.solve_bvp).parameters["maxiter"].default == 100


def test_every_flag_of_symvi_run_is_documented():
    run = parser()._subparsers._group_actions[0].choices["run"]
    for action in run._actions:
        assert action.help, action.dest
    text = run.format_help()
    for flag in ("--param", "--steps", "--h", "--output", "--plot", "--build-dir",
                 "--keep-every"):
        assert flag in text


def test_run_with_a_parameter_writes_the_result_and_a_plot(pendulum, build_dir, tmp_path,
                                                          capsys):
    """``symvi run pendulum --param l=2 --output r.npz --plot r.png``: the archive holds the
    result's arrays, equal to those of ``integrate`` with l = 2 called directly (and not to
    those with the default l = 1); the image is a real plot."""
    npz, png = tmp_path / "r.npz", tmp_path / "r.png"
    code = main(["run", "pendulum", "--build-dir", str(build_dir), "--param", "l=2",
                 "--steps", "2000", "--output", str(npz), "--plot", str(png)])
    out = capsys.readouterr().out
    assert code == 0 and "params     l = 2" in out
    ex = get("pendulum").example
    direct = pendulum.integrate(ex.run_from, 2000, ex.h, params={"l": 2.0})
    default = pendulum.integrate(ex.run_from, 2000, ex.h)
    saved = np.load(npz)
    assert str(saved["status"]) == "SUCCESS" and str(saved["message"]) == direct.message
    for field in ("t", "x", "f", "newton_iterations", "momenta", "energy"):
        np.testing.assert_array_equal(saved[field], getattr(direct, field), err_msg=field)
    assert not np.array_equal(saved["x"], default.x)
    plt = pytest.importorskip("matplotlib.pyplot")
    image = plt.imread(png)
    assert image.shape[0] >= 600 and image.shape[1] >= 600
    ink = (image[..., :3] < 0.5).any(axis=-1).mean()
    assert 0.01 < ink < 0.5, ink          # lines and text, not a blank or filled canvas


def test_an_optimal_control_run_keeps_its_horizon_when_the_steps_change(build_dir,
                                                                        tmp_path, capsys):
    """``symvi run rigid_body_oc --steps 200`` solves on the example's horizon T = 1 (h =
    1/200), not on 200 of the example's steps; the archive has the controls, the cost and
    the status."""
    npz = tmp_path / "oc.npz"
    code = main(["run", "rigid_body_oc", "--build-dir", str(build_dir), "--steps", "200",
                 "--output", str(npz)])
    out = capsys.readouterr().out
    assert code == 0 and "N = 200, h = 0.005, T = 1:" in out, out
    saved = np.load(npz)
    assert saved["t"][-1] == pytest.approx(1.0, abs=1e-12) and saved["t"].size == 201
    assert saved["controls"].shape == (199, 3) and np.isfinite(saved["cost"])
    assert str(saved["status"]) == "SUCCESS"


@pytest.mark.parametrize("argument, message", [
    ("length=2", "model 'pendulum' has no parameter 'length'; its parameters: ['m', 'l', 'g']"),
    ("l=two", "--param l: expected a finite number, got 'two'"),
    ("l=nan", "--param l: expected a finite number, got 'nan'"),
    ("l", "--param expects NAME=VALUE, got 'l'"),
])
def test_a_bad_parameter_is_refused_before_anything_runs(argument, message, build_dir,
                                                        capsys):
    code = main(["run", "pendulum", "--build-dir", str(build_dir), "--param", argument])
    captured = capsys.readouterr()
    assert code == 2 and message in captured.err and "integrate" not in captured.out


def test_solve_bvp_takes_the_step_or_the_horizon(compiled):
    """Item 4: ``solve_bvp(start, end, N, T=...)`` is the solve at h = T/N, to the bit;
    giving both or neither is refused."""
    module = compiled("rigid_body_oc")
    ex = get("rigid_body_oc").example
    by_step = module.solve_bvp(ex.start, ex.end, 200, 1.0 / 200)
    by_horizon = module.solve_bvp(ex.start, ex.end, 200, T=1.0)
    assert by_horizon.success and by_horizon.T == pytest.approx(1.0, abs=1e-14)
    np.testing.assert_array_equal(by_horizon.f, by_step.f)
    assert by_horizon.cost == by_step.cost
    with pytest.raises(ValueError, match="give the step h or the horizon T .*not both"):
        module.solve_bvp(ex.start, ex.end, 200, 0.005, T=1.0)
    with pytest.raises(ValueError, match="not neither"):
        module.solve_bvp(ex.start, ex.end, 200)
    with pytest.raises(ValueError, match="the horizon T must be a positive"):
        module.solve_bvp(ex.start, ex.end, 200, T=-1.0)


def test_a_free_horizon_and_end_conditions_are_reported_as_solved(build_dir, tmp_path, capsys):
    """The solve_bvp line states the optimal T and h of a free horizon, not the guess; a
    run with end conditions prints ν and its archive holds them."""
    code = main(["run", "minimum_time_slew", "--build-dir", str(build_dir), "--steps", "60"])
    out = capsys.readouterr().out
    T = float(out.split("horizon    T = ")[1].split()[0])
    guess = float(out.split("from the guess ")[1].split(";")[0])
    assert code == 0 and f"T = {T:g} (free):" in out and abs(T - guess) > 1e-3, out
    npz = tmp_path / "catch.npz"
    code = main(["run", "cart_pole_catch", "--build-dir", str(build_dir), "--steps", "60",
                 "--output", str(npz)])
    out = capsys.readouterr().out
    assert code == 0 and "for upright, pole at rest, cart at rest" in out, out
    assert np.load(npz)["end_multipliers"].shape == (3,)


def test_compile_profile_says_where_the_time_went(tmp_path, capsys):
    """``symvi compile --profile --quiet`` (issue 23, item 4): the build's own functions by
    cumulative time on stderr — the stages among them (emission and the C compile: the
    derivation may be a memo hit in a test process) — and no progress lines."""
    code = main(["compile", "pendulum", "-o", str(tmp_path), "--force", "--profile",
                 "--quiet"])
    captured = capsys.readouterr()
    assert code == 0 and "ready in" in captured.out
    for stage in ("compile_model", "emit", "compile_extension", "cumulative"):
        assert stage in captured.err, stage
    assert "is running" not in captured.err and "took" not in captured.err
    compile_parser = parser()._subparsers._group_actions[0].choices["compile"]
    assert all(action.help for action in compile_parser._actions)
