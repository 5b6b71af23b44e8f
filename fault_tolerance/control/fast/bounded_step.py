"""The Controller's bounded step with the numba backend: one compiled call per step.

:func:`compiled_bounded_step` builds the step around :func:`fault_tolerance.control.fast.bounded_solve.free_then_bounded`:
the Jacobian from Pinocchio, then one call that takes the unbounded step, checks it against the
rate box (L1) and, only when a bound is met, solves the bounded problem (L2)-(L4) compiled (LNVA
and single-joint JVJA; MDA and multi-joint JVJA take the reference route). No
closure layers, no allocation (with ``out=``). What the kernel refuses (near a singularity of
``J`` or of a reduced Jacobian, an intolerable scenario, an empty box, inputs of other types) takes
the reference route of :mod:`fault_tolerance.control.bounded_step`, counted in ``bounded_reference_steps``
when it solves a bounded problem.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pinocchio as pin

from fault_tolerance.control.workspace import BOUNDED_STEPS, ControllerWorkspace
from fault_tolerance.errors import FaultToleranceError, InvalidInput
from fault_tolerance.resolution.registry import KERNEL_JVJA, KERNEL_LNVA, get

_LWA = pin.LOCAL_WORLD_ALIGNED
_F64 = np.dtype(np.float64)
_ERRORS = (ValueError, TypeError, RuntimeError, AttributeError, IndexError)


def bounded_tables(cw: ControllerWorkspace) -> tuple[tuple, np.ndarray]:
    """``((F, Iw, views), state)``: the compiled bounded steps' workspace of ``cw``, and its state.

    One per controller (its three steps share the scratch and the state); the Controller builds
    it with its workspace (:attr:`ControllerWorkspace.box_tables`, ``box_state``).
    """
    from fault_tolerance.control.fast.bounded_solve import workspace
    from fault_tolerance.control.lapack_steps import TRACE_MAX

    sc, n = cw.scenarios, cw.n
    smax = max(len(S) for S in sc.sets)
    sets = -np.ones((sc.f, smax), dtype=np.int64)
    for k, S in enumerate(sc.sets):
        sets[k, : len(S)] = S
    cols = sc.columns if cw.singletons else np.zeros(0, dtype=np.int64)
    F, Iw, views = workspace(n, cw.m, sets, cols, 0)
    views["fw"][:] = cw.fw
    views["p4"][:] = TRACE_MAX, cw.pivot_threshold, cw.rank_coef, cw.alpha
    views["p3"][:] = TRACE_MAX, cw.pivot_threshold, cw.rank_coef
    views["wrel"][:] = sc.relative_weights / sc.relative_weights.sum()  # no overflow
    views["state"][:] = cw.box_state
    return (F, Iw, views), views["state"]  # last_scale / last_active read the state


def covers(cw: ControllerWorkspace, name: str) -> bool:
    """Whether the compiled bounded step serves method ``name``: LNVA and single-joint JVJA."""
    return get(name).compiled in (KERNEL_LNVA, KERNEL_JVJA) and cw.singletons


def compiled_bounded_step(cw: ControllerWorkspace, name: str, reference: Callable, lim, prm):
    """``step(q, xdot, out=None)`` of LNVA or single-joint JVJA inside the box, compiled.

    ``cw.box_tables`` holds the kernel's workspace (:func:`bounded_tables`); ``reference`` is the
    reference route (same signature); ``lim`` (3, n) the position and velocity limits,
    ``prm = [1/h, alpha]``.
    """
    if cw.box_tables is None:
        raise InvalidInput(
            "the compiled bounded step needs a workspace built with limits=True and the numba "
            "backend (ControllerWorkspace.box_tables)"
        )
    if not covers(cw, name):
        raise InvalidInput(
            f"the compiled bounded step is LNVA's and single-joint JVJA's, not {name}'s"
        )
    F, I0, views = cw.box_tables
    views["lim"][:] = lim
    views["prm"][:] = prm
    Iw = I0.copy()  # its own mode; the int scratch of the copy is its own too
    Iw[4] = get(name).compiled  # the kernel mode of this built-in
    n = cw.n
    J0 = pin.computeFrameJacobian(cw.model, cw.data, pin.neutral(cw.model), cw.frame_id, _LWA)
    target: list[Callable] = []  # the step built below, which retry calls again

    def retry(q, xdot, out):
        """Other types or layouts: contiguous float64 copies once, else the reference route."""
        try:
            q2, x2 = np.ascontiguousarray(q, dtype=float), np.ascontiguousarray(xdot, dtype=float)
            if type(out) is np.ndarray and out.dtype == _F64 and out.flags.c_contiguous:
                if q2.shape == (n,) and x2.shape == (cw.m,) and (q2 is not q or x2 is not xdot):
                    return target[0](q2, x2, out)
        except (TypeError, ValueError):
            pass
        return reference(q, xdot, out)  # converts, or says what is wrong

    return _free_step(cw, name, (retry, target), reference, (F, Iw, views), J0[cw.rows])


def _free_step(cw: ControllerWorkspace, name: str, retrying, reference, tables, J0) -> Callable:
    """LNVA and single-joint JVJA: one call, the lean kernel and, when a bound is met, the solve.

    :func:`fault_tolerance.control.fast.bounded_solve.free_then_bounded`: the unbounded step and
    the box check of :func:`fault_tolerance.control.fast.bounded_free.free_kernel` (its
    workspace a section of the bounded workspace), then, only when a bound is met, the bounded
    solve from its rates. ``retrying = (retry, target)``: ``retry`` converts other types once and
    calls ``target[0]``, this step, again; ``reference`` is the reference route.
    """
    from fault_tolerance.control.fast.bounded_free import free_workspace
    from fault_tolerance.control.fast.bounded_solve import free_then_bounded as kernel

    F, Iw, views = tables
    retry, target = retrying
    n, m, counts = cw.n, cw.m, cw.counts
    views["free"][int(Iw[4])] = free_workspace(n, m, views["p4"], views["fw"], views["lim"],
                                               views["prm"], int(Iw[4]), views["cols"])  # fmt: skip
    model, data, fid, rows = cw.model, cw.data, cw.frame_id, cw.rows
    cfj, empty = pin.computeFrameJacobian, np.empty
    kernel.disable_compile(False)  # compiled for this layout here, then frozen (see above)
    kernel(J0, np.zeros(n + 1), np.zeros(m), np.zeros(n), F, Iw)  # refused: sizes
    kernel.disable_compile(True)

    def step(q: np.ndarray, xdot: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        if out is None:
            out = empty(n)
        try:  # the kernel checks the sizes (status 3), numba the types and layouts (TypeError)
            status = kernel(cfj(model, data, q, fid, _LWA)[rows], q, xdot, out, F, Iw)
        except FaultToleranceError:
            raise
        except _ERRORS:
            return retry(q, xdot, out)
        if status:
            if status == 1:
                counts[BOUNDED_STEPS] += 1
            elif status == 3:
                return reference(q, xdot, out)
        return out

    target.append(step)
    step.__name__ = name
    step.__doc__ = f"{name} inside the rate box of the joint limits; compiled."
    return step
