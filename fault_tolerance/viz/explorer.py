"""An interactive explorer of one lock: arm, lockable joints, algorithm, lock joint and time.

:class:`Explorer` holds the choices and the runs they need; :meth:`Explorer.update` changes some
of them and re-runs only what depends on them:

* the start and the planned run (no lock) once per arm, lockable set and algorithm: the start is
  :func:`~fault_tolerance.planning.default_start.default_start`'s (as ``fault-tolerance lock``
  chooses it), the path the arm's catalog circle (a 5 cm circle of 1 s for other arms);
* the lock run once per lock joint and lock sample. With perfect rate tracking (``tau = 0``, the
  default) a run is a function of ``q`` and ``t`` alone (docs/MATH.md (R1)), so the lock run *is*
  the planned run up to the lock and only the rest is simulated: from the planned run's
  configuration at the lock sample, along the path shifted by the lock time, with the joint
  locking at once (:func:`replay_from_lock`). With a servo lag (``tau > 0``) the servo's state is not a run's
  start, and the whole lock run is simulated.

The jump at the lock is the run's ``summary()["jump_at_lock"]``, the number ``fault-tolerance
lock`` prints: ``‖q̇_after − q̇_before‖²`` [(rad/s)²] of the commanded rates at the lock sample.

:meth:`Explorer.figure` draws λ(t) and K(t) of the planned run and the path error of the lock run,
the lock time marked and the jump stated; :meth:`Explorer.scene_html` is the self-contained
meshcat replay of the lock run (:func:`~fault_tolerance.viz.page.embed`); :meth:`Explorer.widgets`
wires ipywidgets controls to :meth:`Explorer.update`. matplotlib, meshcat and ipywidgets are
imported when first needed.

Example:
    >>> from fault_tolerance.viz.explorer import Explorer
    >>> ex = Explorer("planar_3r", algorithm="lnva", lock_joint="joint2", lock_time=0.4)
    >>> ex.lock_run.meta["lock"]["joint"]
    'joint2'
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from fault_tolerance.errors import FaultToleranceError, IntolerableFailure, InvalidInput
from fault_tolerance.model.arm import Arm
from fault_tolerance.simulation.paths import TaskPath
from fault_tolerance.simulation.run import ARRAYS, Run

#: What :meth:`Explorer.update` changes, in the order it applies them.
CHOICES = ("arm", "lockable", "algorithm", "lock_joint", "lock_time")
#: Task-space feedback gain ``K_p`` [1/s] of the runs: ``fault-tolerance lock``'s default.
FEEDBACK_GAIN = 10.0
#: The path of an arm outside the catalog: a circle of this radius [m], 2π rad/s, 1 s.
DEFAULT_RADIUS = 0.05


@dataclass(frozen=True)
class ShiftedPath(TaskPath):
    """``base`` from ``offset`` seconds on: ``x(t) = base.x(t + offset)`` over ``duration`` [s]."""

    base: TaskPath
    offset: float
    duration: float

    def __post_init__(self) -> None:
        if not (np.isfinite(self.offset) and 0 <= self.offset < self.base.duration):
            raise InvalidInput(
                f"shift must be within [0, {self.base.duration}) s, got {self.offset}"
            )
        if not (np.isfinite(self.duration) and self.duration > 0):
            raise InvalidInput(f"duration must be a finite number > 0 [s], got {self.duration}")

    @property
    def x0(self) -> np.ndarray:
        """Start position: the base path's at ``offset``."""
        return np.asarray(self.base.x(self.offset), dtype=float)

    def x(self, t: float) -> np.ndarray:
        """Desired task position at ``t`` [s] of the shifted path."""
        return self.base.x(t + self.offset)

    def xdot(self, t: float) -> np.ndarray:
        """Desired task velocity at ``t`` [s] of the shifted path."""
        return self.base.xdot(t + self.offset)

    def sample(self, ts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(x, ẋ)`` at the times ``ts``, shape (K, m) each."""
        shifted = np.asarray(ts, dtype=float) + self.offset
        if hasattr(self.base, "sample"):
            return self.base.sample(shifted)
        X = np.array([np.asarray(self.base.x(t), dtype=float).reshape(-1) for t in shifted])
        XD = np.array([np.asarray(self.base.xdot(t), dtype=float).reshape(-1) for t in shifted])
        return X, XD

    def spec(self) -> dict:
        """The base path's description, with the shift."""
        return {**self.base.spec(), "shift": self.offset, "duration": self.duration}


def lock_sample(t: np.ndarray, lock_time: float) -> int:
    """The sample at which a joint locking at ``lock_time`` [s] stops: the first at or after it."""
    return int(np.argmax(t >= lock_time - 1e-12)) if t[-1] >= lock_time - 1e-12 else len(t) - 1


# Eqn. (R1)
def replay_from_lock(arm: Arm, path: TaskPath, planned: Run, joint: str, lock_time: float,
                     **sim) -> Run:  # fmt: skip
    """The lock run of ``planned`` (perfect rate tracking) with only the part after the lock run.

    Up to the lock sample ``k`` the lock run equals ``planned`` (the same start, rates, feedback
    and rate box, all functions of ``q`` and ``t``); from ``k`` on it is a run from
    ``planned.q[k]`` along ``path`` shifted by ``t[k]``, the joint locking at once. ``sim``: the
    options of the planned run (``lockable``, ``dt``, ``feedback_gain``, ``limits``, ...).
    Falls back to the whole lock run when the rest is too short to be a run or its start is
    intolerable (the whole run damps such a sample instead of refusing it).
    """
    from fault_tolerance.simulation.setup import ServoModel
    from fault_tolerance.simulation.simulate import simulate

    algorithm = planned.meta["algorithm"]
    servo = ServoModel(tau=0.0)
    whole = dict(sim, lock_joint=joint, lock_time=lock_time, servo=servo)
    k = lock_sample(planned.t, lock_time)
    rest = planned.meta["duration"] - float(planned.t[k])
    if k == 0 or k >= len(planned.t) - 1:
        return simulate(arm, path, algorithm, q0=planned.q[0], **whole)
    tail_path = ShiftedPath(path, float(planned.t[k]), rest)
    try:
        tail = simulate(arm, tail_path, algorithm, q0=planned.q[k], **dict(
            whole, duration=rest, lock_time=0.0))  # fmt: skip
    except IntolerableFailure:
        return simulate(arm, path, algorithm, q0=planned.q[0], **whole)
    if len(tail.t) != len(planned.t) - k:  # the rest's samples do not fall on the run's
        return simulate(arm, path, algorithm, q0=planned.q[0], **whole)
    return _stitch(planned, tail, k, lock_time)


def _stitch(planned: Run, tail: Run, k: int, lock_time: float) -> Run:
    """``planned`` up to sample ``k``, then ``tail``: one lock run with the planned run's record."""
    arrays = {
        name: np.concatenate([getattr(planned, name)[:k], getattr(tail, name)])
        for name in ARRAYS
        if name != "t"
    }
    head_cmd = planned.qd if planned.qd_cmd is None else planned.qd_cmd
    tail_cmd = tail.qd if tail.qd_cmd is None else tail.qd_cmd
    orientation = None
    if planned.orientation_error is not None and tail.orientation_error is not None:
        orientation = np.concatenate([planned.orientation_error[:k], tail.orientation_error])
    lock = dict(tail.meta["lock"], time=float(lock_time))
    meta = dict(planned.meta, servo=tail.meta["servo"], lock=lock)
    return Run(
        t=planned.t.copy(),
        meta=meta,
        qd_cmd=np.concatenate([head_cmd[:k], tail_cmd]),
        arm_record=planned.arm_record,
        orientation_error=orientation,
        **arrays,
    )


def _circle(arm: Arm, entry: dict | None, duration: float | None):
    """``x0 -> CirclePath``: the catalog's circle of the arm, or the default one (5 cm, 1 s)."""
    from fault_tolerance.simulation.paths import CirclePath

    spec = (entry or {}).get("path", {})
    length = float(duration if duration is not None else spec.get("duration", 1.0))

    def circle(x0):
        return CirclePath(
            np.asarray(x0, dtype=float),
            spec.get("radius", DEFAULT_RADIUS),
            spec.get("omega", 2 * np.pi),
            length,
            rows=tuple(spec.get("rows", (0, 1))),
            sign=spec.get("sign", 1.0),
        )

    return circle


@dataclass(frozen=True)
class Setting:
    """What the explorer shows: the arm, its lockable joints, the algorithm, the lock."""

    arm: str
    lockable: tuple[str, ...]
    algorithm: str
    lock_joint: str
    lock_time: float  # [s]


class Explorer:
    """One lock of one arm, explored: the state, its runs (cached) and their views.

    Args:
        arm: A catalog name (``"planar_3r"``), an example-robot-data name, a description path,
            or an :class:`~fault_tolerance.model.arm.Arm` (e.g. loaded with package folders).
        lockable: Joints that may lock (default: the arm's default lockable joints).
        algorithm: A registered resolver (default ``"jvja"``): one of :attr:`algorithms`.
        lock_joint: The joint that locks (default: the first lockable one).
        lock_time: When it locks [s] (default: the moment of the planned run's largest λ, as
            ``lock --at max``).
        duration: Length of the path [s] (default: the catalog's, else 1 s).
        dt: Time step [s].
        tau: Servo time constant [s] of the lock run (0: perfect rate tracking, the lock run
            re-played from the lock only; > 0: the whole lock run is simulated).
        limits: Honour the joint limits (``fault-tolerance lock``'s default).
        arms: The arms the arm control offers (default: the catalog's, and ``arm`` if another).
    """

    def __init__(
        self,
        arm: str | Path | Arm = "planar_3r",
        lockable: Sequence[str] | None = None,
        algorithm: str = "jvja",
        lock_joint: str | None = None,
        lock_time: float | None = None,
        *,
        duration: float | None = None,
        dt: float = 1e-3,
        tau: float = 0.0,
        limits: bool = True,
        arms: Sequence[str] | None = None,
    ) -> None:
        from fault_tolerance.model.catalog import catalog
        from fault_tolerance.simulation.setup import ServoModel

        self.servo = ServoModel(tau=float(tau))  # validates tau
        self.duration, self.dt, self.limits = duration, float(dt), bool(limits)
        self._arms: dict[str, Arm] = {}
        self._starts: dict = {}
        self._planned: dict = {}
        self._locks: dict = {}
        self.widget_controls: dict = {}
        self.lines: dict = {}
        self._fig = None
        self._syncing = False
        label = self._add_arm(arm)
        self.arms = tuple(dict.fromkeys([*(catalog() if arms is None else arms), label]))
        self.setting = self._fresh(label)
        self.update(lockable=lockable, algorithm=algorithm, lock_joint=lock_joint,
                    lock_time=lock_time)  # fmt: skip

    # -- the state ---------------------------------------------------------------------------

    @property
    def algorithms(self) -> tuple[str, ...]:
        """The algorithms offered: registered resolvers, then the whole-path planners.

        The resolvers are those that run with this explorer's joint limits setting; the planners
        (``global``) have their lock runs simulated whole.
        """
        import fault_tolerance.planning.wholepath.run  # noqa: F401 - registers "global"
        from fault_tolerance.resolution.registry import get, names
        from fault_tolerance.simulation.simulate import PATH_PLANNERS

        steps = (n for n in names() if not self.limits or get(n).bounded is not None)
        return (*steps, *PATH_PLANNERS)

    @property
    def arm(self) -> Arm:
        """The arm shown."""
        return self._arms[self.setting.arm]

    def _add_arm(self, arm) -> str:
        """Load ``arm`` (once) and return its label in :attr:`arms`."""
        from fault_tolerance.model.loading import load_arm

        if isinstance(arm, Arm):
            label = arm.name
            if self._arms.get(label, arm) is not arm:  # another arm of that name: its runs go
                for cache in (self._starts, self._planned, self._locks):
                    for key in [k for k in cache if k[0] == label]:
                        del cache[key]
            self._arms[label] = arm
        else:
            label = str(arm)
            if label not in self._arms:
                self._arms[label] = load_arm(arm)
        return label

    def _fresh(self, label: str) -> Setting:
        """The setting of a newly chosen arm: its default lockable joints, the first of them."""
        arm = self._arms[label]
        lockable = tuple(_single_joints(arm, arm.default_lockable))
        algorithm = getattr(self, "setting", None)
        alg = algorithm.algorithm if algorithm else self.algorithms[0]
        return Setting(label, lockable, alg, lockable[0], -1.0)  # lock time: set on update

    def update(self, **changes) -> Run:
        """Change some of :data:`CHOICES` (``None``: keep), re-run what they need; the lock run.

        A new arm resets the lockable joints and the lock joint to the arm's defaults and the
        lock time to the planned run's largest jump, unless given in the same call. An unknown
        choice or value raises :class:`InvalidInput` naming the allowed ones.
        """
        unknown = sorted(set(changes) - set(CHOICES))
        if unknown:
            raise InvalidInput(f"unknown choice(s) {unknown}; the explorer's are {list(CHOICES)}")
        s = self.setting
        if changes.get("arm") is not None:
            label = self._check_arm(changes["arm"])
            if label != s.arm:
                s = replace(self._fresh(label), algorithm=s.algorithm)
        s = self._apply(s, {k: v for k, v in changes.items() if k != "arm" and v is not None})
        self.setting = s
        self._redraw()
        return self.lock_run

    def _check_arm(self, arm) -> str:
        """The label of ``arm`` (loaded once): one of :attr:`arms`, or a name or path to load."""
        from fault_tolerance.errors import RobotNotFound

        try:
            label = self._add_arm(arm)
        except RobotNotFound as e:
            raise InvalidInput(
                f"arm {arm!r}: choose one of {list(self.arms)}, an example-robot-data name or a "
                f"description path ({e})"
            ) from e
        self.arms = tuple(dict.fromkeys([*self.arms, label]))  # the arm control offers it now
        return label

    def _apply(self, s: Setting, changes: dict) -> Setting:
        """``s`` with the lockable joints, algorithm, lock joint and time of ``changes``, checked."""
        arm = self._arms[s.arm]
        if "lockable" in changes:
            lockable = tuple(_single_joints(arm, changes["lockable"]))
            joint = s.lock_joint if s.lock_joint in lockable else lockable[0]
            s = replace(s, lockable=lockable, lock_joint=joint)
        if "algorithm" in changes:
            if changes["algorithm"] not in self.algorithms:
                raise InvalidInput(
                    f"algorithm {changes['algorithm']!r} is not one of {list(self.algorithms)}"
                )
            s = replace(s, algorithm=changes["algorithm"])
        if "lock_joint" in changes:
            if changes["lock_joint"] not in s.lockable:
                raise InvalidInput(
                    f"lock joint {changes['lock_joint']!r} is not one of the lockable joints "
                    f"{list(s.lockable)}"
                )
            s = replace(s, lock_joint=changes["lock_joint"])
        planned = self._planned_run(s)
        t = changes.get("lock_time")
        if t is None:  # keep the time when it fits the run, else the largest jump
            end = float(planned.t[-1])
            t = s.lock_time if 0 <= s.lock_time <= end else float(planned.t[np.argmax(planned.jvj)])
        t = float(t)
        if not (np.isfinite(t) and 0 <= t <= float(planned.t[-1])):
            raise InvalidInput(f"lock time must be within [0, {float(planned.t[-1])}] s, got {t}")
        return replace(s, lock_time=t)

    # -- the runs ----------------------------------------------------------------------------

    def _sim(self, s: Setting) -> dict:
        """The options of the runs of ``s`` (besides the start, the path and the lock)."""
        return dict(lockable=list(s.lockable), dt=self.dt, feedback_gain=FEEDBACK_GAIN,
                    limits=self.limits)  # fmt: skip

    def start(self, s: Setting | None = None) -> tuple[np.ndarray, TaskPath]:
        """``(q0, path)`` of ``s`` (default: the current setting): the default start, cached."""
        from fault_tolerance.model.catalog import catalog
        from fault_tolerance.planning.default_start import default_start

        s = s or self.setting
        key = (s.arm, s.lockable, s.algorithm)
        if key not in self._starts:
            arm = self._arms[s.arm]
            entry = catalog().get(arm.name) if arm.source == arm.name else None
            circle = _circle(arm, entry, self.duration)
            x0 = np.array(entry["x0"], dtype=float) if entry and "x0" in entry else None
            sim = self._sim(s)
            choice = default_start(arm, sim.pop("lockable"), x0=x0, path=circle,
                                   algorithms=(s.algorithm,), **sim)  # fmt: skip
            self._starts[key] = (choice.q0, circle(choice.x0))
        return self._starts[key]

    def _planned_run(self, s: Setting) -> Run:
        """The run of ``s`` without a lock (perfect rate tracking), cached."""
        from fault_tolerance.simulation.simulate import simulate

        key = (s.arm, s.lockable, s.algorithm)
        if key not in self._planned:
            q0, path = self.start(s)
            self._planned[key] = simulate(self._arms[s.arm], path, s.algorithm, q0=q0,
                                          **self._sim(s))  # fmt: skip
        return self._planned[key]

    @property
    def planned_run(self) -> Run:
        """The current setting's run without a lock."""
        return self._planned_run(self.setting)

    @property
    def lock_run(self) -> Run:
        """The current setting's lock run, cached per lock joint and lock sample.

        Re-played from the lock (:func:`replay_from_lock`) with perfect rate tracking and a step
        resolver; simulated whole with a servo lag or a whole-path planner (whose tracking of its
        plan counts the samples from the run's start).
        """
        from fault_tolerance.simulation.simulate import PATH_PLANNERS, simulate

        s, planned = self.setting, self.planned_run
        k = lock_sample(planned.t, s.lock_time)
        key = (s.arm, s.lockable, s.algorithm, s.lock_joint, k)
        if key not in self._locks:
            arm, (q0, path) = self._arms[s.arm], self.start(s)
            if self.servo.tau == 0 and s.algorithm not in PATH_PLANNERS:
                run = replay_from_lock(
                    arm, path, planned, s.lock_joint, s.lock_time, **self._sim(s)
                )
            else:
                run = simulate(arm, path, s.algorithm, q0=q0, lock_joint=s.lock_joint,
                               lock_time=s.lock_time, servo=self.servo, **self._sim(s))  # fmt: skip
            self._locks[key] = run
        run = self._locks[key]
        return replace(run, meta=dict(run.meta, lock=dict(run.meta["lock"], time=s.lock_time)))

    @property
    def jump(self) -> float:
        """The jump at the lock, ``‖q̇_after − q̇_before‖²`` [(rad/s)²] (``lock`` prints it)."""
        return float(self.lock_run.summary()["jump_at_lock"])

    def describe(self) -> str:
        """One line: the lock and its jump, with units."""
        s = self.setting
        return (
            f"{s.arm}, {s.algorithm}, lockable {list(s.lockable)}: {s.lock_joint} locks at "
            f"t = {s.lock_time:.3f} s; jump at the lock ‖q̇_after − q̇_before‖² = "
            f"{self.jump:.4g} (rad/s)²"
        )

    # -- the views ---------------------------------------------------------------------------

    def figure(self):
        """The matplotlib figure: λ(t), K(t) of the planned run, path errors; the lock marked."""
        if self._fig is None:
            self._fig = self._new_figure()
            self._redraw()
        return self._fig

    def _new_figure(self):
        from matplotlib.figure import Figure

        fig = Figure(figsize=(9, 6.5), layout="constrained")
        axes = fig.subplots(3, 1, sharex=True)
        self.lines = {
            "lambda": axes[0].plot([], [], color="#1f77b4", lw=1.4, label="λ(t), planned")[0],
            "jump": axes[0].plot([], [], "o", color="#d62728", label="jump at the lock")[0],
            "K": axes[1].plot([], [], color="#2ca02c", lw=1.4, label="K(t), planned")[0],
            "error_planned": axes[2].plot([], [], color="0.5", lw=1.2, label="no lock")[0],
            "error": axes[2].plot([], [], color="#d62728", lw=1.4, label="lock run")[0],
        }
        self.lines["lock"] = [ax.axvline(0.0, color="#d62728", ls="--", lw=1) for ax in axes]
        axes[0].set_ylabel("λ [(rad/s)²]")
        axes[1].set_ylabel("K (square-sum RCN)")
        axes[2].set_ylabel("path error [mm]")
        axes[2].set_xlabel("t [s]")
        for ax in axes:
            ax.grid(alpha=0.3)
            ax.legend(loc="upper right", fontsize=8)
        self._axes = axes
        return fig

    def _redraw(self) -> None:
        """Refresh the figure's lines and the widgets' outputs (when they exist)."""
        if self._fig is not None:
            planned, run, s = self.planned_run, self.lock_run, self.setting
            self.lines["lambda"].set_data(planned.t, planned.jvj)
            self.lines["jump"].set_data([s.lock_time], [self.jump])
            self.lines["K"].set_data(planned.t, planned.K)
            self.lines["error_planned"].set_data(planned.t, 1e3 * planned.error)
            self.lines["error"].set_data(run.t, 1e3 * run.error)
            for line in self.lines["lock"]:
                line.set_xdata([s.lock_time, s.lock_time])
            for ax in self._axes:
                ax.relim()
                ax.autoscale_view()
            self._fig.suptitle(self.describe(), fontsize=9)
        if self.widget_controls:
            self._refresh_widgets()

    def scene_html(self, height: int = 420) -> str:
        """The meshcat replay of the lock run: an iframe holding the self-contained page."""
        from fault_tolerance.viz.page import embed

        shown = embed(self.lock_run, arm=self.arm, height=height)
        return getattr(shown, "data", None) or shown._repr_html_()

    def png(self) -> bytes:
        """The figure as PNG bytes."""
        import io

        buf = io.BytesIO()
        self.figure().savefig(buf, format="png", dpi=80)
        return buf.getvalue()

    # -- the widgets -------------------------------------------------------------------------

    def widgets(self, scene: bool = True):
        """The ipywidgets controls wired to :meth:`update`, the figure and (``scene``) the replay.

        Returns a ``VBox``; the controls are also in :attr:`widget_controls` by choice name
        (``arm``, ``lockable``, ``algorithm``, ``lock_time``, ``lock_joint``), the figure in
        ``widget_controls["figure"]`` (an ``Image``), the replay in ``["scene"]`` (an ``HTML``),
        the last error in ``["message"]``.
        """
        try:
            import ipywidgets as w
        except ImportError as e:  # pragma: no cover - the notebooks extra installs it
            raise ImportError(
                "Explorer.widgets needs ipywidgets: pip install 'fault_tolerance[notebooks]'"
            ) from e
        s, end = self.setting, float(self.planned_run.t[-1])
        c = {
            "arm": w.Dropdown(options=list(self.arms), value=s.arm, description="arm"),
            "lockable": w.SelectMultiple(
                options=self.arm.joint_names, value=s.lockable, description="lockable"
            ),  # fmt: skip
            "algorithm": w.Dropdown(
                options=list(self.algorithms), value=s.algorithm, description="algorithm"
            ),  # fmt: skip
            "lock_joint": w.Dropdown(
                options=list(s.lockable), value=s.lock_joint, description="lock joint"
            ),  # fmt: skip
            "lock_time": w.FloatSlider(
                value=s.lock_time,
                min=0.0,
                max=end,
                step=self.dt,
                readout_format=".3f",
                continuous_update=False,
                description="lock t [s]",
            ),  # fmt: skip
        }
        for name, control in c.items():
            control.observe(self._on_change(name), names="value")
        c["message"] = w.HTML(value="")
        c["figure"] = w.Image(format="png", value=self.png())
        c["scene"] = w.HTML(value=self.scene_html() if scene else "")
        self.widget_controls = c
        self._show_scene = scene
        controls = w.VBox(
            [c[n] for n in ("arm", "lockable", "algorithm", "lock_joint", "lock_time")]
        )
        return w.VBox([w.HBox([controls, c["scene"]]), c["message"], c["figure"]])

    def _on_change(self, name: str):
        def changed(event) -> None:
            if self._syncing:
                return
            value = tuple(event["new"]) if name == "lockable" else event["new"]
            try:
                self.update(**{name: value})
                self.widget_controls["message"].value = ""
            except FaultToleranceError as e:  # shown beside the controls, the state unchanged
                self.widget_controls["message"].value = f"<b>{type(e).__name__}</b>: {e}"
                self._refresh_widgets()

        return changed

    def _refresh_widgets(self) -> None:
        """Set the controls to the state (options of a new arm too), redraw figure and scene."""
        c, s = self.widget_controls, self.setting
        self._syncing = True
        try:
            c["arm"].options = list(self.arms)
            c["arm"].value = s.arm
            c["lockable"].options = self.arm.joint_names
            c["lockable"].value = s.lockable
            c["algorithm"].value = s.algorithm
            c["lock_joint"].options = list(s.lockable)
            c["lock_joint"].value = s.lock_joint
            c["lock_time"].max = max(float(self.planned_run.t[-1]), c["lock_time"].min)
            c["lock_time"].value = s.lock_time
        finally:
            self._syncing = False
        c["figure"].value = self.png()
        if self._show_scene:
            c["scene"].value = self.scene_html()


def _single_joints(arm: Arm, joints) -> list[str]:
    """``joints`` as single-joint names of ``arm``, checked: at least one, each a joint of it."""
    items = list(joints) if joints is not None else []
    names = [j[0] if isinstance(j, (list, tuple)) and len(j) == 1 else j for j in items]
    bad = [j for j in names if not isinstance(j, str) or j not in arm.joint_names]
    if bad or not names:
        raise InvalidInput(
            f"lockable joints {items!r}: choose one or more single joints among {arm.joint_names}"
        )
    return list(dict.fromkeys(names))
