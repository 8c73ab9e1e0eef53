"""`python -m mech_regulator` runs the command line."""

import sys

from mech_regulator.cli import entry

sys.exit(entry())
