"""Suite-wide settings. solver.path auto (the scene default) means, for a command, the fast path once its stepper is
compiled on the machine: which path a command took would then depend on what earlier tests happened to compile.
The suite fixes auto to the reference path (MECH_REGULATOR_AUTO_PATH, also in every subprocess and node it starts);
test/test_auto_path.py takes it away to test auto itself.

No command of the suite starts or uses a command server (MECH_REGULATOR_SERVER=off, inherited by every `mech-regulator`
subprocess): a test never depends on one nor leaves one behind. test/test_cli_server.py runs its own, in a folder of
its own, and stops it.

`./dev test` runs the suite on pytest-xdist's workers (`-n auto --dist loadgroup`): each worker is a process of its
own, so that its ROS domains (ros_support.next_domain_id: a lock file per domain), tmp_path and command-server
folders are its own; numba's cache and the fast path's cache folder are shared, written atomically (cache.write).
The tests of a module that share a module-scoped fixture (a node run, a sweep) are kept on one worker
(group_by_shared_fixtures), so that the fixture runs once, not once per worker.

Markers (registered in setup.cfg): `physics`, the physics core's own tests (PHYSICS_MODULES): `pytest -m physics`
runs them alone, in-process on the reference path, in under a minute on the idle 2-core machine."""

import os

import pytest

os.environ["MECH_REGULATOR_AUTO_PATH"] = "reference"
os.environ["MECH_REGULATOR_SERVER"] = "off"

SHARED_SCOPES = ("module", "package", "session")  # the scopes whose fixture value serves several tests
# The modules of the physics core's own tests: no ROS node, no subprocess, no fast path (test_suite_markers.py
# checks it); the machine's kinematics, dynamics, energy method, governor statics and dynamics, linkages
PHYSICS_MODULES = frozenset({
    "test_advice", "test_crank_slider", "test_dynamics", "test_energy_method", "test_energy_method_corners",
    "test_engine_quadrature", "test_four_bar", "test_governor_dynamics", "test_governor_statics", "test_linkage",
    "test_linkage_friction_corners", "test_output_link_loads",
})


def group_by_shared_fixtures(items: list[pytest.Item]) -> None:
    """Mark each test that uses a fixture of the suite's own (not a plugin's, such as tmp_path_factory) of a
    SHARED_SCOPES scope with xdist_group(its module): under `--dist loadgroup` the module's tests that share it run
    on one worker, the others go to any worker."""
    for item in items:
        definitions = getattr(item, "_fixtureinfo", None)
        if definitions is None:  # not a Python function (a doctest): no fixtures of its own
            continue
        if any(definition.scope in SHARED_SCOPES and definition.baseid  # a plugin's fixture has no base id
               for stack in definitions.name2fixturedefs.values() for definition in stack):
            item.add_marker(pytest.mark.xdist_group(item.module.__name__))


def mark_physics(items: list[pytest.Item]) -> None:
    """Mark the tests of PHYSICS_MODULES `physics`."""
    for item in items:
        module = getattr(item, "module", None)
        if module is not None and module.__name__ in PHYSICS_MODULES:
            item.add_marker(pytest.mark.physics)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark the physics tests (mark_physics) and group the tests that share a fixture (group_by_shared_fixtures)."""
    mark_physics(items)
    group_by_shared_fixtures(items)
