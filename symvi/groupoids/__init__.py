"""Lie groupoids known to the derivation engine (DESIGN.md §2)."""
from .base import Groupoid
from .lie import SE2, SE3, SO3, MatrixLieGroup
from .pair import PairGroupoid

__all__ = ["Groupoid", "PairGroupoid", "MatrixLieGroup", "SO3", "SE2", "SE3"]
