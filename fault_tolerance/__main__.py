"""``python -m fault_tolerance`` runs the ``fault-tolerance`` command."""

import sys

from .cli import main

sys.exit(main())
