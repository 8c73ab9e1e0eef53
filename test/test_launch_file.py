"""launch/main_job.launch.py (for `ros2 launch` where ROS comes from a distribution) and the parameter
file it shares with `mech-regulator run`: config/params/main_job.yaml.

The launch packages are not on the package index, so the launch file is checked as source (it compiles,
names the executables that setup.py installs and that `mech-regulator run` starts) and run against
stand-ins of launch / launch_ros that take the real API's signatures and record what the file asks for.
"""

from __future__ import annotations

import ast
import importlib.util
import re
import sys
import time
import types
from pathlib import Path

import pytest
import yaml
from support import setup_arguments

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "mech_regulator"
LAUNCH_FILE = ROOT / "launch" / "main_job.launch.py"
PARAMS_FILE = "config/params/main_job.yaml"
RUN_LAUNCHER = ROOT / PACKAGE / "nodes" / "launch.py"  # `mech-regulator run`
SHARE = "/opt/ros/kilted/share/mech_regulator"  # what the stand-in of get_package_share_directory answers
SIM_TIME_NODES = {"governor", "scenario", "recorder"}  # the nodes that follow the machine's /clock


def node_console_scripts() -> dict[str, str]:
    """setup.py's console scripts of the nodes: executable -> module."""
    scripts = {}
    for line in setup_arguments()["entry_points"]["console_scripts"]:
        name, target = (part.strip() for part in line.split("="))
        module = target.split(":")[0]
        if module.startswith(f"{PACKAGE}.nodes."):
            scripts[name] = module
    return scripts


def nodes_run_starts(governed: bool = True) -> set[str]:
    """The node modules `mech-regulator run` starts (as `python -m mech_regulator.nodes.NAME`)."""
    from mech_regulator.nodes.launch import node_names

    return {f"{PACKAGE}.nodes.{name}" for name in node_names(governed=governed)}


def launch_file_strings() -> set[str]:
    return {
        node.value
        for node in ast.walk(ast.parse(LAUNCH_FILE.read_text(encoding="utf-8")))
        if isinstance(node, ast.Constant) and isinstance(node.value, str)
    }


def test_launch_file_compiles():
    source = LAUNCH_FILE.read_text(encoding="utf-8")
    compile(source, str(LAUNCH_FILE), "exec")
    functions = {node.name for node in ast.parse(source).body if isinstance(node, ast.FunctionDef)}
    assert "generate_launch_description" in functions


def test_launch_file_names_the_node_executables_that_setup_py_installs_and_run_starts():
    scripts = node_console_scripts()
    assert set(scripts) == {"machine_node", "governor_node", "scenario_node", "recorder_node"}, scripts
    assert set(scripts.values()) == nodes_run_starts(), (
        f"setup.py's node scripts run {sorted(scripts.values())}; `mech-regulator run` starts {sorted(nodes_run_starts())}"
    )
    named = {text for text in launch_file_strings() if re.fullmatch(r"\w+_node", text)}
    assert named == set(scripts), f"the launch file names {sorted(named)}; setup.py installs {sorted(scripts)}"


def test_launch_file_and_run_read_the_shipped_params_file():
    assert PARAMS_FILE in launch_file_strings(), f"the launch file does not refer to {PARAMS_FILE}"
    assert (ROOT / PARAMS_FILE).is_file()
    run_strings = {
        node.value
        for node in ast.walk(ast.parse(RUN_LAUNCHER.read_text(encoding="utf-8")))
        if isinstance(node, ast.Constant) and isinstance(node.value, str)
    }
    assert {"params", "main_job.yaml"} <= run_strings, f"{RUN_LAUNCHER} no longer reads params/main_job.yaml"


def test_setup_py_installs_the_launch_file_and_the_params_file_under_share():
    data_files = {destination: files for destination, files in setup_arguments()["data_files"]}
    assert "launch/main_job.launch.py" in data_files.get(f"share/{PACKAGE}/launch", []), data_files
    assert PARAMS_FILE in data_files.get(f"share/{PACKAGE}/config/params", []), data_files


# -------------------------------------------------------------------------------------------------
# The launch file run against stand-ins of the launch API


class LaunchContext:
    """The part of launch.LaunchContext a launch file reads: launch_configurations."""

    def __init__(self, launch_configurations: dict[str, str]):
        self.launch_configurations = launch_configurations


def _launch_stand_ins() -> dict[str, types.ModuleType]:
    """launch, launch.actions, launch.substitutions, launch_ros(.actions) and ament_index_python(.packages),
    with the signatures of ROS 2 kilted's (keyword-only where those are)."""

    class LaunchDescription:
        def __init__(self, initial_entities=None, *, deprecated_reason=None):
            self.entities = list(initial_entities or [])

    class DeclareLaunchArgument:
        def __init__(self, name, *, default_value=None, description=None, choices=None, **kwargs):
            self.name, self.default_value, self.description = name, default_value, description

    class OpaqueFunction:
        def __init__(self, *, function, args=None, kwargs=None, **left_over_kwargs):
            self.function, self.args, self.kwargs = function, list(args or []), dict(kwargs or {})

        def execute(self, context):
            return self.function(context, *self.args, **self.kwargs)

    class LaunchConfiguration:
        def __init__(self, variable_name, *, default=None):
            self.variable_name = variable_name

        def perform(self, context):
            return context.launch_configurations[self.variable_name]

    class Node:
        def __init__(
            self,
            *,
            executable,
            package=None,
            name=None,
            namespace=None,
            exec_name=None,
            parameters=None,
            remappings=None,
            ros_arguments=None,
            arguments=None,
            **kwargs,
        ):
            self.executable, self.package, self.name = executable, package, name
            self.parameters = list(parameters or [])
            self.options = kwargs

    def get_package_share_directory(package_name, print_warning=True):
        assert package_name == PACKAGE
        return SHARE

    modules = {
        name: types.ModuleType(name)
        for name in (
            "launch",
            "launch.actions",
            "launch.substitutions",
            "launch_ros",
            "launch_ros.actions",
            "ament_index_python",
            "ament_index_python.packages",
        )
    }
    modules["launch"].LaunchDescription = LaunchDescription
    modules["launch.actions"].DeclareLaunchArgument = DeclareLaunchArgument
    modules["launch.actions"].OpaqueFunction = OpaqueFunction
    modules["launch.substitutions"].LaunchConfiguration = LaunchConfiguration
    modules["launch_ros.actions"].Node = Node
    modules["ament_index_python.packages"].get_package_share_directory = get_package_share_directory
    return modules


def launched_nodes(arguments: dict[str, str]) -> tuple[dict[str, object], list]:
    """Load the launch file with the stand-ins, then do what `ros2 launch` does with it: arguments with
    their defaults, overridden by `arguments`, and the opaque functions executed. Returns the declared
    arguments by name and the Node actions."""
    with pytest.MonkeyPatch.context() as patch:
        for name, module in _launch_stand_ins().items():
            patch.setitem(sys.modules, name, module)
        spec = importlib.util.spec_from_file_location("main_job_launch", LAUNCH_FILE)
        launch_file = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(launch_file)
        description = launch_file.generate_launch_description()
        declared = {entity.name: entity for entity in description.entities if hasattr(entity, "default_value")}
        context = LaunchContext({name: entity.default_value for name, entity in declared.items()} | arguments)
        nodes = []
        for entity in description.entities:
            if hasattr(entity, "execute"):
                nodes += entity.execute(context) or []
            elif hasattr(entity, "executable"):
                nodes.append(entity)
    return declared, nodes


def test_launch_file_arguments_default_to_engine_direct_and_the_installed_params_file():
    declared, _ = launched_nodes({})
    assert set(declared) == {"scene", "params_file", "controller"}
    assert declared["controller"].default_value == "governor"
    assert declared["scene"].default_value == "engine_direct"
    assert declared["params_file"].default_value == f"{SHARE}/{PARAMS_FILE}"


@pytest.mark.parametrize(
    "scene, expected",
    [
        ("engine_direct", ["recorder_node", "governor_node", "scenario_node", "machine_node"]),
        ("lathe", ["recorder_node", "scenario_node", "machine_node"]),  # no governor
    ],
)
def test_launch_file_starts_the_governor_only_for_a_governed_scene(scene, expected):
    from mech_regulator.scene import load_scene

    assert (load_scene(scene).governor is not None) == ("governor_node" in expected)
    params_file = str(ROOT / PARAMS_FILE)
    _, nodes = launched_nodes({"scene": scene, "params_file": params_file})
    assert [node.executable for node in nodes] == expected
    sections = set(yaml.safe_load((ROOT / PARAMS_FILE).read_text()))
    for node in nodes:
        assert node.package == PACKAGE
        assert node.name in sections, f"{node.executable} is named {node.name!r}: no section of {PARAMS_FILE}"
        assert node.parameters[0] == params_file, f"{node.executable} does not start from the params file"
        overrides = {key: value for extra in node.parameters[1:] for key, value in extra.items()}
        assert overrides.get("scene_file") == scene, f"{node.executable} is not given the scene: {node.parameters}"
    machine = next(node for node in nodes if node.executable == "machine_node")
    peers = next(extra["peers"] for extra in machine.parameters[1:] if "peers" in extra)
    assert sorted(peers) == sorted(node.name for node in nodes if node is not machine), (
        "the machine must wait for every other node started (the recorder too, so that it records from t = 0)"
    )


def test_launch_file_with_an_external_controller_leaves_the_governor_out():
    _, nodes = launched_nodes(
        {"scene": "engine_direct", "params_file": str(ROOT / PARAMS_FILE), "controller": "external"}
    )
    assert [node.executable for node in nodes] == ["recorder_node", "scenario_node", "machine_node"]
    for node in nodes:
        overrides = {key: value for extra in node.parameters[1:] for key, value in extra.items()}
        assert overrides["overrides"] == ["governor=null", "scenario.initial.sleeve=null"], node.parameters
        assert overrides.get("controller", "external") == "external", node.parameters
    machine = nodes[-1]
    assert {"controller": "external"}.items() <= {
        key: value for extra in machine.parameters[1:] for key, value in extra.items()
    }.items()


# -------------------------------------------------------------------------------------------------
# use_sim_time


def test_params_file_sets_use_sim_time_for_the_nodes_that_follow_the_machine_clock():
    parameters = yaml.safe_load((ROOT / PARAMS_FILE).read_text())
    following = {
        section for section, values in parameters.items() if values["ros__parameters"].get("use_sim_time") is True
    }
    assert following == SIM_TIME_NODES
    assert "use_sim_time" not in parameters["/**"]["ros__parameters"]
    machine = parameters["machine"]["ros__parameters"]
    assert machine.get("use_sim_time", False) is False, "the machine publishes /clock; it must not follow it"
    # what the machine waits for follows from the scene (a fixed count made ungoverned scenes hang)
    assert not {"lockstep_inputs", "min_subscribers"} & set(machine), machine


@pytest.fixture
def ros_domain() -> int:
    pytest.importorskip("rclpy", reason="the ROS 2 tests need rclpy (pip install 'mech_regulator[ros]')")
    from ros_support import next_domain_id

    return next_domain_id()


def test_nodes_started_with_the_params_file_follow_a_published_clock(ros_domain):
    """Nodes named as the main job's, given the shipped params file as `--params-file` (as both launchers
    do), in this process: the governor, scenario and recorder take the time of a /clock a test publisher
    sends; the machine keeps the system time."""
    import rclpy
    from builtin_interfaces.msg import Time
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions
    from ros_support import WAIT, ros_environment
    from rosgraph_msgs.msg import Clock

    published = Time(sec=123, nanosec=456_000_789)
    published_ns = published.sec * 1_000_000_000 + published.nanosec
    with pytest.MonkeyPatch.context() as patch:
        for key, value in ros_environment(ros_domain).items():
            if key.startswith(("ROS_", "RMW_", "AMENT_")):
                patch.setenv(key, value)
        context = Context()
        rclpy.init(
            args=["--ros-args", "--params-file", str(ROOT / PARAMS_FILE)],
            context=context,
            domain_id=ros_domain,
            signal_handler_options=SignalHandlerOptions.NO,
        )
        executor = SingleThreadedExecutor(context=context)
        try:
            nodes = {name: rclpy.create_node(name, context=context) for name in ("machine", *sorted(SIM_TIME_NODES))}
            clock_source = rclpy.create_node("clock_source", context=context)
            for node in [*nodes.values(), clock_source]:
                executor.add_node(node)
            clock_publisher = clock_source.create_publisher(Clock, "/clock", 10)
            for name, node in nodes.items():
                assert node.get_parameter("use_sim_time").value == (name in SIM_TIME_NODES), name

            def followers() -> set[str]:
                return {name for name, node in nodes.items() if node.get_clock().now().nanoseconds == published_ns}

            deadline = time.monotonic() + WAIT  # only turns a hang into a failure
            while followers() != SIM_TIME_NODES and time.monotonic() < deadline:
                clock_publisher.publish(Clock(clock=published))
                executor.spin_once(timeout_sec=0.05)
            assert followers() == SIM_TIME_NODES, (
                f"after {WAIT} s of /clock at {published_ns} ns, the nodes on it: {sorted(followers())}"
            )
            machine_clock = nodes["machine"].get_clock()
            assert not machine_clock.ros_time_is_active
            assert machine_clock.now().nanoseconds != published_ns
        finally:
            executor.shutdown()
            rclpy.shutdown(context=context)
