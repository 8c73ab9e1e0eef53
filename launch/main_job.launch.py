"""The main job as a ROS 2 launch file, for a colcon workspace on a ROS 2 distribution:

    ros2 launch mech_regulator main_job.launch.py scene:=lathe [controller:=external]

starts recorder_node, governor_node (only when the scene has a governor), scenario_node and
machine_node with config/params/main_job.yaml, the parameter file `mech-regulator run` starts from. With
controller:=external the scene's governor is left out and the machine waits for a controller the user starts
(docs/ros.md, "Your own controller").
Where ROS comes from the package index (no ros2 launch), `mech-regulator run SCENE` does the same.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from mech_regulator.nodes.controller import CONTROLLERS, governor_left_out
from mech_regulator.nodes.launch import FASTDDS_PROFILE_VARIABLE, node_names
from mech_regulator.scene import load_scene

PACKAGE = "mech_regulator"
PARAMS_FILE = "config/params/main_job.yaml"  # what `mech-regulator run` starts from
FASTDDS_PROFILE = "config/params/fastdds.xml"  # acknowledgements asked every 20 ms (nodes.launch.fastdds_profile)
# node name (its section in the params file) -> executable
EXECUTABLES = {
    "recorder": "recorder_node",
    "governor": "governor_node",
    "scenario": "scenario_node",
    "machine": "machine_node",
}


def _nodes(context, *args, **kwargs):
    """The nodes `mech-regulator run` starts for the chosen scene (the governor only when it has one), with
    the choices it adds to the params file: the scene and the machine's peers (its overspeed trip is the params file's
    machine.overspeed_trip, none unless set there); and, unless one is set, the bundled Fast DDS profile."""
    scene_file = LaunchConfiguration("scene").perform(context)
    params_file = LaunchConfiguration("params_file").perform(context)
    controller = LaunchConfiguration("controller").perform(context)
    scene = load_scene(scene_file)
    overrides = governor_left_out(scene) if controller == "external" else []
    names = node_names(governed=scene.governor is not None and not overrides)
    run_choices = {
        name: {"scene_file": scene_file, **({"overrides": overrides} if overrides else {})} for name in names
    }
    for name in ("machine", "recorder"):
        run_choices[name].update(controller=controller)
    run_choices["machine"].update(peers=[name for name in names if name != "machine"])
    profile = (
        {}
        if FASTDDS_PROFILE_VARIABLE in os.environ
        else {FASTDDS_PROFILE_VARIABLE: os.path.join(get_package_share_directory(PACKAGE), FASTDDS_PROFILE)}
    )
    return [
        Node(
            package=PACKAGE,
            executable=EXECUTABLES[name],
            name=name,
            output="screen",
            parameters=[params_file, run_choices[name]],
            additional_env=profile,
        )
        for name in names
    ]


def generate_launch_description():
    default_params_file = os.path.join(get_package_share_directory(PACKAGE), PARAMS_FILE)
    return LaunchDescription(
        [
            DeclareLaunchArgument(
                "scene", default_value="engine_direct", description="a bundled scene name or the path of a scene file"
            ),
            DeclareLaunchArgument(
                "params_file", default_value=default_params_file, description="node parameters in ros__parameters form"
            ),
            DeclareLaunchArgument(
                "controller",
                default_value="governor",
                choices=list(CONTROLLERS),
                description="what gives the throttle: the scene's governor, or external: a node you "
                "start (the scene's governor is then left out)",
            ),
            OpaqueFunction(function=_nodes),
        ]
    )
