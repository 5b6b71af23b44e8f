"""Regenerate every result of the paper: ``python scripts/reproduce.py [--out DIR] [--quick]``.

A thin entry point; the pipeline is :func:`fault_tolerance.paper.reproduce.reproduce`.
"""

import sys

from fault_tolerance.cli import main

if __name__ == "__main__":
    sys.exit(main(["reproduce", *sys.argv[1:]]))
