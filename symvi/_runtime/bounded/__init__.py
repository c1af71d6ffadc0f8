"""The bounded solve: the interior point, barrier and penalty for inequalities (SciPy)."""
