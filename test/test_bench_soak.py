"""`mech-regulator bench soak`: the main job played through the real nodes, watched from outside — each process's
memory and the exchange rate in rows, the energy balance of the run's samples, the verdict — with its output piped
(a test's pipe is no terminal), and Ctrl-C ending it with what was measured. Short runs only: the figures are
checked for sanity, never for speed.
"""

from __future__ import annotations

import io
import itertools
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from ros_support import WAIT, domain_id, next_domain_id, processes  # noqa: F401 (fixtures)

psutil = pytest.importorskip(
    "psutil", reason="bench soak reads memory with psutil: pip install 'mech_regulator[bench]'"
)

from mech_regulator.bench.soak import (  # noqa: E402
    FLAT_MEMORY_BOUND,
    FLAT_MEMORY_ROWS,
    PROCESS_NAMES,
    Progress,
    Row,
    Soak,
    _Watch,
    between_samples,
    format_row,
    memory_flatness,
    memory_slopes,
    parse_launch_banner,
    parse_progress,
    verdict,
)
from mech_regulator.cli.report.terminal import ProgressLines  # noqa: E402
from mech_regulator.model import build_model  # noqa: E402
from mech_regulator.scene import load_scene  # noqa: E402

EXCHANGE_STEP = 0.02  # [s] engine_direct's
MEMORY_ROW = re.compile(r"^\[\s*(?P<wall>[0-9.]+) s\] memory \[MB\]: (?P<values>.*)$")
RATE_ROW = re.compile(
    r"^\[\s*(?P<wall>[0-9.]+) s\] rate: (?:no progress yet .*|t = (?P<t>[0-9.]+) s, (?:the first "
    r"report|(?P<exchanges>[0-9.]+) exchanges/s, real-time factor (?P<factor>[0-9.e+-]+) over the "
    r"interval))$"
)
WHOLE_RUN = re.compile(
    r"^whole run \(the run's summary\): (?P<exchanges>[0-9.]+) exchanges/s, real-time factor "
    r"(?P<factor>[0-9.e+-]+) over"
)
ENERGY_LINE = re.compile(
    r"^  (?P<span>whole run|first 10%|last 10%) \(.*\): work \S+ J, residual \S+ J "
    r"\((?P<relative>\S+) of the energy involved\)$"
)
VERDICT_MEMORY = re.compile(
    r"(?P<name>\w+) (?P<start>[0-9.]+) -> (?P<end>[0-9.]+) MB \([+-][0-9.]+ MB, [+-][0-9.]+ %\)"
)


def memory_rows(out: str) -> list[dict[str, float]]:
    """Each memory row's RSS [MB] by process name."""
    rows = []
    for line in out.splitlines():
        match = MEMORY_ROW.match(line)
        if match:
            pairs = re.findall(r"(\w+) ([0-9.]+)", match["values"])
            rows.append({name: float(value) for name, value in pairs})
    return rows


def rate_rows(out: str) -> list[dict[str, float | None]]:
    """Each rate row: t [s] (None before the first report), exchanges/s and real-time factor (None without)."""
    rows = []
    for line in out.splitlines():
        if "] rate: " in line:
            match = RATE_ROW.match(line)
            assert match, f"a rate row that does not parse: {line!r}"
            rows.append({key: float(value) if value is not None else None for key, value in match.groupdict().items()})
    return rows


def soak_command(*options: str) -> list[str]:
    return [sys.executable, "-m", "mech_regulator", "bench", "soak", *options]


def nodes_left(marker: str) -> list[str]:
    """Node processes (named <name>_node) still running whose command line (their launcher's) mentions `marker`."""
    left = []
    for process in psutil.process_iter(["name", "cmdline", "status"]):
        if (
            (process.info["name"] or "").endswith("_node")
            and process.info["status"] != psutil.STATUS_ZOMBIE
            and marker in " ".join(process.info["cmdline"] or [])
        ):
            left.append(process.info["name"])
    return left


# ---------------------------------------------------------------------------------------------------------------
# The parsers and the verdict, on fixed input


def test_the_progress_parser_reads_the_lines_the_launcher_prints():
    """Lines made by the launcher's own progress printer (ProgressLines) while the run goes, at its end and when it
    stops short; a long run's time to the second, not to three digits."""
    clock = itertools.count()
    out = io.StringIO()
    bar = ProgressLines(3600.0, "engine_direct on the nodes", "t", "s", 0.0, file=out, clock=lambda: next(clock))
    bar.update(1234.25)
    bar.update(3600.0 - 1234.25)
    bar.close()
    stopped = ProgressLines(3600.0, "engine_direct on the nodes", "t", "s", 0.0, file=out, clock=lambda: next(clock))
    stopped.update(71.74)
    stopped.close()
    lines = out.getvalue().splitlines()
    assert [parse_progress(line, 7.5) for line in lines] == [
        Progress(7.5, 1234.0, False),
        Progress(7.5, 3600.0, False),
        Progress(7.5, 3600.0, True),
        Progress(7.5, 71.7, False),
        Progress(7.5, 71.7, True),
    ], lines
    assert parse_progress("open the recording with: rerun run.rrd", 7.5) is None


def test_the_banner_parser_reads_the_exchange_step_and_the_log():
    banner = (
        "running recorder, governor, scenario, machine nodes on ROS domain 38 (lockstep, exchange step 0.02 s); "
        "node logs in runs/engine_direct-20261128-041500.log"
    )
    assert parse_launch_banner(banner) == (0.02, Path("runs/engine_direct-20261128-041500.log"))
    assert parse_launch_banner("scene engine_direct: complete at t = 2 s") is None


def test_the_rows_and_the_verdict_carry_their_numbers():
    row = Row(30.04, {"launcher": 300.2, "machine": 157.62, "recorder": 238.1}, 312.44, 10.41, 520.5)
    assert format_row(row) == [
        "[   30.0 s] memory [MB]: machine 157.6  recorder 238.1  launcher 300.2",
        "[   30.0 s] rate: t = 312.4 s, 520.5 exchanges/s, real-time factor 10.4 over the interval",
    ]
    assert memory_rows("\n".join(format_row(row))) == [{"machine": 157.6, "recorder": 238.1, "launcher": 300.2}]
    assert rate_rows("\n".join(format_row(row))) == [{"wall": 30.0, "t": 312.4, "exchanges": 520.5, "factor": 10.4}]
    soak = Soak(
        "engine_direct",
        3600.0,
        memory_start={"machine": 100.0, "recorder": 200.0},
        memory_end={"machine": 101.0, "recorder": 250.0},
        rows=[Row(30.0, {}, 300.0, 10.0, 500.0), Row(60.0, {}, 540.0, 8.0, 400.0)],
    )
    assert verdict(soak) == (
        "memory machine 100.0 -> 101.0 MB (+1.0 MB, +1.0 %), recorder 200.0 -> 250.0 MB "
        "(+50.0 MB, +25.0 %); real-time factor 10 in the first interval, 8 in the last (-20.0 %); "
        f"memory flat: no verdict (fewer than {FLAT_MEMORY_ROWS} rows in the second half of the run)"
    )


def soak_rows(growth: dict[str, float], minutes: int = 60, wobble: float = 0.0) -> list[Row]:
    """A row a simulated minute for `minutes`, each process's RSS [MB] growing by `growth` [kB per simulated minute]
    from 150 MB, plus `wobble` [MB] up and down every other row (the allocator's steps)."""
    return [
        Row(
            10.0 * minute,
            {name: 150.0 + (rate * minute) / 1e3 + wobble * (minute % 2) for name, rate in growth.items()},
            60.0 * minute,
            7.0,
            350.0,
        )
        for minute in range(minutes + 1)
    ]


def test_the_memory_verdict_reads_the_growth_over_the_second_half_of_the_run():
    flat = {"machine": 10.0, "governor": 0.0, "scenario": 0.0, "recorder": 30.0, "launcher": 0.0}
    slopes, start, end = memory_slopes(soak_rows(flat, wobble=0.5))
    assert (start, end) == (1800.0, 3600.0)
    assert slopes == pytest.approx(flat, abs=1.0)  # the wobble of half a megabyte does not tilt the line
    assert memory_flatness(soak_rows(flat)).startswith(
        "memory flat: machine +10, governor +0, scenario +0, recorder +30, launcher +0 kB per simulated minute over "
        f"t = 1800-3600 s (bound {FLAT_MEMORY_BOUND:g})"
    )
    # the recorder keeping 1.1 kB of each of engine_direct's 3000 exchanges a minute
    growing = soak_rows({**flat, "recorder": 3300.0})
    assert memory_flatness(growing).startswith(
        "memory GROWS (recorder): machine +10, governor +0, scenario +0, recorder +3300"
    )
    # a machine that grew only in its first half (caches warming) is flat
    warming = [
        Row(
            row.wall,
            {"machine": row.memory["machine"] + 20.0 * min(row.sim_time, 1800.0) / 1800.0},
            row.sim_time,
            7.0,
            350.0,
        )
        for row in soak_rows({"machine": 0.0})
    ]
    assert memory_flatness(warming).startswith("memory flat: machine +0 kB")
    assert memory_flatness(soak_rows(flat, minutes=4)).startswith("memory flat: no verdict")  # 3 rows in the half


def test_the_rate_rows_follow_the_progress_lines_and_show_a_stall():
    """Rows from progress lines come at known wall times: no time before the first line and no pace from it alone,
    then the pace between the lines at the rows' edges, 0 over an interval without a line (a run that stopped
    exchanging), and no row due once the progress up to the run's last line (repeating the time) is reported."""
    reported = []
    watch = _Watch(Soak("engine_direct", 3600.0, exchange_step=0.02), psutil.Process(), 30.0, reported.append)

    def line(wall: float, t: float, end: str = "") -> None:
        watch.take(f"engine_direct on the nodes: {end}t = {t:g} / 3600 s (1 %), 1.0 s elapsed", wall, reported.append)

    watch.row(5.0)
    assert not watch.unreported()
    line(10.0, 0.0)
    assert watch.unreported()
    watch.row(10.5)
    line(11.0, 10.0)
    line(12.0, 20.0)
    watch.row(12.5)
    line(14.0, 40.0)
    watch.row(14.5)
    watch.row(20.0)
    line(21.0, 50.0)
    assert watch.running() and watch.unreported()
    line(23.0, 50.0, "done: ")
    assert watch.running() and watch.unreported()  # the progress up to the last line still to report
    watch.row(24.0)
    assert not watch.running() and not watch.unreported()
    rows = [(row.sim_time, row.real_time_factor, row.exchange_rate) for row in watch.soak.rows]
    assert rows == [
        (None, None, None),
        (0.0, None, None),
        (20.0, 10.0, 500.0),
        (40.0, 10.0, 500.0),
        (40.0, 0.0, 0.0),
        (50.0, pytest.approx(10.0 / 7.0), pytest.approx(500.0 / 7.0)),
    ]
    assert all("launcher" in row.memory and row.memory["launcher"] > 0.0 for row in watch.soak.rows)


def test_the_motion_between_samples_is_exact_for_a_cubic():
    """The rebuilt motion (cubic Hermite on each state's value and sampled rate) is exact when phi is a cubic in
    time: the works are then integrated along the true path."""
    model = build_model(load_scene("lathe"))
    t = np.array([0.0, 0.5, 1.25])
    columns = {"t": t, "phi": t**3 - t, "omega": 3 * t**2 - 1, "epsilon": 6 * t}
    times, states, throttle = between_samples(model, columns, np.array([0.0, 0.3, 0.7, 1.0]))
    np.testing.assert_allclose(times, [0.0, 0.15, 0.35, 0.5, 0.5, 0.725, 1.025, 1.25])
    np.testing.assert_allclose(states, [times**3 - times, 3 * times**2 - 1], atol=1e-14)
    assert throttle is None


# ---------------------------------------------------------------------------------------------------------------
# Through the real nodes


def test_a_short_soak_prints_memory_rates_energy_and_a_verdict_when_piped(tmp_path):
    """Two seconds of engine_direct through the nodes, the output a pipe: memory rows with every process, rate rows
    whose numbers agree with each other, the whole run's pace, the energy balance of the samples and the verdict."""
    result = subprocess.run(
        soak_command(
            "--duration",
            "2",
            "--interval",
            "0.5",
            "--out",
            str(tmp_path / "run.rrd"),
            "--domain-id",
            str(next_domain_id()),
        ),
        capture_output=True,
        text=True,
        timeout=4 * WAIT,
        cwd=tmp_path,
    )
    described = f"exit {result.returncode}\n{result.stdout}\n{result.stderr}"
    assert result.returncode == 0, described
    memory = memory_rows(result.stdout)
    assert memory and all(value > 0.0 for row in memory for value in row.values()), described
    assert any(set(row) == set(PROCESS_NAMES) for row in memory), described
    rates = [row for row in rate_rows(result.stdout) if row["t"] is not None]
    assert rates and rates[-1]["t"] == 2.0, described
    assert [row["t"] for row in rates] == sorted(row["t"] for row in rates), described
    for row in rates:
        if row["factor"] is not None:
            assert row["factor"] >= 0.0 and row["exchanges"] >= 0.0, described
            expected = row["factor"] / EXCHANGE_STEP  # as printed: the factor to 3 digits, the exchanges to 0.1
            assert abs(row["exchanges"] - expected) <= 0.05 + 5e-3 * expected, described
    whole = [WHOLE_RUN.match(line) for line in result.stdout.splitlines() if WHOLE_RUN.match(line)]
    assert len(whole) == 1 and float(whole[0]["exchanges"]) > 0.0 and float(whole[0]["factor"]) > 0.0, described
    assert float(whole[0]["exchanges"]) == pytest.approx(float(whole[0]["factor"]) / EXCHANGE_STEP, rel=0.02)
    energy = {
        match["span"]: float(match["relative"]) for match in map(ENERGY_LINE.match, result.stdout.splitlines()) if match
    }
    assert set(energy) == {"whole run", "first 10%", "last 10%"}, described
    assert abs(energy["whole run"]) < 1e-3, described  # the engine's pulses integrated (the samples alone: 5e-2)
    verdicts = [line for line in result.stdout.splitlines() if line.startswith("verdict: ")]
    assert len(verdicts) == 1, described
    grown = {
        match["name"]: (float(match["start"]), float(match["end"])) for match in VERDICT_MEMORY.finditer(verdicts[0])
    }
    assert set(grown) == set(PROCESS_NAMES) and all(start > 0 and end > 0 for start, end in grown.values()), described
    assert "real-time factor" in verdicts[0], described
    assert "exchange step 0.02 s" in result.stderr and ": t = " not in result.stderr, described  # progress consumed
    assert nodes_left(str(tmp_path)) == [], described


def test_ctrl_c_stops_the_run_and_prints_what_was_measured(tmp_path, processes, domain_id):
    """SIGINT to the soak (a Ctrl-C at the terminal reaches it alone: its run has a session of its own) once the
    nodes exchange: the run is interrupted as `run` is, the soak prints its summary and verdict and exits 130, and no
    node is left."""
    soak = processes.start(
        soak_command("--duration", "600", "--interval", "0.5", "--out", tmp_path / "run.rrd", "--domain-id", domain_id),
        "soak",
    )
    deadline = time.monotonic() + 4 * WAIT
    while not any(row["factor"] is not None for row in rate_rows(processes.log(soak))):
        assert soak.poll() is None and time.monotonic() < deadline, processes.logs()
        time.sleep(0.2)
    soak.send_signal(signal.SIGINT)
    assert processes.wait(soak) == 130, processes.logs()
    out = processes.log(soak)
    assert re.search(r"^soak of engine_direct: interrupted at t = [0-9.]+ s of 600 s \(\d+ exchanges\)$", out, re.M), (
        out
    )
    assert re.search(r"^verdict: memory machine [0-9.]+ -> [0-9.]+ MB", out, re.M), out
    assert "interrupted; the rows above are what was measured" in out, out
    assert nodes_left(str(tmp_path)) == [], out


@pytest.mark.parametrize(
    "options, message",
    [
        (("--interval", "0"), "--interval 0: expected a wall time > 0 s"),
        (("--duration", "-5"), "--duration -5: expected a simulated time in (0, 1e7] s"),
        (("--scene", "no_such_scene"), "no_such_scene"),
    ],
)
def test_bad_input_is_refused_before_the_run(tmp_path, options, message):
    result = subprocess.run(soak_command(*options), capture_output=True, text=True, timeout=WAIT, cwd=tmp_path)
    assert result.returncode == 2 and message in result.stderr and "Traceback" not in result.stderr, result.stderr
    assert not (tmp_path / "runs").exists(), "a run started"
