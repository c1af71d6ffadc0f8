"""A package's ``INFO`` is a frozen, typed, versioned ``ModelInfo`` (issue 49, item 2).

Written once by the build, read back when the package is imported: another schema
version, a key too many or too few, or a value of the wrong type is refused at load with
a message that says to recompile; the run time reads it by attribute and names kernels
by ``Kernel`` (test_architecture.py: no string lookups are left in symvi/).
"""
from __future__ import annotations

import dataclasses
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from symvi._runtime.core.model_info import VERSION, Kernel, KernelInfo, ModelInfo, ModelInfoError


@pytest.fixture(scope="module")
def pendulum(compiled):
    return compiled("pendulum")


def test_info_is_a_frozen_model_info_read_by_attribute(pendulum):
    info = pendulum.INFO
    assert type(info).__name__ == "ModelInfo" and info.version == VERSION
    assert pendulum.model.info is info
    assert (info.name, info.order, info.source_dim, info.fibre_dim) == ("pendulum", 1, 1, 1)
    assert info.parameters == ("m", "l", "g") and info.has_energy and not info.constraints
    step = info.kernel(Kernel.STEP)
    assert step == info.kernel("step") and step.nz == 1 + 2 * 1 and len(step.outputs) == 2
    assert info.has_kernel(Kernel.LEGENDRE) and not info.has_kernel(Kernel.GAUGE)
    with pytest.raises(dataclasses.FrozenInstanceError):
        info.order = 2
    with pytest.raises(ValueError, match="unknown kernel 'nonsense'; known: .*'step'"):
        pendulum.evaluate("nonsense", [0.0] * 3, 0.1)


def test_every_compiled_kernel_is_a_kernel_member(compiled):
    """The run time names kernels by ``Kernel``; every kernel a model compiles is one
    (or an end stencil, ``stencil_end<j>``, named by string)."""
    members = {k.value for k in Kernel}
    for name in ("pendulum", "heavy_top", "rigid_body_oc", "cubic_spline"):
        names = compiled(name).INFO.kernel_names
        strays = [k for k in names if k not in members and not re.fullmatch(r"stencil_end\d+", k)]
        assert not strays, (name, strays)


def test_literal_round_trips_and_refuses_what_does_not_fit(pendulum):
    cls = type(pendulum.INFO)
    literal = pendulum.INFO.to_literal()
    assert cls.from_literal(literal) == pendulum.INFO
    assert ModelInfo.from_literal(literal).to_literal() == literal   # symvi's own copy too
    cases = {
        "another version": ({**literal, "version": VERSION + 1}, "schema version"),
        "no version": ({k: v for k, v in literal.items() if k != "version"}, "schema version"),
        "an unknown key": ({**literal, "node_pairs": True}, r"unknown keys \['node_pairs'\]"),
        "a missing key": ({k: v for k, v in literal.items() if k != "fibre_nodes"},
                          r"missing keys \['fibre_nodes'\]"),
        "a wrong type": ({**literal, "order": "1"}, r"INFO.order = '1' is not of type int"),
        "a bool for an int": ({**literal, "fibre_dim": True}, "INFO.fibre_dim = True"),
        "a kernel's unknown key": (
            {**literal, "kernels": [{**literal["kernels"][0], "width": 3}]},
            r"INFO.kernels\[0\]: unknown keys \['width'\]"),
    }
    for case, (data, message) in cases.items():
        with pytest.raises(ValueError, match=message) as caught:
            cls.from_literal(data)
        assert "recompile" in str(caught.value), case
    assert issubclass(ModelInfoError, ValueError)


def test_a_kernel_info_knows_its_window():
    assert KernelInfo("momentum_plus", nz=3 + 2 * 4, outputs=(4,)).width(3, 4) == 2


def test_a_package_with_another_info_version_is_refused(pendulum, tmp_path):
    """A package whose INFO literal has another schema version does not import: the
    ImportError names the versions and says to recompile."""
    folder = Path(pendulum.__file__).resolve().parent
    out = tmp_path / "out"
    shutil.copytree(folder, out / "pendulum")
    init = out / "pendulum" / "__init__.py"
    text = init.read_text(encoding="utf-8")
    assert text.count(f"{{'version': {VERSION}, ") == 1
    init.write_text(text.replace(f"{{'version': {VERSION}, ", "{'version': 0, "),
                    encoding="utf-8")
    code = (f"import sys; sys.path.insert(0, {str(out)!r}); import pendulum; "
            f"print(pendulum.INFO.version)")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    child = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                           env=env, cwd=str(out), timeout=120)
    assert child.returncode != 0, child.stdout
    assert "ImportError: generated package 'pendulum' does not fit this run time" in child.stderr
    assert "schema version 0" in child.stderr and f"reads version {VERSION}" in child.stderr
    assert "recompile it: symvi compile <model>" in child.stderr, child.stderr
    # the untouched copy imports
    init.write_text(text, encoding="utf-8")
    child = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                           env=env, cwd=str(out), timeout=120)
    assert child.returncode == 0 and child.stdout.strip() == str(VERSION), child.stderr
