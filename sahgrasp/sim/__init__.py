"""Physics hold test of grasps in MuJoCo (the optional extra ``pip install "sahgrasp[sim]"``).

:func:`hold_test` squeezes a grasp and pulls the object in six directions, DexGraspNet's and
BODex's benchmark way; :class:`HoldTester` tests many grasps of one object with one compiled
model. docs/methods/physics.md describes the model, its parameters and the criterion.
"""

from sahgrasp.core.extras import require_extra

try:
    import mujoco  # noqa: F401
except ImportError:  # the optional extra is missing: the one error naming it
    require_extra("sim", "sahgrasp.sim")

from sahgrasp.sim.batch import (
    GraspToCheck,
    ResultsFileError,
    check_grasps,
    grasp_configuration,
    read_grasps,
    summarize,
)
from sahgrasp.sim.hold import REASONS, DirectionResult, HoldResult, HoldTester, Squeeze, hold_test
from sahgrasp.sim.model import SimModel, SimModelError, build_model
from sahgrasp.sim.settings import (
    DEXGRASPBENCH_MASS_KG,
    DIRECTIONS,
    LIGHT_SQUEEZE_N,
    HoldSettings,
    dexgraspbench_solver,
    soft_friction,
)

__all__ = [
    "DEXGRASPBENCH_MASS_KG",
    "DIRECTIONS",
    "LIGHT_SQUEEZE_N",
    "REASONS",
    "DirectionResult",
    "GraspToCheck",
    "HoldResult",
    "HoldSettings",
    "HoldTester",
    "ResultsFileError",
    "SimModel",
    "SimModelError",
    "Squeeze",
    "build_model",
    "check_grasps",
    "dexgraspbench_solver",
    "grasp_configuration",
    "hold_test",
    "read_grasps",
    "soft_friction",
    "summarize",
]
