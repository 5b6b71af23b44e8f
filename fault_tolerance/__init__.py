"""fault_tolerance: minimum joint-velocity-jump redundancy resolution for locked-joint failures.

Zhao & Li, *An Analytical Algorithm with Minimum Joint Velocity Jump for Redundant Robots in the
Presence of Locked-Joint Failures*, on Pinocchio. Importing this package imports neither meshcat
nor matplotlib.
"""

__version__ = "0.1.0"

from .kernel_cache import refresh as _refresh_kernel_cache  # noqa: E402

_refresh_kernel_cache()  # numba's cache knows a kernel's own file only (kernel_cache.py)

from .api import jvj, resolve  # noqa: E402
from .arm import Arm, parse_task  # noqa: E402
from .bounded import BoundedRates, rate_box, resolve_bounded  # noqa: E402
from .errors import (  # noqa: E402
    FaultToleranceError,
    FrameNotFound,
    InfeasibleBounds,
    IntolerableAtStart,
    IntolerableFailure,
    InvalidInput,
    InvalidScenario,
    InvalidTask,
    JointNotFound,
    RobotNotFound,
    StructurallyIntolerable,
    UnsafeDescription,
    URDFError,
)
from .failures import Scenarios, scenarios  # noqa: E402
from .indices import (  # noqa: E402
    fault_tolerance_measure,
    rcn,
    rcn_gradient,
    reduced_manipulability,
    square_sum_rcn,
)
from .linalg import nullspace_projector, pinv, projection, reduced_rates  # noqa: E402
from .loading import load_arm  # noqa: E402
from .planner import (  # noqa: E402
    RESOLVERS,
    jump_reduction,
    jvja,
    jvja_explicit,
    lnva,
    mda,
)
from .start import StartChoice, default_start  # noqa: E402

__all__ = [
    "__version__",
    "Arm",
    "load_arm",
    "parse_task",
    "Scenarios",
    "scenarios",
    "fault_tolerance_measure",
    "jump_reduction",
    "jvj",
    "rcn",
    "rcn_gradient",
    "reduced_manipulability",
    "square_sum_rcn",
    "nullspace_projector",
    "pinv",
    "projection",
    "reduced_rates",
    "RESOLVERS",
    "jvja",
    "jvja_explicit",
    "lnva",
    "mda",
    "resolve",
    "BoundedRates",
    "rate_box",
    "resolve_bounded",
    "InfeasibleBounds",
    "StartChoice",
    "default_start",
    "FaultToleranceError",
    "FrameNotFound",
    "IntolerableFailure",
    "IntolerableAtStart",
    "StructurallyIntolerable",
    "InvalidInput",
    "InvalidScenario",
    "InvalidTask",
    "JointNotFound",
    "RobotNotFound",
    "UnsafeDescription",
    "URDFError",
]
