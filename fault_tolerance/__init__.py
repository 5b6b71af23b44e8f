"""fault_tolerance: minimum joint-velocity-jump redundancy resolution for locked-joint failures.

Zhao & Li, *An Analytical Algorithm with Minimum Joint Velocity Jump for Redundant Robots in the
Presence of Locked-Joint Failures*, on Pinocchio. This façade is the public API; the layers
below it (``model``, ``resolution``, ``control``, ``simulation``, ``planning``, ``analysis``, …)
are described in docs/architecture.md. Importing the package imports neither meshcat nor
matplotlib, and compiles nothing.

Example:
    >>> import numpy as np, fault_tolerance as ft
    >>> arm = ft.load_arm("planar_3r")
    >>> J = arm.jacobian(np.array([0.3, 1.2, 1.0]))
    >>> qd = ft.resolve("jvja", J, np.array([0.1, 0.0]), lockable=[1, 2])
    >>> bool(np.allclose(J @ qd, [0.1, 0.0]))
    True
"""

from fault_tolerance.analysis import batch  # noqa: E402
from fault_tolerance.control.controller import Controller  # noqa: E402
from fault_tolerance.errors import (  # noqa: E402
    AmbiguousFrame,
    DescriptionError,
    DynamicsUnavailable,
    FaultToleranceError,
    FolderLocked,
    FrameNotFound,
    IncompleteResult,
    InfeasibleBounds,
    IntolerableAtStart,
    IntolerableFailure,
    IntolerableUnderLimits,
    InvalidInput,
    InvalidScenario,
    InvalidTask,
    JointNotFound,
    MeshNotFound,
    MeshRefused,
    MJCFError,
    NoStartFound,
    OutputError,
    PackageNotFound,
    RobotNotFound,
    StructurallyIntolerable,
    UnknownFormat,
    UnsafeDescription,
    URDFError,
)
from fault_tolerance.model.arm import Arm, parse_task  # noqa: E402
from fault_tolerance.model.joint_limits import rate_box  # noqa: E402
from fault_tolerance.model.loading import load_arm  # noqa: E402
from fault_tolerance.numerics.linalg import (  # noqa: E402
    nullspace_projector,
    pinv,
    projection,
    reduced_rates,
)
from fault_tolerance.planning.default_start import StartChoice, default_start  # noqa: E402
from fault_tolerance.planning.posture import initial_posture  # noqa: E402
from fault_tolerance.planning.wholepath import run as _global_planner  # noqa: E402, F401 - registers "global"
from fault_tolerance.resolution import registry  # noqa: E402 - the resolvers by name
from fault_tolerance.resolution.api import jvj, resolve  # noqa: E402
from fault_tolerance.resolution.bounded import BoundedRates, resolve_bounded  # noqa: E402
from fault_tolerance.resolution.indices import (  # noqa: E402
    fault_tolerance_measure,
    rcn,
    rcn_gradient,
    reduced_manipulability,
    square_sum_rcn,
)
from fault_tolerance.resolution.jvja import jvja, jvja_explicit  # noqa: E402
from fault_tolerance.resolution.lnva import lnva  # noqa: E402
from fault_tolerance.resolution.mda import mda  # noqa: E402
from fault_tolerance.resolution.registry import ResolverEntry  # noqa: E402
from fault_tolerance.resolution.resolvers import jump_reduction  # noqa: E402
from fault_tolerance.resolution.scenarios import Scenarios, scenarios  # noqa: E402
from fault_tolerance.simulation.paths import (  # noqa: E402
    CirclePath,
    FunctionPath,
    SampledPath,
    TaskPath,
    load_csv,
)
from fault_tolerance.simulation.run import Run  # noqa: E402
from fault_tolerance.simulation.setup import ServoModel  # noqa: E402
from fault_tolerance.simulation.simulate import simulate  # noqa: E402
from fault_tolerance.version import __version__

__all__ = [
    "__version__",
    # arms
    "Arm",
    "load_arm",
    "parse_task",
    "rate_box",
    # scenarios, indices, resolvers
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
    "registry",
    "ResolverEntry",
    "jvja",
    "jvja_explicit",
    "lnva",
    "mda",
    "resolve",
    "BoundedRates",
    "resolve_bounded",
    # control, runs, paths, starts, batches
    "Controller",
    "simulate",
    "Run",
    "ServoModel",
    "TaskPath",
    "CirclePath",
    "SampledPath",
    "FunctionPath",
    "load_csv",
    "StartChoice",
    "default_start",
    "initial_posture",
    "batch",
    # errors
    "AmbiguousFrame",
    "DescriptionError",
    "DynamicsUnavailable",
    "FaultToleranceError",
    "FolderLocked",
    "FrameNotFound",
    "IncompleteResult",
    "InfeasibleBounds",
    "IntolerableAtStart",
    "IntolerableFailure",
    "IntolerableUnderLimits",
    "InvalidInput",
    "InvalidScenario",
    "InvalidTask",
    "JointNotFound",
    "MeshNotFound",
    "MeshRefused",
    "MJCFError",
    "NoStartFound",
    "OutputError",
    "PackageNotFound",
    "RobotNotFound",
    "StructurallyIntolerable",
    "UnknownFormat",
    "URDFError",
    "UnsafeDescription",
]


def __dir__() -> list[str]:
    """The public names only: the layers' modules are reached by their paths, not from here."""
    return sorted(__all__)
