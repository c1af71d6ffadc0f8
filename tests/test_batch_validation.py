"""The batch calls check every argument before any work (issue 48,
``symvi/_runtime/step/batch_arguments.py``), and the memory their results will hold against
what this process may really use (``symvi/_runtime/core/memory.py``): the machine's free
memory, its cgroup's limit and its own address-space limit.

The Dask calls run the same checks on the client (``tests/test_dask.py``).
"""
from __future__ import annotations

import importlib
import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from symvi._runtime.core import memory
from symvi.models import get

GIB = 2**30


@pytest.fixture(scope="module")
def slew(compiled):
    module = compiled("spacecraft_slew")
    ex = get("spacecraft_slew").example
    return module, np.asarray(ex.start, float), np.asarray(ex.end, float)


@pytest.fixture
def no_solve(slew, monkeypatch):
    """The package's batch module with its solve replaced by one that fails the test:
    what is refused must be refused before the first solve."""
    module = slew[0]
    bvp_batch = importlib.import_module(f"{module.__name__}._runtime.bvp.bvp_batch")

    def solve_bvp(*args, **kwargs):
        raise AssertionError("a solve started")
    monkeypatch.setattr(bvp_batch, "solve_bvp", solve_bvp)


def test_zero_solves_are_an_error_not_a_success(slew, compiled, no_solve):
    """An empty batch, or a path of empty sequences, is refused naming it — never
    'SUCCESS: 0 of 0 solves succeeded'."""
    module, start, end = slew
    empty = np.zeros((0, *start.shape))
    with pytest.raises(ValueError, match=r"^starts: the batch is empty \(zero solves\)"):
        module.solve_bvp_many(empty, empty, 20, 0.05)
    with pytest.raises(ValueError, match=r"^path: the sequences are empty \(zero solves\)"):
        module.continuation(start, end, 20, 0.05, path={"tau_max": []})
    pendulum = compiled("double_pendulum")
    with pytest.raises(ValueError, match=r"^initial: the batch is empty \(zero trajectories\)"):
        pendulum.integrate_many(pendulum.State(x=np.zeros((0, 2)), v=np.zeros((0, 2))), 10,
                                0.01)


def test_oversized_solves_are_refused_before_any_solve(slew, no_solve):
    """10⁵ slews at N = 10⁴ (236 B per node each: 220 GiB of results) and a continuation
    of 10⁶ points at N = 1000 (220 GiB): a MemoryError giving the estimate, at once."""
    module, start, end = slew
    starts, ends = (np.broadcast_to(a, (100_000, *a.shape)) for a in (start, end))
    with pytest.raises(MemoryError, match=r"^a batch of 100,000 solves with N = 10,000 "
                                          r"\(2\.25 MiB each\) needs about 220 GiB"):
        module.solve_bvp_many(starts, ends, 10_000, 1e-4)
    with pytest.raises(MemoryError, match=r"^a continuation of 1,000,000 solves with "
                                          r"N = 1,000 .* needs about 220 GiB .*split the path"):
        module.continuation(start, end, 1000, 1e-3,
                            path={"tau_max": np.linspace(11.0, 14.0, 1_000_000)})


@pytest.mark.parametrize("call, pattern", [
    (lambda m, s, e: m.continuation(s, e, 20, 0.05, path={"tau_max": [11.0, 12.0, -1.0]}),
     r"^solve 2: parameter tau_max is declared positive"),
    (lambda m, s, e: m.continuation(s, e, 20, 0.05, path={"tau_max": [11.0]}, tolerance=1),
     r"^continuation: unknown option\(s\) 'tolerance'"),
    (lambda m, s, e: m.solve_bvp_many(np.stack([s] * 3), np.stack([e] * 3), 20, 0.05,
                                      maxiter=0),
     r"^maxiter must be at least 1, got 0"),
    (lambda m, s, e: m.solve_bvp_many(np.stack([s] * 3), np.stack([e] * 3), 1, 0.05),
     r"^n_steps must be at least 4 \(2 fixed nodes at each end"),
    (lambda m, s, e: m.solve_bvp_many(np.stack([s] * 3), np.stack([e] * 3), 20,
                                      [0.05, 0.05, -0.05]),
     r"^solve 2: the time step h must be positive and finite, got -0.05"),
], ids=["a point's parameter", "unknown option", "maxiter", "n_steps", "a solve's step"])
def test_bad_arguments_are_refused_before_any_solve(slew, no_solve, call, pattern):
    """Each refused by the batch itself, before the first solve, naming the argument and
    the solve (today found by the solves, one by one: the continuation's third point
    after two solves, without naming it; an unknown option as a raw TypeError from a
    worker thread)."""
    module, start, end = slew
    with pytest.raises((ValueError, TypeError), match=pattern):
        call(module, start, end)


# -- the memory this process may really use -----------------------------------------------
def _write(root: Path, files: dict[str, str]) -> None:
    for name, text in files.items():
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_text(text)


@pytest.mark.parametrize("cgroup, files, room", [
    ("0::/job\n", {"fs/job/memory.max": f"{4 * GIB}\n", "fs/job/memory.current": f"{GIB}\n",
                   "fs/job/memory.stat": f"anon 1\ninactive_file {GIB // 2}\n",
                   "fs/memory.max": "max\n", "fs/memory.current": f"{8 * GIB}\n"},
     3.5 * GIB),
    ("0::/job/step\n", {"fs/job/step/memory.max": "max\n", "fs/job/memory.max": f"{2 * GIB}\n",
                        "fs/job/memory.current": f"{GIB}\n"}, 1.0 * GIB),
    ("0::/system.slice/docker-1.scope\n", {"fs/memory.max": f"{3 * GIB}\n",
                                           "fs/memory.current": f"{2 * GIB}\n"}, 1.0 * GIB),
    ("4:memory:/a/b\n1:cpu:/\n", {
        "fs/memory/a/b/memory.limit_in_bytes": "9223372036854771712\n",
        "fs/memory/a/b/memory.usage_in_bytes": f"{GIB}\n",
        "fs/memory/a/memory.limit_in_bytes": f"{2 * GIB}\n",
        "fs/memory/a/memory.usage_in_bytes": f"{GIB + GIB // 2}\n",
        "fs/memory/a/memory.stat": f"cache 5\ntotal_inactive_file {GIB // 4}\n"}, 0.75 * GIB),
    ("0::/\n", {"fs/memory.max": "max\n"}, None),
    ("4:memory:/\n", {"fs/memory/memory.limit_in_bytes": "9223372036854771712\n"}, None),
], ids=["v2 limit, page cache", "v2 parent's limit", "v2 host path in a container",
        "v1 parent's limit", "v2 none", "v1 none"])
def test_the_cgroup_limit_is_read(tmp_path, cgroup, files, room):
    """cgroup v2 (memory.max − memory.current) and v1 (limit_in_bytes − usage_in_bytes),
    the tightest of the process's cgroup and those above it, reclaimable page cache not
    counted; "max" and v1's 2⁶³ mean no limit."""
    _write(tmp_path, {"cgroup": cgroup} | files)
    assert memory.cgroup_room(tmp_path / "cgroup", tmp_path / "fs") == room


def test_the_least_of_the_three_limits_counts(monkeypatch):
    """MemAvailable, the cgroup's room and the address space's room: the least; None
    only when none is known."""
    for rooms, least in (((20.0, 3.0, 5.0), 3.0), ((20.0, None, 5.0), 5.0),
                         ((None, None, None), None)):
        for name, value in zip(("_system_available", "cgroup_room", "address_space_room"),
                               rooms):
            monkeypatch.setattr(memory, name, lambda value=value: value)
        assert memory.available_bytes() == least


@pytest.mark.skipif(not Path("/proc/self/statm").exists(), reason="needs Linux's /proc")
def test_an_address_space_limit_is_respected(compiled):
    """A child process limited (RLIMIT_AS, as ``ulimit -v`` or a batch system does) to
    its current virtual size + 200 MiB asks for a batch of 1,000 paths of 7,350 steps,
    about 1 GiB — within this machine's free memory, far beyond its own limit. Refused
    with the estimate (today the check passes on MemAvailable and NumPy's allocation
    fails with a bare "Unable to allocate")."""
    if (memory._system_available() or 0) < 4 * GIB:
        pytest.skip("the batch must fit in the machine's free memory")
    module = compiled("double_pendulum")
    script = textwrap.dedent(f"""
        import os, resource
        import numpy as np
        from symvi.build import load

        module = load({str(Path(module.__file__).parent)!r})
        start = module.State(x=np.zeros((1000, 2)), v=np.zeros((1000, 2)))
        pages = int(open("/proc/self/statm").read().split()[0])
        current = pages * os.sysconf("SC_PAGE_SIZE")
        resource.setrlimit(resource.RLIMIT_AS, (current + 200 * 2**20,
                                                resource.getrlimit(resource.RLIMIT_AS)[1]))
        try:
            module.integrate_many(start, 7350, 0.001, workers=1)
        except MemoryError as exc:
            print("MemoryError:", exc)
        else:
            print("ran")
    """)
    child = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                           timeout=300, env=os.environ | {"OPENBLAS_NUM_THREADS": "1"})
    assert child.returncode == 0, child.stderr[-2000:]
    assert re.match(r"MemoryError: a batch of 1,000 paths of 7,352 stored nodes needs about "
                    r"0\.93\d* GiB but only 0\.[12]\d* GiB of memory are available",
                    child.stdout), child.stdout
