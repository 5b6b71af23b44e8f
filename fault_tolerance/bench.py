"""The performance benchmark: what one control step costs, fast path against the slow routes.

For each arm it times, in one process and after a warm-up, single calls of

* ``jacobian``: the task Jacobian (Pinocchio ``computeFrameJacobian``);
* ``lnva``, ``jvja``, ``rcn``, ``mda``: the :class:`~fault_tolerance.realtime.Controller` steps
  (Jacobian included), with the default backend, and ``lnva_<backend>`` / ``jvja_<backend>`` for
  the other backends installed;
* ``lnva_resolve``, ``jvja_resolve``, ``mda_resolve``, ``rcn_resolve``: ``arm.jacobian`` and the
  plain :func:`fault_tolerance.resolve` / :func:`fault_tolerance.rcn`;
* ``jvja_explicit``: the Jacobian and eq. (5) the explicit way, one pseudo-inverse per scenario for
  eq. (2) (:func:`fault_tolerance.planner.jvja_explicit`);
* ``jvja_qp`` / ``jvja_slsqp``: the Jacobian, eq. (2) per scenario, then the minimisation
  (3)-(4), ``min Σ_S w_S ½‖ˢq̇' - q̇‖²`` s.t. ``J q̇ = ẋ``, handed to a generic solver: the
  dense active-set QP solver ``quadprog`` (if installed) and SciPy's SLSQP (if installed).

Each row is timed call by call in blocks of consecutive calls (a control loop's steady state),
the rows' blocks taking turns over ten rounds so that a drift of the machine hits them alike.
Garbage collection is off while timing (as ``timeit`` does).
Configurations come from a seeded pool of generic postures (no singularity, no near-intolerable
scenario). The table gives the median and the 99th percentile of a call in microseconds, then
the issue's targets with PASS / FAIL. ``--json FILE`` keeps everything (with the machine) for
``--compare A.json B.json``.

Example:
    fault-tolerance bench --robots planar_3r panda_pose --steps 2000 --json new.json
"""

from __future__ import annotations

import argparse
import ctypes
import gc
import json
import os
import platform
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from datetime import datetime, timezone
from importlib import metadata
from pathlib import Path

import numpy as np

from .errors import FaultToleranceError, InvalidInput
from .linalg import reduced_rates_explicit

SCHEMA = "fault_tolerance.bench/1"

#: The benchmark's arms: robot, task and lockable set.
ARMS: dict[str, dict] = {
    "planar_3r": {"robot": "planar_3r", "task": None, "lockable": "all"},
    "spatial_4r": {"robot": "spatial_4r", "task": None, "lockable": ["joint1", "joint2", "joint3"]},
    "panda_pose": {"robot": "panda", "task": "pose", "lockable": "all"},
    "panda_position": {"robot": "panda", "task": "position", "lockable": "all"},
    "powercube_3r": {"robot": "powercube_3r", "task": None, "lockable": "all"},
}
#: Arms run when ``--robots`` is not given.
DEFAULT_ARMS = ("planar_3r", "spatial_4r", "panda_pose", "panda_position")
#: Default number of timed calls per row (the whole default bench takes well under a minute).
DEFAULT_STEPS = 5000
DEFAULT_WARMUP = 200
POOL = 64
SEED = 20240521
#: Rounds of blocks per row (see :func:`_time_rows`) and untimed calls at the start of a block.
ROUNDS = 10
BLOCK_WARMUP = 3

#: The issue's targets.
MAX_JVJA_OVER_LNVA = 1.5
MIN_EXPLICIT_OVER_JVJA = 10.0
EXPLICIT_TARGET_ARMS = ("panda_pose", "panda_position")
MAX_JVJA_P99_US = 100.0

DESCRIPTIONS = {
    "jacobian": "task Jacobian (Pinocchio computeFrameJacobian)",
    "lnva": "LNVA step, fast path (Jacobian included)",
    "jvja": "JVJA step, closed form G2, fast path (Jacobian included)",
    "rcn": "RCN of all scenarios, one batched eigvalsh (Jacobian included)",
    "mda": "MDA step, fast path (Jacobian and its derivatives included)",
    "lnva_resolve": "arm.jacobian + ft.resolve('lnva')",
    "jvja_resolve": "arm.jacobian + ft.resolve('jvja')",
    "mda_resolve": "ft.resolve('mda', arm=, q=) with arm.jacobian(_derivatives)",
    "rcn_resolve": "arm.jacobian + ft.rcn",
    "jvja_explicit": "Jacobian + eq. (5), one pseudo-inverse per scenario (planner.jvja_explicit)",
    "jvja_qp": "Jacobian + eq. (2) per scenario + (3)-(4) by quadprog (dense active-set QP)",
    "qp_solve_only": "the quadprog call alone, its inputs (J, ẋ, Σ w ˢq̇') given",
    "jvja_slsqp": "Jacobian + eq. (2) per scenario + (3)-(4) by scipy.optimize SLSQP",
}


# -- the generic-solver routes ------------------------------------------------------------------


def _post_failure_rates(J: np.ndarray, xdot: np.ndarray, sc) -> np.ndarray:
    """Eq. (2) for every scenario, one pseudo-inverse each (what a generic route has to do)."""
    return np.array([reduced_rates_explicit(J, xdot, S) for S in sc.sets])


# Eqn. (3)-(4) by a QP solver.
def jvja_qp(J: np.ndarray, xdot: np.ndarray, sc) -> np.ndarray:
    r"""JVJA as a QP, eqs. (3)-(4) handed to ``quadprog`` (a dense active-set solver).

    :math:`\min \tfrac12 W\|\dot q\|^2 - (\sum_S w_S\,{}^S\dot q')^T\dot q` s.t.
    :math:`J\dot q = \dot x`, which is (3) up to a constant; ``ˢq̇'`` from eq. (2) per scenario.
    """
    import quadprog

    m, n = J.shape
    post = _post_failure_rates(J, xdot, sc)
    H = sc.weights.sum() * np.eye(n)
    g = sc.weights @ post
    return quadprog.solve_qp(H, g, J.T, xdot, m)[0]


def jvja_slsqp(J: np.ndarray, xdot: np.ndarray, sc) -> np.ndarray:
    """JVJA as eqs. (3)-(4) handed to ``scipy.optimize.minimize(method="SLSQP")`` from q̇ = 0."""
    from scipy.optimize import minimize

    n = J.shape[1]
    post = _post_failure_rates(J, xdot, sc)
    W = float(sc.weights.sum())
    g = sc.weights @ post
    res = minimize(
        lambda x: 0.5 * W * (x @ x) - g @ x,
        np.zeros(n),
        jac=lambda x: W * x - g,
        constraints=[{"type": "eq", "fun": lambda x: J @ x - xdot, "jac": lambda x: J}],
        method="SLSQP",
        options={"ftol": 1e-14, "maxiter": 200},
    )
    return res.x


def _installed(module: str) -> bool:
    try:
        __import__(module)
        return True
    except ImportError:
        return False


# -- machine description ------------------------------------------------------------------------


def _version(dist: str) -> str | None:
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return None


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _blas_threads() -> list[dict]:
    """Threads of every BLAS library loaded in this process (threadpoolctl, else OpenBLAS' API)."""
    try:
        from threadpoolctl import threadpool_info

        return [
            {
                "library": i.get("internal_api"),
                "path": i.get("filepath"),
                "version": i.get("version"),
                "threads": i.get("num_threads"),
            }
            for i in threadpool_info()
        ]
    except ImportError:
        pass
    out = []
    try:
        paths = {
            line.split()[-1]
            for line in Path("/proc/self/maps").read_text().splitlines()
            if "openblas" in line.lower() and line.split()[-1].startswith("/")
        }
    except OSError:
        paths = set()
    for path in sorted(paths):
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for symbol in (
            "openblas_get_num_threads",
            "openblas_get_num_threads64_",
            "scipy_openblas_get_num_threads64_",
            "scipy_openblas_get_num_threads",
        ):
            fn = getattr(lib, symbol, None)
            if fn is not None:
                fn.restype = ctypes.c_int
                out.append({"library": "openblas", "path": path, "threads": int(fn())})
                break
    return out


def _blas_build(module) -> dict | None:
    try:
        blas = module.show_config(mode="dicts")["Build Dependencies"]["blas"]
        return {"name": blas.get("name"), "version": blas.get("version")}
    except Exception:  # noqa: BLE001 - older versions have no mode="dicts"
        return None


def machine_info() -> dict:
    """CPU, library versions, BLAS build and threads, BLAS-related environment, load."""
    import pinocchio as pin

    from . import __version__

    info: dict = {
        "cpu": _cpu_model(),
        "cores": os.cpu_count(),
        "affinity": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None,
        "platform": platform.platform(),
        "python": platform.python_version(),
        "fault_tolerance": __version__,
        "numpy": np.__version__,
        "pinocchio": pin.__version__,
        "scipy": _version("scipy"),
        "numba": _version("numba"),
        "quadprog": _version("quadprog"),
        "numpy_blas": _blas_build(np),
        "env": {
            k: v
            for k, v in sorted(os.environ.items())
            if k.startswith(("OPENBLAS_", "OMP_", "MKL_", "BLIS_", "GOTO", "VECLIB_", "NUMBA_"))
        },
        "loadavg": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
    }
    try:
        import scipy
        import scipy.linalg  # noqa: F401 - load scipy's BLAS so its threads are listed

        info["scipy_blas"] = _blas_build(scipy)
    except ImportError:
        info["scipy"] = None

    info["blas_threads"] = _blas_threads()
    return info


# -- timing ------------------------------------------------------------------------------------


def _time_rows(
    rows: dict[str, tuple[Callable, list[tuple]]], steps: int, warmup: int, rounds: int = ROUNDS
) -> dict[str, np.ndarray]:
    """Time single calls of each row; nanoseconds, shape (steps,).

    The calls of a row are timed in blocks of consecutive calls (the steady state of a control
    loop: one call after another, caches warm for that row), and the rows' blocks take turns over
    ``rounds`` rounds, so a drift of the machine hits every row alike. The first
    :data:`BLOCK_WARMUP` calls of each block are not timed (switching rows refills caches).
    """
    pc = time.perf_counter_ns
    items = [(name, fn, args) for name, (fn, args) in rows.items()]
    out = {name: np.empty(steps) for name in rows}
    for _, fn, args in items:
        for i in range(warmup):
            fn(*args[i % len(args)])
    rounds = max(1, min(rounds, steps))
    bounds = np.linspace(0, steps, rounds + 1).astype(int)
    gc.collect()
    enabled = gc.isenabled()
    gc.disable()
    try:
        for r in range(rounds):
            lo, hi = int(bounds[r]), int(bounds[r + 1])
            for name, fn, args in items:
                samples, k = out[name], len(args)
                for i in range(BLOCK_WARMUP):
                    fn(*args[(lo + i) % k])
                for i in range(lo, hi):
                    a = args[i % k]
                    t0 = pc()
                    fn(*a)
                    t1 = pc()
                    samples[i] = t1 - t0
    finally:
        if enabled:
            gc.enable()
    return out


def _timer_overhead_ns(n: int = 20000) -> float:
    pc = time.perf_counter_ns
    d = np.empty(n)
    for i in range(n):
        t0 = pc()
        t1 = pc()
        d[i] = t1 - t0
    return float(np.median(d))


def _stats(ns: np.ndarray) -> dict:
    us = ns / 1e3
    return {
        "median_us": float(np.median(us)),
        "p99_us": float(np.percentile(us, 99)),
        "mean_us": float(us.mean()),
        "min_us": float(us.min()),
        "max_us": float(us.max()),
        "steps": int(len(us)),
    }


def _pool(arm, sc, rng: np.random.Generator, size: int) -> tuple[list, list]:
    """Generic configurations: σ_min(J) ≥ 0.01 and every scenario pivot ≥ 1e-4; unit ẋ."""
    from .linalg import min_pivot, projection

    qs, xds = [], []
    for _ in range(200 * size):
        q = arm.random_q(rng)
        proj = projection(arm.jacobian(q))
        if proj.sigma_min < 1e-2 or min(min_pivot(proj.N, S) for S in sc.sets) < 1e-4:
            continue
        v = rng.standard_normal(arm.m)
        qs.append(np.ascontiguousarray(q))
        xds.append(v / np.linalg.norm(v))
        if len(qs) == size:
            return qs, xds
    raise InvalidInput(f"{arm.name}: no generic configuration found for the benchmark pool")


def bench_arm(
    key: str, steps: int, warmup: int, backend: str = "auto", progress: Callable | None = None
) -> dict:
    """Time every row for one benchmark arm (a key of :data:`ARMS`)."""
    import fault_tolerance as ft

    from .planner import jvja_explicit
    from .realtime import Controller, available_backends

    spec = ARMS[key]
    arm = ft.load_arm(spec["robot"], **({"task": spec["task"]} if spec["task"] else {}))
    ctrl = Controller(arm, spec["lockable"], backend=backend)
    sc = ctrl.scenarios
    rng = np.random.default_rng(SEED)
    qs, xds = _pool(arm, sc, rng, POOL)
    n = arm.n
    out, kout = np.empty(n), np.empty(sc.f)
    qx = list(zip(qs, xds, strict=True))
    qxo = [(q, xd, out) for q, xd in qx]

    fast: dict[str, tuple[Callable, list[tuple]]] = {
        "jacobian": (ctrl.jacobian, [(q,) for q in qs]),
        "lnva": (ctrl.lnva, qxo),
        "jvja": (ctrl.jvja, qxo),
        "rcn": (ctrl.rcn, [(q, kout) for q in qs]),
        "mda": (ctrl.mda, qxo),
    }
    for other in available_backends():
        if other != ctrl.backend:
            c2 = Controller(arm, spec["lockable"], backend=other)
            fast[f"lnva_{other}"] = (c2.lnva, qxo)
            fast[f"jvja_{other}"] = (c2.jvja, qxo)

    def lnva_resolve(q, xd):
        return ft.resolve("lnva", arm.jacobian(q), xd)

    def jvja_resolve(q, xd):
        return ft.resolve("jvja", arm.jacobian(q), xd, lockable=sc)

    def rcn_resolve(q):
        return ft.rcn(arm.jacobian(q), sc)

    def mda_resolve(q, xd):
        return ft.resolve("mda", arm.jacobian(q), xd, lockable=sc, arm=arm, q=q)

    def explicit(q, xd):
        return jvja_explicit(ctrl.jacobian(q), xd, sc)

    slow: dict[str, tuple[Callable, list[tuple]]] = {
        "lnva_resolve": (lnva_resolve, qx),
        "jvja_resolve": (jvja_resolve, qx),
        "rcn_resolve": (rcn_resolve, [(q,) for q in qs]),
        "jvja_explicit": (explicit, qx),
    }
    if _installed("quadprog"):
        import quadprog

        slow["jvja_qp"] = (lambda q, xd: jvja_qp(ctrl.jacobian(q), xd, sc), qx)
        qp_inputs = []
        for q, xd in qx:
            J = ctrl.jacobian(q).copy()
            g = sc.weights @ _post_failure_rates(J, xd, sc)
            qp_inputs.append((sc.weights.sum() * np.eye(n), g, J.T.copy(), xd, arm.m))
        slow["qp_solve_only"] = (quadprog.solve_qp, qp_inputs)
    slower: dict[str, tuple[Callable, list[tuple]]] = {"mda_resolve": (mda_resolve, qx)}
    if _installed("scipy"):
        slower["jvja_slsqp"] = (lambda q, xd: jvja_slsqp(ctrl.jacobian(q), xd, sc), qx)

    # How far each route is from the fast path over the pool, relative to the size of the rates
    # (a fast wrong answer is no answer).
    deviation = {}
    ref = [ctrl.jvja(q, xd).copy() for q, xd in qx]
    for name in (
        "jvja_resolve",
        "jvja_explicit",
        "jvja_qp",
        "jvja_slsqp",
        *(k for k in fast if k.startswith("jvja_")),
    ):
        fn, args = {**fast, **slow, **slower}.get(name, (None, None))
        if fn is None:
            continue
        got = [np.array(fn(*a[:2]), dtype=float) for a in args]
        deviation[name] = float(
            max(
                np.abs(g - r).max() / max(1.0, np.abs(r).max())
                for g, r in zip(got, ref, strict=True)
            )
        )
    ctrl.fallbacks = 0

    samples: dict[str, np.ndarray] = {}
    groups = [
        ("fast path", fast, steps, warmup),
        ("reference routes", slow, steps, warmup),
        ("slow routes", slower, max(steps // 10, 5), max(warmup // 10, 2)),
    ]
    for label, rows, n_steps, n_warm in groups:
        if progress:
            progress(f"{key}: {label} ({len(rows)} rows x {n_steps} calls)")
        samples.update(_time_rows(rows, n_steps, n_warm))

    return {
        "robot": spec["robot"],
        "task": list(arm.task),
        "n": arm.n,
        "m": arm.m,
        "r": arm.redundancy,
        "lockable": [list(sc.name(S)) for S in sc.sets],
        "backend": ctrl.backend,
        "fallbacks_during_timing": ctrl.fallbacks,
        "max_rel_diff_vs_jvja": deviation,
        "ops": {
            name: {**_stats(ns), "description": DESCRIPTIONS.get(name, _backend_description(name))}
            for name, ns in samples.items()
        },
    }


def _backend_description(name: str) -> str:
    method, _, backend = name.partition("_")
    return f"{method.upper()} step, fast path with the {backend} backend (Jacobian included)"


# -- targets and report --------------------------------------------------------------------------


def targets(results: dict) -> list[dict]:
    """The issue's targets, evaluated on medians (p99 for the latency bound)."""
    out = []
    for key, res in results.items():
        ops = res["ops"]

        def med(name: str, ops: dict = ops) -> float | None:
            return ops[name]["median_us"] if name in ops else None

        jv, ln = med("jvja"), med("lnva")
        if jv and ln:
            out.append(
                {
                    "arm": key,
                    "name": "jvja_over_lnva",
                    "label": "JVJA step / LNVA step",
                    "value": jv / ln,
                    "limit": MAX_JVJA_OVER_LNVA,
                    "relation": "<=",
                    "pass": jv / ln <= MAX_JVJA_OVER_LNVA,
                }
            )
        for backend in ("lapack", "numpy", "numba"):
            j2, l2 = med(f"jvja_{backend}"), med(f"lnva_{backend}")
            if j2 and l2:
                out.append(
                    {
                        "arm": key,
                        "name": f"jvja_over_lnva_{backend}",
                        "label": f"JVJA / LNVA, {backend} backend",
                        "value": j2 / l2,
                        "limit": MAX_JVJA_OVER_LNVA,
                        "relation": "<=",
                        "pass": None,
                    }
                )
        ex = med("jvja_explicit")
        if jv and ex:
            target = key in EXPLICIT_TARGET_ARMS
            out.append(
                {
                    "arm": key,
                    "name": "explicit_over_jvja",
                    "label": "explicit per-scenario route / JVJA",
                    "value": ex / jv,
                    "limit": MIN_EXPLICIT_OVER_JVJA,
                    "relation": ">=",
                    "pass": (ex / jv >= MIN_EXPLICIT_OVER_JVJA) if target else None,
                }
            )
        for name, label in (
            ("jvja_qp", "quadprog route / JVJA"),
            ("jvja_slsqp", "SLSQP route / JVJA"),
            ("qp_solve_only", "quadprog call alone / JVJA"),
        ):
            g = med(name)
            if jv and g:
                out.append(
                    {
                        "arm": key,
                        "name": f"{name}_over_jvja",
                        "label": label,
                        "value": g / jv,
                        "limit": 1.0,
                        "relation": ">",
                        "pass": g / jv > 1.0,
                    }
                )
        rs = med("jvja_resolve")
        if jv and rs:
            out.append(
                {
                    "arm": key,
                    "name": "resolve_over_jvja",
                    "label": "ft.resolve / JVJA",
                    "value": rs / jv,
                    "limit": None,
                    "relation": None,
                    "pass": None,
                }
            )
        if "jvja" in ops:
            p99 = ops["jvja"]["p99_us"]
            out.append(
                {
                    "arm": key,
                    "name": "jvja_p99_us",
                    "label": "JVJA step p99 [µs]",
                    "value": p99,
                    "limit": MAX_JVJA_P99_US,
                    "relation": "<",
                    "pass": p99 < MAX_JVJA_P99_US,
                }
            )
    return out


def format_table(results: dict) -> str:
    """Rows: arm, operation, median and p99 in microseconds, and the ratio to the JVJA step."""
    lines = [f"{'arm':<16}{'operation':<16}{'median µs':>11}{'p99 µs':>11}{'/ jvja':>9}"]
    for key, res in results.items():
        ops = res["ops"]
        jv = ops.get("jvja", {}).get("median_us")
        for name, st in ops.items():
            ratio = f"{st['median_us'] / jv:8.2f}x" if jv else ""
            lines.append(
                f"{key:<16}{name:<16}{st['median_us']:>11.2f}{st['p99_us']:>11.2f}{ratio:>9}"
            )
    return "\n".join(lines)


def format_targets(items: list[dict]) -> str:
    """One line per target: PASS / FAIL (or ``info``), the arm, what, the value and the limit."""
    lines = []
    for t in items:
        verdict = {True: "PASS", False: "FAIL", None: "info"}[t["pass"]]
        limit = f"(target {t['relation']} {t['limit']:g})" if t["limit"] is not None else ""
        if t["pass"] is None and t["limit"] is not None:
            limit = f"(target {t['relation']} {t['limit']:g} applies to the default backend"
            limit += " and the Panda arms)" if t["name"] == "explicit_over_jvja" else ")"
        lines.append(f"{verdict:<5} {t['arm']:<16}{t['label']:<38}{t['value']:9.2f}  {limit}")
    return "\n".join(lines)


def write_json(path: str | Path, data: dict) -> None:
    """Write ``data`` to ``path`` atomically (a temporary file in the same folder, then replace)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w") as fh:
            json.dump(data, fh, indent=2, sort_keys=False)
            fh.write("\n")
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def _load(path: str) -> dict:
    try:
        data = json.loads(Path(path).read_text())
    except OSError as err:
        raise InvalidInput(f"{path}: cannot read it ({err.strerror})") from err
    except json.JSONDecodeError as err:
        raise InvalidInput(f"{path}: not JSON ({err.msg} at line {err.lineno})") from err
    if not isinstance(data, dict) or data.get("schema") != SCHEMA or "results" not in data:
        raise InvalidInput(f"{path}: not a benchmark file of schema {SCHEMA}")
    return data


def compare(a: dict, b: dict) -> list[dict]:
    """Per (arm, operation) in both: medians and p99 of A and B, and the ratios B / A."""
    rows = []
    for key, res_a in a["results"].items():
        res_b = b["results"].get(key)
        if res_b is None:
            continue
        for name, st_a in res_a["ops"].items():
            st_b = res_b["ops"].get(name)
            if st_b is None:
                continue
            rows.append(
                {
                    "arm": key,
                    "operation": name,
                    "median_a": st_a["median_us"],
                    "median_b": st_b["median_us"],
                    "median_ratio": st_b["median_us"] / st_a["median_us"],
                    "p99_a": st_a["p99_us"],
                    "p99_b": st_b["p99_us"],
                    "p99_ratio": st_b["p99_us"] / st_a["p99_us"],
                }
            )
    return rows


def format_compare(rows: list[dict], a_name: str, b_name: str) -> str:
    """The comparison as a table; ratio < 1 means B is faster."""
    lines = [
        f"A = {a_name}\nB = {b_name}   (ratio B/A; below 1 means B is faster)",
        f"{'arm':<16}{'operation':<16}{'A med µs':>10}{'B med µs':>10}{'B/A':>8}"
        f"{'A p99':>10}{'B p99':>10}{'B/A':>8}",
    ]
    for r in rows:
        lines.append(
            f"{r['arm']:<16}{r['operation']:<16}{r['median_a']:>10.2f}{r['median_b']:>10.2f}"
            f"{r['median_ratio']:>8.2f}{r['p99_a']:>10.2f}{r['p99_b']:>10.2f}{r['p99_ratio']:>8.2f}"
        )
    if len(lines) == 2:
        lines.append("(no arm and operation in common)")
    return "\n".join(lines)


# -- command line ---------------------------------------------------------------------------


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``fault-tolerance bench`` (and ``scripts/benchmark.py``)."""
    parser.add_argument(
        "--robots",
        nargs="+",
        default=None,
        metavar="ARM",
        help=f"arms to time (space or comma separated) among {sorted(ARMS)}; "
        f"default {' '.join(DEFAULT_ARMS)}",
    )
    parser.add_argument(
        "--steps",
        type=int,
        default=DEFAULT_STEPS,
        help=f"timed calls per operation (default {DEFAULT_STEPS}; the slowest routes get a "
        "tenth); the default bench takes well under a minute",
    )
    parser.add_argument(
        "--warmup",
        type=int,
        default=DEFAULT_WARMUP,
        help=f"untimed calls per operation first (default {DEFAULT_WARMUP})",
    )
    parser.add_argument(
        "--backend",
        default="auto",
        choices=["auto", "numba", "lapack", "numpy"],
        help="backend of the fast LNVA / JVJA steps (default: the fastest installed); the "
        "other installed backends get their own rows",
    )
    parser.add_argument(
        "--json",
        default=None,
        metavar="FILE",
        help="also write all results and the machine to FILE (atomically)",
    )
    parser.add_argument(
        "--compare",
        nargs=2,
        default=None,
        metavar=("A.json", "B.json"),
        help="print the per-row ratio B/A of two saved runs instead of timing",
    )
    parser.add_argument(
        "--strict", action="store_true", help="exit with status 1 if a target fails"
    )


def _arm_keys(robots: Sequence[str] | None) -> list[str]:
    if not robots:
        return list(DEFAULT_ARMS)
    keys = [k.strip() for item in robots for k in item.split(",") if k.strip()]
    bad = [k for k in keys if k not in ARMS]
    if bad or not keys:
        raise InvalidInput(f"unknown benchmark arm(s) {bad}; allowed: {sorted(ARMS)}")
    return list(dict.fromkeys(keys))


def run(args: argparse.Namespace) -> int:
    """Run the benchmark (or ``--compare``) from parsed options; returns the exit status.

    0 on success, 2 on bad input (a one-line message on stderr), 1 with ``--strict`` when a target
    fails.
    """
    try:
        return _run(args)
    except FaultToleranceError as err:
        print(f"fault-tolerance bench: {err}", file=sys.stderr)
        return 2


def _run(args: argparse.Namespace) -> int:
    if args.compare:
        a, b = (_load(p) for p in args.compare)
        print(format_compare(compare(a, b), *args.compare))
        return 0
    if args.steps < 1 or args.warmup < 0:
        raise InvalidInput(
            f"--steps must be >= 1 and --warmup >= 0, got {args.steps} and {args.warmup}"
        )
    keys = _arm_keys(args.robots)
    from .realtime import available_backends

    if args.backend != "auto" and args.backend not in available_backends():
        raise InvalidInput(
            f"backend '{args.backend}' is not installed here; available: {available_backends()}"
        )

    def progress(msg: str) -> None:
        print(f"  timing {msg}", file=sys.stderr, flush=True)

    started = time.time()
    machine = machine_info()
    results = {}
    for key in keys:
        results[key] = bench_arm(key, args.steps, args.warmup, args.backend, progress)
    items = targets(results)
    machine["loadavg_after"] = list(os.getloadavg()) if hasattr(os, "getloadavg") else None
    data = {
        "schema": SCHEMA,
        "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "command": " ".join(sys.argv),
        "machine": machine,
        "settings": {
            "steps": args.steps,
            "warmup": args.warmup,
            "pool": POOL,
            "seed": SEED,
            "backend": args.backend,
            "gc_disabled_while_timing": True,
            "timing": f"{ROUNDS} rounds of one block per row, "
            f"{BLOCK_WARMUP} untimed calls per block",
            "timer_overhead_ns": _timer_overhead_ns(),
            "seconds": round(time.time() - started, 1),
        },
        "results": results,
        "targets": items,
    }
    backend = next(iter(results.values()))["backend"]
    blas = ", ".join(f"{b['library']} {b['threads']} threads" for b in machine["blas_threads"])
    load = f"{machine['loadavg'][0]:.2f}" if machine["loadavg"] else "?"
    print(
        f"fault_tolerance bench: {len(keys)} arm(s), {args.steps} timed calls per row after "
        f"{args.warmup} warm-up calls, fast-path backend {backend}, "
        f"{data['settings']['seconds']} s\n"
        f"machine: {machine['cpu']} ({machine['cores']} cores), numpy {machine['numpy']}, "
        f"scipy {machine['scipy']}, pinocchio {machine['pinocchio']}, numba {machine['numba']}, "
        f"quadprog {machine['quadprog']}; BLAS: {blas or 'unknown'}; load average {load}\n"
    )
    print(format_table(results))
    print("\ntargets (medians; p99 for the latency bound)")
    print(format_targets(items))
    if args.json:
        write_json(args.json, data)
        print(f"\nwrote {args.json}")
    failed = [t for t in items if t["pass"] is False]
    return 1 if (failed and args.strict) else 0


def main(argv: Sequence[str] | None = None) -> int:
    """``scripts/benchmark.py``: the same options as ``fault-tolerance bench``."""
    parser = argparse.ArgumentParser(
        prog="benchmark.py",
        description=__doc__.split("\n\n")[0],
        epilog="example: python scripts/benchmark.py --robots panda_pose --json new.json",
    )
    add_arguments(parser)
    return run(parser.parse_args(argv))
