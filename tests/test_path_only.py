"""``integrate(..., quantities=False)``: the path alone, no work past the step loop
(issue 23: "no work in the loop that the user did not ask for")."""
import numpy as np
import pytest

from symvi import State


@pytest.mark.parametrize("name, initial", [
    ("double_pendulum", State(x=[0.5, -0.3], v=[0.0, 0.0])),
    ("heavy_top", None)])
def test_the_path_alone_is_the_same_path(compiled, name, initial):
    from symvi.models import get
    mod = compiled(name)
    initial = initial if initial is not None else get(name).example.run_from
    full = mod.integrate(initial, 3000, 0.005)
    alone = mod.integrate(initial, 3000, 0.005, quantities=False)
    assert full.success and alone.success
    for field in ("x", "f", "t", "newton_iterations"):
        np.testing.assert_array_equal(getattr(alone, field), getattr(full, field))
    if full.g is not None:
        np.testing.assert_array_equal(alone.g, full.g)
    assert alone.momenta is None and alone.energy is None and alone.noether is None
    thinned = mod.integrate(initial, 3000, 0.005, keep_every=100, quantities=False)
    np.testing.assert_array_equal(thinned.x, full.x[::100])
    with pytest.raises(TypeError, match="quantities must be True or False"):
        mod.integrate(initial, 10, 0.005, quantities="no")


def test_the_memory_check_counts_what_is_stored(compiled, monkeypatch):
    """A run that fits without its momenta and energies is not refused for them: with
    memory for 1.2 paths, the full run (1.57 paths: momentum and energy per node) is
    refused before anything is allocated and the path alone runs."""
    import importlib
    mod = compiled("pendulum")
    memory = importlib.import_module(f"{mod.__name__}._runtime.core.memory")
    storage = importlib.import_module(f"{mod.__name__}._runtime.core.storage")
    n_steps = 3_000_000
    path_bytes = storage.bytes_per_node(mod.model, quantities=False) * (n_steps + 1)
    assert path_bytes > memory.SMALL
    assert storage.bytes_per_node(mod.model) > 1.5 * storage.bytes_per_node(
        mod.model, quantities=False)
    for module in (memory, storage):
        monkeypatch.setattr(module, "available_bytes", lambda: 1.2 * path_bytes)
    with pytest.raises(MemoryError, match="3,000,001 nodes"):
        mod.integrate([[1.0], [1.01]], n_steps, 0.01)
    alone = mod.integrate([[1.0], [1.01]], n_steps, 0.01, quantities=False)
    assert alone.success and alone.x.shape == (n_steps + 1, 1)


def test_batches_of_paths_alone(compiled, monkeypatch):
    """``integrate_many(..., quantities=False)``: the batch's paths, the same as with
    their quantities and as the single calls', by the C batch loop and one by one."""
    import importlib
    mod = compiled("double_pendulum")
    rng = np.random.default_rng(3)
    starts = State(x=rng.uniform(-1, 1, (5, 2)), v=rng.uniform(-1, 1, (5, 2)))
    full = mod.integrate_many(starts, 400, 0.005, workers=2)
    alone = mod.integrate_many(starts, 400, 0.005, workers=2, quantities=False)
    batch_loop = importlib.import_module(f"{mod.__name__}._runtime.step.batch_loop")
    monkeypatch.setattr(batch_loop, "MAX_PATH_BYTES", 1)      # one trajectory at a time
    one_by_one = mod.integrate_many(starts, 400, 0.005, workers=2, quantities=False,
                                    keep_every=7)
    assert full.success and alone.success and one_by_one.success
    for field in ("x", "f", "t", "newton_iterations"):
        np.testing.assert_array_equal(getattr(alone, field), getattr(full, field))
    np.testing.assert_array_equal(one_by_one.x, full.x[:, ::7])
    for batch in (alone, one_by_one):
        assert batch.momenta is None and batch.energy is None and batch.noether is None
    single = mod.integrate(State(x=starts.x[3], v=starts.v[3]), 400, 0.005, quantities=False)
    np.testing.assert_array_equal(alone[3].x, single.x)
    with pytest.raises(TypeError, match="quantities must be True or False"):
        mod.integrate_many(starts, 10, 0.005, quantities=1)
