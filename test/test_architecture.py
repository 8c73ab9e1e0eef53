"""The physics core stays free of ROS and of the viewer: nodes and recordings are layers over it."""

import subprocess
import sys

CORE = ["scene", "model", "mechanisms", "effects", "governors", "solvers", "analysis"]


def test_the_core_imports_neither_rclpy_nor_rerun():
    imports = "; ".join(f"import mech_regulator.{part}" for part in CORE)
    script = (f"import sys; {imports}; "
              "print(sorted(name for name in sys.modules if name.split('.')[0] in ('rclpy', 'rerun')))")
    found = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True).stdout.strip()
    assert found == "[]"


def test_the_check_sees_an_import_of_rerun():
    """The check above can fail: importing the recording layer does pull rerun in."""
    script = ("import sys; import mech_regulator.viz.recording; "
              "print('rerun' in sys.modules)")
    assert subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          check=True).stdout.strip() == "True"
