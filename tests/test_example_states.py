"""Bundled first-order examples start from a state (issue 22, item 1): ``symvi run``
integrates from ``Example.state`` through the discrete Legendre transform, so that the
step changes the accuracy and not the motion. Measured on every such example: the
discrete energy of the first element from the state at h, h/2, h/4 converges at order 2
(the transform's momentum is ∂L/∂v at the state; fixed nodes would fix the velocity
(q₁ − q₀)/h instead, which moves with h). And ``symvi run NAME --h H`` starts from that
state."""
from __future__ import annotations

import numpy as np
import pytest

from symvi.cli import main
from symvi.models import BUNDLED, get

WITH_STATE = [n for n in BUNDLED if get(n).example.state is not None]


def test_every_first_order_example_has_a_state():
    first_order = [n for n in BUNDLED if get(n).order == 1 and not get(n).example.whole_trajectory]
    assert sorted(WITH_STATE) == sorted(first_order)


@pytest.mark.parametrize("name", WITH_STATE)
def test_the_first_energy_from_the_state_converges_at_order_two(compiled, name):
    module, ex = compiled(name), get(name).example
    energies = [module.integrate(ex.state, 4, ex.h / 2**k).energy[0] for k in range(3)]
    d1, d2 = energies[0] - energies[1], energies[1] - energies[2]
    order = np.log2(abs(d1 / d2))
    assert abs(order - 2.0) < 0.3, (name, energies, order)


def test_run_starts_from_the_state_whatever_the_step(build_dir, tmp_path, capsys):
    """The harmonic oscillator from x = 1 at rest (E = ½): at the example's step and at 5
    times it, the first energy is ½ to O(h²)."""
    for h in (None, "0.05"):
        npz = tmp_path / "r.npz"
        args = ["run", "harmonic_oscillator", "--build-dir", str(build_dir), "--steps", "10",
                "--output", str(npz)] + (["--h", h] if h else [])
        assert main(args) == 0
        out = capsys.readouterr().out
        assert "start      the state v = [0.], x = [1.]" in out, out
        step = float(np.load(npz)["t"][1])
        assert abs(np.load(npz)["energy"][0] - 0.5) <= step**2, (h, np.load(npz)["energy"][0])


def test_a_run_from_a_state_counts_every_step(compiled):
    module, ex = compiled("pendulum"), get("pendulum").example
    r = module.integrate(ex.state, 100, ex.h)
    assert r.t.size == 101 and r.message == \
        "integrated 100 steps (the first by the discrete Legendre transform)"
