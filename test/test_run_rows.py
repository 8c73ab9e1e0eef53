"""The recorder's store of a run's exchanges (nodes/run_rows.py), without ROS: fed the parts of an in-process
co-simulation as the recorder's callbacks feed them, it writes the CSV in pieces byte for byte as one write_csv of
the whole run, gives the run back exactly from its spool, holds no written exchange in memory, writes an exchange
only once its throttle is settled (an overspeed trip) and drops an exchange that never completed.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from mech_regulator.cli.report.data import write_csv
from mech_regulator.model import build_model
from mech_regulator.nodes.run_rows import RunRows
from mech_regulator.scene import load_scene
from mech_regulator.solvers.cosim import cosimulate, seconds, to_nanoseconds

EXCHANGE_STEP = 0.02  # [s] engine_direct's


@pytest.fixture(scope="module")
def engine_run():
    """engine_direct co-simulated in process over 0.6 s (reference path): (model, CoSimulation)."""
    model = build_model(load_scene("engine_direct", ["solver.path=reference"]))
    scenario = model.scene.scenario.model_copy(update={"duration": 0.6})
    shortened = dataclasses.replace(model, scene=model.scene.model_copy(update={"scenario": scenario}))
    return shortened, cosimulate(shortened, EXCHANGE_STEP)


def guarded(what: str, path: Path | None, write) -> bool:
    """The recorder's _write, for a disk that never fails."""
    write()
    return True


def feed(rows: RunRows, model, run, indices, skip_governor: int | None = None, batch: int = 1) -> None:
    """The parts of the exchanges `indices` of `run`, `batch` exchanges at a time as the recorder's batches bring them:
    the machine's, then the governor's (but at `skip_governor`)."""
    governor_names = list(model.governor.state_names)
    indices = list(indices)
    for start in range(0, len(indices), batch):
        taken = np.array(indices[start : start + batch])
        times = np.array([to_nanoseconds(run.times[index]) for index in taken], dtype=np.int64)
        states = run.states[:, taken].T
        machine = np.column_stack([states[:, :2], states[:, 2 + len(governor_names) :]])
        rows.add_machines(times, machine, run.external_load[taken], np.full(taken.size, 0.5))
        answered = taken != skip_governor
        values = {name: states[answered, 2 + column] for column, name in enumerate(governor_names)}
        rows.add_governors(times[answered], {**values, "throttle": run.throttle[taken][answered]})


@pytest.mark.parametrize("batch", [1, 7])  # one by one, and in batches (the last one shorter)
def test_rows_written_in_pieces_make_the_csv_of_the_whole_run(engine_run, tmp_path, batch):
    model, run = engine_run
    csv = tmp_path / "run.csv"
    rows = RunRows(model, False, csv, tmp_path, guarded, print)
    count = run.times.size
    feed(rows, model, run, range(0, 10), batch=batch)
    rows.write(seconds(to_nanoseconds(run.times[6])), None)  # the machine said it had not tripped by then
    assert rows.written == 7 and sorted(rows.machine) == sorted(rows.governor) == rows.ready  # 7 to 9 kept
    assert csv.read_text().count("\n") == 8  # the header and the rows written, on disk
    feed(rows, model, run, range(10, count), batch=batch)
    rows.write(-np.inf, None)  # nothing settled: nothing written
    assert rows.written == 7
    rows.write(np.inf, None)
    assert rows.written == count and not rows.machine and not rows.governor and not rows.ready
    back = rows.cosimulation(run.events, None)
    rows.close()
    assert back is not None
    for name in ("times", "states", "throttle", "external_load"):
        np.testing.assert_array_equal(getattr(back, name), getattr(run, name), err_msg=name)
    whole = tmp_path / "whole.csv"
    write_csv(whole, model.columns(run.times, run.states, run.throttle, run.external_load), digits=17)
    assert csv.read_bytes() == whole.read_bytes()
    assert sorted(path.name for path in tmp_path.iterdir()) == ["run.csv", "whole.csv"]  # the spool had no name


@pytest.mark.parametrize("batch", [1, 7])
def test_the_throttle_is_closed_from_the_trip_and_an_incomplete_exchange_is_dropped(engine_run, tmp_path, batch):
    model, run = engine_run
    rows = RunRows(model, False, None, None, guarded, print)
    feed(rows, model, run, range(run.times.size), skip_governor=3, batch=batch)
    tripped_at = float(run.times[20])
    rows.write(np.inf, tripped_at)
    back = rows.cosimulation([], tripped_at)
    rows.close()
    assert back is not None and rows.completed == run.times.size - 1
    kept = np.arange(run.times.size) != 3
    np.testing.assert_array_equal(back.times, run.times[kept])
    np.testing.assert_array_equal(back.states, run.states[:, kept])
    expected = np.where(run.times >= tripped_at, 0.0, run.throttle)[kept]
    np.testing.assert_array_equal(back.throttle, expected)
    assert back.throttle[19] == 0.0 < back.throttle[18]  # (index 19 of the rows is exchange 20: one dropped)


def test_an_outside_throttle_is_the_machines_and_a_failed_spool_keeps_the_rows(engine_run, tmp_path):
    model, run = engine_run
    said = []
    rows = RunRows(model, True, None, tmp_path / "gone", guarded, said.append)  # a folder that is not there
    feed(rows, model, run, range(5))
    rows.write(np.inf, None)
    back = rows.cosimulation([], None)
    assert back is not None and len(said) == 1 and "kept in memory" in said[0] and "gone" in said[0]
    np.testing.assert_array_equal(back.throttle, 0.5)  # what the machine applied
    np.testing.assert_array_equal(back.times, run.times[:5])
