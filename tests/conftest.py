"""Shared fixtures: every bundled model is compiled once per test session."""
from __future__ import annotations

import os

# Small dense solves (SLSQP, Newton) run many times slower with threaded BLAS on a loaded
# 2-core machine; pin it before NumPy is imported.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import pytest  # noqa: E402

from symvi.build import compile_model  # noqa: E402
from symvi.derive import derive  # noqa: E402
from symvi.discretise import discretise  # noqa: E402
from symvi.models import BUNDLED, CONTROL, get  # noqa: E402

FIRST_ORDER = ("harmonic_oscillator", "pendulum", "double_pendulum")
SECOND_ORDER = ("cubic_spline", "spline_potential")
#: Bundled models on the pair groupoid (node-based oracle, Taylor consistency).
PAIR = FIRST_ORDER + SECOND_ORDER
#: Bundled models on matrix Lie groups (over a point).
LIE = ("rigid_body", "rigid_body_exp", "planar_body", "planar_body_exp", "so3_cubic")
#: Bundled models on action groupoids Q×H.
ACTION = ("heavy_top", "heavy_top_exp", "spherical_pendulum", "spherical_pendulum_exp",
          "se3_body", "se3_body_exp")
#: Bundled optimal-control problems (constrained second-order models, whole trajectories).
assert set(PAIR + LIE + ACTION + CONTROL) == set(BUNDLED)


@pytest.fixture(scope="session")
def build_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("generated")


@pytest.fixture(scope="session")
def compiled(build_dir):
    """compiled(name) -> the generated module of bundled model ``name`` (cached)."""
    cache = {}

    def get_module(name):
        if name not in cache:
            cache[name] = compile_model(get(name), build_dir)
        return cache[name]
    return get_module


@pytest.fixture(scope="session")
def derived():
    """derived(name) -> the DerivedModel (symbolic kernels) of a bundled model (cached)."""
    cache = {}

    def get_derived(name):
        if name not in cache:
            cache[name] = derive(discretise(get(name)))
        return cache[name]
    return get_derived


__all__ = ["BUNDLED", "FIRST_ORDER", "SECOND_ORDER", "PAIR", "LIE", "ACTION", "CONTROL"]
