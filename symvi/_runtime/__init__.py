"""Run-time support copied into every generated package.

In four parts whose imports run one way: ``core/`` (infrastructure) ← ``step/`` (the step
map) ← ``bvp/`` (the whole-trajectory Newton) ← ``bounded/`` (the interior point). This
file and ``compiled.py`` load ``core/`` and ``step/``, which need numpy (and cffi through
the extension) only; ``bvp/`` is imported on a model's first whole-trajectory call, and
``bounded/`` (and SciPy) only by a solve that needs it. Never imports SymPy or symvi.
"""
from .compiled import CompiledModel
from .core.options import SolveOptions, StepOptions
from .core.results import BatchResult, BVPBatch, BVPResult, NewtonError, State, Status, StepResult

__all__ = ["CompiledModel", "NewtonError", "State", "StepResult", "BVPResult", "BatchResult",
           "BVPBatch", "Status", "SolveOptions", "StepOptions"]
