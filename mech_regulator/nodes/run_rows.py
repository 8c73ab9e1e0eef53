"""The recorder's store of a run's exchanges (nodes/recorder.py), kept so that its memory does not grow with the run
(docs/ros.md, "The recorder's memory").

Each exchange comes in parts, one stream each: the machine's state and moments (machine/moments) and, with a
governor, the governor's state (governor/state). An exchange whose parts are all in is complete; once its throttle is
settled too (with_throttle_until: after an overspeed trip the throttle is 0), its row goes to the run's CSV and, as
raw doubles, to a spool file on disk, and leaves memory. What memory holds is the parts not yet written (about the
second of wall time between two writes) and a few counters. At the end the spool gives the run back
(RunRows.cosimulation) for the summary and the bag; the CSV, written in pieces as the run goes, is byte for byte the
one a single write_csv of the whole run writes (each row is formatted on its own), so that the rows written stay on
a Ctrl-C or a failure.

A stream's parts come in the order of their times, each time once (recorder.unrecorded): a part older than the newest
of the other stream that has not completed an exchange never will, and is dropped when a later row is written, as a
run's incomplete exchanges always were. Free of rclpy.
"""

from __future__ import annotations

import contextlib
import errno
import math
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import IO

import numpy as np

from mech_regulator.cli.report.data import write_csv_rows
from mech_regulator.model import MachineModel
from mech_regulator.solvers.cosim import CoSimulation, seconds

MACHINE, GOVERNOR = "machine", "governor"  # the streams an exchange's parts come on

# guard(what, path, write): write(), True when it wrote; False after saying why it could not (recorder._write)
Guard = Callable[[str, "Path | None", Callable[[], None]], bool]


class RunRows:
    """The exchanges of one trial of a run (module docstring): `model` the scene's MachineModel, `external_throttle`
    whether the throttle comes from outside (the recorder's controller external: the machine's applied throttle,
    also a CSV column), `csv_path` the CSV to write (None: none), `spool_folder` where the spool goes (next to the
    recording, so on the disk the outputs go to; None: the system's temporary folder), `guard` the recorder's
    writer of an output that may fail (a full disk: the CSV stops there, the rows written stay), `say` a line for the
    log (the spool failed: the rows are kept in memory from then on)."""

    def __init__(
        self,
        model: MachineModel,
        external_throttle: bool,
        csv_path: Path | None,
        spool_folder: Path | None,
        guard: Guard,
        say: Callable[[str], object],
    ):
        self.model, self.external_throttle, self.csv_path = model, external_throttle, csv_path
        self.spool_folder, self.guard, self.say = spool_folder, guard, say
        self.governed = model.governor is not None
        self.governor_states = tuple(model.governor.state_names) if model.governor is not None else ()
        self.machine: dict[int, tuple[list[float], float, float]] = {}  # [ns] -> (the machine's state as
        # MachineModel.state_names without the governor's, the external load [N m], the applied throttle [-]); not
        # yet written
        self.governor: dict[int, dict[str, float]] = {}  # [ns] -> the governor's values by name; not yet written
        self.newest: dict[str, int | None] = {MACHINE: None, GOVERNOR: None}  # [ns] each stream's newest part
        self.received = {MACHINE: 0, GOVERNOR: 0}  # parts received on each stream
        self.first_machine: int | None = None  # [ns] the machine's first part
        self.completed = 0  # complete exchanges
        self.completed_until: int | None = None  # [ns] the newest complete exchange
        self.ready: list[int] = []  # [ns] complete exchanges not yet written, in the order of their times
        self.written = 0  # rows written
        self.csv: IO[str] | None = None  # open from the first rows on
        self.csv_failed = csv_path is None  # (no CSV, or it could not be written: no more rows go there)
        self.width = 3 + len(model.state_names())  # a row: t [s], the state, the throttle [-], the external load [N m]
        self.spool: IO[bytes] | None = None  # the rows, raw doubles; open from the first rows on
        self.spooled = 0  # rows in the spool
        self.kept: list[np.ndarray] = []  # rows the spool could not take (it failed): kept in memory

    def add_machines(
        self, times: np.ndarray, states: np.ndarray, external_loads: np.ndarray, throttles: np.ndarray
    ) -> None:
        """The machine's parts of the exchanges at `times` [ns] (in order, after its newest): at each, its state
        (a row of `states`: MachineModel.state_names without the governor's), the external load [N m] and the
        throttle it applied [-]."""
        when = times.tolist()
        self.machine.update(zip(when, zip(states.tolist(), external_loads.tolist(), throttles.tolist())))
        self.first_machine = when[0] if self.first_machine is None and when else self.first_machine
        self._arrived(MACHINE, when)

    def add_governors(self, times: np.ndarray, values: dict[str, np.ndarray]) -> None:
        """The governor's parts of the exchanges at `times` [ns] (in order, after its newest): its values by name
        (its states and its throttle), each an array over the times."""
        names, columns = list(values), [column.tolist() for column in values.values()]
        when = times.tolist()
        self.governor.update(zip(when, (dict(zip(names, row)) for row in zip(*columns))))
        self._arrived(GOVERNOR, when)

    def _arrived(self, stream: str, times: list[int]) -> None:
        """Parts came on `stream` at `times` [ns] (in order): the exchange at each is complete once the machine's part
        and (with a governor) the governor's are in. Exchanges complete in the order of their times: each stream's
        parts come in that order."""
        if not times:
            return
        self.newest[stream] = times[-1]
        self.received[stream] += len(times)
        complete = [when for when in times if when in self.machine and (not self.governed or when in self.governor)]
        if complete:
            self.completed += len(complete)
            self.completed_until = complete[-1]
            self.ready += complete

    def received_until(self, stream: str, when: int) -> bool:
        """Whether `stream` has brought its part of the exchange at `when` [ns] or a later one (the governor's stream
        of a scene without a governor always has)."""
        newest = self.newest[stream]
        return (stream == GOVERNOR and not self.governed) or (newest is not None and newest >= when)

    def write(self, with_throttle_until: float, tripped_at: float | None) -> None:
        """Write the complete exchanges up to `with_throttle_until` [s] (math.inf: all) to the CSV and the spool, and
        forget them and every part before them. The throttle of each: the machine's applied one when it comes from
        outside, else 0 from `tripped_at` [s] (the overspeed trip, None: none) on, else the governor's (1 without a
        governor); so an exchange is written once the machine has said whether it had tripped by then."""
        count = 0
        while count < len(self.ready) and seconds(self.ready[count]) <= with_throttle_until:
            count += 1
        if count == 0:
            return
        times, self.ready = self.ready[:count], self.ready[count:]
        tripped = tripped_at if tripped_at is not None else math.inf
        rows = np.empty((count, self.width))
        for index, when in enumerate(times):
            state, external_load, applied = self.machine[when]
            governor = self.governor.get(when, {})
            throttle = (
                applied
                if self.external_throttle
                else 0.0
                if seconds(when) >= tripped
                else governor["throttle"]
                if self.governed
                else 1.0
            )
            full_state = state[:2] + [governor[name] for name in self.governor_states] + state[2:]
            rows[index] = [seconds(when), *full_state, throttle, external_load]
        for parts in (self.machine, self.governor):
            for when in [when for when in parts if when <= times[-1]]:
                del parts[when]
        self._spool(rows)
        if not self.csv_failed:
            self.csv_failed = not self.guard("CSV", self.csv_path, lambda: self._append_csv(rows))
        self.written += count

    def _append_csv(self, rows: np.ndarray) -> None:
        """Append `rows` (the spool's layout) to the CSV as the model's columns, after the header (at the first)."""
        if self.csv is None:
            assert self.csv_path is not None, "_append_csv writes to the CSV the rows were given"
            self.csv = open(self.csv_path, "w", encoding="utf-8")  # noqa: SIM115 (open for the run's length)
        times, states, throttle, external_load = unpack(rows)
        columns = self.model.columns(times, states, throttle, external_load)
        if self.external_throttle:
            columns["throttle"] = throttle
        write_csv_rows(self.csv, columns, digits=17, header=self.written == 0)
        self.csv.flush()  # on disk, should the recorder be killed

    def _spool(self, rows: np.ndarray) -> None:
        """Append `rows` to the spool (a temporary file without a name, gone with the process, opened at the first
        rows), or keep them in memory once it failed (said once; the rows it holds whole are read back)."""
        if not self.kept:
            try:
                if self.spool is None:  # unbuffered: a failed write leaves nothing behind to write again
                    self.spool = tempfile.TemporaryFile(dir=self.spool_folder, buffering=0)  # noqa: SIM115
                data = rows.tobytes()
                if self.spool.write(data) != len(data):
                    raise OSError(errno.ENOSPC, "the disk took part of the rows only")
                self.spooled += rows.shape[0]
                return
            except OSError as error:
                self.say(
                    f"the spool of the samples in '{self.spool_folder or tempfile.gettempdir()}' failed: "
                    f"{error.strerror or error}; the samples from t = {rows[0, 0]:.6g} s on are kept in memory"
                )
        self.kept.append(rows)

    def cosimulation(self, events: list, tripped_at: float | None) -> CoSimulation | None:
        """The rows written, read back, as the core's CoSimulation (status complete; `events` the governor's mode
        changes, `tripped_at` [s] the trip); None before the first row."""
        blocks = []
        if self.spool is not None and self.spooled:
            self.spool.seek(0)
            spooled = np.fromfile(self.spool, count=self.spooled * self.width)  # the rows whole (a failed write: after)
            self.spool.seek(0, 2)
            blocks.append(spooled.reshape(self.spooled, self.width))
        blocks += self.kept
        if not blocks:
            return None
        times, states, throttle, external_load = unpack(np.concatenate(blocks))
        return CoSimulation(
            times=times,
            states=states,
            throttle=throttle,
            external_load=external_load,
            events=events,
            status="complete",
            message="",
            tripped_at=tripped_at,
        )

    def close(self) -> None:
        """Close the CSV (a failure to write it was said already) and the spool (its file goes away)."""
        for stream in (self.csv, self.spool):
            if stream is not None:
                with contextlib.suppress(OSError):
                    stream.close()
        self.csv = self.spool = None


def unpack(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The times [s], states (n_states x n), throttle [-] and external load [N m] of rows in the spool's layout."""
    return rows[:, 0].copy(), rows[:, 1:-2].T.copy(), rows[:, -2].copy(), rows[:, -1].copy()
