"""The main job: the nodes as separate processes on a private ROS domain, playing a scene's scenario
in lockstep, recorded to runs/<scene>-<time>.rrd, with a progress bar and the summary at the end.

ros2 launch is not on the package index, so this is a small launcher of its own: it writes the run's
parameter file (ros__parameters form, next to the recording), starts recorder_node, governor_node,
scenario_node and machine_node with it, follows the machine's /diagnostics for progress, and on
Ctrl-C passes the interrupt on to every node, so the recording is closed properly. What the machine waits
for comes from the scene: the nodes this launcher starts are its `peers`. Every node dies with the
launcher, however it ends (Linux: PR_SET_PDEATHSIG), so none is ever left behind. The nodes' processes are forked
from the launcher after it has imported what they all import (NodeProcess), so that none imports it again.
"""

from __future__ import annotations

import contextlib
import fcntl
import functools
import gc
import importlib
import json
import multiprocessing
import os
import random
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import TextIO

import yaml

from mech_regulator.cli.report.machine_text import format_cosimulation_summary
from mech_regulator.cli.report.terminal import progress_bar
from mech_regulator.nodes.outputs import default_recording
from mech_regulator.processes import die_with_parent
from mech_regulator.scene import SceneError, config_dir

STOP_TIMEOUT = 1.5  # [s] of wall time the nodes get together to stop after an interrupt before they are killed
END_TIMEOUT = 30.0  # [s] of wall time the nodes get to end by themselves after the machine has finished, and
CLOSE_TIME_PER_EXCHANGE = 0.001  # [s] of wall time more per exchange: the recorder's outputs written (end_timeout)
LOG_TAIL_BYTES = 1 << 20  # the nodes' last output the launcher keeps in memory (NodeLog) [bytes]
LOG_DRAIN = 5.0  # [s] of wall time the launcher waits at most for the nodes' last output once they have ended
STALL_REPORT = 30.0  # [s] of wall time without the machine's simulated time advancing before the launcher says so
PARTICIPANT_LEASE = 300.0  # [s] of wall time a participant that announces nothing (its process stopped, starved,
# killed) is still taken for there by the others: the leaseDuration of config/params/fastdds.xml (Fast DDS's default
# is 20 s); a reader stopped longer is taken for gone, and its writers no longer wait for it. A node killed (or ended
# by its alarm after a teardown hang) is remembered on its domain that long: claim_domain gives a domain used within
# it only when no other is free
GRAPH_QUIET = 0.3  # [s] of wall time without a node joining or leaving before a node of this process is destroyed
GRAPH_QUIET_LIMIT = 3.0  # [s] of wall time waited at most for that quiet
FASTDDS_PROFILE_VARIABLE = "FASTDDS_DEFAULT_PROFILES_FILE"  # Fast DDS reads its default profile from this file
NOTHING_SIMULATED = "interrupted before the nodes were up: nothing was simulated"
# A node's exit by SIGALRM: its work had ended normally (exit code 0, everything sent and acknowledged, its files
# closed), then destroying its ROS participant hung inside a call that holds the GIL and its alarm ended it
# (nodes.common.end_if_stuck): not a failure of the run.
TEARDOWN_HANG = -signal.SIGALRM
# ROS domains whose ports do not collide with the ephemeral range: 1..101 and 215..232. A process takes one by holding
# a lock file on it until it ends (claim_domain): `run` without --domain-id, and the test suite for each test. Every
# `run` also holds its domain's run lock (claim_run), which only runs take: a test holds the domain lock of the domain
# it passes to a `run` with --domain-id.
DOMAIN_IDS = (*range(1, 102), *range(215, 233))
DOMAIN_LOCKS = Path(tempfile.gettempdir()) / "mech_regulator_ros_domains"
_claimed_domains: list = []  # the open lock files of this process (closed, and so released, when it ends)
_claimed_runs: dict[int, TextIO] = {}  # domain -> the open run lock file of this process on it
_lingering_domains: list = []  # domains release_domains kept because a run was still on them (tried at its next call)


def _lock(path: Path) -> TextIO | None:
    """The file at `path` opened (created if need be) and locked exclusively by this process until it closes it or
    ends, or None when another process (or this one, through another opening) holds the lock."""
    lock = open(path, "a+")
    try:
        fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        lock.close()
        return None
    return lock


def _last_used(lock_path: Path) -> float:
    """When a domain was last claimed or released (its lock file's modification time, time.time() [s]; 0 for none)."""
    try:
        return lock_path.stat().st_mtime
    except OSError:
        return 0.0


def claim_domain(start: int) -> int:
    """The first ROS domain of DOMAIN_IDS from index `start` on (going round) that no process on this machine holds,
    held by this one until it ends (an exclusive lock on DOMAIN_LOCKS/<domain>.lock; a domain this process holds
    already is skipped too). A domain claimed or released within PARTICIPANT_LEASE s (its lock file's time) is taken
    only when no other is free: the participants of a run whose nodes were killed are remembered there that long, and
    a run's machine refuses to start beside a namesake. Raises SceneError when every domain is held."""
    DOMAIN_LOCKS.mkdir(exist_ok=True)
    rested_since = time.time() - PARTICIPANT_LEASE
    for rested_only in (True, False):
        for offset in range(len(DOMAIN_IDS)):
            domain = DOMAIN_IDS[(start + offset) % len(DOMAIN_IDS)]
            path = DOMAIN_LOCKS / f"{domain}.lock"
            if rested_only and _last_used(path) > rested_since:
                continue
            lock = _lock(path)
            if lock is not None:
                with contextlib.suppress(OSError):
                    os.utime(path)  # used from now on
                _claimed_domains.append(lock)
                return domain
    raise SceneError(
        f"every ROS domain is taken by other runs on this machine (lock files in {DOMAIN_LOCKS}); "
        "expected --domain-id N"
    )


def release_domains(keep: int = 0) -> None:
    """Release the domains this process claimed (claim_domain) after its first `keep` claims: their lock files closed.
    For a process that plays many runs one after another, each on a domain of its own (the test suite: a worker
    holding every domain it ever used took half of them, and two suites side by side all), so that a domain is held
    only while it is used. A domain a run is still on (its run lock held: claim_run; a run's node processes, forked,
    hold it as long as they live, also after their launcher ended) stays held, and is tried again at the next call. A
    child process started with a lock's descriptor (domain_lock_descriptor) holds that domain until it ends."""
    candidates = _lingering_domains + _claimed_domains[keep:]
    del _claimed_domains[keep:]
    _lingering_domains.clear()
    for lock in candidates:
        domain = int(Path(lock.name).name.removesuffix(".lock"))
        run_lock = None if domain in _claimed_runs else _lock(DOMAIN_LOCKS / f"{domain}.run.lock")
        if run_lock is None:  # a run is still on it
            _lingering_domains.append(lock)
            continue
        run_lock.close()
        with contextlib.suppress(OSError):
            os.utime(lock.name)  # used until now (claim_domain)
        lock.close()


def claim_run(domain: int | None) -> int:
    """The ROS domain of a run, its run lock held by this process until it ends (DOMAIN_LOCKS/<domain>.run.lock, with
    this process's pid in it; a domain whose run lock this process holds already is returned as it is): `domain`, or
    when None, a random domain that no process holds (claim_domain) and no other run runs on. Two runs on one domain
    would take each other's messages: raises SceneError naming the domain and the other run's pid when another
    process on this machine holds the run lock of the given domain (another `run` with the same --domain-id), or
    when every domain is taken. Deterministic, unlike the machine's check of the graph for namesakes at start, which
    sees another program's nodes only once discovery has found them (docs/ros.md, "Who may speak")."""
    if domain in _claimed_runs:
        return domain
    DOMAIN_LOCKS.mkdir(exist_ok=True)
    start = random.randrange(len(DOMAIN_IDS))
    while True:
        candidate = domain if domain is not None else claim_domain(start)
        path = DOMAIN_LOCKS / f"{candidate}.run.lock"
        lock = _lock(path)
        if lock is not None:
            lock.truncate(0)
            lock.write(f"{os.getpid()}\n")
            lock.flush()
            _claimed_runs[candidate] = lock
            return candidate
        if domain is None:  # a run with --domain-id there, on a domain no test holds: the next one
            start = DOMAIN_IDS.index(candidate) + 1
            continue
        holder = path.read_text().strip()
        raise SceneError(
            f"--domain-id {domain}: another run on this machine is on ROS domain {domain} "
            f"({f'pid {holder}' if holder.isdigit() else 'its pid not written yet'}; lock file {path}): two runs on "
            "one domain would take each other's messages; expected another --domain-id (or none: a free domain), or "
            "the other run ended first"
        )


def domain_lock_descriptor(domain: int) -> int | None:
    """The file descriptor of this process's lock on `domain` (claim_domain; None if it holds none): a child process
    started with it (subprocess's pass_fds) holds the domain too, until the child ends, also should this process end
    first (the lock is released when its last descriptor closes)."""
    for lock in _claimed_domains:
        if Path(lock.name).name == f"{domain}.lock":
            return lock.fileno()
    return None


def private_environment(domain_id: int) -> dict[str, str]:
    """The environment of a run: its own ROS domain, discovery on this machine only, the message packages found
    in this Python's prefix when no ROS installation is sourced, and the bundled Fast DDS profile unless one is set
    (fastdds_profile)."""
    environment = dict(os.environ)
    environment["ROS_DOMAIN_ID"] = str(domain_id)
    environment["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    environment.setdefault("AMENT_PREFIX_PATH", sys.prefix)
    environment.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
    environment.setdefault(FASTDDS_PROFILE_VARIABLE, str(fastdds_profile()))
    return environment


def fastdds_profile() -> Path:
    """The bundled Fast DDS profile (config/params/fastdds.xml): reliable writers ask for acknowledgements every
    20 ms instead of every 3 s, so that a node waiting for its last samples to be acknowledged before it ends
    (nodes.common.deliver_all) waits that long, not seconds."""
    return config_dir() / "params" / "fastdds.xml"


def node_names(governed: bool) -> list[str]:
    """The nodes of the main job, in the order they are started (the machine last: it waits for the others)."""
    return ["recorder"] + (["governor"] if governed else []) + ["scenario", "machine"]


def run_parameters(
    scene_file: str,
    overrides: list[str],
    exchange_step: float,
    time_mode: str,
    overspeed_trip: float,
    output: Path,
    real_time_factor: float,
    governed: bool,
    duration: float | None,
    coupling: str,
    started: float,
    controller: str = "governor",
    bag: Path | None = None,
    peer_timeout: float | None = None,
    exchange_tolerance: float | None = None,
) -> dict:
    """The bundled config/params/main_job.yaml with this run's choices filled in; the machine's peers are the
    other nodes started (in realtime too, before the clock starts: a governor still starting would miss the run; the
    inputs are then the newest, not awaited);
    started: when the command began, on the clock of time.monotonic() [s] (the recorder's start_up_s counts from
    it); controller: what gives the throttle (nodes.controller.CONTROLLERS; external: a node the user starts, not a
    peer by name); bag: the rosbag2 folder the recorder also writes (None: none); peer_timeout: the machine's [s]
    (None: the file's); exchange_tolerance: the adaptive exchange step's (None: the fixed step)."""
    parameters = yaml.safe_load((config_dir() / "params" / "main_job.yaml").read_text())
    common = parameters["/**"]["ros__parameters"]
    common.update(
        scene_file=scene_file,
        overrides=overrides or [""],
        exchange_step=exchange_step,
        exchange_tolerance=exchange_tolerance or 0.0,
        time_mode=time_mode,
        coupling=coupling,
    )
    machine = parameters.setdefault("machine", {}).setdefault("ros__parameters", {})
    peers = [name for name in node_names(governed) if name != "machine"]
    machine.update(overspeed_trip=overspeed_trip, real_time_factor=real_time_factor, peers=peers, controller=controller)
    if peer_timeout is not None:
        machine.update(peer_timeout=peer_timeout)
    if duration is not None:
        machine.update(duration=duration)
    if time_mode == "realtime":
        machine.update(lockstep_inputs=[""])  # the newest inputs, not awaited; the peers still are, before the clock
    parameters.setdefault("recorder", {}).setdefault("ros__parameters", {}).update(
        output=str(output), launched_at=started, controller=controller, bag=str(bag) if bag is not None else ""
    )
    return parameters


def main_job(
    model,
    scene_file: str,
    overrides: list[str],
    exchange_step: float,
    time_mode: str,
    real_time_factor: float,
    overspeed_trip: float,
    output: Path | None,
    domain_id: int | None,
    quiet: bool,
    duration: float | None,
    coupling: str,
    started: float | None = None,
    controller: str = "governor",
    bag: Path | None = None,
    peer_timeout: float | None = None,
    exchange_tolerance: float | None = None,
) -> int:
    """Run the nodes on the model's scene (its solver.path decided: fast or reference) for `duration` [s] of
    simulated time (None: the scene's), the machine tripping above overspeed_trip [rad/s] (0: no trip, the default:
    nothing else sets one), `started` the command's
    start on the clock of time.monotonic() [s] (None: now; the summary's start_up_s counts from it); returns the exit
    code (0 if the run played to its end, its summary's status `complete` or `tripped`; 1 if a node failed or the
    summary's status is failed (the machine's run failed: a blow-up, driven backwards, no progress) or disturbed
    (docs/ros.md, "Who may speak"), 2 if every node that failed refused its input, 130
    if interrupted; each failed node is named with its reason). controller external: no governor_node, the machine
    waits for a node the user starts (nodes.controller); bag: also a rosbag2 recording there (viz.bag);
    peer_timeout: the machine's [s] (None: the parameter file's); exchange_tolerance: the adaptive exchange step's
    (None: the fixed step; solvers.cosim.ExchangeTimes). Exchange times refused by solvers.cosim.exchange_times_refusal
    (more than limits.MAX_STEPS exchanges, a bad tolerance) raise SceneError."""
    from mech_regulator.solvers.cosim import exchange_times_refusal  # the solvers load with the model (load_steppers)

    scene = model.scene
    refusal = exchange_times_refusal(duration or scene.scenario.duration, exchange_step, exchange_tolerance, coupling)
    if refusal is not None:
        raise SceneError(refusal)
    output = output or default_recording(scene.name)
    output.parent.mkdir(parents=True, exist_ok=True)
    governed = scene.governor is not None
    started = started if started is not None else time.monotonic()
    parameters = run_parameters(
        scene_file,
        overrides,
        exchange_step,
        time_mode,
        overspeed_trip,
        output,
        real_time_factor,
        governed,
        duration,
        coupling,
        started,
        controller,
        bag,
        peer_timeout,
        exchange_tolerance,
    )
    parameter_file = output.with_suffix(".params.yaml")
    parameter_file.write_text(yaml.safe_dump(parameters, sort_keys=False))
    log_file = output.with_suffix(".log")
    domain_id = claim_run(domain_id)
    environment = private_environment(domain_id)
    names = node_names(governed)
    trip = f", overspeed trip at {overspeed_trip:g} rad/s" if overspeed_trip > 0.0 else ""
    print(
        f"running {', '.join(names)} nodes on ROS domain {domain_id} ({time_mode}, exchange step "
        f"{exchange_step:g} s{trip}); node logs in {log_file}",
        file=sys.stderr,
    )
    if controller == "external":
        from mech_regulator.nodes.controller import contract

        print(
            f"{contract(machine_peer_timeout(parameters))}\nstart it with ROS_DOMAIN_ID={domain_id} "
            f"ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, e.g. ROS_DOMAIN_ID={domain_id} "
            "ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST python examples/pid_governor.py",
            file=sys.stderr,
        )
    processes: dict[str, NodeProcess] = {}
    interrupted = False
    ctrl_c: list[int] = []  # a Ctrl-C that came (an import of a C extension it interrupts fails with ImportError)
    signal.signal(signal.SIGINT, functools.partial(_remember_interrupt, ctrl_c))
    with NodeLog(log_file) as log:
        try:
            importlib.import_module("mech_regulator.nodes.common")  # what every node imports (rclpy, the message
            # types, the core with scipy) and what the steppers load on first use, once here for the nodes forked below
            from mech_regulator.solvers.cosim import load_steppers

            load_steppers(model, exchange_step)
            gc.freeze()  # what is loaded here stays out of the nodes' garbage collections: each node's first full
            # collection scanned (and so copied, page by page) the whole heap it was forked with, 0.23-0.44 s of CPU in
            # each of the four at once before the first exchange
            for name in names:
                processes[name] = NodeProcess(name, parameter_file, environment, log)
            log.follow()
            signal.signal(signal.SIGTERM, _interrupt)  # `kill` or a timeout stops the nodes as Ctrl-C does
            _follow(
                processes,
                environment,
                duration or scene.scenario.duration,
                quiet,
                f"{scene.name} on the nodes",
                started,
            )
            if processes["machine"].returncode == 0:  # the others end by themselves once the machine has finished
                timeout = end_timeout(duration or scene.scenario.duration, exchange_step)
                _wait_all(processes, timeout, quiet, closing=timeout - END_TIMEOUT + STOP_TIMEOUT)
        except (KeyboardInterrupt, ImportError) as error:
            if isinstance(error, ImportError) and not ctrl_c:
                raise
            interrupted = True
            print("\ninterrupted: stopping the nodes and closing the recording", file=sys.stderr)
        finally:
            for process in processes.values():
                if process.poll() is None:
                    process.send_signal(signal.SIGINT)
            _wait_all(processes, STOP_TIMEOUT)
    summary_path = output.with_suffix(".json")
    disturbed = False  # the summary says something the run could not refuse may have changed its numbers
    failed = [
        name for name, process in processes.items() if process.returncode not in (0, -signal.SIGINT, TEARDOWN_HANG)
    ]
    hung = [name for name, process in processes.items() if process.returncode == TEARDOWN_HANG]
    if hung:
        print(
            f"mech-regulator: the {', '.join(hung)} node{'s' if len(hung) > 1 else ''} finished {'their' if len(hung) > 1 else 'its'} work, "
            'then hung in ROS\'s teardown (a Fast DDS deadlock; docs/ros.md, "Ending a run") and ended by its alarm',
            file=sys.stderr,
        )
    if interrupted and not summary_path.exists():  # stopped before the recorder could write anything
        from mech_regulator.nodes.outputs import write_empty_run

        write_empty_run(model, output, exchange_step, NOTHING_SIMULATED)
    summary = _read_summary(summary_path)
    if summary is not None:
        print(format_cosimulation_summary(summary))
        for topic, reasons in summary.get("refused", {}).items():
            print(f"refused on {topic}: " + ", ".join(f"{count} {reason}" for reason, count in reasons.items()))
        for sender, topics in summary.get("foreign", {}).items():
            print(f"refused from {sender}: " + ", ".join(f"{count} on {topic}" for topic, count in topics.items()))
        for disturbance in summary.get("disturbances", []):
            print(f"disturbance: {disturbance}")
        disturbed = summary["status"] in ("disturbed", "failed")  # numbers that are not the scene's whole run
        if "start_up_s" in summary:
            print(f"start-up: {summary['start_up_s']:.3g} s from the command to the first exchange")
        if "max_lag_s" in summary:
            print(f"realtime: the simulation time fell behind the wall clock by {summary['max_lag_s']:.3g} s at most")
        print(f"open the recording with: {viewer_command(output)}")
    elif summary_path.exists():
        print(
            f"mech-regulator: the summary {summary_path} cannot be read (written only in part: a full disk?)",
            file=sys.stderr,
        )
    else:
        print(f"mech-regulator: no summary was written ({summary_path})", file=sys.stderr)
    if log.error is not None:
        print(
            f"mech-regulator: the node log {log_file} could not be written whole ({log.error.strerror}); "
            "the launcher kept its last lines",
            file=sys.stderr,
        )
    if failed:
        log_text = log.tail()
        endings: dict[tuple[int | None, str], list[str]] = {}  # (exit code, why) -> the nodes that ended so
        for name in failed:
            endings.setdefault((processes[name].returncode, node_reason(log_text, name)), []).append(name)
        for (code, reason), names in endings.items():
            print(
                f"mech-regulator: the {', '.join(names)} node{'s' if len(names) > 1 else ''} ended with exit code "
                f"{code}{reason}",
                file=sys.stderr,
            )
        print(f"mech-regulator: node(s) {', '.join(failed)} failed; the end of {log_file}:", file=sys.stderr)
        print("".join(log_text.splitlines(keepends=True)[-20:]), file=sys.stderr)
        bad_input = all(processes[name].returncode == 2 for name in failed)  # nodes.common.EXIT_BAD_INPUT
        return 2 if bad_input else 1
    return 130 if interrupted else 1 if disturbed else 0


def _read_summary(path: Path) -> dict | None:
    """The run's summary (the recorder's JSON), or None when there is none or it cannot be read whole (the recorder
    could not write it all: a full disk)."""
    try:
        summary = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return summary if isinstance(summary, dict) and "status" in summary else None


def machine_peer_timeout(parameters: dict) -> float:
    """The machine's peer_timeout [s] in a run's parameters (run_parameters; 10 s, the node's default, when unset)."""
    return float(parameters.get("machine", {}).get("ros__parameters", {}).get("peer_timeout", 10.0))


def node_reason(log_text: str, name: str) -> str:
    """': <why>' from the last line a node's `run` wrote about its end ('mech_regulator: <name>_node: <why>', see
    nodes.common.run, with the indented lines that follow it: the problems of a scene) in the nodes' log, '' when
    there is none."""
    prefix = f"mech_regulator: {name}_node: "
    lines = log_text.splitlines()
    starts = [index for index, line in enumerate(lines) if line.startswith(prefix)]
    if not starts:
        return ""
    reason = [lines[starts[-1]][len(prefix) :]]
    for line in lines[starts[-1] + 1 :]:
        if not line.startswith("  "):
            break
        reason.append(line)
    return ": " + "\n".join(reason)


def viewer_command(recording: Path) -> str:
    """The command that opens a recording in a fresh shell: this Python's `rerun` (the virtual environment's, which
    a fresh shell does not have on its PATH) on the recording's absolute path."""
    viewer = Path(sys.executable).parent / "rerun"
    return f"{viewer if viewer.exists() else 'rerun'} {recording.resolve()}"


def _interrupt(signal_number, frame) -> None:
    raise KeyboardInterrupt


def _remember_interrupt(received: list[int], signal_number, frame) -> None:
    """Ctrl-C: remember it in `received`, then raise KeyboardInterrupt as Python's own handler does."""
    received.append(signal_number)
    raise KeyboardInterrupt


def _follow(
    processes: dict[str, NodeProcess],
    environment: dict[str, str],
    duration: float,
    quiet: bool,
    label: str,
    started: float,
    stall_report: float = STALL_REPORT,
) -> None:
    """Show the machine's progress (its /diagnostics sim_time; `label` names the work; `started`: the command's start,
    time.monotonic() [s], from which its start-up counts) until its process ends, or until another node fails first
    (the launcher then stops the others). A machine whose simulated time has not advanced for stall_report s of wall
    time (paused from outside, waiting for a recorder held back, or stuck) is reported once on stderr, with the time it stands at, and again when it
    goes on."""
    machine = processes["machine"]
    os.environ.update(
        {key: environment[key] for key in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE", "AMENT_PREFIX_PATH")}
    )
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.signals import SignalHandlerOptions

    from mech_regulator.nodes.trust import Refusals, Speakers, about_the_nodes, real_number, receive

    rclpy.init(args=[], signal_handler_options=SignalHandlerOptions.NO)  # Ctrl-C stays a KeyboardInterrupt
    node = rclpy.create_node("main_job")
    advanced = {"sim_time": -1.0, "at": time.monotonic(), "reported": False}  # the machine's time and when it moved
    with progress_bar(duration, quiet, label, started=started) as bar:

        def on_diagnostics(message: DiagnosticArray, speaker: str) -> None:
            for status in message.status:
                if speaker == "machine" and status.name.endswith("/machine"):
                    values = {item.key: item.value for item in status.values}
                    sim_time = real_number(values.get("sim_time", "0"), "sim_time")
                    bar.update(min(sim_time, duration) - bar.n)
                    if sim_time > advanced["sim_time"]:
                        if advanced["reported"]:
                            print(f"\nmech-regulator: the machine goes on at t = {sim_time:.6g} s", file=sys.stderr)
                        advanced.update(sim_time=sim_time, at=time.monotonic(), reported=False)

        speakers = Speakers(node)  # the progress is the machine's; the recorder counts what others say
        speakers.allow("/diagnostics", *node_names(True))
        receive(
            node,
            DiagnosticArray,
            "/diagnostics",
            on_diagnostics,
            50,
            Refusals(node),
            speakers,
            pass_speaker=True,
            concerns=about_the_nodes,
        )
        try:
            while machine.poll() is None:
                rclpy.spin_once(node, timeout_sec=0.2)
                if not advanced["reported"] and time.monotonic() - advanced["at"] > stall_report:
                    advanced["reported"] = True
                    print(
                        f"\nmech-regulator: the machine has not advanced from t = {max(advanced['sim_time'], 0.0):.6g} "
                        f"s for {stall_report:g} s of wall time (paused through its ~/pause service, waiting for its recorder held "
                        "back, or stuck); Ctrl-C ends the run with its summary",
                        file=sys.stderr,
                    )
                ended = [name for name, process in processes.items() if process.poll() not in (None, 0)]
                if ended and machine.poll() is None:
                    print(
                        f"\nmech-regulator: the {', '.join(ended)} node ended early; stopping the others",
                        file=sys.stderr,
                    )
                    return
        finally:
            wait_for_a_quiet_graph(node, lambda timeout: rclpy.spin_once(node, timeout_sec=timeout))
            node.destroy_node()
            rclpy.try_shutdown()


def wait_for_a_quiet_graph(
    node, spin: Callable[[float], None], quiet: float = GRAPH_QUIET, limit: float = GRAPH_QUIET_LIMIT
) -> None:
    """Spin (`spin(timeout [s])`) until the nodes `node` sees on its domain have not changed for `quiet` s of wall
    time, at most `limit` s. Fast DDS can deadlock when a participant is destroyed while it handles another's leaving
    (eProsima/Fast-DDS#6193 and kin; seen here once as a hang), so a node is destroyed once the nodes that were ending
    as it closes (the machine's peers at the end of a run) have left."""
    deadline = time.monotonic() + limit
    seen, since = node.get_node_names_and_namespaces(), time.monotonic()
    while time.monotonic() < deadline and time.monotonic() - since < quiet:
        spin(0.05)
        now = node.get_node_names_and_namespaces()
        if now != seen:
            seen, since = now, time.monotonic()


def end_timeout(duration: float, exchange_step: float) -> float:
    """The wall time [s] the nodes get to end by themselves once the machine has finished a run of `duration` [s] at
    `exchange_step` [s]: END_TIMEOUT, and CLOSE_TIME_PER_EXCHANGE for each exchange, what the recorder's outputs take
    to write (the CSV's last rows, the recording closed, the summary of the run read back from its spool: the
    walking beam through the nodes for 10 000 s, 500 001 exchanges, was killed after 30 s of it, its summary lost;
    docs/ros.md, "Ends, Ctrl-C and no process left behind")."""
    return END_TIMEOUT + CLOSE_TIME_PER_EXCHANGE * (duration / exchange_step + 1)


def _wait_all(
    processes: dict[str, NodeProcess], timeout: float, quiet: bool = True, closing: float = STOP_TIMEOUT
) -> None:
    """Wait for the nodes to end; stop those still running after timeout [s] of wall time in all as Ctrl-C does
    (SIGINT: the recorder closes with what it has and writes its summary), and kill those still running `closing` s
    of wall time later. Not quiet: a wait past END_TIMEOUT is said once, naming the nodes still running and how long
    they may still take."""
    deadline = time.monotonic() + timeout
    said = quiet
    for process in processes.values():
        while True:
            try:
                process.wait(max(min(deadline, time.monotonic() + END_TIMEOUT) - time.monotonic(), 0.0))
                break
            except subprocess.TimeoutExpired:
                if time.monotonic() >= deadline:
                    process.send_signal(signal.SIGINT)
                    try:
                        process.wait(closing)
                    except subprocess.TimeoutExpired:
                        process.kill()
                        process.wait()
                    break
                if not said:
                    running = [name for name, other in processes.items() if other.poll() is None]
                    print(
                        f"mech-regulator: waiting for the {', '.join(running)} node{'s' if len(running) > 1 else ''} "
                        f"to write {'their' if len(running) > 1 else 'its'} outputs (at most "
                        f"{deadline - time.monotonic():.0f} s more) ...",
                        file=sys.stderr,
                    )
                    said = True


class NodeLog:
    """The nodes' output (stdout and stderr of every node, through one pipe) copied to the run's log file by a thread
    of the launcher, its last LOG_TAIL_BYTES kept in memory as well: a node's last words (why it failed) reach the
    launcher's summary even when the log cannot be written (a full disk). Use as a context manager; `follow` starts the
    copying once the nodes are forked (no thread runs in the launcher while it forks); leaving the context closes
    the launcher's end of the pipe and waits LOG_DRAIN s at most for the nodes' last output (the copying thread closes
    the log file at the pipe's end)."""

    def __init__(self, path: Path):
        self.file = open(path, "wb", buffering=0)
        self.read_end, self.write_end = os.pipe()
        self.error: OSError | None = None  # the first failed write to the log file; the copying stops there
        self._tail = bytearray()
        self._copier = threading.Thread(target=self._copy, name="node log", daemon=True)

    def fileno(self) -> int:
        """The descriptor the nodes write to (their stdout and stderr)."""
        return self.write_end

    def follow(self) -> None:
        if self._copier.ident is None:  # not started yet
            self._copier.start()

    def tail(self) -> str:
        """The nodes' last output, at most LOG_TAIL_BYTES (what the log file holds at its end when it could be written)."""
        return self._tail.decode(errors="replace")

    def _copy(self) -> None:
        with self.file:
            while chunk := os.read(self.read_end, 65536):
                self._tail += chunk
                del self._tail[:-LOG_TAIL_BYTES]
                if self.error is None:
                    try:
                        written = 0
                        while written < len(chunk):
                            written += self.file.write(chunk[written:]) or 0
                    except OSError as error:
                        self.error = error
        os.close(self.read_end)

    def __enter__(self) -> NodeLog:
        return self

    def __exit__(self, *exception) -> None:
        os.close(self.write_end)
        self.follow()
        self._copier.join(LOG_DRAIN)  # a node not yet ended keeps it open: the thread then ends with the process


class NodeProcess:
    """A node's process, forked from the launcher once what every node imports is imported (a node then starts without
    the 0.7-1 s of CPU that importing rclpy, scipy and the core takes in a new Python, four times at once on a small
    machine), with the part of subprocess.Popen's interface the launcher uses. The node runs as
    `python -m mech_regulator.nodes.<name> --ros-args --params-file <file>` would, in its own session (Ctrl-C reaches
    the launcher only; it passes it on), with the run's environment and its output in the run's log."""

    def __init__(self, name: str, parameter_file: Path, environment: dict[str, str], log):
        self.process = multiprocessing.get_context("fork").Process(
            target=_node_main, args=(name, parameter_file, environment, log.fileno()), name=f"{name}_node"
        )
        self.process.start()

    @property
    def returncode(self) -> int | None:
        """The exit code; minus the signal's number if a signal ended it; None while it runs."""
        return self.process.exitcode

    def poll(self) -> int | None:
        return self.process.exitcode

    def wait(self, timeout: float | None = None) -> int:
        """Wait at most timeout [s] for the end; raise subprocess.TimeoutExpired if it is still running then."""
        self.process.join(timeout)
        code = self.process.exitcode
        if code is None:
            assert timeout is not None, "join without a timeout returns once the process has ended"
            raise subprocess.TimeoutExpired(self.process.name, timeout)
        return code

    def send_signal(self, number: int) -> None:
        if self.process.exitcode is None:
            assert self.process.pid is not None, "__init__ started the process"
            os.kill(self.process.pid, number)

    def kill(self) -> None:
        self.process.kill()


def keep_niceness_in_own_session() -> None:
    """Give this process's session the process's niceness. A new session (os.setsid) is a new autogroup on Linux, and
    the kernel shares the CPU between autogroups before niceness counts inside one: without this, `nice
    mech-regulator run` would lower the launcher and not its nodes. Written to /proc/self/autogroup when the niceness
    is above 0 (raising an autogroup's niceness needs no privilege); nothing where the kernel has no autogroups."""
    niceness = os.getpriority(os.PRIO_PROCESS, 0)
    if niceness > 0:
        try:
            Path("/proc/self/autogroup").write_text(str(niceness))
        except OSError:  # no autogroups (the file missing, or refused)
            pass


def _node_main(name: str, parameter_file: Path, environment: dict[str, str], log_descriptor: int) -> None:
    """In a node's forked process: its own session, the launcher's death passed on (die_with_parent), its name
    (<name>_node, _name_process), output to the log, the run's environment and command line, then the node's main;
    its return value is the exit code."""
    os.setsid()
    keep_niceness_in_own_session()
    die_with_parent()
    _name_process(f"{name}_node")
    os.dup2(log_descriptor, sys.stdout.fileno())
    os.dup2(log_descriptor, sys.stderr.fileno())
    os.environ.clear()
    os.environ.update(environment)
    sys.argv = [f"{name}_node", "--ros-args", "--params-file", str(parameter_file)]
    try:
        node = importlib.import_module(f"mech_regulator.nodes.{name}")  # (the recorder's Rerun is imported here)
    except KeyboardInterrupt:  # the launcher's Ctrl-C before the node was up: a normal stop, nothing to close
        sys.exit(0)
    sys.exit(node.main())


def _name_process(name: str) -> None:
    """Give the process the name `name` (at most 15 bytes; Linux: PR_SET_NAME), which ps -o comm, top and pgrep
    show: a forked node's command line is its launcher's."""
    import ctypes

    PR_SET_NAME = 15
    ctypes.CDLL(None, use_errno=True).prctl(PR_SET_NAME, name.encode()[:15])
