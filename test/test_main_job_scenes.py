"""The main job plays every scene: every bundled scene, a user's scene and two generated linkages through the nodes
(`mech-regulator run`), the nodes ending by themselves and leaving no process behind, a missing peer named,
a scene the nodes cannot play refused at once, and the machine's services (~/pause, ~/step, ~/resume,
~/reset) between trials.

Every run's CSV is compared with the in-process co-simulation of the core (solvers.cosim.cosimulate) of
the same scene over the same simulated time: the nodes only move messages.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest
import yaml
from linkage_family import member
from ros_support import (  # noqa: F401 (fixtures)
    STATE_LISTEN_QOS,
    WAIT,
    Processes,
    RunListener,
    domain_id,
    next_domain_id,
    probe,
    processes,
    stamp_ns,
)

# after ros_support, which skips this module when rclpy is missing
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger
from support import SMOOTH_DIRECT_GOVERNOR, SMOOTH_GOVERNED_MACHINE
from test_linkage_family import strip_counts

from mech_regulator.cli.report.data import write_csv
from mech_regulator.model import build_model
from mech_regulator.scene import bundled_scenes, load_scene, validate_scene
from mech_regulator.solvers.cosim import DEFAULT_COUPLING, cosimulate, to_nanoseconds

PLAYED = 0.3  # [s] of simulated time each bundled scene is played


def in_process_csv(
    model, duration: float, path: Path, coupling: str = DEFAULT_COUPLING, overspeed_trip: float = 0.0
) -> bytes:
    """The CSV the in-process co-simulation of `model` over `duration` [s] writes (what the nodes must write);
    overspeed_trip [rad/s] as `run --overspeed-trip` (0: none)."""
    scenario = model.scene.scenario.model_copy(update={"duration": duration})
    shortened = dataclasses.replace(model, scene=model.scene.model_copy(update={"scenario": scenario}))
    run = cosimulate(shortened, model.scene.solver.exchange_step, overspeed_trip=overspeed_trip, coupling=coupling)
    write_csv(path, shortened.columns(run.times, run.states, run.throttle, run.external_load), digits=17)
    return path.read_bytes()


def node_processes(marker: str) -> list[str]:
    """The names and command lines of the running node processes whose arguments mention `marker` (a run's
    folder): started by hand (python -m mech_regulator.nodes.<name>), or forked by `run` (named <name>_node, with
    the launcher's command line)."""
    listing = subprocess.run(["ps", "-ww", "-eo", "comm=,args="], capture_output=True, text=True, check=True).stdout
    return [
        line
        for line in listing.splitlines()
        if marker in line and ("mech_regulator.nodes" in line or line.split(maxsplit=1)[0].endswith("_node"))
    ]


def play(scene: str, folder: Path, *options: str) -> tuple[subprocess.CompletedProcess, Path]:
    """`mech-regulator run SCENE --duration PLAYED` on a private domain; returns the finished process and the
    recording's path."""
    folder.mkdir(parents=True, exist_ok=True)
    rrd = folder / "run.rrd"
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "mech_regulator",
            "run",
            scene,
            "--duration",
            str(PLAYED),
            "--out",
            str(rrd),
            "--domain-id",
            str(next_domain_id()),
            "--quiet",
            *options,
        ],
        capture_output=True,
        text=True,
        timeout=4 * WAIT,
        cwd=folder,
        env=dict(os.environ, PYTHONUNBUFFERED="1"),
    )
    return result, rrd


def assert_played(
    scene: str, model, result: subprocess.CompletedProcess, rrd: Path, tmp_path: Path, coupling: str = DEFAULT_COUPLING
) -> None:
    """The run ended by itself with exit 0 and status complete, wrote every exchange to its CSV exactly as the
    in-process co-simulation does, and left no node running."""
    log = rrd.with_suffix(".log")
    described = (
        f"{scene}: exit {result.returncode}\n{result.stdout}\n{result.stderr}\n"
        f"{log.read_text() if log.exists() else ''}"
    )
    assert result.returncode == 0, described
    summary = json.loads(rrd.with_suffix(".json").read_text())
    assert summary["status"] == "complete" and summary["t_end"] == PLAYED, described
    assert summary["start_up_s"] > 0.0 and "max_lag_s" not in summary, described  # the command came first; lockstep
    assert "s from the command to the first exchange" in result.stdout, described
    rows = rrd.with_suffix(".csv").read_bytes()
    step = model.scene.solver.exchange_step  # [s] the exchanges: the grid and each load change off it
    off_grid = [
        time for time in model.breakpoints() if 0.0 < time < PLAYED and abs(time / step - round(time / step)) > 1e-9
    ]
    assert rows.count(b"\n") == 1 + round(PLAYED / step) + 1 + len(off_grid), described  # header, exchanges
    assert rows == in_process_csv(model, PLAYED, tmp_path / f"{scene}.in_process.csv", coupling), (
        f"{scene}: the nodes' CSV differs from the in-process co-simulation"
    )
    assert node_processes(str(rrd.parent)) == [], f"{scene}: nodes left running"


def test_every_bundled_scene_plays_to_the_end_through_the_nodes(tmp_path):
    """Governed or not, direct and indirect governors, two-mass machines, a clutch with branches, engines,
    linkages: each plays PLAYED s through the nodes, two runs side by side."""
    scenes = bundled_scenes()
    assert len(scenes) >= 17
    with ThreadPoolExecutor(max_workers=2) as pool:
        results = dict(zip(scenes, pool.map(lambda scene: play(scene, tmp_path / scene), scenes)))
    for scene, (result, rrd) in results.items():
        assert_played(scene, build_model(load_scene(scene)), result, rrd, tmp_path)


def test_the_waveform_coupling_through_the_nodes_is_the_in_process_one(tmp_path):
    """The machine sends its speed at the middle of each step, the governor follows it, the machine extrapolates
    the throttle: the same operations as cosimulate(coupling='waveform'), so the same CSV to the last bit."""
    scene = "engine_indirect_isodromic"
    result, rrd = play(scene, tmp_path / "run", "--coupling", "waveform")
    assert_played(scene, build_model(load_scene(scene)), result, rrd, tmp_path, "waveform")
    assert json.loads(rrd.with_suffix(".json").read_text())["coupling"] == "waveform"


def test_realtime_says_how_far_it_fell_behind_the_wall_clock(tmp_path):
    """--time-mode realtime: the machine integrates a step only once the wall clock has reached its end, so the
    simulation time it publishes is never ahead of the wall clock: the largest lag in the summary is >= 0 (and
    finite), printed with the summary; the run completes its simulated time."""
    result, rrd = play("engine_direct", tmp_path / "realtime", "--time-mode", "realtime")
    described = f"exit {result.returncode}\n{result.stdout}\n{result.stderr}"
    assert result.returncode == 0, described
    summary = json.loads(rrd.with_suffix(".json").read_text())
    assert summary["status"] == "complete" and summary["t_end"] == PLAYED, described
    assert 0.0 <= summary["max_lag_s"] < np.inf, described
    assert f"behind the wall clock by {summary['max_lag_s']:.3g} s at most" in result.stdout, described


def four_bar_from_rest() -> dict:
    """A user's scene: an ungoverned four-bar (crank 0.1 m, coupler 0.4 m, rocker 0.3 m, frame 0.35 m) started
    from rest by an induction motor against a viscous load."""
    return {
        "name": "my_four_bar",
        "machine": {
            "inertia": 0.2,
            "mechanism": {
                "type": "four_bar",
                "crank": 0.1,
                "coupler": 0.4,
                "rocker": 0.3,
                "frame": 0.35,
                "branch": "open",
                "coupler_mass": 2.0,
                "coupler_cg": 0.2,
                "rocker_mass": 3.0,
                "rocker_cg": 0.15,
            },
            "drive": {"type": "linear_motor", "stall_torque": 60.0, "no_load_speed": 100.0},
            "loads": [{"type": "viscous", "coefficient": 0.2}],
        },
        "scenario": {"initial": {"phi": 0.0, "omega": 0.0}, "duration": PLAYED},
        "solver": {"method": "DOP853", "rtol": 1e-9, "atol": 1e-11},
    }


def test_a_user_scene_plays_through_the_nodes(tmp_path):
    path = tmp_path / "my_four_bar.yaml"
    path.write_text(yaml.safe_dump(four_bar_from_rest(), sort_keys=False))
    model = build_model(validate_scene(four_bar_from_rest()))
    result, rrd = play(str(path), tmp_path / "run")
    assert_played("my_four_bar", model, result, rrd, tmp_path)
    csv = np.genfromtxt(rrd.with_suffix(".csv"), delimiter=",", names=True)
    assert csv["omega"][0] == 0.0 and csv["omega"][-1] > 1.0, "the machine did not start from rest"
    assert "theta4" in csv.dtype.names, "no rocker columns in the CSV of a four-bar"


def test_generated_linkages_play_through_the_nodes_without_a_trip_nobody_asked_for(tmp_path):
    """Two members of the generated family (test/linkage_family.py) side by side: the all-revolute Watt six-bar with
    its governor (a linkage without sliders could not be recorded, so `run` failed) and the six-bar with a ram,
    ungoverned, started at 10 rad/s well below its running speed (the trip once defaulted to 1.25 x the initial
    speed and closed its throttle at 12.5 rad/s while the run still said complete). Each plays as the in-process
    co-simulation without a trip, and its recording draws every link but the crank and each slider block."""
    scenes = {}
    for name, changes in (("watt_six_bar", {}), ("six_bar_ram", {"omega": 10.0})):
        data = member(name, 7)
        data.pop("expected")
        data["scenario"]["initial"].update(changes)
        path = tmp_path / f"{name}.yaml"
        path.write_text(yaml.safe_dump(data, sort_keys=False))
        scenes[name] = (path, data)
    with ThreadPoolExecutor(max_workers=2) as pool:
        results = dict(zip(scenes, pool.map(lambda name: play(str(scenes[name][0]), tmp_path / name), scenes)))
    for name, (result, rrd) in results.items():
        path, data = scenes[name]
        assert_played(name, build_model(validate_scene(data)), result, rrd, tmp_path)
        mechanism = data["machine"]["mechanism"]
        prismatic = sum(joint["type"] == "prismatic" for joint in mechanism["joints"].values())
        assert strip_counts(rrd, "/mechanism/links") == {len(mechanism["links"]) - 1}
        assert strip_counts(rrd, "/mechanism/sliders") == {prismatic}
        assert "overspeed trip" not in result.stdout + result.stderr
    omega = np.genfromtxt(results["six_bar_ram"][1].with_suffix(".csv"), delimiter=",", names=True)["omega"]
    assert omega[0] == 10.0 and omega[-1] > 1.25 * 10.0, "the ram's machine did not pass the former default trip"


def test_a_scene_the_nodes_cannot_play_is_refused_at_once(tmp_path):
    data = four_bar_from_rest() | {"solver": {"method": "energy"}}
    path = tmp_path / "energy.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    result, rrd = play(str(path), tmp_path / "run")
    assert result.returncode == 2 and "solver.method: 'energy'" in result.stderr, result.stderr
    assert "cannot be played by the nodes" in result.stderr and "Traceback" not in result.stderr
    assert not rrd.with_suffix(".log").exists(), "nodes were started for a scene refused at once"


def test_a_missing_peer_is_named_and_the_machine_ends(tmp_path, processes):
    machine = processes.node("machine", {"scene_file": "lathe", "peers": ["scenario", "recorder"], "peer_timeout": 3.0})
    processes.node("scenario", {"scene_file": "lathe"})
    assert processes.wait(machine) == 1, processes.logs()
    log = processes.log(machine)
    assert "no recorder node subscribed to /joint_states (or /machine/moments) within 3 s" in log and "peers" in log, (
        log
    )
    assert "scenario" not in log.split("no ")[1].split(" node")[0], log


def test_hand_started_nodes_end_by_themselves_with_the_run(tmp_path, processes):
    scene = "engine_direct"
    overrides = ["scenario.duration=0.2", "scenario.load_events=[]"]
    parameters = {"scene_file": scene, "overrides": overrides}
    governor = processes.node("governor", parameters)
    scenario = processes.node("scenario", parameters)
    machine = processes.node("machine", parameters | {"peer_timeout": 60.0})
    for process in (machine, governor, scenario):
        assert processes.wait(process) == 0, processes.logs()
    assert "finished at t = 0.2 s: complete" in processes.log(machine), processes.logs()
    assert node_processes(str(tmp_path)) == []


def _call(probe, name: str, describe) -> Trigger.Response:
    response = probe.call(Trigger, f"/machine/{name}", Trigger.Request(), describe=describe)
    assert response.success, response.message
    return response


def test_the_services_pause_step_resume_and_reset_between_trials(tmp_path, processes, probe):
    """Paused from the start, ~/step advances step_exchanges exchanges at a time; ~/resume plays on; ~/reset
    starts a second trial from the initial state, and the governor follows: the second trial is the in-process
    co-simulation to the last bit, as the first."""
    scene = "engine_direct"
    overrides = ["scenario.duration=0.1", "scenario.load_events=[]"]
    model = build_model(load_scene(scene, overrides))
    run = cosimulate(model, 0.002, coupling=DEFAULT_COUPLING)  # the nodes' default coupling
    parameters = {"scene_file": scene, "overrides": overrides, "exchange_step": 0.002}
    processes.node("governor", parameters)
    processes.node("scenario", parameters)
    machine = processes.node(
        "machine",
        parameters
        | {
            "peer_timeout": 60.0,
            "start_paused": True,
            "step_exchanges": 5,
            "at_end": "hold",
            "peers": ["governor", "scenario", probe.node.get_name()],
        },
    )
    listener = RunListener(probe, governed=True, diagnostics_publishers=0, describe=processes.logs)
    trials: list[dict[int, float]] = [{}]  # per trial: exchange time [ns] -> omega [rad/s] (a state sent again
    # while the machine waits counts once)
    listener.open_gate(lambda message: trials[-1].update({stamp_ns(message.header.stamp): message.velocity[0]}))

    def times(trial: int) -> list[int]:
        return sorted(trials[trial])

    probe.spin_until(lambda: times(0) == [0], "the first state at t = 0", describe=processes.logs)
    _call(probe, "step", processes.logs)
    probe.spin_until(lambda: len(times(0)) == 6, "5 exchanges after ~/step", describe=processes.logs)
    assert times(0) == [to_nanoseconds(0.002 * k) for k in range(6)]
    later = time.monotonic() + 1.0
    probe.spin_until(lambda: time.monotonic() > later, "a second of listening")
    assert len(times(0)) == 6, "the machine went on after its steps while paused"
    _call(probe, "resume", processes.logs)
    probe.spin_until(lambda: times(0)[-1] == to_nanoseconds(0.1), "the end of the first trial", describe=processes.logs)
    assert machine.poll() is None, "at_end: hold, but the machine ended"
    trials.append({})
    _call(probe, "reset", processes.logs)
    probe.spin_until(
        lambda: times(1) and times(1)[-1] == to_nanoseconds(0.1), "the end of the second trial", describe=processes.logs
    )
    for trial in trials:
        assert times(trials.index(trial)) == [to_nanoseconds(t) for t in run.times]
        np.testing.assert_array_equal(
            [trial[when] for when in sorted(trial)], run.states[1], err_msg="a trial differs from the in-process run"
        )


def _process_state(process: subprocess.Popen) -> str:
    """A process's state letter (Linux /proc/<pid>/stat): R running, S sleeping, T stopped, ..."""
    return Path(f"/proc/{process.pid}/stat").read_text().rsplit(")", 1)[1].split()[0]


def test_a_stopped_recorder_or_scenario_delays_no_exchange(tmp_path, processes, probe):
    """The recorder and the scenario are off the lockstep's critical path (docs/ros.md, "Speed"): both stopped
    (SIGSTOP) before the first step, the machine and the governor still play every exchange, more than the
    publishers' history holds for a stopped subscriber; resumed, the recorder records every exchange, its CSV the
    in-process co-simulation's. (The scenario's load is held from its answer at t = 0 to the end: a load event
    would be waited for, as the machine must know the load it applies.)"""
    duration, step = 0.3, 0.002  # 150 exchanges: beyond COMMAND_QOS's depth of 100
    data = {
        "name": "smooth",
        "machine": SMOOTH_GOVERNED_MACHINE,
        "governor": SMOOTH_DIRECT_GOVERNOR,
        "scenario": {"initial": {"omega": 100.0}, "duration": duration, "external_load": 6.0, "load_events": []},
        "solver": {"exchange_step": step},
    }  # cheap per step on the reference path
    scene = tmp_path / "smooth.yaml"
    scene.write_text(yaml.safe_dump(data, sort_keys=False))
    model = build_model(validate_scene(data))
    parameters = {"scene_file": str(scene)}
    rrd = tmp_path / "run.rrd"
    # the moments at t = 0 go out once the inputs at t = 0 are taken, and machine/moments keeps every message for a
    # reader it matches late (machine/status keeps its latest only: a reader matched after the machine's second
    # 'paused', seen under load, saw one 'paused' and waited for it for ever)
    moments = probe.listen(JointState, "machine/moments", STATE_LISTEN_QOS)
    joint_states = probe.listen(JointState, "joint_states", STATE_LISTEN_QOS)
    recorder = processes.node("recorder", parameters | {"output": str(rrd)})
    processes.node("governor", parameters)
    scenario = processes.node("scenario", parameters)
    processes.node(
        "machine",
        parameters | {"peer_timeout": 10 * WAIT, "start_paused": True, "peers": ["governor", "scenario", "recorder"]},
    )  # (a peer waited for would fail the test by its WAIT, not end the wait after peer_timeout)
    probe.spin_until(
        lambda: 0 in RunListener.by_group(moments),
        "the machine paused with the inputs at t = 0 taken (its moments at t = 0)",
        describe=processes.logs,
    )
    stopped = (recorder, scenario)
    try:
        for process in stopped:
            process.send_signal(signal.SIGSTOP)
        wait_for(lambda: all(_process_state(process) == "T" for process in stopped), "both stopped", processes.logs)
        _call(probe, "resume", processes.logs)
        end = to_nanoseconds(duration)
        probe.spin_until(
            lambda: any(stamp_ns(message.header.stamp) == end for message in joint_states),
            "the machine's state at the end of the run",
            describe=processes.logs,
        )
        assert all(_process_state(process) == "T" for process in stopped), "a stopped node ran before the end"
    finally:
        for process in stopped:
            process.send_signal(signal.SIGCONT)
    for process, _ in processes.started:
        assert processes.wait(process) == 0, processes.logs()
    assert rrd.with_suffix(".csv").read_bytes() == in_process_csv(model, duration, tmp_path / "in_process.csv")
    summary = json.loads(rrd.with_suffix(".json").read_text())
    assert summary["status"] == "complete" and summary["samples"] == round(duration / step) + 1, summary


def test_a_killed_launcher_leaves_no_node_behind(tmp_path, processes):
    """However the launcher ends — here SIGKILL, which it cannot catch — its nodes end too (they get SIGINT when
    their parent dies), closing the recording."""
    rrd = tmp_path / "killed" / "run.rrd"
    rrd.parent.mkdir()
    launcher = processes.start(
        [
            sys.executable,
            "-m",
            "mech_regulator",
            "run",
            "engine_direct",
            "--out",
            rrd,
            "--domain-id",
            next_domain_id(),
            "--quiet",
        ],
        "launcher",
    )

    def nodes_running() -> bool:  # the machine stepping: the scenario gave its first load
        log = rrd.with_suffix(".log")
        return len(node_processes(str(rrd.parent))) == 4 and log.exists() and "load 6 N m" in log.read_text()

    wait_for(nodes_running, "the four nodes running", lambda: f"{node_processes(str(rrd.parent))}\n{processes.logs()}")
    launcher.kill()
    wait_for(lambda: not node_processes(str(rrd.parent)), "the nodes ending after their launcher", processes.logs)
    assert rrd.with_suffix(".json").exists(), "the recorder did not close the run"


def wait_for(condition, what: str, describe) -> None:
    """Poll condition() every 0.1 s; a failure (with the logs) after WAIT seconds."""
    deadline = time.monotonic() + WAIT
    while not condition():
        if time.monotonic() > deadline:
            pytest.fail(f"timed out after {WAIT} s waiting for {what}\n{describe()}")
        time.sleep(0.1)


def test_a_run_driven_backwards_ends_failed_with_exit_1_and_says_why(tmp_path):
    """A load that drives the engine backwards past its trip (9.9e4 N m from 0.1 s, trip 300 rad/s both ways): the
    machine's run fails there, and the summary says `failed` with why (not `interrupted`, as the recorder once wrote
    over it); `run` exits 1, and the CSV keeps every exchange the governor answered: the in-process co-simulation's
    but the last, whose state (beyond the governor's speed range) the governor refuses. The recorder closes as soon
    as the governor has ended, not after its FINISH_GRACE (10 s) for that answer (once every such run ended 10 s
    late)."""
    load = "scenario.load_events=[{time: 0.1, torque: 99000.0}]"
    result, rrd = play("engine_direct", tmp_path / "run", "--overspeed-trip", "300", "--set", load)
    described = f"exit {result.returncode}\n{result.stdout}\n{result.stderr}"
    assert result.returncode == 1 and "Traceback" not in result.stderr, described
    summary = json.loads(rrd.with_suffix(".json").read_text())
    assert summary["status"] == "failed" and "driven backwards at t = " in summary["message"], summary
    assert 0.1 <= summary["t_end"] < PLAYED, summary
    log = rrd.with_suffix(".log").read_text()
    assert "closing with all that can still come" in log and "did not come within" not in log, log
    model = build_model(load_scene("engine_direct", [load]))
    in_process = in_process_csv(model, PLAYED, tmp_path / "in_process.csv", overspeed_trip=300.0)
    assert rrd.with_suffix(".csv").read_bytes() == b"".join(in_process.splitlines(keepends=True)[:-1])
    assert node_processes(str(rrd.parent)) == []


def _working_directory(pid: int) -> Path | None:
    """The working directory of process `pid`, None once it has ended: `pgrep` lists a recorder_node of another run on
    this machine (another test's, on another pytest-xdist worker) that has ended and not yet been waited for (a
    zombie) or that ends before this look, and its /proc/<pid>/cwd is then gone (Path.resolve raised FileNotFoundError
    in a loaded run; it does for any zombie)."""
    try:
        return Path(os.readlink(f"/proc/{pid}/cwd")).resolve()
    except OSError:
        return None


def _play_holding_the_recorder(
    folder: Path, scene: str, played: float, domain: int, hold: Callable, until_end: Callable = lambda run: None
) -> tuple[str, Path]:
    """Play `scene` through the nodes for `played` s (`run --out folder/run.rrd`), its recorder held back once it
    runs by `hold(recorder's pid, run)` in a thread while `until_end(run)` waits here; assert the run `complete` with
    every exchange in its summary and its CSV, and return what describes it and the recording's path."""
    rrd = folder / "run.rrd"
    run = subprocess.Popen(
        [sys.executable, "-m", "mech_regulator", "run", scene, "--duration", str(played), "--out", str(rrd)]
        + ["--domain-id", str(domain), "--quiet"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=folder,
    )

    def held() -> None:
        deadline, recorder = time.monotonic() + 4 * WAIT, None
        while recorder is None and run.poll() is None and time.monotonic() < deadline:
            listing = subprocess.run(["pgrep", "-x", "recorder_node"], capture_output=True, text=True).stdout.split()
            ours = [int(pid) for pid in listing if _working_directory(int(pid)) == folder.resolve()]
            recorder = ours[0] if ours else None
            time.sleep(0.05)
        assert recorder is not None, "no recorder_node of this run"
        hold(recorder, run)

    try:
        with ThreadPoolExecutor(1) as pool:
            holding = pool.submit(held)
            until_end(run)
            holding.result()
        stdout, stderr = run.communicate(timeout=4 * WAIT)
    finally:
        if run.poll() is None:
            run.kill()
    described = f"exit {run.returncode}\n{stdout}\n{stderr}"
    assert run.returncode == 0, described
    summary = json.loads(rrd.with_suffix(".json").read_text())
    exchanges = round(played / load_scene(scene).solver.exchange_step) + 1  # (constant loads: no exchange between)
    assert summary["status"] == "complete" and summary["t_end"] == played, described
    assert summary["samples"] == exchanges and rrd.with_suffix(".csv").read_bytes().count(b"\n") == 1 + exchanges
    return described, rrd


def test_a_recorder_slower_than_the_machine_sets_the_run_s_pace(tmp_path, probe, domain_id):
    """The recorder held back 0.4 s of every 0.5 s (SIGSTOP, SIGCONT) for a whole 600-s walking-beam run (16 columns,
    some 2500 exchanges a second otherwise): the machine keeps within RECORDER_LEAD exchanges of what the recorder
    has taken (recorder/progress; MachineNode.keep_pace_with_the_recorder), so the run goes at the recorder's pace and
    ends `complete` with every exchange. Seen from a test node: the machine's time in its /diagnostics less the
    recorder's progress, at most RECORDER_LEAD exchanges and the machine's look every PROGRESS_EVERY (and two batches,
    and the messages' own delays); without the pace it reached 22 500 exchanges here, and on a loaded machine the
    shaper's recorder through the nodes for 10 000 s was 5 minutes behind at the end, 13 203 exchanges lost."""
    from diagnostic_msgs.msg import DiagnosticArray
    from std_msgs.msg import Header

    from mech_regulator.nodes.common import BATCH_SIZE, PROGRESS_EVERY, RECORDER_LEAD

    played, step = 600.0, load_scene("walking_beam").solver.exchange_step
    newest = {"machine": 0.0, "recorded": 0.0, "lead": 0.0}  # [s]

    def on_progress(message) -> None:
        newest["recorded"] = max(newest["recorded"], message.stamp.sec + 1e-9 * message.stamp.nanosec)

    def on_diagnostics(message) -> None:
        for status in message.status:
            if status.name.endswith("/machine"):
                values = {item.key: item.value for item in status.values}
                newest["machine"] = max(newest["machine"], float(values.get("sim_time", 0.0)))
        newest["lead"] = max(newest["lead"], newest["machine"] - newest["recorded"])

    def hold(recorder: int, run) -> None:
        while run.poll() is None and newest["machine"] == 0.0:  # held from the first exchange on, not in discovery
            time.sleep(0.05)
        with contextlib.suppress(ProcessLookupError):  # (a recorder that ended: the asserts below say why)
            while run.poll() is None and newest["machine"] < played:
                os.kill(recorder, signal.SIGSTOP)
                time.sleep(0.4)
                os.kill(recorder, signal.SIGCONT)
                time.sleep(0.1)

    probe.listen(Header, "recorder/progress", callback=on_progress)
    probe.listen(DiagnosticArray, "/diagnostics", callback=on_diagnostics)
    described, _ = _play_holding_the_recorder(
        tmp_path,
        "walking_beam",
        played,
        domain_id,
        hold,
        lambda run: probe.spin_until(lambda: run.poll() is not None, "the run's end", timeout=12 * WAIT),
    )
    described += f"\nlead {newest}"
    assert newest["machine"] == played and newest["recorded"] == played, described  # both seen to the end
    delays = 50.0  # [s] of simulated time: the last progress sent before the recorder was stopped, a second of
    # the machine at 50 times real time (without the pace the lead reached 450 s)
    assert newest["lead"] <= (RECORDER_LEAD + PROGRESS_EVERY + 2 * BATCH_SIZE) * step + delays, described


def test_a_recorder_held_back_slows_the_run_and_loses_no_exchange(tmp_path):
    """The recorder stopped (SIGSTOP) for 30 s of wall time in the middle of a run whose exchanges go at some 2000 a
    second: the machine's batches wait for its acknowledgements (nodes.common.Batch, ACKED_EVERY, wait_for_readers)
    instead of running past what their publisher's history keeps, and say so on the log, so the run ends `complete`
    with every exchange in its CSV. Before, the recorder missed thousands of exchanges and the run ended
    `interrupted`: with no wait at all, and (a wait of at most 10 s) with a stop longer than that. 30 s is past Fast
    DDS's default participant lease, 20 s: with it (the run's profile without its leaseDuration) the machine took the
    recorder for gone and went on, and the run ended without a summary; the run's profile sets PARTICIPANT_LEASE."""

    def hold(recorder: int, run) -> None:
        csv = tmp_path / "run.csv"
        deadline = time.monotonic() + 4 * WAIT
        while not (csv.exists() and csv.stat().st_size > 100_000) and time.monotonic() < deadline:
            time.sleep(0.05)  # the recorder has written its first rows: exchanges are under way
        os.kill(recorder, signal.SIGSTOP)
        time.sleep(30.0)
        os.kill(recorder, signal.SIGCONT)

    described, rrd = _play_holding_the_recorder(tmp_path, "lathe", 800.0, next_domain_id(), hold)
    log = rrd.with_suffix(".log").read_text()
    assert "left while the run waited" not in log, described
    assert "machine/moments (the recorder among them) have not acknowledged" in log, described
