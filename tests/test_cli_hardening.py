"""The command line checks every argument before the work starts (issue 48, finding 4).

Each bad argument of ``symvi run``, ``symvi sweep`` and ``symvi check`` exits 2 with one
line on stderr in argparse's words (``symvi run: error: ...``) and no traceback, before
anything is compiled: the build folder of each case is a fresh one and must not exist
afterwards. ``--plot`` replaces an existing symlink as ``--output`` does, and a model
file imports the modules beside it, as ``python model.py`` would.
"""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

from symvi.cli import main


def _refused(capsys, command: str, argv: list[str], build: Path) -> str:
    """Run ``symvi`` on ``argv``; assert exit 2 with one ``symvi <command>: error:`` line
    and no build folder; return that line."""
    code = main(argv)
    captured = capsys.readouterr()
    assert not build.exists(), f"compiled before refusing: {captured.err}"
    lines = captured.err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and captured.out == "", captured
    assert lines[0].startswith(f"symvi {command}: error: "), lines[0]
    return lines[0]


@pytest.mark.parametrize("argv, message", [
    (["run", "rigid_body_oc", "--steps", "0"], "--steps must be an integer ≥ 1, got 0"),
    (["sweep", "rigid_body_oc", "--param", "I1=0.5:1.5:3", "--steps", "0"],
     "--steps must be an integer ≥ 1, got 0"),
    (["run", "rigid_body_oc", "--steps", "3"], "--steps must be an integer ≥ 4 (2 fixed "
                                               "nodes at each end of an order-2 problem"),
    (["run", "cubic_spline", "--steps", "2"], "--steps must be an integer ≥ 3"),
    (["run", "pendulum", "--h", "-0.1"], "--h must be a positive, finite time step, got -0.1"),
    (["run", "pendulum", "--h", "nan"], "--h must be a positive, finite time step, got nan"),
    (["run", "pendulum", "--keep-every", "0"], "--keep-every must be an integer ≥ 1, got 0"),
    (["run", "pendulum", "--param", "m=-1"], "--param m: parameter m is declared positive"),
    (["sweep", "pendulum", "--h", "0:0.1:3"], "--h must be a positive, finite time step"),
    (["sweep", "pendulum", "--param", "l=1:2:3", "--workers", "0"],
     "--workers must be an integer ≥ 1, got 0"),
])
def test_numbers_are_refused_before_the_build(argv, message, tmp_path, capsys):
    """``--steps 0`` on an optimal-control example was a ZeroDivisionError traceback
    after the build; every number is now checked against what the command needs (the
    run time's fewest steps of the model's order) before it."""
    build = tmp_path / "generated"
    line = _refused(capsys, argv[0], argv + ["--build-dir", str(build)], build)
    assert message in line


@pytest.mark.parametrize("command", ["run", "sweep"])
@pytest.mark.parametrize("flag, name, message", [
    ("--output", "missing/r.npz", "the folder 'missing' does not exist"),
    ("--output", "r.txt", "give a file name ending in .npz"),
    ("--output", "folder", "'folder' is a directory: give a file name, e.g. "
                           "'folder/result.npz'"),
    ("--plot", "missing/r.png", "the folder 'missing' does not exist"),
    ("--plot", "r.npz", "give a file name ending in .png, .pdf, .svg"),
    ("--plot", "r", "give a file name ending in .png"),
    ("--plot", "folder", "'folder' is a directory"),
])
def test_output_files_are_refused_before_the_build(command, flag, name, message, tmp_path,
                                                  monkeypatch, capsys):
    """A file ``--output`` or ``--plot`` could not write was found only after the whole
    run (exit 1, the work lost; a directory a raw "[Errno 21] Is a directory")."""
    pytest.importorskip("matplotlib")
    monkeypatch.chdir(tmp_path)
    (tmp_path / "folder").mkdir()
    build = tmp_path / "generated"
    sweep = ["--param", "l=1:2:3"] if command == "sweep" else []
    line = _refused(capsys, command, [command, "pendulum", "--steps", "10", *sweep, flag,
                                      name, "--build-dir", str(build)], build)
    assert f"{flag} '{name}'" in line and message in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["folder"]


def test_the_default_sweep_archive_is_checked_too(tmp_path, monkeypatch, capsys):
    """``symvi sweep`` writes MODEL_sweep.npz by default: a folder of that name is found
    before the sweep, not after it."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "pendulum_sweep.npz").mkdir()
    build = tmp_path / "generated"
    line = _refused(capsys, "sweep", ["sweep", "pendulum", "--param", "l=1:2:3",
                                      "--build-dir", str(build)], build)
    assert "--output 'pendulum_sweep.npz' is a directory" in line


@pytest.mark.parametrize("only", [",,", "", " , ", "routes,bogus"])
def test_check_only_names_at_least_one_known_check(only, capsys):
    """``symvi check --only ,,`` ran 0 checks and exited 0: no names, or a name that is
    not a check, is refused with the list of checks, before the model is loaded."""
    code = main(["check", "pendulum", "--only", only])
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and captured.out == "", captured
    assert lines[0].startswith("symvi check: error: --only")
    assert lines[0].endswith("checks: algebroid, routes, consistency, regularity, noether, "
                             "structure, equations")


def test_plot_replaces_a_symlink_as_output_does(compiled, build_dir, tmp_path, capsys):
    """``--output`` renames its archive over an existing symlink; ``--plot`` wrote through
    it, into the file the link points to. Both now replace the link and leave its target
    untouched."""
    pytest.importorskip("matplotlib")
    compiled("pendulum")
    targets = {suffix: tmp_path / f"elsewhere{suffix}" for suffix in (".npz", ".png")}
    for suffix, target in targets.items():
        target.write_text("the user's file")
        (tmp_path / f"link{suffix}").symlink_to(target)
    code = main(["run", "pendulum", "--build-dir", str(build_dir), "--steps", "50",
                 "--output", str(tmp_path / "link.npz"), "--plot", str(tmp_path / "link.png")])
    assert code == 0, capsys.readouterr()
    for suffix, target in targets.items():
        link = tmp_path / f"link{suffix}"
        assert not link.is_symlink() and link.stat().st_size > 1000, suffix
        assert target.read_text() == "the user's file", suffix


SPRING = """\
import sympy as sp
import symvi
from spring_constants_48 import STIFFNESS

G = symvi.PairGroupoid("x")
k = sp.Symbol("k", positive=True)
model = symvi.Model("spring_48", G, lagrangian=G.qdot[0] ** 2 / 2 - k * G.q[0] ** 2 / 2,
                    parameters={k: STIFFNESS})
"""


def test_a_model_file_imports_the_module_beside_it(tmp_path, capsys):
    """A model file in a folder could not import its sibling module under the CLI (its
    folder was not on ``sys.path``, as it is for ``python model.py``); the folder is
    first on ``sys.path`` while the file runs, and taken off again."""
    folder = tmp_path / "models"
    folder.mkdir()
    (folder / "spring_constants_48.py").write_text("STIFFNESS = 2.5\n")
    (folder / "spring.py").write_text(SPRING)
    path = list(sys.path)
    try:
        code = main(["check", str(folder / "spring.py"), "--only", "algebroid"])
        captured = capsys.readouterr()
        assert code == 0 and "PASS  algebroid" in captured.out, captured
        assert sys.modules["spring_constants_48"].STIFFNESS == 2.5
    finally:
        sys.modules.pop("spring_constants_48", None)
    assert sys.path == path
