"""Lie groupoids known to the derivation engine (DESIGN.md §2)."""
from .base import Groupoid
from .pair import PairGroupoid

__all__ = ["Groupoid", "PairGroupoid"]
