"""Suite-wide settings. solver.path auto (the scene default) means, for a command, the fast path once its stepper is
compiled on the machine: which path a command took would then depend on what earlier tests happened to compile.
The suite fixes auto to the reference path (MECH_REGULATOR_AUTO_PATH, also in every subprocess and node it starts);
test/test_auto_path.py takes it away to test auto itself.

No command of the suite starts or uses a command server (MECH_REGULATOR_SERVER=off, inherited by every `mech-regulator`
subprocess): a test never depends on one nor leaves one behind. test/test_cli_server.py runs its own, in a folder of
its own, and stops it."""

import os

os.environ["MECH_REGULATOR_AUTO_PATH"] = "reference"
os.environ["MECH_REGULATOR_SERVER"] = "off"
