"""``python -m prsm_health`` runs the ``prsm-health`` command line."""

import sys

from prsm_health.cli import main

sys.exit(main())
