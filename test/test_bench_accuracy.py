"""`mech-regulator bench accuracy`: the quick benchmark end to end, and what its numbers must show.

The quick benchmark (startup and engine_direct, tiny durations) runs once for the module. Its errors are
asserted (convergence orders, tolerance proportionality, the reference check); its CPU times never are.
"""

from __future__ import annotations

import csv
import multiprocessing
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import matplotlib.image
import numpy as np
import pytest
from rerun.chunk import RrdReader
from support import run_cli, write_scene

from mech_regulator.bench import accuracy
from mech_regulator.bench.accuracy import ADAPTIVE, COSIM, SCENES, Setting, Task, _measured, startup_closed_form
from mech_regulator.bench.report import CSV_COLUMNS
from mech_regulator.cli.main import main
from mech_regulator.model import build_model
from mech_regulator.scene import load_scene

QUICK_SCENES = ("startup", "engine_direct")
TOLERANCE_FACTOR = 30.0  # DOP853's achieved error stays below this many times the requested rtol ...
RESOLVED_FACTOR = 10.0  # ... and this many times above the two references' disagreement


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    """The quick benchmark on startup and engine_direct: (exit code, output folder, CSV rows)."""
    out = tmp_path_factory.mktemp("accuracy")
    code = main(["bench", "accuracy", "--quick", "--scenes", ",".join(QUICK_SCENES), "--out", str(out)])
    with open(out / "runs.csv", newline="", encoding="utf-8") as stream:
        rows = list(csv.DictReader(stream))
    return code, out, rows


def runs(rows: list[dict], scene: str, method: str) -> list[dict]:
    """A method's rows on a scene, loosest setting first (as the CSV lists them)."""
    return [row for row in rows if row["scene"] == scene and row["method"] == method]


def errors(rows: list[dict]) -> np.ndarray:
    return np.array([float(row["error"]) for row in rows])


def test_quick_benchmark_writes_the_files(quick):
    code, out, _ = quick
    assert code == 0
    names = ["runs.csv", "README.md", "tolerance_proportionality.png", "work_precision.rrd"]
    names += [f"work_precision_{scene}.png" for scene in QUICK_SCENES]
    assert sorted(path.name for path in out.iterdir()) == sorted(names)
    for scene in QUICK_SCENES:
        height, width, _ = matplotlib.image.imread(out / f"work_precision_{scene}.png").shape
        assert width > 800 and height > 600
    readme = (out / "README.md").read_text(encoding="utf-8")
    assert all(f"## {scene}" in readme and f"](work_precision_{scene}.png)" in readme for scene in QUICK_SCENES)
    assert "## What each effect costs" in readme and "| + elastic coupling | 6 |" in readme
    entities = set(RrdReader(out / "work_precision.rrd").store().schema().entity_paths())
    assert {
        "/startup/methods/DOP853",
        "/startup/methods/RK4/points",
        "/engine_direct/methods/co-simulation",
        "/engine_direct/reference_error",
        "/engine_direct/grid",
        "/about",
    } <= entities


def test_csv_has_the_expected_columns_and_one_row_per_run(quick):
    _, out, rows = quick
    with open(out / "runs.csv", newline="", encoding="utf-8") as stream:
        header = next(csv.reader(stream))
    states = [
        "phi_rms_rad",
        "phi_end_rad",
        "omega_rms_rel",
        "omega_end_rel",
        "arm_angle_rms_rel",
        "arm_angle_end_rel",
        "arm_rate_rms_rel",
        "arm_rate_end_rel",
    ]
    assert header == [*CSV_COLUMNS, *states, "message"]
    assert {row["status"] for row in rows} == {"complete"}
    assert {row["method"] for row in rows if row["scene"] == "startup"} == {*ADAPTIVE, "RK4", "energy"}
    assert {row["method"] for row in rows if row["scene"] == "engine_direct"} == {*ADAPTIVE, "RK4", COSIM}
    for row in rows:
        assert float(row["error"]) == float(row["omega_rms_rel"]) > 0.0
        assert float(row["cpu_s"]) > 0.0 and int(row["steps"]) > 0
        assert row["nfev"] == "" if row["method"] == COSIM else int(row["nfev"]) > 0
        assert row["arm_angle_rms_rel"] == ("" if row["scene"] == "startup" else row["arm_angle_rms_rel"])
    assert all(row["reference_error"] == "0" for row in rows if row["scene"] == "startup")  # closed form: exact


@pytest.mark.parametrize("scene", QUICK_SCENES)
def test_dop853_error_falls_as_rtol_tightens_and_stays_resolved(quick, scene):
    """The achieved error falls with every tighter rtol, stays within TOLERANCE_FACTOR of the requested rtol,
    and stays RESOLVED_FACTOR above the disagreement of DOP853 (rtol 1e-13) and Radau (the reference check),
    so the fall measured is DOP853's own."""
    dop853 = runs(quick[2], scene, "DOP853")
    achieved, rtol = errors(dop853), np.array([float(row["value"]) for row in dop853])
    assert np.all(np.diff(rtol) < 0) and np.all(np.diff(achieved) < 0), achieved
    assert np.all(achieved < TOLERANCE_FACTOR * rtol), achieved / rtol
    reference_error = float(dop853[0]["reference_error"])
    assert np.all(achieved > RESOLVED_FACTOR * reference_error) and not any(
        int(row["below_reference"]) for row in dop853
    )
    if scene == "engine_direct":
        assert 0.0 < reference_error < 1e-9  # the check is a real second solution, and a close one


def test_rk4_is_fourth_order_on_startup(quick):
    """Halving the step divides RK4's error by about 2^4 = 16 against the closed form."""
    rk4 = runs(quick[2], "startup", "RK4")
    steps = np.array([float(row["value"]) for row in rk4])
    assert np.allclose(steps[1:] / steps[:-1], 0.5)
    ratios = errors(rk4)[:-1] / errors(rk4)[1:]
    assert np.all((ratios > 12.0) & (ratios < 20.0)), ratios


def test_cosimulation_is_first_order_in_the_exchange_step(quick):
    """Halving the exchange step halves the lockstep co-simulation's error (zero-order hold: first order)."""
    cosim = runs(quick[2], "engine_direct", COSIM)
    steps = np.array([float(row["value"]) for row in cosim])
    assert np.allclose(steps[1:] / steps[:-1], 0.5)
    ratios = errors(cosim)[:-1] / errors(cosim)[1:]
    assert np.all((ratios > 1.6) & (ratios < 2.5)), ratios


def test_closed_form_solves_the_equation_of_motion():
    """The startup reference satisfies J omega' = M0 (1 - omega / omega0) - c omega (the model's right-hand
    side) and phi' = omega, from the scene's initial state; also from a running start."""
    for overrides in ([], ["scenario.initial.omega=40.0", "scenario.initial.phi=1.0"]):
        model = build_model(load_scene("startup", overrides))
        exact = startup_closed_form(model)
        t = np.linspace(0.0, 2.0, 41)
        h = 1e-6
        rates = (exact(t + h) - exact(t - h)) / (2 * h)
        expected = np.array([model.rhs()(ti, yi) for ti, yi in zip(t, exact(t).T)]).T
        assert np.allclose(rates, expected, rtol=1e-7, atol=1e-6)
        assert np.allclose(exact(np.array([0.0]))[:, 0], model.initial_state())


def test_closed_form_refuses_a_machine_it_does_not_describe():
    with pytest.raises(ValueError, match="closed form needs"):
        startup_closed_form(build_model(load_scene("compressor")))


def test_every_reference_scene_loads_with_its_overrides():
    """The table of reference scenes stays valid as the bundled scenes change (both durations)."""
    for bench in SCENES:
        for quick_run in (False, True):
            scene = bench.load(quick_run)
            assert scene.scenario.duration > max((event.time for event in scene.scenario.load_events), default=0.0)


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--scenes", "nosuch"], "no reference scene 'nosuch'"),
        (["--scenes", ","], "expected scene names"),
        (["--jobs", "0"], "--jobs 0"),
    ],
)
def test_bad_options_end_in_a_message_and_exit_2(capsys, tmp_path, argv, message):
    code, _, err = run_cli(capsys, "bench", "accuracy", "--quick", "--out", str(tmp_path), *argv)
    assert code == 2 and message in err
    assert not (tmp_path / "runs.csv").exists()


def test_an_out_that_is_a_file_exits_2(capsys, tmp_path):
    path = write_scene(tmp_path, "not a folder", "taken")
    code, _, err = run_cli(capsys, "bench", "accuracy", "--quick", "--out", str(path))
    assert code == 2 and "expected a folder, and it is a file" in err and str(path) in err


def test_ctrl_c_keeps_the_runs_measured(tmp_path):
    """SIGINT after a few runs: exit 130 and runs.csv with the rows measured so far, no traceback."""
    process = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "mech_regulator",
            "bench",
            "accuracy",
            "--quick",
            "--scenes",
            "startup,engine_direct",
            "--out",
            str(tmp_path),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=Path(__file__).resolve().parents[1],
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    lines = [process.stdout.readline() for _ in range(4)]
    process.send_signal(signal.SIGINT)
    out, err = process.communicate(timeout=60)
    assert process.returncode == 130, err
    assert "Traceback" not in err and "interrupted" in err
    with open(tmp_path / "runs.csv", newline="", encoding="utf-8") as stream:
        rows = list(csv.DictReader(stream))
    assert 1 <= len(rows) < 42, lines  # 42 runs in all: it stopped early
    assert not (tmp_path / "README.md").exists()


def test_ctrl_c_while_the_parent_works_stops_the_workers_at_the_next_measurement():
    """Ctrl-C only marks the interrupt while the workers measure (never a KeyboardInterrupt inside the pool's own
    locks, which could leave terminate() waiting for ever); it is raised when the next measurement is asked for,
    and Ctrl-C is what it was before again afterwards (Python's here: a pytest started as a background job of a
    script inherits an ignored SIGINT, so the test sets Python's handler first)."""
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        tasks = [Task("startup", True, Setting("RK45", rtol)) for rtol in (1e-3, 1e-4, 1e-5, 1e-6)]
        measurements = _measured(tasks, 2)
        assert next(measurements).task in tasks
        os.kill(os.getpid(), signal.SIGINT)  # as if pressed while the parent adds the measurement
        with pytest.raises(KeyboardInterrupt):
            next(measurements)
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    finally:
        signal.signal(signal.SIGINT, before)


def test_the_measurement_imports_neither_rerun_nor_matplotlib_nor_rclpy():
    script = (
        "import sys; import mech_regulator.bench.accuracy, mech_regulator.bench.report; "
        "print(sorted({name.split('.')[0] for name in sys.modules} & {'rerun', 'matplotlib', 'rclpy'}))"
    )
    found = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True).stdout.strip()
    assert found == "[]"


def test_workers_stopped_while_sending_a_measurement_leave_nothing_behind(monkeypatch):
    """Stopped while a worker is in the middle of sending a measurement larger than a pipe's buffer (every real one
    is: 160-340 kB), the benchmark neither waits for it nor leaves a worker running: each worker has a pipe of its own
    (multiprocessing.Pool's terminate() once waited for ever on its shared result queue's write lock, held by such a
    worker)."""
    size = 4_000_000  # [B] some 60 pipe buffers
    monkeypatch.setattr(accuracy, "measure", lambda task: bytes(size))  # (the workers are forked with it)
    tasks = [Task("startup", True, Setting("RK45", rtol)) for rtol in (1e-3, 1e-4, 1e-5)]
    before = set(multiprocessing.active_children())
    measurements = _measured(tasks, 2)
    assert len(next(measurements)) == size  # the other worker's measurement unread: it is blocked sending it
    workers = set(multiprocessing.active_children()) - before
    measurements.close()
    assert len(workers) == 2 and not any(worker.is_alive() for worker in workers), workers


def _raises(task: Task):
    raise ValueError(f"no such setting: {task.setting.value}")


def _ends(task: Task):
    os._exit(3)


@pytest.mark.parametrize(
    "measure, error, message",
    [(_raises, ValueError, "no such setting: 0.001"), (_ends, RuntimeError, "ended while measuring (exit code 3)")],
)
def test_a_worker_s_error_or_end_is_raised_in_the_parent(monkeypatch, measure, error, message):
    monkeypatch.setattr(accuracy, "measure", measure)
    with pytest.raises(error, match=re.escape(message)):
        next(_measured([Task("startup", True, Setting("RK45", 1e-3))] * 2, 2))
