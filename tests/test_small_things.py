"""Issue 53, item 6: the small things a new user met, one test each — a status prints as
its name, ``INFO.defaults`` is a mapping, a pair-groupoid result prints its final node
and velocity (not the node twice), the README's model file and Dask snippet run as
written, and a long single call says how far it has come on stderr.
"""
from __future__ import annotations

import importlib
import io
import pickle
import re
from pathlib import Path

import numpy as np
import pytest

from symvi._runtime.core.results import Status
from symvi._runtime.core import progress
from symvi._runtime.core.model_info import VERSION, ModelInfo, ModelInfoError
from symvi.cli import _load, _warn_if_shadowed
from symvi.models import get

README = (Path(__file__).resolve().parent.parent / "README.md").read_text(encoding="utf-8")


def _python_blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", README, flags=re.S)


def test_a_status_prints_as_its_name_and_stays_an_int():
    """``str(res.status)`` was ``'0'`` (IntEnum since Python 3.11): every Status prints
    as its name, in f-strings too, and still compares, formats and pickles as its int."""
    for status in Status:
        assert str(status) == status.name == f"{status}" == f"{status:>0}".strip()
        assert status == int(status) and f"{status:d}" == str(int(status))
        assert pickle.loads(pickle.dumps(status)) is status
    assert f"{Status.SADDLE:>8}" == "  SADDLE"


def test_info_defaults_is_a_mapping_of_the_parameters(compiled):
    """``INFO.defaults`` maps each parameter's name to its default, in the parameter
    vector's order; the literal carries it as a dict, a list is refused at load."""
    info = compiled("pendulum").INFO
    assert info.defaults == {"m": 1.0, "l": 1.0, "g": 9.81}
    assert tuple(info.defaults) == info.parameters and info.defaults["l"] == 1.0
    assert hash(info) == hash(ModelInfo.from_literal(info.to_literal()))
    literal = info.to_literal()
    assert literal["version"] == VERSION and literal["defaults"] == {"m": 1.0, "l": 1.0,
                                                                     "g": 9.81}
    with pytest.raises(ModelInfoError, match="not a mapping"):
        ModelInfo.from_literal(literal | {"defaults": [1.0, 1.0, 9.81]})
    with pytest.raises(ModelInfoError, match="not the parameters"):
        ModelInfo.from_literal(literal | {"defaults": {"m": 1.0, "g": 9.81, "l": 1.0}})


def test_a_pair_groupoid_result_prints_its_velocity_not_the_node_twice(compiled):
    """On a pair groupoid f_k is the next node q_{k+1}: the summary shows the final node
    and the last element's velocity (q_N − q_{N−1})/h; on a group the fibres ξ as before."""
    pendulum = compiled("pendulum")
    res = pendulum.integrate(pendulum.State(x=[1.0], v=[0.0]), 100, 0.01)
    text = repr(res)
    assert "f = " not in text and "x = " in text and "v = " in text
    velocity = (res.x[-1] - res.x[-2]) / 0.01
    assert f"v = [{velocity[0]:.6f}]" in text, text
    rigid = compiled("rigid_body")
    group = rigid.integrate(rigid.State(v=[1.0, 0.1, 0.0]), 10, 0.01)
    assert "f = " in repr(group) and "v = " not in repr(group)


def test_the_readme_model_file_compiles_without_the_shadowing_warning(tmp_path, capsys):
    """The README's declaration, saved under the name its first line gives, loads as the
    command line loads it and draws no 'named like its model' warning."""
    block = next(b for b in _python_blocks() if "Model(" in b and "PairGroupoid" in b)
    name = re.match(r"# (\w+\.py)", block).group(1)
    path = tmp_path / name
    path.write_text(block, encoding="utf-8")
    model = _load(str(path))
    _warn_if_shadowed(str(path), model.name)
    err = capsys.readouterr().err
    assert model.name == "pendulum" and "named like its model" not in err, err
    _warn_if_shadowed(str(tmp_path / "pendulum.py"), model.name)
    assert "named like its model" in capsys.readouterr().err


def test_the_readme_dask_snippet_starts_its_cluster_under_a_main_guard():
    """Dask's worker processes import the script that started them: the README's Dask
    snippet creates its cluster and client only under ``if __name__ == "__main__":``."""
    block = next(b for b in _python_blocks() if "symvi.dask.integrate_many(" in b)
    compile(block, "snippet.py", "exec")
    lines = block.splitlines()
    guard = next(i for i, line in enumerate(lines)
                 if line.startswith('if __name__ == "__main__":'))
    starts = [i for i, line in enumerate(lines) if "Client(" in line or "Cluster(" in line]
    assert starts and all(i > guard and lines[i].startswith("    ") for i in starts)


def _package_progress(model):
    """The progress module of ``model``'s package (each package has its own copy)."""
    package = type(model.integrate.__self__).__module__.rsplit("._runtime", 1)[0]
    return importlib.import_module(f"{package}._runtime.core.progress")


def test_a_long_integrate_shows_a_progress_line_and_erases_it(compiled, monkeypatch,
                                                              capsys):
    """``integrate(..., progress=True)`` past the delay writes one line rewritten in place
    (``\\r``) with the steps done, erased at the end; by default stderr is not a
    terminal here, so nothing is written; the path is the same either way."""
    pendulum = compiled("pendulum")
    monkeypatch.setattr(_package_progress(pendulum), "DELAY", 0.0)
    monkeypatch.setattr(_package_progress(pendulum), "INTERVAL", 0.0)
    start = pendulum.State(x=[1.0], v=[0.0])
    shown = pendulum.integrate(start, 100_000, 0.01, progress=True, quantities=False)
    err = capsys.readouterr().err
    assert "symvi: integrate pendulum: step " in err and " of 99,999 (" in err, err
    assert err.endswith("\r") and err.split("\r")[-2].strip() == ""      # erased
    quiet = pendulum.integrate(start, 100_000, 0.01, quantities=False)
    assert capsys.readouterr().err == ""
    np.testing.assert_array_equal(shown.x, quiet.x)
    with pytest.raises(ValueError, match="progress must be True, False or None"):
        pendulum.integrate(start, 10, 0.01, progress="yes")


def test_a_solve_bvp_shows_its_iterations_on_the_progress_line(compiled, monkeypatch,
                                                              capsys):
    """``solve_bvp(..., progress=True)`` past the delay names the phase, the iteration and
    its correction; a batch's solves show none (their bar is the batch's)."""
    oc = compiled("rigid_body_oc")
    monkeypatch.setattr(_package_progress(oc), "DELAY", 0.0)
    monkeypatch.setattr(_package_progress(oc), "INTERVAL", 0.0)
    ex = get("rigid_body_oc").example
    res = oc.solve_bvp(ex.start, ex.end, 100, T=1.0, progress=True)
    err = capsys.readouterr().err
    assert res.success and "symvi: solve_bvp rigid_body_oc: " in err, err
    assert re.search(r"Newton, iteration \d+, correction", err), err
    oc.solve_bvp_many([ex.start] * 2, [ex.end] * 2, 100, T=1.0, progress=False)
    assert "symvi:" not in capsys.readouterr().err


def test_the_progress_line_waits_for_its_delay_and_follows_the_terminal(monkeypatch):
    """Below the delay nothing is written; None follows whether stderr is a terminal."""
    stream = io.StringIO()
    monkeypatch.setattr("sys.stderr", stream)
    with progress.ProgressLine("integrate m", True, delay=60.0) as line:
        line.update(lambda: "never asked")
    assert stream.getvalue() == ""
    assert progress.ProgressLine("m", None).on is False     # a StringIO is no terminal
    monkeypatch.setattr(stream, "isatty", lambda: True, raising=False)
    assert progress.ProgressLine("m", None).on is True
