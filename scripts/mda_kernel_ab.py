"""The compiled MDA kernel of a git revision against the working tree's, in one process.

Both kernels (``control/fast/mda_step.py`` as of ``REV``, and as checked out) run on the
benchmark's pool of Jacobians, in alternated rounds so that the shared machine's load falls on
both alike; prints the median over rounds of each kernel's 10th-percentile and median call time,
and the largest gap between their rates. The bench's ``mda_over_jvja`` row cannot separate
changes of a few percent from its noise; this can::

    python scripts/mda_kernel_ab.py HEAD~1 panda_pose panda_position spatial_4r
"""

from __future__ import annotations

import argparse
import importlib.util
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pinocchio as pin
from mda_breakdown import call_times_us  # scripts/, beside this file

from fault_tolerance.bench.cases import ARMS, make_case
from fault_tolerance.control.fast import mda_step

KERNEL = "fault_tolerance/control/fast/mda_step.py"
ROUNDS, CALLS = 8, 20000


def kernel_at(rev: str, folder: Path):
    """The module ``mda_step`` as of ``rev``, imported under another name (no numba cache)."""
    text = subprocess.run(["git", "show", f"{rev}:{KERNEL}"], check=True, capture_output=True,
                          text=True, cwd=Path(__file__).resolve().parents[1]).stdout  # fmt: skip
    path = folder / "mda_step_at_rev.py"
    path.write_text(text.replace("cache=True", "cache=False"))
    spec = importlib.util.spec_from_file_location("mda_step_at_rev", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def call_times(kernel, calls) -> tuple[float, float]:
    """10th percentile and median of ``kernel(*calls[i])`` over :data:`CALLS` calls [µs]."""
    ts = call_times_us(kernel, calls, CALLS)
    return float(np.percentile(ts, 10)), float(np.median(ts))


def compare(key: str, modules: dict) -> None:
    """Print both kernels' times and their largest rate gap on the bench case ``key``."""
    case = make_case(key)
    cw = case.ctrl.workspace
    Jfs = [pin.computeFrameJacobian(cw.model, cw.data, q, cw.frame_id, pin.LOCAL_WORLD_ALIGNED).copy()
           for q in case.qs]  # fmt: skip
    calls, outs = {}, {}
    for name, module in modules.items():
        F, Iw = module.gradient_workspace(cw)
        out = np.empty(cw.n)
        calls[name] = [(Jf, xd, out, F, Iw) for Jf, xd in zip(Jfs, case.xds, strict=True)]
        outs[name] = out
    gap = 0.0
    for a, b in zip(calls["rev"][:200], calls["tree"][:200], strict=True):
        modules["rev"].mda_kernel(*a)
        modules["tree"].mda_kernel(*b)
        ref = outs["rev"]
        gap = max(gap, float(np.abs(ref - outs["tree"]).max() / max(1.0, np.abs(ref).max())))
    rounds = {name: [] for name in modules}
    for r in range(ROUNDS):
        for name in ("rev", "tree") if r % 2 == 0 else ("tree", "rev"):
            rounds[name].append(call_times(modules[name].mda_kernel, calls[name]))
    for name, label in (("rev", "revision"), ("tree", "working tree")):
        p10, med = np.median(np.array(rounds[name]), axis=0)
        print(f"{key}: {label} kernel {p10:.2f} µs (10th percentile), {med:.2f} µs (median)")
    print(f"{key}: largest rate gap {gap:.1e} of the rates")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("rev", help="git revision of the kernel to compare with, e.g. HEAD~1")
    parser.add_argument("arms", nargs="+", choices=sorted(ARMS), metavar="ARM",
                        help="benchmark arms, e.g. panda_pose spatial_4r")  # fmt: skip
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        modules = {"rev": kernel_at(args.rev, Path(folder)), "tree": mda_step}
        for key in args.arms:
            compare(key, modules)


if __name__ == "__main__":
    main()
