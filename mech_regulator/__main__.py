"""`python -m mech_regulator` runs the command line."""

import sys

from mech_regulator.cli.main import main

sys.exit(main())
