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
