"""Shared fixtures: every bundled model is compiled once per test session."""
from __future__ import annotations

import hashlib
import os
import pickle
import threading

# Small dense solves (SLSQP, Newton) run many times slower with threaded BLAS on a loaded
# 2-core machine; pin it before NumPy is imported.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from concurrent.futures import ThreadPoolExecutor  # noqa: E402

import pytest  # noqa: E402
import sympy as sp  # noqa: E402

import symvi.derivation.derive  # noqa: E402
from symvi.build import compile_model  # noqa: E402
from symvi.derivation.derive import derive  # noqa: E402
from symvi.discretisation.discretise import discretise  # noqa: E402
from symvi.models import BOUNDED, BUNDLED, CONTROL, NONHOLONOMIC, get  # noqa: E402

FIRST_ORDER = ("harmonic_oscillator", "pendulum", "double_pendulum", "robot_arm")
SECOND_ORDER = ("cubic_spline", "spline_potential")
#: Bundled Lagrangians of order k > 2 on the pair groupoid (issue 25).
HIGHER_ORDER = ("minimum_jerk", "minimum_snap")
#: Bundled models on the pair groupoid (node-based oracle, Taylor consistency).
PAIR = FIRST_ORDER + SECOND_ORDER + HIGHER_ORDER
#: Bundled models on matrix Lie groups (over a point).
LIE = ("rigid_body", "rigid_body_exp", "planar_body", "planar_body_exp", "so3_cubic",
       "so3_jerk", "se3_snap")
#: Bundled models on action groupoids Q×H.
ACTION = ("heavy_top", "heavy_top_exp", "spherical_pendulum", "spherical_pendulum_exp",
          "se3_body", "se3_body_exp")
#: Bundled optimal-control problems (constrained second-order models, whole trajectories).
assert set(PAIR + LIE + ACTION + CONTROL + BOUNDED + NONHOLONOMIC) == set(BUNDLED)
#: Bundled models whose derivation takes longest (seconds of CPU: SE(3) ≈ 20–30, heavy top
#: ≈ 8, the rest ≤ 5): prebuilt first, so that the pool's threads finish together.
COSTLIEST = ("se3_body_exp", "se3_body", "heavy_top_exp", "heavy_top",
             "heavy_top_rotors_oc_variational", "double_pendulum_oc", "heavy_top_rotors_oc",
             "spherical_pendulum_exp", "spherical_pendulum", "heavy_top_rotors_oc_exp")

# Every derivation of the session stays in the process's cache (the library keeps the last
# 32): the checks, the kernels-versus-SymPy tests and the builds share them.
symvi.derivation.derive.PROCESS_CACHE.size = 1024


def _worker() -> tuple[int, int]:
    """(index, count) of this pytest-xdist worker; (0, 1) in a run without workers."""
    name = os.environ.get("PYTEST_XDIST_WORKER")
    if name is None:
        return 0, 1
    return int(name.removeprefix("gw")), int(os.environ["PYTEST_XDIST_WORKER_COUNT"])


@pytest.fixture(scope="session")
def build_dir(tmp_path_factory):
    """One build directory for the run, shared by pytest-xdist workers.

    The build cache and its per-model lock make a worker that meets a model another
    worker is building wait for it and load it, so each model is compiled once per run.
    """
    if _worker()[1] == 1:
        return tmp_path_factory.mktemp("generated")
    shared = tmp_path_factory.getbasetemp().parent / "generated"
    shared.mkdir(exist_ok=True)
    return shared


@pytest.fixture(scope="session", autouse=True)
def shared_derivations(build_dir):
    """Derivations shared between pytest-xdist workers through the build directory.

    The worker that derives a model (in its share of the prebuild) pickles the
    DerivedModel under its fingerprint; another worker whose tests need the symbolic
    kernels (the checks, the kernels-versus-SymPy tests) loads it instead of deriving it
    again (se3_body_exp: 3 s instead of 14 s). SymPy's Dummy symbols compare by name and
    index, so each worker numbers its own from a range of its own: symbols loaded from
    another worker can never equal one made here.
    """
    sp.Dummy._base_dummy_index = (_worker()[0] + 1) * 10**12
    directory = build_dir / "derived"
    directory.mkdir(exist_ok=True)
    own = symvi.derivation.derive._derive

    def derive_or_load(dm):
        path = directory / f"{hashlib.sha256(dm.fingerprint.encode()).hexdigest()}.pickle"
        try:
            return pickle.loads(path.read_bytes())
        except (FileNotFoundError, EOFError, pickle.UnpicklingError):
            pass
        derived = own(dm)
        # one partial file per process and thread: threads of one process (the build
        # tests' concurrent compiles) derive the same model at once
        partial = path.with_name(f"{path.name}.{os.getpid()}.{threading.get_ident()}.partial")
        partial.write_bytes(pickle.dumps(derived))
        os.replace(partial, path)
        return derived
    symvi.derivation.derive._derive = derive_or_load
    yield
    symvi.derivation.derive._derive = own


def _bundled_models_used(session) -> list[str]:
    """The bundled models that the collected tests name in their parameters."""
    used = {value for item in session.items for value in
            getattr(getattr(item, "callspec", None), "params", {}).values()
            if isinstance(value, str) and value in BUNDLED}
    ordered = sorted(used, key=lambda n: (COSTLIEST.index(n) if n in COSTLIEST else len(COSTLIEST), n))
    index, count = _worker()
    # Worker k starts on every count-th model from its own offset, costliest first, then
    # meets the others' models already built (or waits on their lock and loads them).
    mine = ordered[index::count]
    return mine + [n for n in ordered if n not in mine]


@pytest.fixture(scope="session")
def prebuilt(request, build_dir, shared_derivations) -> None:
    """Compile, once per run, every bundled model the collected tests name, in threads.

    Derivation holds the GIL but the C compile runs in a child process, so one thread
    derives while another compiles (little overlap: derivation and emission are ~80 % of
    a build), and every derivation lands in this process's memo for the tests that need
    the symbolic kernels. Under pytest-xdist each worker starts on its own share of the
    models (:func:`_bundled_models_used`) and loads the others' from the shared build
    directory, deriving them again only if one of its tests asks for the symbolic
    kernels (measured: 140 s of prebuild per worker instead of 250 s). A model that fails
    here is compiled again, and its error raised, when a test asks for it.
    """
    def build(name: str) -> None:
        try:
            compile_model(get(name), build_dir)
        except Exception:       # reported by the test that uses the model
            pass

    threads = max(2, (os.cpu_count() or 1) // _worker()[1] + 1)
    with ThreadPoolExecutor(max_workers=threads) as pool:
        list(pool.map(build, _bundled_models_used(request.session)))


@pytest.fixture(scope="session")
def compiled(build_dir, prebuilt):
    """compiled(name) -> the generated module of bundled model ``name`` (cached)."""
    cache = {}

    def get_module(name):
        if name not in cache:
            cache[name] = compile_model(get(name), build_dir)
        return cache[name]
    return get_module


@pytest.fixture(scope="session")
def derived(prebuilt):
    """derived(name) -> the DerivedModel (symbolic kernels) of a bundled model (cached)."""
    cache = {}

    def get_derived(name):
        if name not in cache:
            cache[name] = derive(discretise(get(name)))
        return cache[name]
    return get_derived


__all__ = ["BOUNDED", "BUNDLED", "NONHOLONOMIC", "FIRST_ORDER", "SECOND_ORDER", "HIGHER_ORDER", "PAIR", "LIE", "ACTION", "CONTROL"]


@pytest.fixture
def ctrl_c():
    """``arm()``: Ctrl-C 0.2 s from then (``_thread.interrupt_main``); returns the time it
    was armed. Python's SIGINT handler is in place for the test: a process started in the
    background by a shell without job control inherits SIGINT ignored, and then the
    simulated Ctrl-C would do nothing."""
    import _thread
    import signal
    import time

    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    timer = threading.Timer(0.2, _thread.interrupt_main)

    def arm() -> float:
        timer.start()
        return time.perf_counter()
    try:
        yield arm
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, previous)
