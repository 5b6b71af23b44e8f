"""The toolkit's exceptions: one base class, data in the message, no bare asserts."""

from __future__ import annotations

from collections.abc import Sequence


class FaultToleranceError(Exception):
    """Base class of the toolkit's errors (the CLI turns these into exit code 2)."""


class RobotNotFound(FaultToleranceError):
    """A robot name is neither a catalog entry, an example-robot-data name nor a file.

    The message lists the arms that suit the command (``suits``, default: the shipped arms and the
    example-robot-data arms with a preset), the closest names among all ``known`` ones, and says
    that ``fault-tolerance robots --all`` lists every example-robot-data model.
    """

    def __init__(
        self,
        name: str,
        known: Sequence[str],
        suits: Sequence[str] | None = None,
        command: str | None = None,
    ) -> None:
        import difflib

        self.name, self.known = name, sorted(known)
        self.suits = list(known if suits is None else suits)
        close = difflib.get_close_matches(name, self.known, n=3, cutoff=0.6)
        hint = f"did you mean {' or '.join(repr(c) for c in close)}? " if close else ""
        what = f"arms that suit `{command}`" if command else "arms with a preset"
        super().__init__(
            f"robot '{name}' is not a shipped robot, an example-robot-data arm or an existing "
            f"URDF file; {hint}{what}: {self.suits} (`fault-tolerance robots`; "
            "`fault-tolerance robots --all` lists every example-robot-data model, loadable with "
            "--robot NAME --tip FRAME)"
        )


class JointNotFound(FaultToleranceError):
    """A joint name is not among the joints it may be chosen from."""

    def __init__(self, name: str, joints: Sequence[str]) -> None:
        super().__init__(f"joint '{name}' is not in the model; its joints are {list(joints)}")


class FrameNotFound(FaultToleranceError):
    """A frame name is not in the model."""

    def __init__(self, name: str, frames: Sequence[str]) -> None:
        super().__init__(f"frame '{name}' is not in the model; its frames are {list(frames)}")


class AmbiguousFrame(FrameNotFound):
    """Several frames of the model carry the name, at different places (e.g. a link and a joint)."""

    def __init__(self, name: str, frames: Sequence[str]) -> None:
        FaultToleranceError.__init__(
            self,
            f"frame name '{name}' is ambiguous: {len(frames)} frames at different places carry it "
            f"({', '.join(frames)}); rename the link or the joint in the URDF so the tip is unique",
        )


class DescriptionError(FaultToleranceError):
    """A robot description (URDF, xacro, MJCF) cannot be read or turned into an arm."""


class URDFError(DescriptionError):
    """A URDF file cannot be read or turned into an arm."""


class MJCFError(DescriptionError):
    """A MuJoCo MJCF file cannot be read or turned into an arm."""


class UnknownFormat(DescriptionError):
    """A file is in none of the description formats the toolkit reads."""

    def __init__(self, path, formats: Sequence[str]) -> None:
        self.formats = list(formats)
        super().__init__(
            f"{path}: not a robot description the toolkit reads; the known formats are "
            f"{self.formats} (URDF: .urdf or .xml with <robot>; xacro: .xacro, .urdf.xacro; "
            "MJCF: .xml with <mujoco>)"
        )


class PackageNotFound(URDFError):
    """A ``package://pkg`` or ``$(find pkg)`` names a package none of the package folders holds."""

    def __init__(
        self, package: str, package_dirs: Sequence[str], where: str = "", note: str = ""
    ) -> None:
        self.package = package
        dirs = [str(d) for d in package_dirs]
        looked = f"looked in {dirs} and below" if dirs else "no package folder was given"
        super().__init__(
            f"{where + ': ' if where else ''}package '{package}' not found ({looked}"
            f"{'; ' + note if note else ''}); pass the folder that holds '{package}/', whose "
            "package.xml names it, or a workspace with it below, with package_dirs=[...] "
            "(--package-dir DIR, repeatable)"
        )


class UnsafeDescription(URDFError):
    """A description that would run code, read a file it should not, or expand without bound.

    Raised for a xacro ``${...}`` expression outside the accepted ones (docs/xacro.md), a read
    outside the folders the user named, or an expansion past one of the limits of
    :mod:`fault_tolerance.xacro_eval`. The message names the file, the line where it can be had
    and the expression or file refused.
    """


class MeshNotFound(URDFError):
    """A mesh file a description names is not where its name leads, inside the allowed folders."""

    def __init__(self, uri: str, reason: str) -> None:
        self.uri = uri
        super().__init__(f"mesh {uri[:120]!r}: {reason}")


class MeshRefused(UnsafeDescription):
    """A mesh name leads outside the folders a description may read (``..``, a link, a path)."""

    def __init__(self, uri: str, reason: str) -> None:
        self.uri = uri
        super().__init__(f"mesh {uri[:120]!r}: {reason}")


class InvalidTask(FaultToleranceError):
    """A task specification is not one of the allowed ones."""


class InvalidScenario(FaultToleranceError):
    """A lockable set or failure scenario is empty, duplicated, out of range or too large."""


class IntolerableFailure(FaultToleranceError):
    """Locking these joints loses the task: the reduced Jacobian drops rank (N[S, S] singular)."""

    def __init__(self, joints: Sequence[str], pivot: float) -> None:
        self.joints = list(joints)
        self.pivot = pivot
        names = ", ".join(self.joints)
        super().__init__(
            f"locking {names} loses the task (N[S, S] is singular, smallest pivot {pivot:.2e}): "
            f"the remaining joints cannot keep the tool on its path; remove {names} from the "
            "lockable joints"
        )


class StructurallyIntolerable(IntolerableFailure):
    """Locking these joints loses the task at every sampled configuration, not only at this one."""

    def __init__(self, joints: Sequence[str], pivot: float, samples: int) -> None:
        self.joints = list(joints)
        self.pivot = pivot
        self.samples = samples
        names = ", ".join(self.joints)
        FaultToleranceError.__init__(
            self,
            f"locking {names} loses the task structurally: N[S, S] is singular at every one of "
            f"{samples} sampled regular configurations (here: smallest pivot {pivot:.2e}), so no "
            f"start helps; remove {names} from the lockable joints",
        )


class IntolerableAtStart(IntolerableFailure):
    """Locking these joints loses the task at this start only; ``q0`` is a start that works."""

    def __init__(
        self, joints: Sequence[str], pivot: float, q0: Sequence[float] | None, why: str = ""
    ) -> None:
        self.joints = list(joints)
        self.pivot = pivot
        self.q0 = None if q0 is None else [float(v) for v in q0]
        names = ", ".join(self.joints)
        if self.q0 is None:
            advice = f"choose another start (--q0/--x0) or remove {names} from the lockable joints"
        else:
            advice = (
                f"a start that works: --q0 {','.join(f'{v:.6f}' for v in self.q0)}"
                + (f" ({why})" if why else "")
                + f"; or remove {names} from the lockable joints"
            )
        FaultToleranceError.__init__(
            self,
            f"locking {names} loses the task at this start only (N[S, S] is singular here, "
            f"smallest pivot {pivot:.2e}, but not at other configurations); {advice}",
        )


class InvalidInput(FaultToleranceError, ValueError):
    """A numeric input (configuration, rate, time step, path) has the wrong shape or value.

    Also a ``ValueError``, so code that catches NumPy-style value errors catches it too.
    """


class NoStartFound(InvalidInput):
    """No candidate start passed the default start's checks; why, by category, and what works.

    ``reasons``: ``(category, count, joints)`` of the dominant failure categories (see
    ``fault_tolerance.planning.start_checks.CATEGORIES``); ``fixes``: option texts that were tried
    and found a start (the command line adds them; empty when none was tried or none worked);
    ``still``: joints that do not move the tip (a tip at the wrist centre, named in the message as
    the cause; empty otherwise).
    """

    def __init__(
        self,
        message: str,
        reasons: Sequence[tuple[str, int, tuple[str, ...]]] = (),
        fixes: Sequence[str] = (),
        still: Sequence[str] = (),
    ) -> None:
        self.reasons = [(c, int(n), tuple(j)) for c, n, j in reasons]
        self.fixes = list(fixes)
        self.still = tuple(still)
        super().__init__(message)


class DynamicsUnavailable(FaultToleranceError):
    """An arm's description cannot serve dynamics (no usable inertias), or a dynamics option is wrong."""


class InfeasibleBounds(FaultToleranceError):
    """No joint rates inside the rate box of the joint limits reach the task, not even scaled to 0."""


class IntolerableUnderLimits(IntolerableFailure):
    """Locking these joints leaves a robot that cannot keep the task inside its joint limits at q."""

    def __init__(self, joints: Sequence[str], scale: float) -> None:
        self.joints = list(joints)
        self.pivot = float("nan")
        self.scale = scale
        names = ", ".join(self.joints)
        FaultToleranceError.__init__(
            self,
            f"locking {names} is intolerable under limits here: inside their rate box the other "
            f"joints reach only {100 * scale:.3g}% of the task velocity; slow the task, start "
            f"farther from the limits, or remove {names} from the lockable joints",
        )


class IncompleteResult(FaultToleranceError):
    """A result folder is not whole: no completion record, or files that differ from it."""


class OutputError(FaultToleranceError):
    """The file system refused to take a result (full, read-only, permissions); nothing was moved."""


class FolderLocked(FaultToleranceError):
    """Another live process is writing the output folder."""

    def __init__(self, folder, holder: dict) -> None:
        self.folder = folder
        self.holder = dict(holder)
        who = f"pid {holder.get('pid', '?')}"
        if holder.get("host"):
            who += f" on {holder['host']}"
        if holder.get("command"):
            who += f": {holder['command']}"
        since = f", since {holder['started']}" if holder.get("started") else ""
        super().__init__(
            f"{folder}: another command is writing this folder ({who}{since}); wait for it to "
            "finish or choose another output folder"
        )
