"""Errors raised by generated modules.

:class:`NewtonError` is defined in :mod:`.results`, beside the results it carries, so
that it is shared by every package of one runtime like them (see there).
"""
from .results import NewtonError

__all__ = ["NewtonError"]
