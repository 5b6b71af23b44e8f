"""Measure the batched API's agreement with the scalar API on the shipped arms and the Panda.

Usage: python scripts/batch_agreement.py [--rows 2000] [--seed 0]
Prints one line per arm, task and kind of row (random, ill-conditioned): the largest relative
difference of LNVA's and JVJA's rates, of λ and of every k_S (docs/batch.md quotes the result).
"""

from __future__ import annotations

import argparse

import fault_tolerance as ft
from fault_tolerance.analysis.batch_agreement import BATCH_RTOL, batch_agreement

CASES = [
    ("planar_3r", {}, [0, 1, 2]),
    ("spatial_4r", {}, [0, 1, 2]),
    ("powercube_3r", {}, [0, 1, 2]),
    ("panda", {"task": "position"}, [0, 1, 2, 3, 4, 5, 6]),
    ("panda", {"task": "pose"}, [0, 1, 2, 3, 4, 5, 6]),
]


def main() -> int:
    """Print the table; exit 1 when a difference exceeds BATCH_RTOL."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=2000, help="rows of each kind per arm")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    worst = 0.0
    print("arm task kind rows sigma_min lnva jvja jvja_cont jvj rcn")
    for name, kw, lockable in CASES:
        arm = ft.load_arm(name, **kw)
        res = batch_agreement(
            arm, lockable, random_rows=args.rows, ill_rows=args.rows, seed=args.seed
        )
        for kind in ("random", "ill"):
            r = res[kind]
            print(
                f"{name} {kw.get('task', '-')} {kind} {int(r['rows'])} {r['sigma_min']:.1e} "
                f"{r['lnva']:.1e} {r['jvja']:.1e} {r['jvja_continuation']:.1e} {r['jvj']:.1e} {r['rcn']:.1e}"
            )
        worst = max(
            worst, *(res["all"][k] for k in ("lnva", "jvja", "jvja_continuation", "jvj", "rcn"))
        )
    print(f"largest relative difference {worst:.2e} (tolerance {BATCH_RTOL:g})")
    return int(worst > BATCH_RTOL)


if __name__ == "__main__":
    raise SystemExit(main())
