"""Compare two reproduce summary.json files number by number (relative + absolute tolerance).

Usage: python scripts/compare_summary.py BASE/summary.json NEW/summary.json [--tol 1e-9]
Exit 0 when every number agrees to tol (|a-b| <= tol * max(1, |a|)) and the structure matches;
timings (keys named ``seconds`` and ``step_time_us``) are ignored.
"""

from __future__ import annotations

import argparse
import json
import math
import sys

IGNORED = {"seconds", "step_time_us", "created", "command", "version"}


def diffs(a, b, path="", tol=1e-9):
    """Differences between two JSON values, as (path, a, b)."""
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if k in IGNORED:
                continue
            if k not in a or k not in b:
                yield (f"{path}/{k}", a.get(k, "<missing>"), b.get(k, "<missing>"))
            else:
                yield from diffs(a[k], b[k], f"{path}/{k}", tol)
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            yield (f"{path}[len]", len(a), len(b))
        for i, (x, y) in enumerate(zip(a, b, strict=False)):
            yield from diffs(x, y, f"{path}[{i}]", tol)
    elif isinstance(a, bool) or isinstance(b, bool) or not isinstance(a, (int, float)):
        if a != b:
            yield (path, a, b)
    elif isinstance(b, (int, float)):
        if math.isnan(a) and math.isnan(b):
            return
        if not abs(a - b) <= tol * max(1.0, abs(a)):
            yield (path, a, b)
    else:
        yield (path, a, b)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("base")
    p.add_argument("new")
    p.add_argument("--tol", type=float, default=1e-9)
    args = p.parse_args(argv)
    a = json.load(open(args.base))
    b = json.load(open(args.new))
    found = list(diffs(a, b, tol=args.tol))
    for path, x, y in found[:50]:
        print(f"{path}: {x!r} != {y!r}")
    n = sum(1 for _ in _numbers(a))
    print(f"{len(found)} difference(s) beyond {args.tol:g} among {n} numbers")
    return 1 if found else 0


def _numbers(x):
    if isinstance(x, dict):
        for v in x.values():
            yield from _numbers(v)
    elif isinstance(x, list):
        for v in x:
            yield from _numbers(v)
    elif isinstance(x, (int, float)) and not isinstance(x, bool):
        yield x


if __name__ == "__main__":
    sys.exit(main())
