"""Suite-wide settings. solver.path auto (the scene default) means, for a command, the fast path once its stepper is
compiled on the machine: which path a command took would then depend on what earlier tests happened to compile.
The suite fixes auto to the reference path (MECH_REGULATOR_AUTO_PATH, also in every subprocess and node it starts);
test/test_auto_path.py takes it away to test auto itself.

No command of the suite starts or uses a command server (MECH_REGULATOR_SERVER=off, inherited by every `mech-regulator`
subprocess): a test never depends on one nor leaves one behind. test/test_cli_server.py runs its own, in a folder of
its own, and stops it.

`./dev test` runs the suite on pytest-xdist's workers (`-n auto --dist loadfile`, one more worker than cores:
pytest_xdist_auto_num_workers): each worker is a process of its
own, so that its ROS domains (ros_support.next_domain_id: a lock file per domain), tmp_path and command-server folders
are its own; numba's cache and the fast path's cache folder are shared, written atomically (cache.write), a stepper
compiled under its method's lock (solvers/compiled/warm.py). A module's tests all run on one worker, so that a
module-scoped fixture (a node run, a sweep) runs once. (Not `--dist loadgroup`: pytest-xdist 3.8 marks a group by
rewriting a test's nodeid, which pytest 9 no longer reads, so no test is grouped.)

The order of the files (order_files): pytest-xdist's loadfile hands out whole files, by default those with the most
tests first, which left the longest files (a few long node runs or integrations each) to the suite's end, where one
worker ran them while the other had finished; LONGEST_FILES are handed out first instead, longest first, and the many
short files then fill both workers' ends (docs/speed.md, "The test suite").

Markers (registered in setup.cfg): `physics`, the physics core's own tests (PHYSICS_MODULES): `pytest -m physics`
runs them alone, in-process on the reference path (its time: docs/speed.md, The test suite)."""

import os
import sys

import pytest

import mech_regulator  # noqa: F401  (first: it fixes OpenBLAS's kernels before anything loads numpy)

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


# The files whose tests take longest on the 2-core machine (docs/speed.md, "The test suite": a fresh clone's whole run,
# the sum of each file's --durations), longest first: node runs, long integrations, the fast path's first compiles
LONGEST_FILES = (
    "test_fast_path_summaries",
    "test_main_job_scenes",
    "test_hard_cases_machine",
    "test_hard_cases_governor",
    "test_ros_nodes",
    "test_compiled_path",
    "test_hostile_participant",
    "test_bench_accuracy",
    "test_linkage_family",
    "test_fast_path_warming",
    "test_hostile_input",
    "test_own_controller",
    "test_cli_startup",
)


def order_files(items: list[pytest.Item]) -> None:
    """Order `items` in place by their files (module docstring): LONGEST_FILES first in that order, then the other
    files by their number of tests, most first (pytest-xdist's own order); each file's tests in their own order."""
    counts: dict[str, int] = {}
    for item in items:
        counts[item.path.stem] = counts.get(item.path.stem, 0) + 1

    def rank(item: pytest.Item) -> tuple[int, int, str]:
        name = item.path.stem
        if name in LONGEST_FILES:
            return LONGEST_FILES.index(name), 0, name
        return len(LONGEST_FILES), -counts[name], name

    items.sort(key=rank)


def pytest_xdist_auto_num_workers(config: pytest.Config) -> int:
    """`-n auto`'s number of workers: one more than the cores this process may run on. On two workers the suite left
    the two cores idle a third to a half of the time for minutes together (vmstat: the node runs wait on each other
    and on their timeouts), which a third worker fills: 11 min 21 s on two workers, 9 min 16 s on three, idle, with
    995 s of CPU (docs/speed.md, "The test suite")."""
    return len(os.sched_getaffinity(0)) + 1


def pytest_configure(config: pytest.Config) -> None:
    """Have pytest-xdist hand out the files in the order of order_files, not re-sorted by their number of tests."""
    if hasattr(config.option, "loadscopereorder"):
        config.option.loadscopereorder = False


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark the physics tests (mark_physics) and order the files (order_files)."""
    mark_physics(items)
    order_files(items)


@pytest.fixture(autouse=True)
def ros_domains_released():
    """The ROS domains a test claimed (ros_support.next_domain_id) released once it and its fixtures have ended (an
    autouse fixture is torn down after the test's others, so after its processes are stopped; a module fixture's runs
    end within the fixture). A worker held every domain it had used until it ended: some 60 each, and a second suite
    beside this one then found all 119 taken."""
    launch = sys.modules.get("mech_regulator.nodes.launch")  # imported by the ROS tests only
    held = len(launch._claimed_domains) if launch else 0
    yield
    launch = sys.modules.get("mech_regulator.nodes.launch")
    if launch:
        launch.release_domains(keep=held)
