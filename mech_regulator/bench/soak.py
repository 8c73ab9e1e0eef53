"""The soak benchmark (`mech-regulator bench soak`): the main job, `mech-regulator run` (the ROS nodes, docs/ros.md),
played for a long simulated time (an hour by default) as a subprocess, watched from outside without touching it.

What is read, and where from:

- memory: the resident set size (RSS, psutil) of the launcher (the `run` process) and of each node process it forks,
  each named by the name the launcher gives it (`<name>_node`, nodes/launch.py): machine, governor, scenario,
  recorder, launcher. Read at every row, and at every progress line of the run for the figures at its start (the
  first line: the nodes exchanging) and at its end (the last line, each process's last reading).
- pace: the launcher's own progress lines (cli/report/terminal.py ProgressLines, the lines it prints when stderr is not a
  terminal: the machine's simulated time from its /diagnostics, which it publishes about once a second of wall time;
  MECH_REGULATOR_PROGRESS_INTERVAL=0 so that the launcher prints each one), each timed as it arrives. Over each
  interval: simulated seconds per second of wall time (the real-time factor) and exchanges per second (simulated time
  over the exchange step the launcher announces; lockstep: one exchange per step). An interval shorter than the
  machine's one second between reports reads 0 when no report fell in it. Over the whole run: the run's summary (the
  recorder's JSON: exchanges, and the wall time between the first and the last exchange).
- energy: `run`'s summary has no energy balance (the nodes keep no dense output), so at the end it is computed from
  the CSV the recorder writes (the state, its rates and the moments at every exchange): the works of the moments
  (analysis.energy.powers) over each exchange step by Gauss-Legendre quadrature along the motion rebuilt between the
  samples (cubic Hermite: the samples hold each state's rate), against the change of the stored energy (E_kinetic,
  plus E_elastic with a coupling), over the whole run and over its first and last tenth of simulated time. The
  residual is then mostly the rebuilt path's error within a step (about 1e-4 of the work on engine_direct at 20 ms,
  where the trapezoid rule on the samples alone is off by 0.65 %), far above the machine's own integration error:
  what the soak looks for is a change between the first and the last tenth.

Numbers to read, never to assert. No rclpy here: the run is a subprocess.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import queue
import re
import signal
import subprocess
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import psutil

from mech_regulator.analysis.energy import GAUSS_NODES, GAUSS_WEIGHTS, powers
from mech_regulator.processes import command_line_child, die_with_parent

PROCESS_NAMES = ("machine", "governor", "scenario", "recorder", "launcher")  # the order of the memory rows
NODE_SUFFIX = "_node"  # a forked node's process name is <name>_node (nodes/launch.py _name_process)
MEGABYTE = 1e6  # [bytes]
ENERGY_SPAN_SHARE = 0.1  # the first and the last tenth of the simulated time have their own energy balance
SUBSTEPS = 8  # equal parts of an exchange step, each with 4-point Gauss-Legendre quadrature, for the works
CHUNK_STEPS = 2000  # exchange steps whose motion is rebuilt at once (the memory it takes)
KILOBYTE = 1e3  # [bytes]
FLAT_MEMORY_BOUND = 100.0  # [kB per simulated minute] the largest growth of a process's RSS over the second half of
# the run still called flat: 6 MB a simulated hour, where keeping the least of every exchange at engine_direct's 50 a
# second (a few doubles) would take 200 kB a minute; above the steps of Python's allocator (its 1 MB arenas)
FLAT_MEMORY_ROWS = 4  # rows in the second half of the run, at least, for a verdict on the memory
# The launcher's announcement (nodes/launch.py main_job): its exchange step and the log next to the run's files.
LAUNCH_BANNER = re.compile(r"exchange step (?P<step>[^ ]+) s\); node logs in (?P<log>.+)$")
# A progress line of the launcher (cli/report/terminal.py ProgressLines): "<label>: t = 312 / 3600 s (9 %), ..." while it runs,
# "<label>: done: t = 3600 / 3600 s in ..." or "<label>: stopped at t = 71.7 / 3600 s after ..." at the end.
PROGRESS_LINE = re.compile(r": (?P<end>done: |stopped at )?t = (?P<t>[0-9.e+-]+) / [0-9.e+-]+ s\b")


@dataclasses.dataclass(frozen=True)
class Progress:
    """One progress line of the run: when it came (time.monotonic() [s]), the machine's simulated time then [s], and
    whether it is the run's last (done or stopped)."""

    wall: float
    sim_time: float
    final: bool


@dataclasses.dataclass(frozen=True)
class Row:
    """One row of the soak: wall time since the soak began [s], each process's RSS [MB] then, the machine's simulated
    time at the last progress line [s] (None before the first), and over the interval before the row (from the first
    progress line for the first; None before a second line): the real-time factor [simulated s per wall s] and the
    exchanges per second of wall time (None if the launcher did not announce its exchange step)."""

    wall: float
    memory: dict[str, float]
    sim_time: float | None
    real_time_factor: float | None
    exchange_rate: float | None


@dataclasses.dataclass(frozen=True)
class EnergySpan:
    """The energy balance over a span of the run's samples: from t_start to t_end [s], the works of the moments [J]
    (exchange_step_works), the residual works - change of stored energy [J] and the residual relative to the largest
    energy involved (the sum of |work| of each moment, or the largest stored energy)."""

    label: str
    t_start: float
    t_end: float
    work: float
    residual: float
    relative_residual: float


@dataclasses.dataclass
class Soak:
    """What a soak measured: the rows, each process's memory [MB] at the run's first and last progress line, the
    run's summary (its JSON, None if none was written), the energy balance of its samples, the launcher's exit code
    and whether the soak was interrupted."""

    scene: str
    duration: float
    exchange_step: float | None = None
    log: Path | None = None
    rows: list[Row] = dataclasses.field(default_factory=list)
    memory_start: dict[str, float] = dataclasses.field(default_factory=dict)
    memory_end: dict[str, float] = dataclasses.field(default_factory=dict)
    summary: dict | None = None
    energy: list[EnergySpan] = dataclasses.field(default_factory=list)
    exit_code: int | None = None
    interrupted: bool = False


def parse_launch_banner(line: str) -> tuple[float, Path] | None:
    """The exchange step [s] and the log file the launcher announces in its first line, None for another line."""
    match = LAUNCH_BANNER.search(line)
    return (float(match["step"]), Path(match["log"])) if match else None


def parse_progress(line: str, wall: float) -> Progress | None:
    """The launcher's progress line `line`, come at `wall` (time.monotonic() [s]), None for another line."""
    match = PROGRESS_LINE.search(line)
    return Progress(wall, float(match["t"]), match["end"] is not None) if match else None


def process_memory(launcher) -> dict[str, float]:
    """RSS [MB] of the launcher (a psutil.Process) and of each node process it forked, by name (machine, governor,
    scenario, recorder, launcher); a process that has ended is left out."""
    memory: dict[str, float] = {}
    try:
        processes = [("launcher", launcher)] + [
            (child.name().removesuffix(NODE_SUFFIX), child)
            for child in launcher.children()
            if child.name().endswith(NODE_SUFFIX)
        ]
    except psutil.Error:  # the launcher has ended
        return memory
    for name, process in processes:
        try:
            if process.status() != psutil.STATUS_ZOMBIE:  # ended, not yet reaped: no memory
                memory[name] = process.memory_info().rss / MEGABYTE
        except psutil.Error:
            continue
    return memory


def run_command(
    scene: str, duration: float, overrides: list[str], out: Path | None, domain_id: int | None
) -> list[str]:
    """The `mech-regulator run` command line of the soak (no --quiet: its progress lines are what the soak reads)."""
    command = ["run", scene, "--duration", repr(duration)]
    for override in overrides:
        command += ["--set", override]
    if out is not None:
        command += ["--out", str(out)]
    if domain_id is not None:
        command += ["--domain-id", str(domain_id)]
    return command_line_child(*command)


def run_soak(
    scene: str,
    duration: float,
    interval: float,
    overrides: list[str],
    out: Path | None = None,
    domain_id: int | None = None,
    report: Callable[[str], None] = print,
    passed_on: Callable[[str], None] = print,
) -> Soak:
    """Play `scene` on the nodes for `duration` [s] of simulated time (`mech-regulator run` with `overrides` as --set,
    `out` its recording, `domain_id` its ROS domain; None: run's defaults) and report a memory row and a rate row
    (format_row) every `interval` [s] of wall time while it runs; the launcher's other lines (its summary, its
    messages) are passed on as they come, its standard output to `report` too, its standard error to `passed_on`.
    Ctrl-C (KeyboardInterrupt) interrupts the run as Ctrl-C interrupts `run` (SIGINT to the launcher, which stops its
    nodes and closes the recording), waits for its end, then returns what was measured; a second Ctrl-C stops
    waiting."""
    soak = Soak(scene, duration)
    environment = dict(os.environ, MECH_REGULATOR_PROGRESS_INTERVAL="0", PYTHONUNBUFFERED="1")
    # its own session, so that a Ctrl-C at the terminal reaches the soak only, which passes it on once
    process = subprocess.Popen(
        run_command(scene, duration, overrides, out, domain_id),
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=environment,
        start_new_session=True,
        preexec_fn=die_with_parent,
    )
    watch = _Watch(soak, psutil.Process(process.pid), interval, report)
    for stream, destination in ((process.stdout, report), (process.stderr, passed_on)):
        threading.Thread(target=_read_lines, args=(stream, destination, watch.lines), daemon=True).start()
    try:
        watch.follow()
        soak.exit_code = process.wait()
    except KeyboardInterrupt:
        soak.interrupted = True
        if process.poll() is None:
            process.send_signal(signal.SIGINT)
        try:
            watch.follow(rows=False)
            soak.exit_code = process.wait()
        except KeyboardInterrupt:
            soak.exit_code = process.poll()
    soak.summary = _run_summary(soak, out)
    return soak


class _Watch:
    """The soak's view of the running launcher: its lines as they come (from the reader threads, in `lines`), the
    progress, the memory, and the rows every interval."""

    def __init__(self, soak: Soak, launcher, interval: float, report: Callable[[str], None]):
        self.soak, self.launcher, self.interval, self.report = soak, launcher, interval, report
        self.lines: queue.Queue = queue.Queue()
        self.open_streams = 2
        self.start = time.monotonic()
        self.next_row = self.start + interval
        self.latest: Progress | None = None  # the last progress line with the machine's time
        self.anchor: Progress | None = None  # where the next row's interval starts: the first progress line, then the
        # last one at each row
        self.anchored_by_a_row = False  # whether the anchor is a row's (a row without a new line then shows a stall)
        self.ended = False  # the run's last progress line has come

    def follow(self, rows: bool = True) -> None:
        """Read the launcher's lines until both its streams end, with a row every interval while the run goes
        (rows), and one more for the progress after the last row, if any."""
        while self.open_streams:
            try:
                line, wall, destination = self.lines.get(timeout=max(self.next_row - time.monotonic(), 0.0))
            except queue.Empty:
                pass
            else:
                if line is None:
                    self.open_streams -= 1
                else:
                    self.take(line, wall, destination)
            now = time.monotonic()
            if now >= self.next_row:
                self.next_row += self.interval * math.ceil((now - self.next_row) / self.interval + 1e-9)
                if rows and self.running():
                    self.row(now)
        if rows and self.unreported():
            self.row(time.monotonic())

    def running(self) -> bool:
        """Whether a row has something to say: the run has not ended, or it has unreported progress."""
        return not self.ended or self.unreported()

    def unreported(self) -> bool:
        """Whether a progress line came that no row has reported."""
        return self.latest is not None and (self.latest is not self.anchor or not self.anchored_by_a_row)

    def take(self, line: str, wall: float, destination: Callable[[str], None]) -> None:
        """One line of the launcher, come at `wall` (time.monotonic() [s]): a progress line (the memory read with it),
        or another line (its banner among them) passed on to `destination`."""
        progress = parse_progress(line, wall)
        if progress is None:
            banner = parse_launch_banner(line)
            if banner is not None:
                self.soak.exchange_step, self.soak.log = banner
            destination(line)
            return
        self.ended = progress.final
        if self.latest is None or progress.sim_time != self.latest.sim_time:  # the last line repeats the time
            self.latest = progress
        self.anchor = self.anchor or progress
        memory = process_memory(self.launcher)
        if not self.soak.memory_start and "machine" in memory:
            self.soak.memory_start = memory
        if self.soak.memory_start:
            self.soak.memory_end.update(memory)

    def row(self, now: float) -> None:
        """Report the memory row and the rate row of the interval ending now (time.monotonic() [s]): the pace between
        the last progress line before the interval (or the first line) and the last one in it, 0 without a new one;
        none before a second line."""
        rate = exchanges = None
        if (
            self.latest is not None
            and self.anchor is not None
            and (self.latest is not self.anchor or self.anchored_by_a_row)
        ):
            span = (self.latest.wall if self.latest is not self.anchor else now) - self.anchor.wall
            rate = (self.latest.sim_time - self.anchor.sim_time) / span if span > 0.0 else 0.0
            exchanges = rate / self.soak.exchange_step if self.soak.exchange_step else None
        self.anchor, self.anchored_by_a_row = self.latest, self.latest is not None
        row = Row(
            now - self.start,
            process_memory(self.launcher),
            self.latest.sim_time if self.latest is not None else None,
            rate,
            exchanges,
        )
        self.soak.rows.append(row)
        for line in format_row(row):
            self.report(line)


def _read_lines(stream, destination: Callable[[str], None], lines: queue.Queue) -> None:
    """Put each line of `stream` in `lines` with the time.monotonic() [s] it came at and where it is passed on; None
    at the end."""
    for line in stream:
        lines.put((line.rstrip("\n"), time.monotonic(), destination))
    lines.put((None, time.monotonic(), destination))


def _run_summary(soak: Soak, out: Path | None) -> dict | None:
    """The run's summary (the JSON next to its recording), None if it wrote none."""
    recording = out if out is not None else soak.log
    if recording is None or not recording.with_suffix(".json").exists():
        return None
    return json.loads(recording.with_suffix(".json").read_text())


def energy_spans(model, columns: dict, share: float = ENERGY_SPAN_SHARE) -> list[EnergySpan]:
    """The energy balance (EnergySpan) of a run's samples `columns` (its CSV's columns: model.columns at the exchange
    times) over the whole run and over its first and last `share` of simulated time, the works from
    exchange_step_works; empty with fewer than two samples."""
    t = columns["t"]
    if t.size < 2:
        return []
    works = {
        name: np.concatenate([[0.0], np.cumsum(steps)])  # [J] from the first sample to each
        for name, steps in exchange_step_works(model, columns).items()
    }
    stored = columns["E_kinetic"] + columns.get("E_elastic", 0.0)
    first_end = int(np.searchsorted(t, t[0] + share * (t[-1] - t[0]), side="right")) - 1
    last_start = int(np.searchsorted(t, t[-1] - share * (t[-1] - t[0]), side="left"))
    spans = []
    for label, start, end in (
        ("whole run", 0, t.size - 1),
        (f"first {share:.0%}", 0, max(first_end, 1)),
        (f"last {share:.0%}", min(last_start, t.size - 2), t.size - 1),
    ):
        work = [float(done[end] - done[start]) for done in works.values()]
        residual = sum(work) - float(stored[end] - stored[start])
        scale = max(sum(abs(value) for value in work), float(np.max(stored[start : end + 1])), 1e-300)
        spans.append(EnergySpan(label, float(t[start]), float(t[end]), sum(work), residual, residual / scale))
    return spans


def exchange_step_works(model, columns: dict) -> dict[str, np.ndarray]:
    """The work [J] of each moment (analysis.energy.powers, by name) over each exchange step of a run's samples
    `columns`: its power integrated by 4-point Gauss-Legendre quadrature on SUBSTEPS equal parts of the step, along
    the motion between the samples rebuilt by between_samples. A moment that depends on the crank angle alone (an
    engine's cylinders) does the same work along any path between two angles, so the engine's pulses, which the
    samples alone miss, are integrated right; the rest of the residual is the path's error in the moments that
    depend on the speed and the throttle's within the step."""
    edges = np.linspace(0.0, 1.0, SUBSTEPS + 1)
    fractions = (edges[:-1, None] + 0.5 * np.diff(edges)[:, None] * (GAUSS_NODES[None, :] + 1.0)).ravel()
    weights = (0.5 * np.diff(edges)[:, None] * GAUSS_WEIGHTS[None, :]).ravel()
    parts = []
    for first in range(0, columns["t"].size - 1, CHUNK_STEPS):  # a chunk at a time: an hour has 180 000 steps
        chunk = {name: values[first : first + CHUNK_STEPS + 1] for name, values in columns.items()}
        times, states, throttle = between_samples(model, chunk, fractions)
        width = np.diff(chunk["t"])
        parts.append(
            {
                name: power.reshape(width.size, fractions.size) @ weights * width
                for name, power in powers(model, model.columns(times, states, throttle)).items()
            }
        )
    return {name: np.concatenate([part[name] for part in parts]) for name in parts[0]}


def between_samples(model, columns: dict, fractions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """The motion between a run's samples `columns` at `fractions` (in [0, 1]) of each exchange step: the times [s],
    the states (model.state_names, shape n_states x steps * fractions) and the throttle (None without a governor).
    A state whose rate is sampled too (phi: omega, omega: epsilon, twist: omega - omega_driven, omega_driven:
    epsilon_driven) is the cubic Hermite interpolant of its values and rates at the step's ends; the throttle and the
    governor's states are interpolated linearly (no moment reads the governor's state once the throttle is given; its
    arm_rate, not in the samples, is left 0)."""
    t = columns["t"]
    width, s = np.diff(t)[:, None], fractions[None, :]
    rates = {"phi": columns["omega"], "omega": columns["epsilon"]}
    if "epsilon_driven" in columns:
        rates["omega_driven"] = columns["epsilon_driven"]
    if "twist" in columns:
        rates["twist"] = columns["omega"] - columns["omega_driven"]

    def between(name: str) -> np.ndarray:
        values = columns[name]
        start, end = values[:-1, None], values[1:, None]
        if name not in rates:
            return (start + (end - start) * s).ravel()
        rate = rates[name]
        return (
            (2 * s**3 - 3 * s**2 + 1) * start
            + (s**3 - 2 * s**2 + s) * width * rate[:-1, None]
            + (3 * s**2 - 2 * s**3) * end
            + (s**3 - s**2) * width * rate[1:, None]
        ).ravel()

    times = (t[:-1, None] + width * s).ravel()
    states = np.array([between(name) if name in columns else np.zeros(times.size) for name in model.state_names()])
    return times, states, between("throttle") if "throttle" in columns else None


def run_energy(soak: Soak, model) -> list[EnergySpan]:
    """The energy balance of the run's CSV (the recorder's, named in its summary) for `model` (the scene's
    MachineModel); empty when the run wrote none."""
    csv = (soak.summary or {}).get("csv")
    if csv is None or not Path(csv).exists():
        return []
    with open(csv, encoding="utf-8") as stream:
        names = stream.readline().strip().split(",")
        values = np.loadtxt(stream, delimiter=",", ndmin=2)
    return energy_spans(model, dict(zip(names, values.T)))


def format_row(row: Row) -> list[str]:
    """A row's two lines: `[   30.0 s] memory [MB]: machine 212.4  governor 180.1  ...` and `[   30.0 s] rate: t =
    312.4 s, 520.6 exchanges/s, real-time factor 10.4 over the interval`."""
    when = f"[{row.wall:7.1f} s]"
    names = [name for name in PROCESS_NAMES if name in row.memory]
    memory = "  ".join(f"{name} {row.memory[name]:.1f}" for name in names) or "no process running"
    if row.sim_time is None:
        rate = "no progress yet (the nodes are starting)"
    elif row.real_time_factor is None:
        rate = f"t = {row.sim_time:.1f} s, the first report"
    else:
        exchanges = f"{row.exchange_rate:.1f} exchanges/s, " if row.exchange_rate is not None else ""
        rate = f"t = {row.sim_time:.1f} s, {exchanges}real-time factor {row.real_time_factor:.3g} over the interval"
    return [f"{when} memory [MB]: {memory}", f"{when} rate: {rate}"]


def format_soak(soak: Soak) -> str:
    """The soak's closing lines: how the run ended, its pace over the whole run, its energy balance and the verdict
    (memory at the start and at the end of each process, the real-time factor of the first and the last interval,
    whether the memory stayed flat)."""
    summary = soak.summary
    if summary is None:
        lines = [f"soak of {soak.scene}: the run wrote no summary (exit code {soak.exit_code})"]
    else:
        lines = [
            f"soak of {soak.scene}: {summary['status']} at t = {summary['t_end']:.6g} s of {soak.duration:g} s "
            f"({summary['samples']} exchanges)"
        ]
        if "wall_time_s" in summary:
            lines.append(
                f"whole run (the run's summary): {summary['samples'] / summary['wall_time_s']:.1f} "
                f"exchanges/s, real-time factor {summary['real_time_factor']:.3g} over "
                f"{summary['wall_time_s']:.1f} s of wall time between the first and the last exchange"
            )
    if soak.energy:
        lines.append(
            "energy balance of the run's samples (its CSV; the works along the motion rebuilt between the "
            "exchanges, docs/speed.md#soak--bench-soak):"
        )
        lines += [
            f"  {span.label} ({span.t_start:.6g}-{span.t_end:.6g} s): work {span.work:.6g} J, residual "
            f"{span.residual:.4g} J ({span.relative_residual:.3g} of the energy involved)"
            for span in soak.energy
        ]
    else:
        lines.append("energy balance: none (the run wrote no CSV, or Ctrl-C came while it was computed)")
    lines.append("verdict: " + verdict(soak))
    return "\n".join(lines)


def verdict(soak: Soak) -> str:
    """Memory at the run's start and end per process (growth in MB and %), the real-time factor of the first and
    the last row with a pace (0 for an interval without progress) and whether the memory stayed flat
    (memory_flatness), in one line."""
    growth = []
    for name in PROCESS_NAMES:
        if name in soak.memory_start and name in soak.memory_end:
            start, end = soak.memory_start[name], soak.memory_end[name]
            growth.append(
                f"{name} {start:.1f} -> {end:.1f} MB ({end - start:+.1f} MB, {100.0 * (end - start) / start:+.1f} %)"
            )
    memory = "memory " + ", ".join(growth) if growth else "memory: no reading while the nodes ran"
    rates = [row.real_time_factor for row in soak.rows if row.real_time_factor is not None]
    if not rates:
        pace = "real-time factor: no interval with a pace"
    elif len(rates) == 1:
        pace = f"real-time factor {rates[0]:.3g} (one interval)"
    else:
        change = f" ({100.0 * (rates[-1] - rates[0]) / rates[0]:+.1f} %)" if rates[0] > 0.0 else ""
        pace = f"real-time factor {rates[0]:.3g} in the first interval, {rates[-1]:.3g} in the last{change}"
    return f"{memory}; {pace}; {memory_flatness(soak.rows)}"


def memory_slopes(rows: list[Row]) -> tuple[dict[str, float], float, float] | None:
    """Each process's growth of RSS [kB per simulated minute] over the second half of the run's simulated time (the
    least-squares line through the rows from the middle between the first and the last row's time on, against
    the machine's simulated time), with that half's first and last time [s]; None with fewer than
    FLAT_MEMORY_ROWS rows there or no simulated time between them."""
    timed = [(row.sim_time, row.memory) for row in rows if row.sim_time is not None]
    if not timed:
        return None
    middle = 0.5 * (timed[0][0] + timed[-1][0])
    half = [(time, memory) for time, memory in timed if time >= middle]
    if len(half) < FLAT_MEMORY_ROWS or half[-1][0] <= half[0][0]:
        return None
    slopes = {}
    for name in PROCESS_NAMES:
        read = [(time, memory[name]) for time, memory in half if name in memory]
        if len(read) >= FLAT_MEMORY_ROWS and read[-1][0] > read[0][0]:
            times, megabytes = np.array(read).T
            slopes[name] = float(np.polyfit(times / 60.0, megabytes * MEGABYTE / KILOBYTE, 1)[0])
    return slopes, half[0][0], half[-1][0]


def memory_flatness(rows: list[Row], bound: float = FLAT_MEMORY_BOUND) -> str:
    """'memory flat' when no process's RSS grew by more than `bound` [kB per simulated minute] over the second half
    of the run (memory_slopes), else 'memory GROWS' naming those that did; with each slope and the span."""
    found = memory_slopes(rows)
    if found is None or not found[0]:
        return f"memory flat: no verdict (fewer than {FLAT_MEMORY_ROWS} rows in the second half of the run)"
    slopes, start, end = found
    growing = [name for name, slope in slopes.items() if slope > bound]
    head = f"memory GROWS ({', '.join(growing)})" if growing else "memory flat"
    figures = ", ".join(f"{name} {round(slope):+d}" for name, slope in slopes.items())
    return f"{head}: {figures} kB per simulated minute over t = {start:.6g}-{end:.6g} s (bound {bound:g})"
