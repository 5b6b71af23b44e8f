"""The design search (quasi-random candidates, then a pattern search) and its result files."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fault_tolerance.analysis.design.planar import (
    MIN_HALF_WIDTH,
    MIN_LINK_SHARE,
    OBJECTIVES,
    PER_CHUNK,
    VARY,
    default_task,
    design_chunk,
    evaluate,
)
from fault_tolerance.analysis.sweep import run
from fault_tolerance.errors import InvalidInput
from fault_tolerance.model.arm_spec import arm_of, robot_spec
from fault_tolerance.model.planar import planar_chain, require_planar_chain
from fault_tolerance.storage.budget import check_design
from fault_tolerance.storage.result_folder import staged_folder

#: Files of a saved design (an existing result with these is replaced whole).
DESIGN_FILES = ("design.json", "design.png", "design.urdf", "replay.html")


def _bounds(arm, vary: str, objective: str) -> np.ndarray:
    """Box of the search parameters [c1, w1, c2, w2, c3, w3 (, share1, share2)], shape (D, 2)."""
    lo, hi = arm.lower, arm.upper
    pc, hp = (lo + hi) / 2, (hi - lo) / 2
    rows = []
    for i in range(3):
        fixed = objective == "ftw-area" and i == 0  # the area does not depend on c1
        rows.append([pc[i], pc[i]] if fixed else [pc[i] - hp[i], pc[i] + hp[i]])
        rows.append([MIN_HALF_WIDTH, hp[i]])
    if vary == "links,limits":
        rows += [[MIN_LINK_SHARE, 1 - 2 * MIN_LINK_SHARE]] * 2
    return np.array(rows, dtype=float)


def clamp(p: np.ndarray, box: np.ndarray) -> np.ndarray:
    """Parameters inside the box; link shares with the third at least MIN_LINK_SHARE."""
    p = np.clip(p, box[:, 0], box[:, 1])
    if len(p) > 6 and p[6] + p[7] > 1 - MIN_LINK_SHARE:
        excess = p[6] + p[7] - (1 - MIN_LINK_SHARE)
        p[6:8] -= excess / 2
    return p


def _baseline(arm, vary: str) -> np.ndarray:
    lo, hi = arm.lower, arm.upper
    p = np.ravel(np.stack([(lo + hi) / 2, (hi - lo) / 2], 1))
    if vary == "links,limits":
        L = require_planar_chain(arm).lengths
        p = np.concatenate([p, L[:2] / L.sum()])
    return p


def _search(spec, box, baseline, candidates, generations, rounds, seed, opts) -> dict:
    """Differential evolution over the free parameters of ``box``, then the pattern search (H4).

    The first population is the baseline and ``candidates`` - 1 quasi-random designs (so
    ``generations=0`` is the quasi-random search alone); every round is one chunked sweep.
    """
    from fault_tolerance.analysis.design.search_core import global_search

    lo, width = box[:, 0], box[:, 1] - box[:, 0]
    free = width > 0
    rounds_seen: list[dict] = []

    def params(U: np.ndarray) -> np.ndarray:
        P = np.tile(lo, (len(U), 1))
        P[:, free] = lo[free] + U * width[free]
        return np.array([clamp(p, box) for p in P])

    def evaluate_round(U: np.ndarray, tag: str) -> np.ndarray:
        rounds_seen.append(_round(spec, params(U), tag, opts))
        return rounds_seen[-1]["score"]

    dims = int(free.sum())
    start = np.clip((baseline - lo)[free] / width[free], 0.0, 1.0)
    global_search(
        evaluate_round, dims=dims, seed=seed, popsize=max(4, -(-candidates // dims)),
        generations=generations, pattern_rounds=rounds, start=start,
    )  # fmt: skip
    return {k: np.concatenate([r[k] for r in rounds_seen]) for k in rounds_seen[0]}


def pareto(points: np.ndarray) -> np.ndarray:
    """Indices of the rows of ``points`` (P, 2) no other row beats in both (minimisation)."""
    keep = []
    for i, p in enumerate(points):
        dominated = np.any(np.all(points <= p, axis=1) & np.any(points < p, axis=1))
        if np.all(np.isfinite(p)) and not dominated:
            keep.append(i)
    return np.array(keep, dtype=int)


@dataclass
class Design:
    """The chosen design's record (``design.json``), every evaluated candidate, and its workspace."""

    record: dict
    evaluated: dict = field(repr=False)
    workspace: object = field(repr=False, default=None)

    def save(
        self, folder: str | Path, draw: Callable[[Design, Path], object] | None = None
    ) -> Path:
        """Write ``design.json`` into ``folder``, and ``design.png`` with ``draw`` when given.

        ``draw`` is :func:`fault_tolerance.figures.design.plot_design` for the usual figure
        (figures sit above the analyses, so the caller passes it). Whole or absent like a run:
        staged beside ``folder`` with a completion record, then renamed into place; finished
        chunks (``chunks-*/``) are kept.
        """
        folder = Path(folder)
        with staged_folder(folder, replaceable=DESIGN_FILES, aside=("chunks-*",)) as tmp:
            (tmp / "design.json").write_text(json.dumps(self.record, indent=2) + "\n")
            if draw is not None:
                draw(self, tmp / "design.png")
        return folder


def _round(spec, cands, tag, opts) -> dict:
    s = dict(spec, candidates=np.asarray(cands).tolist(), round=tag)
    n = -(-len(cands) // PER_CHUNK)
    chunks = run(design_chunk, s, n, desc=f"design {tag}", **opts)
    out = {k: np.concatenate([c[k] for c in chunks]) for k in chunks[0]}
    out["params"] = np.asarray(cands)
    return out


def design(
    arm,
    vary: str = "limits",
    objective: str = "ftw-area",
    *,
    task=None,
    rcn_max=None,
    candidates: int = 128,
    rounds: int = 4,
    generations: int = 0,
    grid: int = 201,
    search_dt: float = 2e-3,
    seed: int = 0,
    workers: int = 0,
    scheduler=None,
    folder=None,
    progress=False,
) -> Design:
    """Search limits (and links) of a planar 3R for ``objective`` (module doc of :mod:`.design`)."""
    if vary not in VARY:
        raise InvalidInput(f"vary '{vary}' is not one of {list(VARY)}")
    if objective not in OBJECTIVES:
        raise InvalidInput(f"objective '{objective}' is not one of {list(OBJECTIVES)}")
    chain = planar_chain(arm)
    if chain is None or arm.n != 3:
        raise InvalidInput(
            f"design needs a planar 3R (three revolute joints about parallel z axes, planar "
            f"task); {arm.name} has {arm.n} joints and task {'/'.join(arm.task)}"
        )
    candidates, rounds, grid = check_design(candidates, rounds, grid)
    if generations < 0:
        raise InvalidInput(f"generations must be >= 0 (--generations), got {generations}")
    if rcn_max is not None and not (np.isfinite(rcn_max) and rcn_max >= 1):
        raise InvalidInput(f"rcn_max must be a finite number >= 1 (--rcn-max), got {rcn_max}")
    t0 = time.perf_counter()
    task = task or default_task(arm)
    spec = {
        "kind": "design",
        "robot": robot_spec(arm),
        "vary": vary,
        "objective": objective,
        "lockable": list(arm.default_lockable),
        "total_length": float(chain.lengths.sum()),
        "task": {**task.__dict__, "x0": list(task.x0)},
        "rcn_max": rcn_max,
        "grid": int(grid),
        "search_dt": float(search_dt),
    }
    opts = dict(folder=folder, workers=workers, scheduler=scheduler, progress=progress)
    box = _bounds(arm, vary, objective)
    seen = _search(spec, box, _baseline(arm, vary), candidates, generations, rounds, seed, opts)
    k = int(np.argmin(seen["score"]))
    if not np.isfinite(seen["score"][k]):
        raise InvalidInput("no candidate design is feasible: relax rcn_max or choose another task")
    chosen = evaluate(spec, seen["params"][k], final=True)
    base = evaluate(spec, seen["params"][0], final=True)
    return Design(
        _record(spec, chosen, base, seen, time.perf_counter() - t0), seen, chosen["workspace"]
    )


def _record(spec, chosen, base, seen, elapsed) -> dict:
    pts = np.stack([seen["jvj"], seen["rcn"]], 1)
    pts[~seen["feasible"]] = np.nan  # a run that leaves its limits is not a design
    front = pareto(pts) if spec["objective"] != "ftw-area" else np.array([], dtype=int)
    from fault_tolerance.analysis.design.planar import limits_of, links_of

    arm = arm_of(spec)
    phys = np.stack([arm.lower, arm.upper], 1)

    def entry(i):
        p = seen["params"][i]
        e = {
            "limits": limits_of(p, phys).tolist(),
            "jvj": float(seen["jvj"][i]),
            "rcn": float(seen["rcn"][i]),
        }
        links = links_of(p, spec["total_length"])
        if links is not None:
            e["links"] = links.tolist()
        return e

    keep = (
        "limits",
        "links",
        "area_ftw",
        "area_pre",
        "jvj",
        "rcn",
        "rcn_max",
        "feasible",
        "q0",
        "reason",
    )
    for r in (chosen, base):
        for k in ("jvj", "rcn", "rcn_max"):
            r.setdefault(k, None)  # the task is not reachable within the limits (see reason)
    rec = {
        "robot": spec["robot"]["source"],
        "vary": spec["vary"],
        "objective": spec["objective"],
        "task": spec["task"],
        "rcn_requirement": spec["rcn_max"],
        "lockable": spec["lockable"],
        **{k: chosen[k] for k in keep if k in chosen},
        "baseline": {k: base[k] for k in keep if k in base},
        "evaluations": int(len(seen["score"])),
        "pareto": [entry(i) for i in front],
        "units": {"limits": "rad", "links": "m", "area": "m^2", "jvj": "(rad/s)^2", "rcn": "1"},
        "notes": "jvj/rcn: mean of λ (9)/(10) and K (15) of JVJA along the task (dt 1 ms) from "
        "the minimum-K start within the limits; area_ftw on the final grid",
        "grid": spec["grid"],
        "elapsed_s": round(elapsed, 1),
    }
    return rec
