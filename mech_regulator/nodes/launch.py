"""The main job: the nodes as separate processes on a private ROS domain, playing a scene's scenario
in lockstep, recorded to runs/<scene>-<time>.rrd, with a progress bar and the summary at the end.

ros2 launch is not on the package index, so this is a small launcher of its own: it writes the run's
parameter file (ros__parameters form, next to the recording), starts recorder_node, governor_node,
scenario_node and machine_node with it, follows the machine's /diagnostics for progress, and on
Ctrl-C passes the interrupt on to every node, so the recording is closed properly.
"""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import yaml

from mech_regulator.cli.report import format_cosimulation_summary, progress_bar
from mech_regulator.scene import config_dir

OVERSPEED_TRIP_FACTOR = 1.25  # default trip speed: this times the scene's initial speed
STOP_TIMEOUT = 20.0  # [s] of wall time a node gets to stop after an interrupt before it is killed


def private_environment(domain_id: int) -> dict[str, str]:
    """The environment of a run: its own ROS domain, discovery on this machine only, and the message
    packages found in this Python's prefix when no ROS installation is sourced."""
    environment = dict(os.environ)
    environment["ROS_DOMAIN_ID"] = str(domain_id)
    environment["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    environment.setdefault("AMENT_PREFIX_PATH", sys.prefix)
    environment.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
    return environment


def run_parameters(scene_file: str, overrides: list[str], exchange_step: float, time_mode: str,
                   overspeed_trip: float, output: Path, real_time_factor: float) -> dict:
    """The bundled config/params/main_job.yaml with this run's choices filled in."""
    parameters = yaml.safe_load((config_dir() / "params" / "main_job.yaml").read_text())
    common = parameters["/**"]["ros__parameters"]
    common.update(scene_file=scene_file, overrides=overrides or [""], exchange_step=exchange_step, time_mode=time_mode)
    machine = parameters["machine"]["ros__parameters"]
    machine.update(overspeed_trip=overspeed_trip, real_time_factor=real_time_factor)
    if time_mode == "realtime":
        machine.update(lockstep_inputs=[""], min_subscribers=0)
    parameters["recorder"]["ros__parameters"]["output"] = str(output)
    return parameters


def default_recording(scene_name: str) -> Path:
    """runs/<scene>-<local time>.rrd"""
    return Path("runs") / f"{scene_name}-{time.strftime('%Y%m%d-%H%M%S')}.rrd"


def main_job(scene, scene_file: str, overrides: list[str], exchange_step: float, time_mode: str,
             real_time_factor: float, overspeed_trip: float | None, output: Path | None, domain_id: int | None,
             quiet: bool) -> int:
    """Run the nodes on the scene; returns the exit code (0, 1 if a node failed, 130 if interrupted)."""
    output = output or default_recording(scene.name)
    output.parent.mkdir(parents=True, exist_ok=True)
    if overspeed_trip is None:
        overspeed_trip = OVERSPEED_TRIP_FACTOR * abs(scene.scenario.initial.omega)
    parameters = run_parameters(scene_file, overrides, exchange_step, time_mode, overspeed_trip, output,
                                real_time_factor)
    parameter_file = output.with_suffix(".params.yaml")
    parameter_file.write_text(yaml.safe_dump(parameters, sort_keys=False))
    log_file = output.with_suffix(".log")
    domain_id = domain_id if domain_id is not None else random.randint(1, 101)
    environment = private_environment(domain_id)
    names = ["recorder"] + (["governor"] if scene.governor is not None else []) + ["scenario", "machine"]
    print(f"running {', '.join(names)} nodes on ROS domain {domain_id} ({time_mode}, exchange step "
          f"{exchange_step:g} s); node logs in {log_file}", file=sys.stderr)
    processes: dict[str, subprocess.Popen] = {}
    interrupted = False
    with open(log_file, "w") as log:
        try:
            for name in names:
                processes[name] = subprocess.Popen(
                    [sys.executable, "-m", f"mech_regulator.nodes.{name}", "--ros-args", "--params-file",
                     str(parameter_file)], env=environment, stdout=log, stderr=subprocess.STDOUT,
                    start_new_session=True)  # Ctrl-C reaches this launcher only; it passes it on
            signal.signal(signal.SIGTERM, _interrupt)  # `kill` or a timeout stops the nodes as Ctrl-C does
            _follow(processes, environment, scene.scenario.duration, quiet)
            _wait(processes["recorder"], STOP_TIMEOUT)
        except KeyboardInterrupt:
            interrupted = True
            print("\ninterrupted: stopping the nodes and closing the recording", file=sys.stderr)
        finally:
            for process in processes.values():
                if process.poll() is None:
                    process.send_signal(signal.SIGINT)
            for process in processes.values():
                _wait(process, STOP_TIMEOUT)
    summary_path = output.with_suffix(".json")
    failed = [name for name, process in processes.items() if process.returncode not in (0, -signal.SIGINT)]
    if summary_path.exists():
        summary = json.loads(summary_path.read_text())
        print(format_cosimulation_summary(summary))
        print(f"open the recording with: rerun {output}")
    else:
        print(f"mech-regulator: no summary was written ({summary_path})", file=sys.stderr)
    if failed:
        print(f"mech-regulator: node(s) {', '.join(failed)} failed; the end of {log_file}:", file=sys.stderr)
        print("".join(log_file.read_text().splitlines(keepends=True)[-20:]), file=sys.stderr)
        return 1
    return 130 if interrupted else 0


def _interrupt(signal_number, frame) -> None:
    raise KeyboardInterrupt


def _follow(processes: dict[str, subprocess.Popen], environment: dict[str, str], duration: float,
            quiet: bool) -> None:
    """Show the machine's progress (its /diagnostics sim_time) until its process ends, or until another
    node fails first (the launcher then stops the others)."""
    machine = processes["machine"]
    os.environ.update({key: environment[key] for key in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE",
                                                          "AMENT_PREFIX_PATH")})
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.signals import SignalHandlerOptions

    rclpy.init(args=[], signal_handler_options=SignalHandlerOptions.NO)  # Ctrl-C stays a KeyboardInterrupt
    node = rclpy.create_node("main_job")
    with progress_bar(duration, quiet) as bar:
        def on_diagnostics(message: DiagnosticArray) -> None:
            for status in message.status:
                if status.name.endswith("/machine"):
                    values = {item.key: item.value for item in status.values}
                    bar.update(min(float(values.get("sim_time", 0.0)), duration) - bar.n)

        node.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, 50)
        try:
            while machine.poll() is None:
                rclpy.spin_once(node, timeout_sec=0.2)
                ended = [name for name, process in processes.items() if process.poll() not in (None, 0)]
                if ended and machine.poll() is None:
                    print(f"\nmech-regulator: the {', '.join(ended)} node ended early; stopping the others",
                          file=sys.stderr)
                    return
        finally:
            node.destroy_node()
            rclpy.try_shutdown()


def _wait(process: subprocess.Popen, timeout: float) -> None:
    """Wait for a node to end; kill it if it does not within timeout [s]."""
    try:
        process.wait(timeout)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()

