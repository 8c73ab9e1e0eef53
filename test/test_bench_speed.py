"""`mech-regulator bench speed`: the paths it compares give equal answers (MuJoCo's multibody crank–slider, the
solve_ivp baseline and the fast path against the reference path), the interpolation at the target error, and the
command end to end. Speeds are never asserted."""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest
from support import run_cli, simulate_complete

from mech_regulator.bench.mujoco_model import MujocoCrankSlider, crank_slider_mjcf, mujoco_refusal
from mech_regulator.bench.speed_precision import at_error, work_precision_front
from mech_regulator.bench.speed_ros import failure_text, ros_summary, ros_target
from mech_regulator.bench.speed_runs import FAST, REFERENCE, SOLVE_IVP, Row, SpeedBenchmark, ode_runner
from mech_regulator.mechanisms.crank_slider import slider_kinematics
from mech_regulator.model import build_model
from mech_regulator.scene import SceneError, load_scene
from mech_regulator.scene.scenario_keys import DEFAULT_EXCHANGE_STEP
from mech_regulator.solvers.cosim import DEFAULT_COUPLING

SHORT = "scenario.duration=0.5"
# every MuJoCo-native form at once: constant drive, constant and viscous crank loads, a spring on the slider, a
# crank with its own mass off the axis, gravity with both components
VARIANT = (
    SHORT,
    "machine.drive={type: constant, torque: 30.0}",
    "machine.mechanism.crank_mass=0.8",
    "machine.mechanism.crank_cg=0.02",
    "machine.gravity=[3.0, -9.81]",
    "machine.loads=[{type: constant, torque: 5.0}, {type: viscous, coefficient: 0.05}, "
    "{type: slider_spring, stiffness: 2000.0, free_position: 0.21}, {type: slider_viscous, coefficient: 2.0}]",
)


def reference_run(*overrides: str):
    """The reference path at a tight tolerance on crank_slider_bench with overrides: (model, trajectory)."""
    model = build_model(load_scene("crank_slider_bench", [*overrides, "solver.rtol=1e-12", "solver.atol=1e-12"]))
    return model, simulate_complete(model)


@pytest.mark.parametrize("overrides", [(SHORT,), VARIANT], ids=["crank_slider_bench", "every native force"])
def test_mujoco_multibody_crank_slider_moves_as_the_reduced_model(overrides):
    """MuJoCo integrates three bodies and a loop constraint; our model the crank's reduced equation. Same machine,
    same omega(t): within 1e-6 of max omega (RMS) at a 0.25 ms step, and the slider where the closed-form
    kinematics puts it at MuJoCo's own crank angle (the loop stays closed)."""
    pytest.importorskip("mujoco", reason="MuJoCo is an optional dependency (extra 'bench')")
    model, trajectory = reference_run(*overrides)
    run = MujocoCrankSlider(model.scene, 2.5e-4).run(model.scene.scenario.duration)
    assert run.times[-1] == pytest.approx(0.5)
    omega_ref = trajectory(run.times)[1]
    assert np.max(omega_ref) > 30.0 and run.phi[-1] > 2 * math.pi  # run up through both dead centres
    error = np.sqrt(np.mean((run.omega - omega_ref) ** 2)) / np.max(np.abs(omega_ref))
    assert error < 1e-6
    link = model.scene.machine.mechanism
    x_closed = np.array([slider_kinematics(phi, link.crank, link.rod, link.offset)[0] for phi in run.phi])
    assert np.max(np.abs(run.x_slider - x_closed)) < 1e-7


def test_mujoco_model_refuses_what_it_cannot_express():
    compressor = load_scene("compressor")
    assert "machine.loads[3] type 'slider_table'" in mujoco_refusal(compressor)
    with pytest.raises(SceneError, match="slider_table"):
        crank_slider_mjcf(compressor, 1e-3)
    assert "loads[1] type 'fan'" in mujoco_refusal(
        load_scene("engine_direct", ["machine.drive={type: constant, torque: 10.0}"])
    )
    assert "external load" in mujoco_refusal(load_scene("crank_slider_bench", ["scenario.external_load=3.0"]))
    assert mujoco_refusal(load_scene("crank_slider_bench")) is None


def _omega(path: str, method: str, rtol: float, *overrides: str) -> tuple[np.ndarray, np.ndarray]:
    model = build_model(
        load_scene(
            "crank_slider_bench",
            [SHORT, *overrides, f"solver.method={method}", f"solver.rtol={rtol!r}", f"solver.atol={rtol!r}"],
        )
    )
    outcome = ode_runner(path, method, model)()
    assert outcome.status == "complete"
    return outcome.times, outcome.omega


@pytest.mark.parametrize("method", ["RK45", "DOP853"])
def test_solve_ivp_baseline_solves_the_reference_paths_problem(method):
    """solve_ivp on the model's plain-Python RHS (no events) lands on the tight reference within its tolerance."""
    times, omega = _omega(SOLVE_IVP, method, 1e-8)
    _model, trajectory = reference_run(SHORT)
    omega_ref = trajectory(times)[1]
    assert np.max(np.abs(omega - omega_ref)) / np.max(omega_ref) < 30 * 1e-8


@pytest.mark.parametrize("method", ["RK45", "DOP853"])
def test_fast_path_rows_equal_the_reference_path(method):
    times, omega = _omega(FAST, method, 1e-9, "solver.path=fast")
    omega_ref = _omega(REFERENCE, "DOP853", 1e-12)[1]
    assert np.max(np.abs(omega - omega_ref)) / np.max(omega_ref) < 30 * 1e-9


def _row(error: float, cpu: float) -> Row:
    return Row("precision", "s", "p", "m", "rtol", 0.0, 1.0, cpu_s=cpu, nfev=1e4 * cpu, error=error)


def test_cost_at_the_target_error_is_interpolated_log_log_along_the_front():
    """cpu = 1e-3 error^-1/2 at 1e-5 and 1e-7 gives 1 s at 1e-6; a dearer run that is less accurate is off the
    front; a target looser than every run costs the cheapest run; one tighter than every run gives nan."""
    rows = [_row(1e-5, 1e-3 * 1e-5**-0.5), _row(1e-7, 1e-3 * 1e-7**-0.5), _row(1e-4, 5.0)]
    assert [row.error for row in work_precision_front(rows)] == [1e-5, 1e-7]
    assert at_error(rows, 1e-6) == pytest.approx(1.0, rel=1e-12)
    assert at_error(rows, 1e-6, "nfev") == pytest.approx(1e4, rel=1e-12)
    assert at_error(rows, 1e-4) == pytest.approx(1e-3 * 1e-5**-0.5, rel=1e-12)
    assert math.isnan(at_error(rows, 1e-9))


def test_ros_real_time_factors():
    """The nodes' real-time factor is the simulated time over the exchanges' wall time (16 s in 32 s: 0.5), the
    target's measure at run's default (the fast path, DEFAULT_EXCHANGE_STEP, DEFAULT_COUPLING); the in-process run's
    factor and largest error are passed on; a failed run (no time) gives none; another design is not the target's."""

    def row(path, method, wall, error=math.nan, coupling=DEFAULT_COUPLING, step=DEFAULT_EXCHANGE_STEP):
        return Row("ros", "engine_direct", path, method, coupling, step, 16.0, wall, steps=800, error=error)

    rows = [
        row(REFERENCE, "nodes", 80.0),
        row(REFERENCE, "in process", 16.0, 6e-5),
        row(FAST, "nodes", 32.0),
        row(FAST, "in process", 4.0, 2e-5),
    ]
    benchmark = SpeedBenchmark(rows=rows)
    reference, fast = ros_summary(benchmark)
    assert reference["real_time_factor"] == pytest.approx(0.2, rel=1e-12) and not reference["default"]
    assert fast["real_time_factor"] == pytest.approx(0.5, rel=1e-12) and fast["default"]
    assert fast["in_process_real_time_factor"] == pytest.approx(4.0, rel=1e-12) and fast["max_error"] == 2e-5
    assert ros_target(benchmark) == pytest.approx(0.5, rel=1e-12)
    assert math.isnan(ros_target(SpeedBenchmark(rows=rows[:2])))
    assert math.isnan(ros_target(SpeedBenchmark(rows=[row(FAST, "nodes", math.nan)])))
    held = row(FAST, "nodes", 8.0, coupling="hold", step=1e-3)
    summary = ros_summary(SpeedBenchmark(rows=rows + [held]))
    assert [item["coupling"] for item in summary] == [DEFAULT_COUPLING, DEFAULT_COUPLING, "hold"]
    assert summary[2]["real_time_factor"] == pytest.approx(2.0, rel=1e-12) and not summary[2]["default"]
    assert math.isnan(ros_target(SpeedBenchmark(rows=[held]))), "the target's measure is run's default"


def test_the_ros_picture_is_drawn_only_when_the_main_job_was_measured(tmp_path):
    from mech_regulator.viz.speed import plot_ros_speed

    rows = [
        Row(
            "ros",
            "engine_direct",
            path,
            how,
            DEFAULT_COUPLING,
            DEFAULT_EXCHANGE_STEP,
            16.0,
            wall,
            steps=800,
            error=error,
        )
        for path, how, wall, error in ((FAST, "nodes", 4.0, math.nan), (FAST, "in process", 2.0, 2e-5))
    ]
    assert plot_ros_speed(SpeedBenchmark(rows=rows), tmp_path / "ros.png")
    assert (tmp_path / "ros.png").read_bytes().startswith(b"\x89PNG")
    assert not plot_ros_speed(SpeedBenchmark(rows=[]), tmp_path / "none.png")
    assert not (tmp_path / "none.png").exists()


def test_quick_command_writes_its_files(capsys, tmp_path):
    pytest.importorskip("mujoco", reason="MuJoCo is an optional dependency (extra 'bench')")
    code, out, err = run_cli(
        capsys, "bench", "speed", "--quick", "--scenes", "crank_slider_bench", "--out", str(tmp_path)
    )
    assert code == 0, err
    assert "targets (on crank_slider_bench" in out and "fast : MuJoCo" in out
    with open(tmp_path / "speed.csv", newline="", encoding="utf-8") as stream:
        rows = list(csv.DictReader(stream))
    measured = {row["path"] for row in rows if row["section"] == "precision" and row["error"]}
    assert {REFERENCE, SOLVE_IVP, "MuJoCo"} <= measured
    for row in rows:
        if row["section"] == "precision" and row["error"]:
            assert 0.0 < float(row["error"]) < 1e-3  # every path solved the same machine
    assert {row["section"] for row in rows} >= {"precision", "duration", "effects", "sweep", "startup"}
    # --quick measures the fast path's start-up warm only (a cold compile would take some 50 s of the quick run)
    startup = [(row["path"], row["setting"], row["note"]) for row in rows if row["section"] == "startup"]
    assert [(path, setting) for path, setting, _ in startup] == [(REFERENCE, "warm"), (FAST, "warm")]
    assert all(note.endswith("run complete") for _, _, note in startup), startup
    summary = json.loads((tmp_path / "speed.json").read_text())
    assert [item["target"] for item in summary["targets"]] == [
        "fast : solve_ivp",
        "fast : MuJoCo",
        "ROS real-time factor",
    ]
    assert (tmp_path / "speed.png").read_bytes().startswith(b"\x89PNG")


@pytest.mark.parametrize(
    "argv, message",
    [
        (("--scenes", "nope"), "--scenes: no speed scene 'nope'; choose from crank_slider_bench"),
        (("--scenes", ","), "--scenes: expected scene names"),
    ],
)
def test_bad_option_exits_2_with_a_message(capsys, tmp_path, argv, message):
    code, _out, err = run_cli(capsys, "bench", "speed", "--quick", "--out", str(tmp_path), *argv)
    assert code == 2
    assert message in err
    assert not (tmp_path / "speed.csv").exists()


def test_a_failed_ros_run_is_named_by_its_nodes_not_by_a_crash_dumps_last_line():
    """A node's crash ends the launcher's stderr with the log tail it prints, whose last line is the interpreter's list
    of extension modules: the row's note names the node, its exit code and the fatal error instead."""
    stderr = (
        "mech-regulator: the machine node ended with exit code -11\n"
        "mech-regulator: node(s) machine failed; the end of /tmp/x.log:\n"
        "Fatal Python error: Segmentation fault\n\nCurrent thread 0x1 (most recent call first):\n"
        '  File "x.py", line 1 in f\n\nExtension modules: yaml._yaml, numpy (total: 2)\n'
    )
    assert failure_text(stderr) == (
        "mech-regulator: the machine node ended with exit code -11; Fatal Python error: Segmentation fault"
    )
    assert (
        failure_text("usage: mech-regulator run\nmech-regulator run: error: bad option\n")
        == "mech-regulator run: error: bad option"
    )
