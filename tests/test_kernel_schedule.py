"""Large kernels are ordered, split into parts (``symvi/codegen/schedule.py``) and
compiled as translation units of their own (``symvi/build/_cffi_build.py``) without
changing one operation: the split C gives the same bits as the unsplit C.

Two tests. The work array's bookkeeping is checked by executing random statement graphs
part by part against a store that records which value each slot holds; and a model
compiled with every kernel in a unit of its own, split into parts of a few statements, is
compared bit for bit with the same model compiled whole (every kernel at random points,
and a run).
"""
from __future__ import annotations

import random

import numpy as np
import pytest

from symvi.build import compile_model
from symvi.codegen import emit as emit_module
from symvi.codegen import schedule
from symvi.codegen.schedule import Statement, on_demand, split
from symvi.derivation.derive import derive
from symvi.discretisation.discretise import discretise
from symvi.models import get


def _random_graph(rng: random.Random, temporaries: int, outputs: int):
    temps = []
    for i in range(temporaries):
        uses = tuple(sorted({f"t{rng.randrange(i)}" for _ in range(rng.randrange(4))})) if i else ()
        temps.append(Statement(f"t{i}", "", True, uses))
    outs = [Statement(f"out[{j}]", "", False,
                      tuple(sorted({f"t{rng.randrange(temporaries)}" for _ in range(3)})))
            for j in range(outputs)]
    return temps, outs


@pytest.mark.parametrize("seed", range(20))
def test_parts_read_what_was_stored(seed, monkeypatch):
    """Every value a part reads is computed before it, in that part or stored by an
    earlier one in a slot no later value has overwritten; outputs keep their order and
    each temporary is computed once."""
    rng = random.Random(seed)
    temps, outs = _random_graph(rng, rng.randrange(5, 300), rng.randrange(1, 60))
    code = on_demand(temps, outs)
    assert [s.target for s in code if not s.temporary] == [s.target for s in outs]
    names = [s.target for s in code if s.temporary]
    assert len(names) == len(set(names))
    monkeypatch.setattr(schedule, "PART", rng.randrange(1, 12))
    parts, size = split(code)
    work: dict[int, str] = {}
    for part in parts:
        local = {}
        for name, slot in part.loads:
            assert work[slot] == name, f"slot {slot} holds {work[slot]}, not {name}"
            local[name] = True
        for s in part.statements:
            assert all(u in local for u in s.uses), f"{s.target} reads an unknown value"
            if s.temporary:
                local[s.target] = True
            if s.slot is not None:
                assert 0 <= s.slot < size
                work[s.slot] = s.target
    assert size <= len(names)


@pytest.fixture(scope="module")
def whole_and_split(tmp_path_factory):
    model = get("double_pendulum")
    whole = compile_model(model, tmp_path_factory.mktemp("whole"), force=True)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(emit_module, "SPLIT_ABOVE", 0)
        patch.setattr(emit_module, "UNIT_ABOVE", 0)
        patch.setattr(schedule, "PART", 5)
        parts = compile_model(model, tmp_path_factory.mktemp("parts"), force=True)
        source = emit_module.emit(derive(discretise(model)))
    # every kernel in a translation unit of its own, in parts of 5 statements
    assert [name for name, _ in source.units] == list(whole.INFO.kernel_names)
    assert sum(text.count("SYMVI_PART k_") for _, text in source.units) > 40
    return model, whole, parts


def test_split_kernels_give_the_same_bits(whole_and_split):
    model, whole, parts = whole_and_split
    assert ([(k.name, k.nz, k.outputs) for k in whole.INFO.kernels]
            == [(k.name, k.nz, k.outputs) for k in parts.INFO.kernels])
    rng = np.random.default_rng(0)
    for spec in whole.INFO.kernels:
        kernel = spec.name
        for _ in range(5):
            z, h = rng.uniform(-1, 1, spec.nz), rng.uniform(0.01, 0.2)
            for a, b in zip(whole.evaluate(kernel, z, h), parts.evaluate(kernel, z, h)):
                np.testing.assert_array_equal(a, b, err_msg=kernel)
    ex = model.example
    runs = [m.integrate(ex.initial, h=ex.h, n_steps=500) for m in (whole, parts)]
    assert runs[0].success
    for field in ("x", "f", "momenta", "energy"):
        np.testing.assert_array_equal(getattr(runs[0], field), getattr(runs[1], field))
