#!/usr/bin/env python3
"""Performance benchmark of the real-time steps: the same as ``fault-tolerance bench``.

python scripts/benchmark.py                                   # table and targets
python scripts/benchmark.py --robots panda_pose --json new.json
python scripts/benchmark.py --compare old.json new.json       # per-row ratio
"""

from fault_tolerance.bench.command import main

if __name__ == "__main__":
    raise SystemExit(main())
