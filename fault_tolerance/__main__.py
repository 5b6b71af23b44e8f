"""``python -m fault_tolerance`` runs the ``fault-tolerance`` command."""

import sys

from fault_tolerance.cli import main

sys.exit(main())
