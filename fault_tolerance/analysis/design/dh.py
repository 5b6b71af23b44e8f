"""Dimensional synthesis of serial arms from DH tables: the jump and the RCN on a task (MATH.md (H3)).

The paper ends by asking which joint layout and DH parameters minimise the joint velocity jump
while the reduced condition numbers stay under a threshold. A design space is a base
:class:`~fault_tolerance.model.dh.DHTable` and the parameters that vary (:class:`DHParam`: a
length, an offset, a twist from a set such as {0, ±π/2}, or a joint limit, each with bounds).
Every candidate arm runs the paper's planning on the task (Sec. III.D: the minimum-``K`` start,
then JVJA; :func:`~fault_tolerance.planning.paper_loop.plan`) and is scored by its mean (or
largest) square-sum jump λ, subject to ``max k_S ≤ rcn_max`` along the task (H3).

The search (:mod:`.search_core`) is differential evolution, then a pattern search around the best;
every generation is one chunked, resumable round of :func:`~fault_tolerance.analysis.sweep.run`
(serial or on Dask), so results do not depend on the number of workers and a rerun reuses the
finished chunks.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace

import numpy as np

from fault_tolerance.analysis.design.search import DESIGN_FILES, pareto
from fault_tolerance.errors import FaultToleranceError, InvalidInput
from fault_tolerance.model.dh import DHTable, arm_from_dh, table_from_dict
from fault_tolerance.planning.paper_loop import plan
from fault_tolerance.planning.posture import initial_posture
from fault_tolerance.resolution.indices import RCN_THRESHOLD
from fault_tolerance.simulation.paths import CirclePath, SampledPath

#: What a parameter may vary: a DH field or a joint limit.
FIELDS = ("a", "d", "theta", "alpha", "lower", "upper")
#: Objectives of a DH design (all minimised; manipulability is maximised as its negative).
DH_OBJECTIVES = ("mean-jvj", "max-jvj", "manipulability", "ftw-volume")
#: Sampled failure-tolerant volume of a candidate (objective ftw-volume): grid cells per axis,
#: configurations per set and lock angles per lockable joint (the sampled workspace's settings,
#: stated in design.json). The candidate's joint limits are the artificial limits A, the base
#: table's the physical ones (docs/workspace.md), so ``--vary dh,limits`` designs A.
FTW_SETTINGS = {"grid": 16, "samples": 4000, "theta_samples": 5}
#: Candidates evaluated per chunk of a round.
DH_PER_CHUNK = 4
#: Seeds of the minimum-K start search per candidate (the paper's runs use 24; a search needs speed).
SEARCH_SEEDS = 12


@dataclass(frozen=True)
class DHParam:
    """One varied parameter: ``field`` of joint ``joint`` (1-based) in ``[lo, hi]`` or ``choices``."""

    joint: int
    field: str
    lo: float = 0.0
    hi: float = 0.0
    choices: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        if self.field not in FIELDS:
            raise InvalidInput(f"DH parameter field {self.field!r} is not one of {list(FIELDS)}")
        if self.joint < 1:
            raise InvalidInput(f"DH parameter joints count from 1, got {self.joint}")
        if self.choices:
            if not all(math.isfinite(c) for c in self.choices):
                raise InvalidInput(f"{self.name}: choices must be finite numbers")
        elif not (math.isfinite(self.lo) and math.isfinite(self.hi) and self.lo < self.hi):
            raise InvalidInput(f"{self.name}: bounds need finite lo < hi, got {self.lo}, {self.hi}")

    @property
    def name(self) -> str:
        """The parameter's name: ``a2``, ``alpha3``, ``upper1``."""
        return f"{self.field}{self.joint}"

    def value(self, u: float) -> float:
        """The parameter's value at the unit coordinate ``u ∈ [0, 1]``."""
        u = min(max(float(u), 0.0), 1.0)
        if self.choices:
            return self.choices[min(int(u * len(self.choices)), len(self.choices) - 1)]
        return self.lo + u * (self.hi - self.lo)


def parse_params(text: str) -> tuple[DHParam, ...]:
    """``"d3:0.2:0.6,a4:0.1:0.5,alpha2:{0|pi/2|-pi/2}"`` → the parameters (``--params``)."""
    out = []
    for item in (s.strip() for s in text.split(",") if s.strip()):
        name, _, rest = item.partition(":")
        field = name.rstrip("0123456789")
        joint = name[len(field) :]
        if not joint or not rest:
            raise InvalidInput(
                f"DH parameter {item!r} is not FIELDJOINT:LO:HI or FIELDJOINT:{{A|B|...}} "
                f"(fields {list(FIELDS)}, e.g. d3:0.2:0.6 or alpha2:{{0|pi/2|-pi/2}})"
            )
        if rest.startswith("{") and rest.endswith("}"):
            choices = tuple(_number(c, item) for c in rest[1:-1].split("|"))
            out.append(DHParam(int(joint), field, choices=choices))
        else:
            lo, sep, hi = rest.partition(":")
            if not sep:
                raise InvalidInput(f"DH parameter {item!r}: give LO:HI bounds")
            out.append(DHParam(int(joint), field, _number(lo, item), _number(hi, item)))
    if not out:
        raise InvalidInput("no DH parameter to vary: give e.g. --params d3:0.2:0.6,a4:0.1:0.5")
    names = [p.name for p in out]
    if len(set(names)) != len(names):
        raise InvalidInput(f"a DH parameter is given twice: {names}")
    return tuple(out)


def _number(text: str, item: str) -> float:
    """A number, ``pi`` multiples allowed (``pi/2``, ``-pi``, ``0.5``)."""
    t = text.strip().replace(" ", "")
    sign = -1.0 if t.startswith("-") else 1.0
    t = t.lstrip("+-")
    try:
        if t.startswith("pi"):
            rest = t[2:]
            return sign * math.pi / (float(rest[1:]) if rest.startswith("/") else 1.0)
        return sign * float(t)
    except ValueError:
        raise InvalidInput(f"DH parameter {item!r}: {text!r} is not a number") from None


# Eqn. (H3): a candidate of the design space.
def candidate_table(base: DHTable, params: Sequence[DHParam], u, total_length=None) -> DHTable:
    """The table at unit coordinates ``u`` (one per parameter).

    With ``total_length`` [m] every length (|a|, |d| and the tool offset) is scaled so that their
    sum is ``total_length``.
    """
    table = base
    for p, ui in zip(params, u, strict=True):
        if p.joint > table.n:
            raise InvalidInput(f"{p.name}: the table has {table.n} joints")
        table = table.with_joint(p.joint - 1, **{p.field: p.value(ui)})
    if total_length is not None:
        total = table.length
        if total <= 0:
            raise InvalidInput("a fixed total length needs an arm with a non-zero length")
        s = total_length / total
        joints = tuple(replace(j, a=j.a * s, d=j.d * s) for j in table.joints)
        table = replace(table, joints=joints, tool_xyz=tuple(v * s for v in table.tool_xyz))
    return table


def table_dict(table: DHTable) -> dict:
    """The JSON form of a table (``--dh FILE``'s, see :func:`~.dh.table_from_dict`)."""
    rows = []
    for j in table.joints:
        row = asdict(j)
        row["type"] = row.pop("kind")
        rows.append(row)
    return {
        "name": table.name,
        "convention": table.convention,
        "tool_xyz": list(table.tool_xyz),
        "joints": rows,
    }


@dataclass(frozen=True)
class DHTask:
    """The task of a DH design: a circle of the paper's kind (Figs. 6-7 by default) or a path.

    A sampled path (``--csv``) has ``t`` [s] and ``xs`` [m], one position per time; then
    ``x0 = xs[0]`` and the circle fields are unused.
    """

    x0: tuple[float, ...]
    radius: float
    omega: float = 2 * math.pi
    duration: float = 1.0
    rows: tuple[int, int] = (1, 2)
    t: tuple[float, ...] = ()
    xs: tuple[tuple[float, ...], ...] = ()

    def path(self) -> CirclePath | SampledPath:
        """The task path."""
        if self.t:
            return SampledPath(np.array(self.t), np.array(self.xs), source="design task")
        return CirclePath(np.array(self.x0), self.radius, self.omega, self.duration, rows=self.rows)

    @classmethod
    def sampled(cls, path: SampledPath) -> DHTask:
        """The task of a sampled path (a position task: three columns x, y, z)."""
        xs = np.asarray(path.xs, dtype=float)
        if xs.ndim != 2 or xs.shape[1] != 3:
            raise InvalidInput(
                f"a DH design's path needs three position columns x, y, z; got {xs.shape[1]}"
            )
        rows = tuple(tuple(float(v) for v in x) for x in xs)
        return cls(rows[0], 0.0, t=tuple(float(v) for v in path.t), xs=rows)

    def as_spec(self) -> dict:
        """The JSON form (a circle's keeps exactly its old keys, so its chunks are reused)."""
        out = asdict(self) | {"x0": list(self.x0), "rows": list(self.rows)}
        if not self.t:
            out.pop("t"), out.pop("xs")
        else:
            out.update(t=list(self.t), xs=[list(x) for x in self.xs])
        return out

    @classmethod
    def from_spec(cls, task: dict) -> DHTask:
        """The task of a design spec's (JSON) ``task`` entry."""
        fields: dict = dict(task, x0=tuple(task["x0"]), rows=tuple(task["rows"]))
        fields.update(t=tuple(task.get("t", ())), xs=tuple(tuple(x) for x in task.get("xs", ())))
        return cls(**fields)


def evaluate_table(
    table: DHTable,
    task: DHTask,
    lockable: Sequence[str],
    *,
    rcn_max: float = RCN_THRESHOLD,
    dt: float = 1e-3,
    seeds: int | None = None,
    ftw: dict | None = None,
) -> dict:
    """The paper's planning of ``table``'s arm on ``task``: JVJA's mean and max λ, max k_S.

    ``ftw`` (:data:`FTW_SETTINGS` and ``physical``, the base table's limits): also the sampled
    failure-tolerant volume [m³] of the table's limits inside the physical ones (``ftw_volume``).

    A candidate that cannot reach the task, whose every start fails, or whose run breaks is
    *refused*: ``feasible`` False and the reason, never an exception (one refused candidate is
    not the end of a search).
    """
    try:
        arm = arm_from_dh(table, task="position")
        path = task.path()
        posture = initial_posture(arm, path.x0, list(lockable), seeds=seeds)
        run, _ = plan(
            arm, path, "jvja", lockable=list(lockable), posture=posture, limits=False, dt=dt,
            threshold=rcn_max, engine="reference",
        )  # fmt: skip
    except FaultToleranceError as err:
        return {"feasible": False, "reason": str(err).splitlines()[0][:200]}
    k_max = float(np.max(run.rcn))
    J = np.array([arm.jacobian(q) for q in run.q[:: max(len(run.q) // 50, 1)]])
    manip = float(np.mean(np.sqrt(np.abs(np.linalg.det(J @ np.swapaxes(J, 1, 2))))))
    ok = bool(np.isfinite(run.jvj).all() and k_max <= rcn_max)
    extra = {} if ftw is None else {"ftw_volume": ftw_volume(table, lockable, ftw)}
    return extra | {
        "feasible": ok,
        "reason": "" if ok else f"largest k_S {k_max:.4g} > rcn_max {rcn_max:g}",
        "mean_jvj": float(np.mean(run.jvj)),
        "max_jvj": float(np.max(run.jvj)),
        "rcn_max": k_max,
        "K_max": float(np.max(run.K)),
        "manipulability": manip,
        "q0": [float(v) for v in run.meta["q0"]],
    }


def ftw_volume(table: DHTable, lockable: Sequence[str], settings: dict) -> float:
    """The sampled failure-tolerant volume [m³] of ``table``'s limits as artificial limits.

    The physical limits are ``settings["physical"]``; every lock angle in A (docs/workspace.md).
    """
    from fault_tolerance.analysis.workspace.closed_form import workspace_spec
    from fault_tolerance.analysis.workspace.sampled import sampled_in_process

    options = {k: v for k, v in settings.items() if k != "physical"}
    A = np.array([[j.lower, j.upper] for j in table.joints])
    joints = tuple(
        replace(j, lower=lo, upper=hi)
        for j, (lo, hi) in zip(table.joints, settings["physical"], strict=True)
    )
    arm = arm_from_dh(replace(table, joints=joints), task="position")
    spec = workspace_spec(arm, np.clip(A, arm.lower[:, None], arm.upper[:, None]), list(lockable),
                          **options)  # fmt: skip
    return sampled_in_process(arm, spec).size_ftw


def dh_score(objective: str, rec: dict) -> float:
    """The minimised number of a record (inf when refused)."""
    if not rec.get("feasible"):
        return math.inf
    if objective == "mean-jvj":
        return rec["mean_jvj"]
    if objective == "max-jvj":
        return rec["max_jvj"]
    if objective == "ftw-volume":
        return -rec["ftw_volume"]
    return -rec["manipulability"]


def spec_table(spec: dict) -> DHTable:
    """The base table of a design spec."""
    return table_from_dict(spec["table"], "design spec")


def spec_params(spec: dict) -> tuple[DHParam, ...]:
    """The varied parameters of a design spec."""
    return tuple(
        DHParam(p["joint"], p["field"], p["lo"], p["hi"], tuple(p["choices"]))
        for p in spec["params"]
    )


def evaluate_candidate(spec: dict, u) -> dict:
    """One candidate of a spec at unit coordinates ``u``, with its score."""
    table = candidate_table(spec_table(spec), spec_params(spec), u, spec["total_length"])
    task = DHTask.from_spec(spec["task"])
    rec = evaluate_table(
        table, task, spec["lockable"], rcn_max=spec["rcn_max"], dt=spec["search_dt"],
        seeds=SEARCH_SEEDS, ftw=spec.get("ftw"),
    )  # fmt: skip
    rec["score"] = dh_score(spec["objective"], rec)
    return rec


def dh_design_chunk(spec: dict, k: int) -> dict[str, np.ndarray]:
    """Scores and indices of the candidates of chunk ``k`` of a round (a sweep's compute)."""
    U = np.asarray(spec["candidates"])[k * DH_PER_CHUNK : (k + 1) * DH_PER_CHUNK]
    recs = [evaluate_candidate(spec, u) for u in U]
    nan = float("nan")
    return {
        key: np.array([r.get(key, nan) for r in recs], dtype=float)
        for key in ("score", "mean_jvj", "max_jvj", "rcn_max", "manipulability", "ftw_volume")
    } | {"feasible": np.array([bool(r["feasible"]) for r in recs])}


def design_spec(
    base: DHTable,
    params: Sequence[DHParam],
    task: DHTask,
    lockable: Sequence[str],
    *,
    objective: str = "mean-jvj",
    rcn_max: float = RCN_THRESHOLD,
    total_length: float | None = None,
    search_dt: float = 1e-2,
) -> dict:
    """The JSON-able spec of a DH design (what every chunk of the search is computed from)."""
    if objective not in DH_OBJECTIVES:
        raise InvalidInput(f"objective '{objective}' is not one of {list(DH_OBJECTIVES)}")
    if not (math.isfinite(rcn_max) and rcn_max >= 1):
        raise InvalidInput(f"rcn_max must be a finite number >= 1, got {rcn_max}")
    if total_length is not None and not (math.isfinite(total_length) and total_length > 0):
        raise InvalidInput(f"total_length must be a positive number [m], got {total_length}")
    if not (math.isfinite(search_dt) and 0 < search_dt <= 0.05):
        raise InvalidInput(f"search_dt must be in (0, 0.05] s, got {search_dt}")
    for p in params:
        if p.joint > base.n:
            raise InvalidInput(f"{p.name}: the table has {base.n} joints")
    names = [f"joint{i}" for i in range(1, base.n + 1)]
    bad = [j for j in lockable if j not in names]
    if bad or not lockable:
        raise InvalidInput(f"lockable joints {list(lockable)}: choose among {names}")
    spec = {
        "kind": "dh-design",
        "table": table_dict(base),
        "params": [asdict(p) | {"choices": list(p.choices)} for p in params],
        "task": task.as_spec(),
        "lockable": list(lockable),
        "objective": objective,
        "rcn_max": float(rcn_max),
        "total_length": None if total_length is None else float(total_length),
        "search_dt": float(search_dt),
    }
    if objective == "ftw-volume":  # only then: the other objectives' chunk names stay as they were
        spec["ftw"] = FTW_SETTINGS | {"physical": [[j.lower, j.upper] for j in base.joints]}
    json.dumps(spec)  # JSON-able: a chunk's name is its hash
    return spec


# -- the search and its result -----------------------------------------------------------------


def baseline_u(base: DHTable, params: Sequence[DHParam]) -> np.ndarray | None:
    """Unit coordinates of the base table's own values, or None if one lies outside its bounds."""
    u = []
    for p in params:
        j = base.joints[p.joint - 1]
        v = getattr(j, "kind" if p.field == "type" else p.field)
        if p.choices:
            hits = [i for i, c in enumerate(p.choices) if abs(c - v) < 1e-12]
            if not hits:
                return None
            u.append((hits[0] + 0.5) / len(p.choices))
        elif p.lo <= v <= p.hi:
            u.append((v - p.lo) / (p.hi - p.lo))
        else:
            return None
    return np.array(u)


@dataclass(frozen=True)
class DHDesign:
    """The chosen design: its table, its record (design.json) and every evaluated candidate."""

    table: DHTable
    record: dict
    evaluated: dict

    def save(self, folder, draw=None, extra=None):
        """Write ``design.json`` and ``design.urdf`` into ``folder``, whole or absent.

        ``draw(design, path)`` writes ``design.png`` and ``extra(staging_folder)`` more files
        (the CLI's replay page), both inside the staged folder, so the completion record lists
        them; finished chunks (``chunks-*/``) are kept.
        """
        from pathlib import Path

        from fault_tolerance.model.dh import dh_urdf
        from fault_tolerance.storage.result_folder import staged_folder

        folder = Path(folder)
        with staged_folder(folder, replaceable=DESIGN_FILES, aside=("chunks-*",)) as tmp:
            (tmp / "design.urdf").write_text(dh_urdf(self.table))
            (tmp / "design.json").write_text(json.dumps(self.record, indent=2) + "\n")
            if draw is not None:
                draw(self, tmp / "design.png")
            if extra is not None:
                extra(tmp)
        return folder


def dh_design(
    spec: dict,
    *,
    seed: int = 0,
    popsize: int = 8,
    generations: int = 10,
    pattern_rounds: int = 4,
    workers: int = 0,
    scheduler: str | None = None,
    folder=None,
    progress: bool = False,
) -> DHDesign:
    """Search the DH design space of ``spec`` (:func:`design_spec`); module doc, MATH.md (H3)-(H4)."""
    from fault_tolerance.analysis.design.search_core import global_search
    from fault_tolerance.analysis.sweep import run

    base, params = spec_table(spec), spec_params(spec)
    columns: dict[str, list[np.ndarray]] = {}

    def evaluate_round(U: np.ndarray, tag: str) -> np.ndarray:
        s = dict(spec, candidates=U.tolist(), round=tag)
        n = -(-len(U) // DH_PER_CHUNK)
        chunks = run(
            dh_design_chunk, s, n, folder=folder, workers=workers, scheduler=scheduler,
            progress=progress, desc=f"design {tag}",
        )  # fmt: skip
        for key in chunks[0]:
            columns.setdefault(key, []).append(np.concatenate([c[key] for c in chunks]))
        return np.concatenate([c["score"] for c in chunks])

    start = baseline_u(base, params)
    found = global_search(
        evaluate_round, dims=len(params), seed=seed, popsize=popsize, generations=generations,
        pattern_rounds=pattern_rounds, start=start,
    )  # fmt: skip
    if not math.isfinite(found.score):
        raise InvalidInput(
            "no candidate design is feasible (every one was refused: out of reach, intolerable "
            "or over --rcn-max); widen the bounds, relax --rcn-max or choose another task"
        )
    seen = {k: np.concatenate(v) for k, v in columns.items()}
    seen["u"] = found.evaluated
    chosen = candidate_table(base, params, found.u, spec["total_length"])
    return DHDesign(chosen, _dh_record(spec, chosen, base, found, seen, seed), seen)


def _values(table: DHTable, params: Sequence[DHParam]) -> dict[str, float]:
    """The varied parameters' values in ``table`` (after a fixed total length's scaling)."""
    return {p.name: float(getattr(table.joints[p.joint - 1], p.field)) for p in params}


def _dh_record(spec, chosen: DHTable, base: DHTable, found, seen: dict, seed: int) -> dict:
    """design.json: the chosen table and values, the baseline, the Pareto front, the settings."""
    task = DHTask.from_spec(spec["task"])
    ftw = spec.get("ftw")
    final = evaluate_table(chosen, task, spec["lockable"], rcn_max=spec["rcn_max"], ftw=ftw)
    base_rec = evaluate_table(base, task, spec["lockable"], rcn_max=spec["rcn_max"], ftw=ftw)
    pts = np.stack([seen["mean_jvj"], seen["rcn_max"]], 1)
    pts[~seen["feasible"].astype(bool)] = np.nan
    front = pareto(pts).tolist()
    params = spec_params(spec)
    return {
        "kind": "dh",
        "objective": spec["objective"],
        "dh": table_dict(chosen),
        "parameters": _values(chosen, params),
        "mean_jvj": final.get("mean_jvj"),
        "max_jvj": final.get("max_jvj"),
        "rcn_max": final.get("rcn_max"),
        "K_max": final.get("K_max"),
        "manipulability": final.get("manipulability"),
        "ftw_volume": final.get("ftw_volume"),
        "feasible": final["feasible"],
        "q0": final.get("q0"),
        "baseline": {"dh": table_dict(base)}
        | {
            k: base_rec.get(k)
            for k in ("mean_jvj", "max_jvj", "rcn_max", "manipulability", "ftw_volume", "feasible")
        },  # fmt: skip
        "pareto": [
            {
                "parameters": _values(
                    candidate_table(base, params, seen["u"][i], spec["total_length"]), params
                ),
                "mean_jvj": float(pts[i, 0]),
                "rcn_max": float(pts[i, 1]),
            }
            for i in front
        ],  # fmt: skip
        "settings": {
            k: spec[k]
            for k in ("params", "task", "lockable", "rcn_max", "total_length", "search_dt", "ftw")
            if k in spec
        }
        | {"seed": seed},  # fmt: skip
        "evaluations": int(found.evaluations),
        "units": {
            "mean_jvj": "(rad/s)^2",
            "max_jvj": "(rad/s)^2",
            "rcn_max": "1",
            "manipulability": "m^3/rad^3 (position task)",
            "ftw_volume": "m^3 (sampled: settings.ftw; cell edge 2R/grid, R the reach bound)",
            "dh": "m, rad",
        },  # fmt: skip
    }
