"""Suite-wide settings. solver.path auto (the scene default) means, for a command, the fast path once its stepper is
compiled on the machine: which path a command took would then depend on what earlier tests happened to compile.
The suite fixes auto to the reference path (MECH_REGULATOR_AUTO_PATH, also in every subprocess and node it starts);
test/test_auto_path.py takes it away to test auto itself.

No command of the suite starts or uses a command server (MECH_REGULATOR_SERVER=off, inherited by every `mech-regulator`
subprocess): a test never depends on one nor leaves one behind. test/test_cli_server.py runs its own, in a folder of
its own, and stops it.

`./dev test` runs the suite on pytest-xdist's workers (`-n auto --dist loadfile`): each worker is a process of its
own, so that its ROS domains (ros_support.next_domain_id: a lock file per domain), tmp_path and command-server folders
are its own; numba's cache and the fast path's cache folder are shared, written atomically (cache.write), a stepper
compiled under its method's lock (solvers/compiled/warm.py). A module's tests all run on one worker, so that a
module-scoped fixture (a node run, a sweep) runs once. (Not `--dist loadgroup`: pytest-xdist 3.8 marks a group by
rewriting a test's nodeid, which pytest 9 no longer reads, so no test is grouped.)

Markers (registered in setup.cfg): `physics`, the physics core's own tests (PHYSICS_MODULES): `pytest -m physics`
runs them alone, in-process on the reference path (its time: docs/speed.md, The test suite)."""

import os

import pytest

os.environ["MECH_REGULATOR_AUTO_PATH"] = "reference"
os.environ["MECH_REGULATOR_SERVER"] = "off"

# The modules of the physics core's own tests: no ROS node, no subprocess, no fast path (test_suite_markers.py
# checks it); the machine's kinematics, dynamics, energy method, governor statics and dynamics, linkages
PHYSICS_MODULES = frozenset(
    {
        "test_advice",
        "test_crank_slider",
        "test_dynamics",
        "test_energy_method",
        "test_energy_method_corners",
        "test_engine_quadrature",
        "test_four_bar",
        "test_governor_dynamics",
        "test_governor_statics",
        "test_linkage",
        "test_linkage_friction_corners",
        "test_output_link_loads",
    }
)


def mark_physics(items: list[pytest.Item]) -> None:
    """Mark the tests of PHYSICS_MODULES `physics`."""
    for item in items:
        module = getattr(item, "module", None)
        if module is not None and module.__name__ in PHYSICS_MODULES:
            item.add_marker(pytest.mark.physics)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark the physics tests (mark_physics)."""
    mark_physics(items)
