"""rosbag2 recordings of a run: a folder with one MCAP file and the `metadata.yaml` that `ros2 bag info|play` read,
the topics the nodes publish as CDR-serialised ROS 2 messages with their definitions (schema encoding ros2msg), so
that Foxglove, PlotJuggler and `ros2 bag` open any run, with or without ROS installed (mcap and mcap-ros2-support
serialise; nothing here imports rclpy).

One message per topic and exchange time, stamped (header and log time) with the simulation time [ns] since 0:
`/joint_states` (joint "crank": phi [rad], omega [rad/s], effort the net moment [N m]; a slider's x, v, a rocker's
or a shuttle's as the machine publishes them), `/throttle` (joint "throttle", position 0..1: the throttle applied over
the step from that time), `/load_torque_stamped` (torque.z: the external load [N m] from that time), `/governor/state`
with a governor (joints "sleeve" z [m], z' [m/s]; "arm" angle [rad], rate [rad/s]; "throttle"; "servo",
"feedback_shift" for indirect action; a PI governor's "throttle" and "integral", its integral part [-]),
`/machine/moments` (efforts "drive", "resistance", "external", "net" [N m] on
the crank and "load", the external load applied [N m]), `/clock`; `/diagnostics` once at the start and once at the end
(the run's status). The nodes' batches (nodes.common.Batch) are a transport detail: here each exchange time is its own
message. docs/ros.md, "Bags", says how to open one.
"""

from __future__ import annotations

import math
import os
import tempfile
from pathlib import Path

import numpy as np
import yaml

from mech_regulator.model import MachineModel
from mech_regulator.model.columns import crank_moments
from mech_regulator.model.joints import output_joints

NANOSECONDS = 1_000_000_000
SEPARATOR = "=" * 80
ROS_DISTRO = "kilted"  # the distribution whose message definitions these are (setup.py's ros extra)

# The message definitions (comments left out), each with the definitions it uses.
DEFINITIONS = {
    "builtin_interfaces/Time": "int32 sec\nuint32 nanosec",
    "std_msgs/Header": "builtin_interfaces/Time stamp\nstring frame_id",
    "sensor_msgs/JointState": "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\n"
    "float64[] effort",
    "geometry_msgs/Vector3": "float64 x\nfloat64 y\nfloat64 z",
    "geometry_msgs/Wrench": "Vector3 force\nVector3 torque",
    "geometry_msgs/WrenchStamped": "std_msgs/Header header\nWrench wrench",
    "rosgraph_msgs/Clock": "builtin_interfaces/Time clock",
    "diagnostic_msgs/KeyValue": "string key\nstring value",
    "diagnostic_msgs/DiagnosticStatus": "byte OK=0\nbyte WARN=1\nbyte ERROR=2\nbyte STALE=3\nbyte level\nstring name\n"
    "string message\nstring hardware_id\nKeyValue[] values",
    "diagnostic_msgs/DiagnosticArray": "std_msgs/Header header\nDiagnosticStatus[] status",
}
USES = {
    "std_msgs/Header": ["builtin_interfaces/Time"],
    "sensor_msgs/JointState": ["std_msgs/Header", "builtin_interfaces/Time"],
    "geometry_msgs/WrenchStamped": [
        "std_msgs/Header",
        "builtin_interfaces/Time",
        "geometry_msgs/Wrench",
        "geometry_msgs/Vector3",
    ],
    "rosgraph_msgs/Clock": ["builtin_interfaces/Time"],
    "diagnostic_msgs/DiagnosticArray": [
        "std_msgs/Header",
        "builtin_interfaces/Time",
        "diagnostic_msgs/DiagnosticStatus",
        "diagnostic_msgs/KeyValue",
    ],
}
TOPIC_TYPES = {
    "/joint_states": "sensor_msgs/JointState",
    "/throttle": "sensor_msgs/JointState",
    "/load_torque_stamped": "geometry_msgs/WrenchStamped",
    "/governor/state": "sensor_msgs/JointState",
    "/machine/moments": "sensor_msgs/JointState",
    "/clock": "rosgraph_msgs/Clock",
    "/diagnostics": "diagnostic_msgs/DiagnosticArray",
}
DIAGNOSTIC_LEVELS = {"complete": 0, "interrupted": 1}  # other statuses (failed, ...): ERROR (2)


def message_definition(datatype: str) -> str:
    """The ros2msg text of `datatype` ('sensor_msgs/JointState'): its definition, then each one it uses after a line
    of '=' and 'MSG: <type>', as rosbag2 writes them."""
    parts = [DEFINITIONS[datatype]] + [
        f"{SEPARATOR}\nMSG: {used}\n{DEFINITIONS[used]}" for used in USES.get(datatype, [])
    ]
    return "\n".join(parts) + "\n"


def full_name(datatype: str) -> str:
    """'sensor_msgs/msg/JointState' for 'sensor_msgs/JointState' (the names of ROS 2 types in bags)."""
    package, name = datatype.split("/")
    return f"{package}/msg/{name}"


def _time(nanoseconds: int) -> dict[str, int]:
    return {"sec": nanoseconds // NANOSECONDS, "nanosec": nanoseconds % NANOSECONDS}


def _joints(when: int, joints: list[tuple[str, float, float, float]]) -> dict:
    """A sensor_msgs/JointState stamped `when` [ns] with joints (name, position, velocity, effort)."""
    names, positions, velocities, efforts = (list(column) for column in zip(*joints))
    return {
        "header": {"stamp": _time(when), "frame_id": ""},
        "name": names,
        "position": positions,
        "velocity": velocities,
        "effort": efforts,
    }


def _diagnostics(when: int, model: MachineModel, status: str, message: str, values: dict[str, object]) -> dict:
    """A diagnostic_msgs/DiagnosticArray with the machine's status as machine_node words it."""
    level = DIAGNOSTIC_LEVELS.get(status, 2)
    return {
        "header": {"stamp": _time(when), "frame_id": ""},
        "status": [
            {
                "level": level,
                "name": "mech_regulator: /machine",
                "message": message or status,
                "hardware_id": model.scene.name or "",
                "values": [{"key": key, "value": str(value)} for key, value in values.items()],
            }
        ],
    }


def run_messages(
    model: MachineModel,
    times: np.ndarray,
    states: np.ndarray,
    throttle: np.ndarray | None = None,
    external: np.ndarray | None = None,
    status: str = "complete",
    message: str = "",
):
    """The run's messages in time order, as (topic, time [ns], message as a dict): at each exchange time of `times`
    [s] the states `states` (MachineModel.state_names x n) with the throttle [-] and the external load [N m] held from
    then on (None: the scene's own, as MachineModel.columns); `status` and `message`: how the run ended, in the last
    /diagnostics."""
    columns = model.columns(times, states, throttle, external)
    moments = crank_moments(columns)
    applied = (
        columns["throttle"]
        if throttle is None and "throttle" in columns
        else np.ones(times.size)
        if throttle is None
        else np.asarray(throttle, dtype=float)
    )
    load = (
        -columns["M_external"]
        if external is None and "M_external" in columns
        else np.array([model.external_load(t) for t in times])
        if external is None
        else np.asarray(external, dtype=float)
    )
    extra = [
        (name, np.broadcast_to(position, times.shape), np.broadcast_to(velocity, times.shape))
        for name, position, velocity in output_joints(model, columns)
    ]
    nan = math.nan
    stamps = [round(t * NANOSECONDS) for t in times]
    yield "/diagnostics", stamps[0], _diagnostics(stamps[0], model, "complete", "running", {"sim_time": 0.0})
    for i, when in enumerate(stamps):
        phi, omega = float(columns["phi"][i]), float(columns["omega"][i])
        yield "/clock", when, {"clock": _time(when)}
        yield (
            "/joint_states",
            when,
            _joints(
                when,
                [
                    ("crank", phi, omega, float(moments["net"][i])),
                    *((name, float(p[i]), float(v[i]), nan) for name, p, v in extra),
                ],
            ),
        )
        yield "/throttle", when, _joints(when, [("throttle", float(applied[i]), nan, nan)])
        yield (
            "/load_torque_stamped",
            when,
            {
                "header": {"stamp": _time(when), "frame_id": "crank"},
                "wrench": {
                    "force": {"x": 0.0, "y": 0.0, "z": 0.0},
                    "torque": {"x": 0.0, "y": 0.0, "z": float(load[i])},
                },
            },
        )
        yield (
            "/machine/moments",
            when,
            _joints(
                when,
                [
                    *((name, nan, nan, float(moments[name][i])) for name in ("drive", "resistance", "external", "net")),
                    ("load", nan, nan, float(load[i])),
                    ("crank", phi, omega, nan),
                ],
            ),
        )
        if model.governor is not None:  # its joints (GovernorKind.joints), the throttle the one applied
            governor = [
                (
                    name,
                    applied[i] if name == "throttle" else columns[position][i],
                    0.0 if velocity is None else columns[velocity][i],
                )
                for name, position, velocity in model.governor.joints()
            ]
            yield "/governor/state", when, _joints(when, [(name, float(p), float(v), nan) for name, p, v in governor])
    yield (
        "/diagnostics",
        stamps[-1],
        _diagnostics(stamps[-1], model, status, message, {"sim_time": float(times[-1]), "finished_at_ns": stamps[-1]}),
    )


def bag_refusal(folder: Path) -> str | None:
    """Why a bag cannot be written to `folder` (None: it can): it exists already, its parent folder does not, or no
    folder can be made in that parent (a kernel folder such as /proc, a read-only file system, no permission, a full
    disk: tried by making an empty folder there and removing it)."""
    if folder.exists():
        return (
            f"cannot write the bag '{folder}': it exists; a rosbag2 recording is a new folder (as ros2 bag record -o)"
        )
    if not folder.parent.is_dir():
        return f"cannot write the bag '{folder}': the folder '{folder.parent}' does not exist"
    try:
        os.rmdir(tempfile.mkdtemp(prefix=".bag-check-", dir=folder.parent))
    except OSError as error:
        return (
            f"cannot write the bag '{folder}': no folder can be made in '{folder.parent}' "
            f"({error.strerror or error}); expected a folder of yours"
        )
    return None


def write_bag(
    folder: Path,
    model: MachineModel,
    times: np.ndarray,
    states: np.ndarray,
    throttle: np.ndarray | None = None,
    external: np.ndarray | None = None,
    status: str = "complete",
    message: str = "",
) -> Path:
    """Write the run (as run_messages takes it) as a rosbag2 folder `folder`: <folder>/<folder name>_0.mcap and
    metadata.yaml; returns the folder. The folder must not exist (as `ros2 bag record -o`); its parent is made."""
    from mcap_ros2.writer import Writer

    folder.mkdir(parents=True)
    relative = f"{folder.name}_0.mcap"
    counts = dict.fromkeys(TOPIC_TYPES, 0)
    first: int | None = None
    last = 0
    with open(folder / relative, "wb") as stream:
        writer = Writer(stream)
        schemas = {
            datatype: writer.register_msgdef(full_name(datatype), message_definition(datatype))
            for datatype in sorted(set(TOPIC_TYPES.values()))
        }
        for topic, when, contents in run_messages(model, times, states, throttle, external, status, message):
            writer.write_message(
                topic, schemas[TOPIC_TYPES[topic]], contents, log_time=when, publish_time=when, sequence=counts[topic]
            )
            counts[topic] += 1
            first = when if first is None else first
            last = max(last, when)
        writer.finish()
    counts = {topic: count for topic, count in counts.items() if count}
    duration = {"nanoseconds": last - (first or 0)}
    start = {"nanoseconds_since_epoch": first or 0}
    information = {
        "version": 5,
        "storage_identifier": "mcap",
        "duration": duration,
        "starting_time": start,
        "message_count": sum(counts.values()),
        "topics_with_message_count": [
            {
                "topic_metadata": {
                    "name": topic,
                    "type": full_name(TOPIC_TYPES[topic]),
                    "serialization_format": "cdr",
                    "offered_qos_profiles": "",
                },
                "message_count": count,
            }
            for topic, count in counts.items()
        ],
        "compression_format": "",
        "compression_mode": "",
        "relative_file_paths": [relative],
        "files": [
            {
                "path": relative,
                "starting_time": dict(start),
                "duration": dict(duration),
                "message_count": sum(counts.values()),
            }
        ],
        "ros_distro": ROS_DISTRO,
    }
    (folder / "metadata.yaml").write_text(yaml.safe_dump({"rosbag2_bagfile_information": information}, sort_keys=False))
    return folder
