"""Run-time support copied into every generated package.

Depends on numpy (and cffi through the extension) only; SciPy is imported lazily by the
whole-trajectory solver. Never imports SymPy or symvi.
"""
from .compiled import CompiledModel
from .options import SolveOptions, StepOptions
from .results import BatchResult, BVPBatch, BVPResult, NewtonError, State, Status, StepResult

__all__ = ["CompiledModel", "NewtonError", "State", "StepResult", "BVPResult", "BatchResult",
           "BVPBatch", "Status", "SolveOptions", "StepOptions"]
