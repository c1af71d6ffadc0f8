"""Lie groupoids known to the derivation engine (DESIGN.md §2)."""
from .action import ActionGroupoid
from .base import Groupoid
from .lie import SE2, SE3, SO3, MatrixLieGroup
from .pair import PairGroupoid
from .product import ProductGroupoid

__all__ = ["Groupoid", "PairGroupoid", "MatrixLieGroup", "ActionGroupoid", "ProductGroupoid",
           "SO3", "SE2", "SE3"]
