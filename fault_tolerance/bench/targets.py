"""The targets, evaluated on a benchmark's results: one dict per target, PASS / FAIL / info."""

from __future__ import annotations

#: JVJA step / LNVA step, and the bounds of the fast path's other ratios.
MAX_JVJA_OVER_LNVA = 1.5
#: Tighter JVJA / LNVA bounds for some arms.
JVJA_OVER_LNVA_BY_ARM = {"panda_pose": 1.15, "panda_position": 1.15, "chain_50": 1.3}
MAX_JVJA_OVER_FLOOR = 1.3
MAX_SIM_OVER_STEP = 10.0
MAX_MULTI_OVER_SINGLE = 2.0
MIN_EXPLICIT_OVER_JVJA = 10.0
EXPLICIT_TARGET_ARMS = ("panda_pose", "panda_position")
MAX_JVJA_P99_US = 100.0
#: Joint limits: bounded JVJA step / unbounded, with no bound and with two bounds active.
MAX_BOUNDED_FREE_OVER_JVJA = 1.3
MAX_BOUNDED_TWO_OVER_JVJA = 4.0
#: Joint limits, task scaled (s < 1, most joints at a bound): bounded step / unbounded step.
MAX_SCALED_JVJA_OVER_JVJA = 50.0
MAX_SCALED_LNVA_OVER_LNVA = 10.0
#: Dynamics: one dynamics sample (control law + ABA step) / one kinematic JVJA step.
MAX_DYN_OVER_STEP = 20.0

#: Generic routes that must be slower than the fast JVJA step: (row, label).
SLOWER_ROUTES = (
    ("jvja_qp", "quadprog route / JVJA"),
    ("jvja_slsqp", "SLSQP route / JVJA"),
    ("qp_solve_only", "quadprog call alone / JVJA"),
)


def _item(arm, name, label, value, limit, relation, passed) -> dict:
    return {
        "arm": arm,
        "name": name,
        "label": label,
        "value": value,
        "limit": limit,
        "relation": relation,
        "pass": passed,
    }


def arm_targets(key: str, ops: dict) -> list[dict]:
    """The targets of one arm from its rows ``ops`` (name -> statistics)."""

    def med(name: str) -> float | None:
        return ops[name]["median_us"] if name in ops else None

    out = []
    jv, ln = med("jvja"), med("lnva")
    if jv and ln:
        r, lim = jv / ln, JVJA_OVER_LNVA_BY_ARM.get(key, MAX_JVJA_OVER_LNVA)
        out.append(
            _item(key, "jvja_over_lnva", "JVJA step / LNVA step", r, lim, "<=", r <= lim)
        )  # fmt: skip
    out += _overhead_targets(key, med, jv)
    for backend in ("numpy", "numba"):
        j2, l2 = med(f"jvja_{backend}"), med(f"lnva_{backend}")
        if j2 and l2:
            out.append(
                _item(key, f"jvja_over_lnva_{backend}", f"JVJA / LNVA, {backend} backend",
                      j2 / l2, MAX_JVJA_OVER_LNVA, "<=", None)
            )  # fmt: skip
    ex = med("jvja_explicit")
    if jv and ex:
        passed = (ex / jv >= MIN_EXPLICIT_OVER_JVJA) if key in EXPLICIT_TARGET_ARMS else None
        out.append(
            _item(key, "explicit_over_jvja", "explicit per-scenario route / JVJA", ex / jv,
                  MIN_EXPLICIT_OVER_JVJA, ">=", passed)
        )  # fmt: skip
    for name, label in SLOWER_ROUTES:
        g = med(name)
        if jv and g:
            out.append(_item(key, f"{name}_over_jvja", label, g / jv, 1.0, ">", g / jv > 1.0))
    out += _limit_targets(key, jv, med)
    dyn = med("dyn_sample")
    if jv and dyn:
        out.append(_at_most(key, "dyn_over_jvja", "dynamics sample / kinematic JVJA step",
                            dyn / jv, MAX_DYN_OVER_STEP))  # fmt: skip
    mda, sim_mda = med("mda"), med("sim_mda")
    if jv and mda:  # MDA is the paper's baseline: its cost is information, not a target
        out.append(_item(key, "mda_over_jvja", "MDA step / JVJA step", mda / jv,
                         None, None, None))  # fmt: skip
    grad = med("mda_gradient")
    if jv and grad:  # what the MDA ratio is made of: ∇K alone against the whole JVJA step
        out.append(_item(key, "mda_gradient_over_jvja", "Jacobian + ∇K alone / JVJA step",
                         grad / jv, None, None, None))  # fmt: skip
    if jv and sim_mda:
        r = sim_mda / jv
        out.append(_item(key, "sim_mda_over_jvja", "simulated MDA sample / JVJA step", r,
                         None, None, None))  # fmt: skip
    rs = med("jvja_resolve")
    if jv and rs:
        out.append(_item(key, "resolve_over_jvja", "ft.resolve / JVJA", rs / jv, None, None, None))
    if "jvja" in ops:
        p99 = ops["jvja"]["p99_us"]
        out.append(
            _item(key, "jvja_p99_us", "JVJA step p99 [µs]", p99, MAX_JVJA_P99_US, "<",
                  p99 < MAX_JVJA_P99_US)
        )  # fmt: skip
    return out


def _at_most(key: str, name: str, label: str, r: float, limit: float) -> dict:
    """A ratio target ``r <= limit``."""
    return _item(key, name, label, r, limit, "<=", r <= limit)


def _overhead_targets(key: str, med, jv) -> list[dict]:
    """The fast path's overheads: over the floor, the simulated samples, two-joint scenarios."""
    out = []
    floor, sim, multi = med("floor"), med("sim_jvja"), med("jvja_multi")
    if jv and floor:
        out.append(_at_most(key, "jvja_over_floor", "JVJA step / floor", jv / floor,
                            MAX_JVJA_OVER_FLOOR))  # fmt: skip
    if jv and sim:
        out.append(_at_most(key, "sim_over_jvja", "simulated JVJA sample / JVJA step", sim / jv,
                            MAX_SIM_OVER_STEP))  # fmt: skip
    lim, run, free = med("sim_jvja_lim"), med("jvja_bounded_run"), med("jvja_bounded_free")
    if run and lim:  # the step at the run's own samples: both sides meet the same bounds
        out.append(_at_most(key, "sim_lim_over_bounded", "simulated JVJA sample under limits / "
                            "bounded JVJA step, same samples", lim / run, MAX_SIM_OVER_STEP))  # fmt: skip
    if free and lim:
        out.append(_item(key, "sim_lim_over_bounded_free", "simulated JVJA sample under limits / "
                         "bounded JVJA step, no bound active", lim / free, None, None, None))  # fmt: skip
    if jv and multi:
        out.append(_at_most(key, "multi_over_single", "two-joint JVJA / single-joint JVJA",
                            multi / jv, MAX_MULTI_OVER_SINGLE))  # fmt: skip
    return out


def _limit_targets(key, jv, med) -> list[dict]:
    """Bounded JVJA step against the unbounded step (timed in the same rounds) and against quadprog."""
    out = []
    free, two, qp = med("jvja_bounded_free"), med("jvja_bounded_2"), med("jvja_bounded_2_qp")
    jv = med("jvja_unbounded_limits") or jv  # timed in the same rounds as the bounded rows
    if jv and free:
        out.append(_at_most(key, "bounded_free_over_jvja", "bounded JVJA, no bound active / JVJA",
                            free / jv, MAX_BOUNDED_FREE_OVER_JVJA))  # fmt: skip
    if jv and two:
        out.append(_at_most(key, "bounded_two_over_jvja", "bounded JVJA, two bounds active / JVJA",
                            two / jv, MAX_BOUNDED_TWO_OVER_JVJA))  # fmt: skip
    out += _scaled_targets(key, med)
    if two and qp:
        out.append(_item(key, "bounded_qp_over_bounded", "quadprog on the bounded problem / "
                         "bounded JVJA (two active)", qp / two, 1.0, ">", qp / two > 1.0))  # fmt: skip
    return out


def _scaled_targets(key, med) -> list[dict]:
    """Bounded JVJA and LNVA with the task scaled, against their unbounded steps (same rounds)."""
    out = []
    for method, limit in (("jvja", MAX_SCALED_JVJA_OVER_JVJA), ("lnva", MAX_SCALED_LNVA_OVER_LNVA)):
        free = med(f"{method}_unbounded_scaled") or med(method)
        scaled = med(f"{method}_bounded_scaled")
        if free and scaled:
            out.append(_at_most(key, f"scaled_{method}_over_{method}", f"bounded "
                                f"{method.upper()}, task scaled / {method.upper()}", scaled / free,
                                limit))  # fmt: skip
        for other, label in (("pink_tick", "pink QP tick"), ("qp_soft_task", "soft-task QP")):
            o = med(other)
            if scaled and o:
                r = scaled / o
                out.append(_item(key, f"scaled_{method}_over_{other}", f"bounded "
                                 f"{method.upper()}, task scaled / {label}", r, 1.0, "<", r < 1.0))  # fmt: skip
    return out


def targets(results: dict) -> list[dict]:
    """The targets, evaluated on medians (p99 for the latency bound)."""
    return [item for key, res in results.items() for item in arm_targets(key, res["ops"])]
