"""Bundled models, usable by name on the command line (``symvi compile pendulum``) and in tests.

Each module of this package defines ``model``, a :class:`symvi.Model`; models on matrix
groups also define ``build(retraction)``, and ``<name>_exp`` is ``build("exp")``.
"""
from __future__ import annotations

import importlib
import runpy
import traceback
from pathlib import Path

from ..errors import ModelError
from ..declaration.model import Model

_GROUP_MODELS = ("rigid_body", "heavy_top", "spherical_pendulum", "planar_body", "se3_body",
                 "rigid_body_oc", "heavy_top_rotors_oc")
#: Lagrangians of order k > 2 (issue 25): minimum jerk (k = 3) and snap (k = 4) on the
#: pair groupoid, their analogues in the Lie algebras of SO(3) and SE(3).
HIGHER_ORDER = ("minimum_jerk", "minimum_snap", "so3_jerk", "se3_snap")
#: Optimal control of nonholonomic systems on D⁽²⁾ (issue 25): first-order constrained
#: models on D × D, solved as whole trajectories.
NONHOLONOMIC = ("unicycle_parking", "chaplygin_sled", "rolling_coin")
BUNDLED = ("harmonic_oscillator", "pendulum", "double_pendulum", "robot_arm", "cubic_spline",
           "spline_potential", "so3_cubic", "double_pendulum_oc", "cart_pole_oc",
           "heavy_top_rotors_oc_variational", "spacecraft_slew", "minimum_time_slew",
           "cart_pole_swing_up", "planar_flyer", "cart_pole_catch",
           "minimum_time_double_integrator") + HIGHER_ORDER + NONHOLONOMIC \
    + tuple(f"{name}{suffix}" for name in _GROUP_MODELS for suffix in ("", "_exp"))
#: Optimal-control problems (constrained second-order models solved as whole trajectories).
CONTROL = ("rigid_body_oc", "rigid_body_oc_exp", "heavy_top_rotors_oc",
           "heavy_top_rotors_oc_exp", "heavy_top_rotors_oc_variational",
           "double_pendulum_oc", "cart_pole_oc")
#: Optimal-control problems with bounds (inequalities; the interior-point solve).
BOUNDED = ("spacecraft_slew", "minimum_time_slew", "cart_pole_swing_up", "planar_flyer",
           "cart_pole_catch", "minimum_time_double_integrator")


def get(name: str) -> Model:
    """The bundled model called ``name``."""
    if name not in BUNDLED:
        raise ModelError(f"no bundled model {name!r}; bundled models: {', '.join(BUNDLED)}")
    if name.endswith("_exp"):
        return importlib.import_module(f"{__name__}.{name[:-4]}").build("exp")
    return importlib.import_module(f"{__name__}.{name}").model


def load(spec: str) -> Model:
    """A bundled model by name, or the ``model`` defined by a Python model file."""
    return load_with_equations(spec)[0]


def load_with_equations(spec: str) -> tuple[Model, tuple]:
    """The model named by ``spec`` and the hand-derived equations that come with it.

    ``spec`` is a bundled model name (no equations), a paper fixture name
    (:data:`symvi.fixtures.FIXTURES`: the model and the paper's printed equations) or a
    Python model file defining ``model`` and, optionally, ``equations``.
    """
    from ..fixtures import FIXTURES
    path = Path(spec)
    if path.suffix != ".py":
        if spec in FIXTURES:
            module = importlib.import_module(f"{__package__.rsplit('.', 1)[0]}.fixtures.{spec}")
            return module.model, tuple(module.equations)
        return get(spec), ()
    if not path.is_file():
        raise ModelError(f"model file {spec!r} does not exist")
    namespace = _run_model_file(path, spec)
    model = namespace.get("model")
    if not isinstance(model, Model):
        found = [k for k, v in namespace.items() if isinstance(v, Model)]
        hint = f" (found Model objects named {found})" if found else ""
        raise ModelError(f"model file {spec!r} must define `model = symvi.Model(...)`{hint}")
    return model, tuple(namespace.get("equations", ()))


def _run_model_file(path: Path, spec: str) -> dict:
    """The namespace of the model file ``path``; a syntax error or an exception in it is a
    :class:`ModelError` naming the file and line (a ModelError of its own passes)."""
    try:
        return runpy.run_path(str(path))
    except ModelError:
        raise
    except SyntaxError as exc:
        text = f": {exc.text.strip()}" if exc.text and exc.text.strip() else ""
        raise ModelError(f"model file {spec!r}: syntax error at line {exc.lineno}: "
                         f"{exc.msg}{text}") from None
    except Exception as exc:
        lines = [frame.lineno for frame in traceback.extract_tb(exc.__traceback__)
                 if Path(frame.filename).resolve() == path.resolve()]
        where = f" at line {lines[-1]}" if lines else ""
        raise ModelError(f"model file {spec!r} raised {type(exc).__name__}{where}: "
                         f"{exc}") from exc
