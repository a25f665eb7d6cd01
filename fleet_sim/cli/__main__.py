"""`python -m fleet_sim.cli`: the `fleet-sim` command."""

import sys

from fleet_sim.cli import main

sys.exit(main())
