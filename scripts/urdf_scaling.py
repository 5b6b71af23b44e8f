"""Time and peak memory of `inspect` and a short `simulate` on serial chains of N joints.

Usage: python scripts/urdf_scaling.py 50 100 200 400 [--timeout 600]

Each command runs in its own process (``/usr/bin/time``-free: the child's peak RSS comes from
``resource.getrusage(RUSAGE_CHILDREN)``, a running maximum); the chain alternates z and y axes, so every
N gives a spatial arm with redundancy N - 3 for the position task. This measurement set
``arm.MAX_ACTIVE_JOINTS`` (200): past it the commands exit 2 at once.
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def chain(n: int) -> str:
    """A serial chain of ``n`` revolute joints j1..jn ending in link ``tool``."""
    parts = ['<?xml version="1.0"?>\n<robot name="chain">', '<link name="l0"/>']
    for i in range(1, n + 1):
        child = "tool" if i == n else f"l{i}"
        axis = "0 0 1" if i % 2 else "0 1 0"
        parts.append(
            f'<joint name="j{i}" type="revolute"><parent link="l{i - 1}"/><child link="{child}"/>'
            f'<origin xyz="0 0 {0.0 if i == 1 else 0.1}"/><axis xyz="{axis}"/>'
            '<limit lower="-3" upper="3" effort="10" velocity="2"/></joint>'
        )
        parts.append(f'<link name="{child}"/>')
    return "\n".join(parts + ["</robot>\n"])


def measure(args: list[str], timeout: float) -> tuple[float, float, int]:
    """(seconds, peak RSS [MiB], exit code) of ``python -m fault_tolerance ARGS``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    start = time.perf_counter()
    try:
        rc = subprocess.run(
            [sys.executable, "-m", "fault_tolerance", *args],
            capture_output=True,
            timeout=timeout,
        ).returncode
    except subprocess.TimeoutExpired:
        rc = -1
    seconds = time.perf_counter() - start
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return seconds, max(peak, before) / 1024, rc


DATA = """
import resource, sys, time
from pathlib import Path
from fault_tolerance.model.formats.build import build_model
from fault_tolerance.model.formats.urdf import read_urdf
model = build_model(read_urdf(Path(sys.argv[1])))
t = time.perf_counter()
data = model.createData()
print(time.perf_counter() - t, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
"""


def measure_data(path: Path, timeout: float) -> tuple[float, float]:
    """(seconds, peak RSS [MiB]) of Pinocchio's ``createData`` for the whole chain, in a child."""
    r = subprocess.run(
        [sys.executable, "-c", DATA, str(path)], capture_output=True, text=True, timeout=timeout
    )
    if r.returncode != 0:
        return float("nan"), float("nan")
    seconds, mib = (float(v) for v in r.stdout.split())
    return seconds, mib


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("sizes", type=int, nargs="+")
    p.add_argument("--timeout", type=float, default=600.0)
    p.add_argument(
        "--no-data", action="store_true", help="skip Pinocchio's createData (N³ memory!)"
    )
    a = p.parse_args()
    print(f"{'N':>6} {'command':10} {'seconds':>8} {'peak MiB':>9} {'exit':>5}")
    with tempfile.TemporaryDirectory() as tmp:
        for n in a.sizes:
            path = Path(tmp) / f"chain{n}.urdf"
            path.write_text(chain(n))
            commands = {
                "inspect": ["inspect", str(path)],
                "simulate": [
                    "simulate",
                    "--urdf",
                    str(path),
                    "--task",
                    "position",
                    "--duration",
                    "0.01",
                    "--algorithms",
                    "jvja",
                    "--no-progress",
                    "--out",
                    f"{tmp}/out{n}",
                ],
            }
            if not a.no_data:
                s, mib = measure_data(path, a.timeout)
                print(f"{n:6d} {'createData':10} {s:8.2f} {mib:9.0f} {'':>5}", flush=True)
            for name, args in commands.items():
                s, mib, rc = measure(args, a.timeout)
                print(f"{n:6d} {name:10} {s:8.2f} {mib:9.0f} {rc:5d}", flush=True)


if __name__ == "__main__":
    main()
