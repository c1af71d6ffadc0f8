"""The whole-trajectory Newton: assembly, banded solves, globalisation, batches (SciPy)."""
