"""Batches on a Dask cluster (``symvi/dask.py``, issue 24, item 3): a
``LocalCluster`` of two worker processes runs a batch of 100 trajectories and 10
optimal-control solves from a freshly compiled package, and the results are the local
ones — trajectories bit for bit, solves to 1e-12."""
from __future__ import annotations

import numpy as np
import pytest

distributed = pytest.importorskip("distributed")

import symvi.dask  # noqa: E402
from symvi.build import compile_model  # noqa: E402
from symvi.models import get  # noqa: E402


@pytest.fixture(scope="module")
def client():
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        yield client


def test_a_batch_on_two_worker_processes_is_the_local_batch(client, tmp_path):
    module = compile_model(get("double_pendulum"), tmp_path, force=True)
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
    module = compiled("double_pendulum")
    start = module.State(x=np.zeros((6, 2)), v=np.zeros((6, 2)))
    with pytest.raises(ValueError, match=r"in the chunk of members 4–5: trajectory 0: .*l1"):
        symvi.dask.integrate_many(client, module, start, 10, 0.01,
                                  {"l1": [1.0, 1.0, 1.0, 1.0, -1.0, 1.0]}, chunk=4)


def test_a_worker_that_cannot_load_the_package_says_so(client, tmp_path):
    """The package's folder gone before the tasks run (as on a worker without the shared
    file system): the error names the folder and says how to make it readable."""
    import shutil

    module = compile_model(get("pendulum"), tmp_path / "build", force=True)
    shutil.rmtree(tmp_path / "build")
    with pytest.raises(ImportError, match=r"cannot load the package .*build.* on a worker"):
        symvi.dask.integrate_many(client, module, module.State(x=np.zeros((2, 1)),
                                                               v=np.zeros((2, 1))), 10, 0.01)
