"""Models from ``sympy.physics.mechanics`` systems: :func:`from_system`,
:func:`from_lagrangian` (:mod:`symvi.declaration.mechanics`)."""
from .declaration.mechanics import from_lagrangian, from_system

__all__ = ["from_system", "from_lagrangian"]
