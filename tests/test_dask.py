"""Batches on a Dask cluster (``symvi/dask.py``, issue 24, item 3): a
``LocalCluster`` of two worker processes runs a batch of 100 trajectories and 10
optimal-control solves from a freshly compiled package, and the results are the local
ones — trajectories bit for bit, solves to 1e-12."""
from __future__ import annotations

import re
import shutil

import numpy as np
import pytest

distributed = pytest.importorskip("distributed")

import symvi.dask  # noqa: E402
from symvi.build import compile_model  # noqa: E402
from symvi.build.generic import CACHE_ENV  # noqa: E402
from symvi.models import get  # noqa: E402


@pytest.fixture(scope="module")
def client():
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        yield client


def test_a_batch_on_two_worker_processes_is_the_local_batch(client, tmp_path, monkeypatch):
    """...from a package whose build cache is gone: the generic library (issue 54) is
    inside its extension, which the workers load."""
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "cache"))
    module = compile_model(get("double_pendulum"), tmp_path / "out", force=True)
    shutil.rmtree(tmp_path / "cache")
    rng = np.random.default_rng(24)
    start = module.State(x=rng.uniform(-1, 1, (100, 2)), v=rng.uniform(-1, 1, (100, 2)))
    lengths = rng.uniform(0.5, 2.0, 100)
    remote = symvi.dask.integrate_many(client, module, start, 500, 0.005, {"l1": lengths},
                                       chunk=30)
    local = module.integrate_many(start, 500, 0.005, {"l1": lengths})
    assert remote.success and remote.message == "100 of 100 trajectories succeeded"
    for name in ("t", "x", "f", "momenta", "energy", "newton_iterations"):
        assert np.array_equal(getattr(remote, name), getattr(local, name)), name
    assert sorted(client.run(lambda: 1)) and len(client.scheduler_info()["workers"]) == 2


def test_solves_on_two_worker_processes_are_the_local_solves(client, compiled):
    module = compiled("spacecraft_slew")
    ex = get("spacecraft_slew").example
    start, end = (np.repeat(np.asarray(a, float)[None], 10, axis=0) for a in (ex.start, ex.end))
    limits = np.linspace(10.0, 14.0, 10)
    remote = symvi.dask.solve_bvp_many(client, module, start, end, 60, 1 / 60,
                                       {"tau_max": limits}, chunk=4)
    assert remote.success and len(remote) == 10, remote.message
    for b in (0, 5, 9):
        single = module.solve_bvp(ex.start, ex.end, 60, 1 / 60, {"tau_max": limits[b]})
        assert np.abs(remote[b].g - single.g).max() <= 1e-12
        assert remote.cost[b] == pytest.approx(single.cost, rel=1e-12)


def test_bad_data_in_a_chunk_names_it(client, compiled):
    """What only the kernels judge (a rotation off SO(3)) is found on the worker, which
    names its chunk."""
    module = compiled("rigid_body")
    g0 = np.repeat(np.eye(3)[None], 6, axis=0)
    g0[4, 0, 0] = 1.01
    with pytest.raises(ValueError, match=r"in the chunk of members 4–5: trajectory 0: "
                                         r".*(rotation|orthogonal|SO\(3\))"):
        symvi.dask.integrate_many(client, module, module.State(v=np.ones((6, 3)), g=g0), 10,
                                  0.01, chunk=4)


def test_a_worker_that_cannot_load_the_package_says_so(client, tmp_path):
    """The package's folder gone before the tasks run (as on a worker without the shared
    file system): the error names the folder and says how to make it readable."""
    import shutil

    module = compile_model(get("pendulum"), tmp_path / "build", force=True)
    shutil.rmtree(tmp_path / "build")
    with pytest.raises(ImportError, match=r"cannot load the package .*build.* on a worker"):
        symvi.dask.integrate_many(client, module, module.State(x=np.zeros((2, 1)),
                                                               v=np.zeros((2, 1))), 10, 0.01)


# -- arguments checked on the client, by the local calls' own checks (issue 48) ----------
@pytest.fixture(scope="module")
def slew(compiled):
    """spacecraft_slew, three copies of its example's ends and h (N = 20)."""
    module = compiled("spacecraft_slew")
    ex = get("spacecraft_slew").example
    starts, ends = (np.repeat(np.asarray(a, float)[None], 3, axis=0) for a in (ex.start, ex.end))
    return module, starts, ends, 1 / 20


def _message(call) -> str:
    with pytest.raises((ValueError, TypeError)) as info:
        call()
    return str(info.value)


@pytest.mark.parametrize("chunk", [0, -1, -2, 2.5, "3", True])
def test_a_bad_chunk_is_refused_in_the_local_calls_words(client, slew, compiled, chunk):
    """chunk = 0, −1, −2 (today: a range() error, or SUCCESS on 0 of 0 solves), 2.5, "3"
    (raw TypeErrors) and True (taken as 1): refused before any task with the message the
    local calls give the same value as ``workers``, their count of the same kind."""
    module, starts, ends, h = slew
    local = _message(lambda: module.solve_bvp_many(starts, ends, 20, h, workers=chunk))
    expected = local.replace("workers", "chunk")
    assert expected.startswith("chunk must be") and expected.endswith(f"got {chunk!r}")
    assert _message(lambda: symvi.dask.solve_bvp_many(client, module, starts, ends, 20, h,
                                                      chunk=chunk)) == expected
    pendulum = compiled("double_pendulum")
    start = pendulum.State(x=np.zeros((3, 2)), v=np.zeros((3, 2)))
    assert _message(lambda: symvi.dask.integrate_many(client, pendulum, start, 10, 0.01,
                                                      chunk=chunk)) == expected


def test_chunk_none_is_refused_and_numpy_integers_are_taken(client, slew):
    module, starts, ends, h = slew
    assert _message(lambda: symvi.dask.solve_bvp_many(client, module, starts, ends, 20, h,
                                                      chunk=None)) \
        == "chunk must be an integer, got None"
    batch = symvi.dask.solve_bvp_many(client, module, starts, ends, 20, h, chunk=np.int64(2))
    assert batch.success and len(batch) == 3


#: Batch-size mismatches of a batch of 3 solves: (what the call is given, the argument
#: and sizes its message must name).
MISMATCHES = {
    "ends": (lambda s, e, h: ((s, e[:2], 20, h), {}), r"^ends: 2 given for a batch of 3 starts$"),
    "h": (lambda s, e, h: ((s, e, 20, np.full(2, h)), {}),
          r"^h: shape \(2,\) does not broadcast against the batch of 3 solves"),
    "T": (lambda s, e, h: ((s, e, 20), {"T": np.ones(2)}),
          r"^T: shape \(2,\) does not broadcast against the batch of 3 solves"),
    "params": (lambda s, e, h: ((s, e, 20, h, {"tau_max": [11.0, 12.0]}), {}),
               r"^params\['tau_max'\]: shape \(2,\) does not broadcast against the batch "
               r"of 3 solves"),
    "guesses": (lambda s, e, h: ((s, e, 20, h), {"guesses": [None] * 4}),
                r"^guesses: 4 given for a batch of 3 solves$"),
}


@pytest.mark.parametrize("case", MISMATCHES)
def test_batch_size_mismatches_of_solves_are_refused_in_the_local_calls_words(
        client, slew, case):
    """ends, h, T, params or guesses sized for another batch: today IndexErrors, raw
    broadcast errors, or a chunk's error about its own size; now the local call's
    message, which names the argument, its size and the batch's."""
    module, starts, ends, h = slew
    given, pattern = MISMATCHES[case]
    args, keywords = given(starts, ends, h)
    local = _message(lambda: module.solve_bvp_many(*args, **keywords))
    remote = _message(lambda: symvi.dask.solve_bvp_many(client, module, *args, chunk=2,
                                                        **keywords))
    assert remote == local
    assert re.search(pattern, local), local


@pytest.mark.parametrize("h, params, pattern", [
    (np.full(3, 0.01), None, r"^h: shape \(3,\) does not broadcast against the batch of 4 "
                             r"trajectories"),
    (0.01, {"l1": [1.0, 2.0, 3.0]}, r"^params\['l1'\]: shape \(3,\) does not broadcast"),
    (0.01, {"l1": [1.0, 1.0, 1.0, 1.0, -1.0]}, r"^params\['l1'\]: shape \(5,\)"),
    (0.01, {"l1": [1.0, 1.0, 1.0, -1.0]},
     r"^trajectory 3: parameter l1 is declared positive"),
], ids=["h", "params", "params longer", "member's parameter"])
def test_trajectory_batches_are_refused_in_the_local_calls_words(client, compiled, h, params,
                                                                 pattern):
    """h or params sized for another batch, or one member's parameter out of its sign:
    the local message exactly (today a raw broadcast error, or the chunk's own index)."""
    module = compiled("double_pendulum")
    start = module.State(x=np.zeros((4, 2)), v=np.zeros((4, 2)))
    local = _message(lambda: module.integrate_many(start, 10, h, params))
    assert _message(lambda: symvi.dask.integrate_many(client, module, start, 10, h, params,
                                                      chunk=3)) == local
    assert re.search(pattern, local), local


def test_zero_solves_are_refused_on_the_cluster(client, slew):
    """An empty batch is an error naming it, as in the local call, not '0 of 0 solves
    succeeded'."""
    module, starts, ends, h = slew
    local = _message(lambda: module.solve_bvp_many(starts[:0], ends[:0], 20, h))
    assert local == "starts: the batch is empty (zero solves); give at least one"
    assert _message(lambda: symvi.dask.solve_bvp_many(client, module, starts[:0], ends[:0],
                                                      20, h)) == local


def test_an_unknown_option_is_refused_before_any_task(client, slew):
    module, starts, ends, h = slew
    local = _message(lambda: module.solve_bvp_many(starts, ends, 20, h, tolerance=1e-9))
    assert local.startswith("solve_bvp_many: unknown option(s) 'tolerance'")
    assert _message(lambda: symvi.dask.solve_bvp_many(client, module, starts, ends, 20, h,
                                                      tolerance=1e-9)) == local


def test_the_memory_estimate_refuses_before_any_task(client, tmp_path):
    """10⁵ slews at N = 10⁴ hold about 220 GiB of results where they are gathered: refused
    on the client before any task — the package's folder is gone, so a task submitted
    would fail on its worker with an ImportError instead."""
    import shutil

    module = compile_model(get("spacecraft_slew"), tmp_path / "build", force=True)
    shutil.rmtree(tmp_path / "build")
    ex = get("spacecraft_slew").example
    starts, ends = (np.broadcast_to(np.asarray(a, float), (100_000, *np.shape(a)))
                    for a in (ex.start, ex.end))
    with pytest.raises(MemoryError, match=r"a batch of 100,000 solves with N = 10,000 .*"
                                          r"needs about .* GiB"):
        symvi.dask.solve_bvp_many(client, module, starts, ends, 10_000, 1e-4, chunk=50_000)
