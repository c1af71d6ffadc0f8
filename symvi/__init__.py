"""symvi — a compiler for structure-preserving integrators on Lie groupoids.

Declare a groupoid and a Lagrangian with SymPy (:class:`Model`), compile it to a C
extension (:func:`compile_model`, or ``symvi compile`` on the command line) and integrate
with the generated module, which needs numpy and cffi only.
"""
from .version import __version__  # noqa: E402,F401

from .errors import (BuildError, CacheWarning, CompilerNotFoundError,  # noqa: E402
                     DamagedPackageError, ModelError, SymviError)
from .groupoids import (SE2, SE3, SO3, ActionGroupoid, Groupoid, MatrixLieGroup,  # noqa: E402
                        PairGroupoid, ProductGroupoid)
from .declaration.model import Example, Model, h  # noqa: E402
from ._runtime.core.results import State  # noqa: E402
from ._runtime.core.options import SolveOptions, StepOptions  # noqa: E402
from .declaration.symmetry import Symmetry  # noqa: E402
from .declaration.control import euler_lagrange_operator, optimal_control  # noqa: E402
from .declaration.nonholonomic import distribution, nonholonomic_control  # noqa: E402
from .build import compile_model, load  # noqa: E402


__all__ = ["Model", "Example", "State", "SolveOptions", "StepOptions", "Symmetry", "optimal_control", "euler_lagrange_operator",
           "distribution", "nonholonomic_control", "PairGroupoid", "MatrixLieGroup",
           "ActionGroupoid",
           "ProductGroupoid", "SO3", "SE2", "SE3",
           "Groupoid", "h", "compile_model", "load",
           "ModelError", "BuildError", "CompilerNotFoundError", "DamagedPackageError",
           "CacheWarning", "SymviError", "__version__"]
