"""Sweeps (docs/sweep.md): the grid syntax and its messages, rows equal to single runs on every executor (in process,
local processes, a Dask local cluster, a Dask scheduler address), a failing point as a row, Ctrl-C, the stability
verdict by simulation against Vyshnegradsky's A B = 1, and the flywheel's delta against the energy-swing formula.

Tiny grids and short durations keep the CPU small; the lathe runs take a few hundredths of a second each.
"""

from __future__ import annotations

import csv
import math
import sys

import numpy as np
import pytest
from support import run_cli, write_scene

import mech_regulator.analysis.sweep as sweep_module
from mech_regulator.analysis import energy_swing
from mech_regulator.analysis.sweep import parse_grid, run_point, run_sweep, sweep_points
from mech_regulator.cli.sweep import _unit_of
from mech_regulator.model import build_model
from mech_regulator.scene import SceneError, validate_scene
from mech_regulator.solvers import simulate

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
LATHE_SHORT = ["scenario.duration=1.0"]
COMPARED = ("status", "t_end", "omega_end", "steady", "omega_m", "omega_average", "delta", "rhs_evaluations")


def lathe_points(values: str = "4,15.453292519943295,40", *overrides: str):
    return sweep_points(["lathe"], [*LATHE_SHORT, *overrides], [parse_grid(f"machine.flywheel.inertia={values}")])


def same_rows(rows: list[dict], expected: list[dict]) -> None:
    """Equal rows but for the wall time: the same scenes, grid values and numbers, bit for bit."""
    assert [{key: row[key] for key in ("scene", "machine.flywheel.inertia", *COMPARED)} for row in rows] == [
        {key: row[key] for key in ("scene", "machine.flywheel.inertia", *COMPARED)} for row in expected
    ]


# ----------------------------------------------------------------------------------------------
# the grid


def test_grid_linear_geometric_and_list():
    linear = parse_grid("governor.damping=0:100:5")
    assert linear.values == (0.0, 25.0, 50.0, 75.0, 100.0) and not linear.geometric
    geometric = parse_grid("machine.flywheel.inertia=0.01:10:4:log")
    assert geometric.geometric
    assert geometric.values == pytest.approx((0.01, 0.1, 1.0, 10.0), rel=1e-12)
    listed = parse_grid("solver.method = RK45, DOP853")
    assert (listed.key, listed.values) == ("solver.method", ("RK45", "DOP853"))
    assert parse_grid("machine.loads.0.coefficient=1e-3,2").values == (1e-3, 2)
    assert parse_grid("governor.damping=7:9:1").values == (7.0,)


@pytest.mark.parametrize(
    "description, unit",
    [("crank speed [rad/s]", "[rad/s]"), ("a count", ""), ("a [m] side note", ""), ("ratio [-] of [N m]", "[N m]")],
)
def test_the_plot_takes_the_unit_that_ends_a_keys_description(description, unit):
    assert _unit_of(description) == unit


def test_grid_cartesian_product_sets_the_scene_keys():
    axes = [parse_grid("machine.flywheel.inertia=4,8"), parse_grid("machine.drive.torque=80:90:3")]
    points = sweep_points(["lathe"], LATHE_SHORT, axes)
    assert [tuple(point.values.values()) for point in points] == [
        (4, 80.0),
        (4, 85.0),
        (4, 90.0),
        (8, 80.0),
        (8, 85.0),
        (8, 90.0),
    ]
    for point in points:
        assert point.scene["machine"]["flywheel"]["inertia"] == point.values["machine.flywheel.inertia"]
        assert point.scene["machine"]["drive"]["torque"] == point.values["machine.drive.torque"]
        assert point.scene["scenario"]["duration"] == 1.0


@pytest.mark.parametrize(
    "grid, expected",
    [
        ("machine.flywheel.inertia", ["--grid 'machine.flywheel.inertia'", "expected KEY=START:STOP:N"]),
        ("machine.flywheel.inertia=1:2:0", ["N = '0'", "whole number of values >= 1"]),
        ("machine.flywheel.inertia=1:2:two", ["N = 'two'"]),
        ("machine.flywheel.inertia=a:2:3", ["START and STOP must be numbers", "'a'"]),
        ("machine.flywheel.inertia=0:2:3:log", ["geometric (log) grid needs START > 0"]),
        ("machine.flywheel.inertia=1:2:3:lin", ["expected START:STOP:N or START:STOP:N:log"]),
        (
            "machine.flywheel.inertai=1,2",
            ["--grid 'machine.flywheel.inertai=1,2'", "inertai: unknown key", "did you mean 'inertia'"],
        ),
        (
            "machine.flywheel.inertia=5,-1",
            [
                "--grid 'machine.flywheel.inertia=5,-1'",
                "machine.flywheel.inertia = -1: input",
                "greater than or equal to 0",
            ],
        ),
        ("machine.loads.3.torque=1,2", ["--grid 'machine.loads.3.torque=1,2'", "must index the list (0 to 0)"]),
        ("machine.flywheel.inertia=1,,2", ["an empty value in the list"]),
    ],
)
def test_bad_grid_is_a_clear_message_before_anything_runs(capsys, tmp_path, grid, expected):
    out = tmp_path / "sweep"
    code, stdout, stderr = run_cli(capsys, "sweep", "lathe", "--grid", grid, "--out", str(out), "--quiet")
    assert code == 2
    for fragment in expected:
        assert fragment in stderr
    assert not out.exists()  # refused before the output folder, let alone a run


@pytest.mark.parametrize(
    "argv, expected",
    [
        (["--grid", "machine.flywheel.inertia=1,2", "--grid", "machine.flywheel.inertia=3"], "given more than once"),
        (["--jobs", "0"], "--jobs 0: expected at least 1"),
        (["--scheduler", "tcp://127.0.0.1:1"], "needs --engine dask"),
    ],
)
def test_bad_sweep_options(capsys, tmp_path, argv, expected):
    code, _, stderr = run_cli(capsys, "sweep", "lathe", *argv, "--out", str(tmp_path / "out"), "--quiet")
    assert code == 2 and expected in stderr
    assert not (tmp_path / "out").exists()


def test_sweep_needs_a_scene(capsys):
    code, _, stderr = run_cli(capsys, "sweep", "--grid", "machine.flywheel.inertia=1,2")
    assert code == 2 and "give a SCENE or --scenes" in stderr


# ----------------------------------------------------------------------------------------------
# the rows are the single runs, on every executor


@pytest.fixture(scope="module")
def single_runs() -> list[dict]:
    """The lathe points run one by one in this process, without the sweep's executors."""
    return [run_point(point.scene, point.values) for point in lathe_points()]


def test_a_row_is_the_single_run(single_runs):
    point = lathe_points()[1]
    trajectory = simulate(build_model(validate_scene(point.scene)))
    assert single_runs[1]["omega_end"] == float(trajectory(trajectory.t_end)[1])
    assert single_runs[1]["rhs_evaluations"] == trajectory.stats.nfev
    assert single_runs[1]["status"] == "complete" and single_runs[1]["t_end"] == 1.0
    assert [row["machine.flywheel.inertia"] for row in single_runs] == [4, 15.453292519943295, 40]


@pytest.mark.parametrize("jobs", [1, 2])
def test_local_rows_equal_single_runs_in_point_order(single_runs, jobs):
    points = lathe_points()
    completed = []
    rows = run_sweep(points, jobs=jobs, progress=lambda point, row: completed.append(point))
    same_rows(rows, single_runs)
    assert sorted(completed, key=points.index) == points  # each point reported once, in whatever order


def test_a_failing_point_is_a_row_and_the_others_run(capsys, tmp_path):
    """The energy method refuses a negative initial speed at run time: that point's row says so."""
    out = tmp_path / "failing"
    code, stdout, stderr = run_cli(
        capsys,
        "sweep",
        "lathe",
        "--set",
        "solver.method=energy",
        "--set",
        "scenario.duration=0.5",
        "--grid",
        "scenario.initial.omega=15.15,-1,15",
        "--jobs",
        "1",
        "--out",
        str(out),
        "--quiet",
    )
    assert code == 0, stderr
    with (out / "sweep.csv").open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert [row["status"] for row in rows] == ["complete", "failed", "complete"]
    assert "initial omega = -1" in rows[1]["message"] and rows[1]["omega_end"] == ""
    assert float(rows[2]["omega_end"]) > 14.0
    assert "scenario.initial.omega=-1: failed" in stderr


def test_a_point_the_model_refuses_is_a_row():
    row = run_point({"name": "broken", "machine": {"inertia": 1.0}, "scenario": {"duration": -1}}, {"x": 1})
    assert row["status"] == "refused" and "scenario.duration" in row["message"] and row["x"] == 1


def test_ctrl_c_keeps_the_finished_rows(capsys, tmp_path, monkeypatch):
    """The second point is interrupted: the first is in sweep.csv, the others are 'not run', exit 130."""
    real_run_point = sweep_module.run_point
    calls = []

    def interrupted(scene, values):
        calls.append(values)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real_run_point(scene, values)

    monkeypatch.setattr(sweep_module, "run_point", interrupted)
    out = tmp_path / "interrupted"
    code, stdout, stderr = run_cli(
        capsys,
        "sweep",
        "lathe",
        "--set",
        "scenario.duration=0.5",
        "--grid",
        "machine.flywheel.inertia=4,8,16",
        "--jobs",
        "1",
        "--out",
        str(out),
        "--quiet",
    )
    assert code == 130 and "interrupted" in stderr
    with (out / "sweep.csv").open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert [row["status"] for row in rows] == ["complete", "not run", "not run"]
    assert float(rows[0]["omega_end"]) > 14.0


# ----------------------------------------------------------------------------------------------
# Dask


@pytest.fixture(scope="module")
def dask_cluster():
    """A Dask LocalCluster of one worker process, started by the test (as a user starts `dask scheduler`)."""
    distributed = pytest.importorskip(
        "dask.distributed", reason="the Dask tests need dask[distributed] (pip install 'mech_regulator[distributed]')"
    )
    cluster = distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None)
    yield cluster
    cluster.close()


def test_dask_local_cluster_gives_the_local_rows(single_runs):
    pytest.importorskip(
        "dask.distributed", reason="the Dask tests need dask[distributed] (pip install 'mech_regulator[distributed]')"
    )
    same_rows(run_sweep(lathe_points(), jobs=2, engine="dask"), single_runs)


def test_dask_scheduler_address_gives_the_local_rows(single_runs, dask_cluster, capsys, tmp_path):
    same_rows(run_sweep(lathe_points(), engine="dask", scheduler=dask_cluster.scheduler_address), single_runs)
    out = tmp_path / "dask"
    code, stdout, stderr = run_cli(
        capsys,
        "sweep",
        "lathe",
        "--set",
        "scenario.duration=1.0",
        "--grid",
        "machine.flywheel.inertia=4,15.453292519943295,40",
        "--engine",
        "dask",
        "--scheduler",
        dask_cluster.scheduler_address,
        "--path",
        "reference",
        "--out",
        str(out),
        "--quiet",
    )
    assert code == 0, stderr
    assert f"on a Dask cluster at {dask_cluster.scheduler_address}" in stdout
    with (out / "sweep.csv").open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert [float(row["omega_end"]) for row in rows] == [row["omega_end"] for row in single_runs]


def test_dask_scheduler_that_does_not_answer(capsys, tmp_path):
    pytest.importorskip("dask.distributed", reason="the Dask tests need dask[distributed]")
    code, _, stderr = run_cli(
        capsys,
        "sweep",
        "lathe",
        "--engine",
        "dask",
        "--scheduler",
        "tcp://127.0.0.1:9",
        "--out",
        str(tmp_path / "none"),
        "--quiet",
    )
    assert code == 2 and "--scheduler tcp://127.0.0.1:9: no Dask scheduler answers there" in stderr


def test_without_dask_the_message_gives_the_pip_command(capsys, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "dask.distributed", None)  # import dask.distributed now fails
    code, _, stderr = run_cli(capsys, "sweep", "lathe", "--engine", "dask", "--out", str(tmp_path / "none"), "--quiet")
    assert code == 2 and "--engine dask needs Dask distributed: pip install 'mech_regulator[distributed]'" in stderr


# ----------------------------------------------------------------------------------------------
# physics


def test_stability_by_simulation_agrees_with_vyshnegradsky_away_from_the_boundary():
    """engine_direct (critical sleeve damping ~57 N s/m at 8 N m) with 10 and 300 N s/m: the oscillation after the
    load step grows into the sleeve's stops / decays, as A B < 1 / A B > 1 predicts."""
    points = sweep_points(
        ["engine_direct"],
        [
            "scenario.duration=4.5",
            "scenario.load_events=[{time: 0.5, torque: 8}]",
            "solver.rtol=1e-6",
            "solver.atol=1e-8",
        ],
        [parse_grid("governor.damping=10,300")],
    )
    little, plenty = run_sweep(points, jobs=2)
    for row in (little, plenty):
        assert row["status"] == "complete", row["message"]
    assert little["vyshnegradsky_A"] * little["vyshnegradsky_B"] < 0.5
    assert plenty["vyshnegradsky_A"] * plenty["vyshnegradsky_B"] > 4.0
    assert (little["stable_linear"], little["stable_by_simulation"]) == (False, False)
    assert (plenty["stable_linear"], plenty["stable_by_simulation"]) == (True, True)
    assert little["oscillation_ratio"] > 0.95 and plenty["oscillation_ratio"] < 0.75


def test_flywheel_sweep_delta_falls_with_inertia_as_the_energy_swing_says(capsys, tmp_path):
    """lathe (constant J, source 000): delta falls with the flywheel; for constant J the energy swing gives
    omega_max^2 - omega_min^2 = 2 dE_max / J, i.e. delta = dE_max / (J omega_m^2) exactly (pi F r / 4 = 78.54 J)."""
    out = tmp_path / "flywheel"
    code, stdout, stderr = run_cli(
        capsys,
        "sweep",
        "lathe",
        "--set",
        "scenario.duration=2.0",
        "--grid",
        "machine.flywheel.inertia=2:60:4:log",
        "--out",
        str(out),
        "--quiet",
    )
    assert code == 0, stderr
    with (out / "sweep.csv").open(newline="") as handle:
        reader = csv.DictReader(handle)
        rows = list(reader)
    assert reader.fieldnames[:4] == ["scene", "machine.flywheel.inertia", "status", "message"]
    assert {"omega_end", "omega_m", "delta", "steady", "wall_time", "rhs_evaluations"} <= set(reader.fieldnames)
    assert (out / "sweep.png").read_bytes()[:8] == PNG_SIGNATURE
    assert "4 of 4 points" in stdout and f"wrote {out / 'sweep.png'}" in stdout
    delta = np.array([float(row["delta"]) for row in rows])
    assert np.all(np.diff(delta) < 0.0)
    for row in rows:
        point = sweep_points(["lathe"], [f"machine.flywheel.inertia={row['machine.flywheel.inertia']}"], [])[0]
        model = build_model(validate_scene(point.scene))
        omega_m = float(row["omega_m"])
        swing = np.ptp(energy_swing(model, omega_m)[1])
        assert swing == pytest.approx(math.pi * 100.0 / 4.0, rel=1e-9)
        inertia = model.inertia(0.0)[0]
        assert inertia == pytest.approx(2.0 + float(row["machine.flywheel.inertia"]), rel=1e-12)
        assert float(row["delta"]) == pytest.approx(swing / (inertia * omega_m**2), rel=1e-4)


def test_a_list_of_scenes(capsys, tmp_path):
    out = tmp_path / "scenes"
    code, stdout, stderr = run_cli(
        capsys,
        "sweep",
        "--scenes",
        "lathe",
        "startup",
        "--set",
        "scenario.duration=0.5",
        "--jobs",
        "1",
        "--out",
        str(out),
        "--quiet",
    )
    assert code == 0, stderr
    with (out / "sweep.csv").open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert [(row["scene"], row["status"]) for row in rows] == [("lathe", "complete"), ("startup", "complete")]
    assert (out / "sweep.png").read_bytes()[:8] == PNG_SIGNATURE


def test_fast_path_by_default_where_the_scene_compiles(capsys, tmp_path, single_runs):
    out = tmp_path / "paths"
    # every machine compiles; a solver method without a compiled stepper stays on the reference path
    lsoda = write_scene(tmp_path, "name: lathe_lsoda\nbase: lathe\nsolver: {method: LSODA}\n", "lathe_lsoda.yaml")
    code, stdout, stderr = run_cli(
        capsys,
        "sweep",
        "--scenes",
        "lathe",
        str(lsoda),
        "--set",
        "scenario.duration=1.0",
        "--grid",
        "machine.flywheel.inertia=15.453292519943295",
        "--jobs",
        "1",
        "--out",
        str(out),
        "--quiet",
    )
    assert code == 0, stderr
    with (out / "sweep.csv").open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    # LSODA is not compiled: that scene runs on the reference path, and the row says so
    assert [(row["scene"], row["status"], row["path"]) for row in rows] == [
        ("lathe", "complete", "fast"),
        ("lathe_lsoda", "complete", "reference"),
    ]
    assert float(rows[0]["omega_end"]) == pytest.approx(single_runs[1]["omega_end"], rel=1e-9)
    assert single_runs[1]["path"] == "reference"


def test_scene_refused_before_running(capsys, tmp_path):
    with pytest.raises(SceneError, match="no such file, nor a bundled scene"):
        sweep_points(["no_such_scene"], [], [])
