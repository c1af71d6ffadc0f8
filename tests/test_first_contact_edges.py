"""The smaller edges a new user met (issue 22, item 7): a model file with a syntax error
or an exception, a model file named like its model, ``symvi list`` on a narrow terminal,
a parameter value against its symbol's sign, and a README that stands on its own.
"""
from __future__ import annotations

import textwrap
from pathlib import Path

import pytest
import sympy as sp

from symvi import Model, ModelError, PairGroupoid
from symvi.cli import main
from symvi.models import BUNDLED, get

GOOD = """\
import sympy as sp
from symvi import Model, PairGroupoid
G = PairGroupoid("x")
(x,), (v,) = G.q, G.qdot
model = Model("{name}", G, lagrangian=v**2 / 2 - x**2 / 2)
"""


@pytest.mark.parametrize("body, message", [
    ("model = Model(\n    'bad' G)\n", "syntax error at line 2"),
    ("from symvi import Model\nmodel = Model('bad', G, lagrangian=x)\n",
     "raised NameError at line 2: name 'G' is not defined"),
])
def test_a_broken_model_file_is_one_line_naming_the_line(tmp_path, capsys, body, message):
    path = tmp_path / "broken.py"
    path.write_text(body)
    code = main(["compile", str(path), "-o", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and message in err and "broken.py" in err, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_a_model_file_named_like_its_model_is_warned_about(tmp_path, capsys):
    path = tmp_path / "spring.py"
    path.write_text(GOOD.format(name="spring"))
    assert main(["compile", str(path), "-o", str(tmp_path / "out")]) == 0
    err = capsys.readouterr().err
    assert "warning: the model file spring.py is named like its model 'spring'" in err
    assert "spring_model.py" in err
    other = tmp_path / "spring_model.py"
    other.write_text(GOOD.format(name="spring"))
    assert main(["compile", str(other), "-o", str(tmp_path / "out")]) == 0
    assert "warning" not in capsys.readouterr().err


def test_symvi_list_fits_the_terminal(monkeypatch, capsys):
    monkeypatch.setenv("COLUMNS", "80")
    assert main(["list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert max(len(line) for line in lines) <= 80
    starts = [line.split()[0] for line in lines if not line.startswith(" ")]
    assert starts == list(BUNDLED)
    width = max(len(name) for name in BUNDLED) + 2
    assert all(line[width - 1] == " " for line in lines)       # one column for the text


def test_a_parameter_value_must_have_its_symbols_sign(compiled):
    """The pendulum's m, l, g are declared positive: a negative mass or a zero length is
    refused by name, before anything runs; a default of the wrong sign is refused when
    the model is declared."""
    pendulum = compiled("pendulum")
    ex = get("pendulum").example
    with pytest.raises(ValueError, match=r"parameter m is declared positive .*> 0, got -1"):
        pendulum.integrate(ex.initial, 10, ex.h, params={"m": -1.0})
    with pytest.raises(ValueError, match=r"parameter l is declared positive .*got 0"):
        pendulum.integrate(ex.initial, 10, ex.h, params={"l": 0.0})
    assert pendulum.integrate(ex.initial, 10, ex.h, params={"m": 2.0}).success
    G = PairGroupoid("x")
    (x,), (v,) = G.q, G.qdot
    k = sp.Symbol("k", nonnegative=True)
    with pytest.raises(ModelError, match="parameter k is declared nonnegative but its "
                                         "default is -1.0"):
        Model("spring", G, lagrangian=v**2 / 2 - k * x**2 / 2, parameters={k: -1.0})
    Model("spring", G, lagrangian=v**2 / 2 - k * x**2 / 2, parameters={k: 0.0})


def test_the_readme_stands_on_its_own():
    """What a clone has: no pointer outside the repository, and the suite's duration."""
    readme = (Path(__file__).resolve().parent.parent / "README.md").read_text()
    assert "../shared" not in readme
    quick_start = readme[readme.index("## Quick start"):readme.index("## Declaring a model")]
    assert "minutes" in textwrap.dedent(quick_start)
