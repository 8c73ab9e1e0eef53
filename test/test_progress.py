"""Progress of long work where nobody watches a terminal (CI logs, `| tee`, a notebook): plain lines on stderr
with the simulated time, the share done, the elapsed time and an ETA every few seconds, and a final line; tqdm's
bar on a terminal; nothing with --quiet. No timing is asserted: the interval is set through
MECH_REGULATOR_PROGRESS_INTERVAL (0: a line at every update)."""

from __future__ import annotations

import io
import itertools
import os
import re
import subprocess
import sys

import pytest
from support import run_cli

from mech_regulator.cli.report.terminal import PROGRESS_INTERVAL, ProgressLines, progress_bar, progress_interval

DURATION = r"(?:[0-9.]+ s|\d+ min \d+ s|\d+ h \d+ min)"  # report._duration: '4.1 s', '2 min 05 s', '1 h 02 min'
LINE = re.compile(
    rf"^simulating lathe: t = ([0-9.e+-]+) / 20 s \((\d+) %\), ({DURATION}) elapsed, "
    rf"ETA ({DURATION}|unknown)$"
)
FINAL = re.compile(rf"^simulating lathe: done: t = 20 / 20 s in ({DURATION})$")


def simulate(*options: str, interval: str | None = "0") -> subprocess.CompletedProcess:
    """`mech-regulator simulate lathe` for 20 s in a child process with stdout and stderr to pipes."""
    env = dict(os.environ)
    env.pop("MECH_REGULATOR_PROGRESS_INTERVAL", None)
    if interval is not None:
        env["MECH_REGULATOR_PROGRESS_INTERVAL"] = interval
    return subprocess.run(
        [sys.executable, "-m", "mech_regulator", "simulate", "lathe", "--set", "scenario.duration=20", *options],
        capture_output=True,
        text=True,
        env=env,
        check=True,
    )


def test_piped_simulate_prints_progress_lines_and_a_final_line():
    done = simulate()
    lines = done.stderr.splitlines()
    progress = [LINE.match(line) for line in lines[:-1]]
    assert progress and all(progress), done.stderr
    times = [float(match.group(1)) for match in progress]
    assert times == sorted(times) and 0.0 < times[-1] <= 20.0
    assert all(0 <= int(match.group(2)) <= 100 for match in progress)
    assert FINAL.match(lines[-1]), lines[-1]
    assert "simulating" not in done.stdout and done.stdout.startswith("scene lathe: complete at t = 20 s")


def test_quiet_prints_no_progress():
    done = simulate("--quiet")
    assert "simulating" not in done.stderr and "ETA" not in done.stderr
    assert done.stdout.startswith("scene lathe: complete")


def test_work_within_one_interval_prints_nothing():
    done = simulate(interval="1e6")
    assert done.stderr == ""


def test_a_line_names_time_share_elapsed_and_eta():
    clock = iter([0.0, 4.1, 4.2, 5.0, 12.3]).__next__
    out = io.StringIO()
    bar = ProgressLines(10.0, "simulating lathe", "t", "s", 3.0, file=out, clock=clock)
    bar.update(3.2)  # 4.1 s after the start: a line
    bar.update(0.1)  # 0.1 s after that line: none
    bar.update(6.7)
    bar.close()
    assert out.getvalue().splitlines() == [
        "simulating lathe: t = 3.2 / 10 s (32 %), 4.1 s elapsed, ETA 8.7 s",
        "simulating lathe: done: t = 10 / 10 s in 5.0 s",
    ]  # the last update


def test_work_ended_short_says_where_it_stopped():
    clock = itertools.count(0.0, 5.0).__next__
    out = io.StringIO()
    with ProgressLines(10.0, "simulating lathe", "t", "s", 3.0, file=out, clock=clock) as bar:
        bar.update(0.0)
        bar.update(4.0)
    assert out.getvalue().splitlines() == [
        "simulating lathe: t = 0 / 10 s (0 %), 0.0 s elapsed, ETA unknown",
        "simulating lathe: t = 4 / 10 s (40 %), 5.0 s elapsed, ETA 7.5 s",
        "simulating lathe: stopped at t = 4 / 10 s after 5.0 s; start-up 5.0 s",
    ]


def test_a_count_without_total_and_its_stage():
    clock = itertools.count(0.0, 130.0).__next__
    out = io.StringIO()
    with ProgressLines(
        None, "flywheel for lathe", None, "dynamic periods simulated", 3.0, file=out, clock=clock
    ) as bar:
        bar.set_description_str("J_fw = 18.9 kg m^2")
        bar.update(1)
    assert out.getvalue().splitlines() == [
        "flywheel for lathe (J_fw = 18.9 kg m^2): 1 dynamic periods simulated, 2 min 10 s elapsed",
        "flywheel for lathe: done: 1 dynamic periods simulated in 2 min 10 s",
    ]


def test_a_start_up_is_neither_in_the_eta_nor_in_the_duration():
    """The nodes: 4 s from the command to the first diagnostics (t = 0), then 16 s simulated at an even 3 s of wall
    time per simulated second; after 10 % of the run the ETA is the time left, and the final line gives the run's
    wall time over the exchanges and the start-up from the command, as the summary does."""
    wall = {"now": 1.0}  # the bar is made 1 s after the command
    out = io.StringIO()
    bar = ProgressLines(
        16.0, "engine_direct on the nodes", "t", "s", 0.0, file=out, clock=lambda: wall["now"], started=0.0
    )
    wall["now"] = 4.0
    bar.update(0.0)  # the machine's first diagnostics, as its exchanges start
    for step in range(1, 17):
        wall["now"] = 4.0 + 3.0 * step
        bar.update(1.0)
    wall["now"] = 60.0  # the nodes' graph settling before the bar closes
    bar.close()
    lines = out.getvalue().splitlines()
    assert lines[2] == "engine_direct on the nodes: t = 2 / 16 s (12 %), 6.0 s elapsed, ETA 42.0 s"
    assert lines[-1] == "engine_direct on the nodes: done: t = 16 / 16 s in 48.0 s; start-up 4.0 s"


def test_no_eta_from_the_first_instants_of_the_work():
    """A line 3.6 s after the bar's creation, the work (after a start-up that reported nothing done) begun 0.02 s
    before with 6.2e-5 s of 120 simulated: its pace would give an ETA of 11 h; it says unknown until the work has run
    ETA_AFTER s (or done ETA_SHARE of the total: the sweep's lines below), then the time left at the pace so far."""
    wall = {"now": 0.0}
    out = io.StringIO()
    bar = ProgressLines(120.0, "simulating engine_direct", "t", "s", 0.0, file=out, clock=lambda: wall["now"])
    wall["now"] = 3.58
    bar.update(0.0)  # the probe done: the run begins
    wall["now"] = 3.6
    bar.update(6.2e-5)
    wall["now"] = 3.58 + 2.0
    bar.update(1.0 - bar.n)
    lines = out.getvalue().splitlines()
    assert lines[1] == "simulating engine_direct: t = 6.2e-05 / 120 s (0 %), 0.0 s elapsed, ETA unknown"
    assert lines[2] == "simulating engine_direct: t = 1 / 120 s (1 %), 2.0 s elapsed, ETA 3 min 58 s"


def test_a_long_run_s_probe_is_its_start_up(monkeypatch):
    """A run longer than LONG_RUN is probed before it starts (solvers.step_limit_refusal, without progress); the
    progress callback is told that the work begins (0 s simulated) after the probe, before the run's own steps."""
    import mech_regulator.solvers as solvers
    from mech_regulator.model import build_model
    from mech_regulator.scene import load_scene
    from mech_regulator.scene.limits import LONG_RUN

    events = []
    integrate = solvers._integrate

    def logged(model, progress=None, stream=None):
        events.append("run" if progress is not None else "probe")
        return integrate(model, progress, stream)

    monkeypatch.setattr(solvers, "_integrate", logged)
    model = build_model(
        load_scene(
            "lathe", ["solver.path=reference", f"scenario.duration={LONG_RUN + 1.0!r}", "scenario.load_events=[]"]
        )
    )
    solvers.simulate(model, progress=lambda t: events.append(t) if not events or events[-1] != t else None)
    assert events[:3] == ["probe", 0.0, "run"] and events[3] > 0.0 and events[-1] == pytest.approx(LONG_RUN + 1.0)


def test_silent_when_quiet():
    out = io.StringIO()
    with ProgressLines(10.0, "x", "t", "s", 0.0, enabled=False, file=out) as bar:
        bar.update(10.0)
    assert bar.n == 10.0 and out.getvalue() == ""


@pytest.mark.parametrize(
    "value, expected",
    [
        ("0.5", 0.5),
        ("0", 0.0),
        ("", PROGRESS_INTERVAL),
        ("soon", PROGRESS_INTERVAL),
        ("-1", PROGRESS_INTERVAL),
        ("nan", PROGRESS_INTERVAL),
    ],
)
def test_interval_from_the_environment(monkeypatch, value, expected):
    monkeypatch.setenv("MECH_REGULATOR_PROGRESS_INTERVAL", value)
    assert progress_interval() == expected


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_a_terminal_gets_tqdms_bar(monkeypatch):
    from tqdm import tqdm

    monkeypatch.setattr(sys, "stderr", Terminal())
    with progress_bar(10.0, False, "simulating lathe") as bar:
        assert isinstance(bar, tqdm)
        bar.update(10.0)
    assert "simulating lathe: 100%" in sys.stderr.getvalue()
    monkeypatch.setattr(sys, "stderr", io.StringIO())  # not a terminal
    assert isinstance(progress_bar(10.0, False), ProgressLines)


def test_sweep_and_flywheel_report_progress_in_a_log(capsys, monkeypatch, tmp_path):
    monkeypatch.setenv("MECH_REGULATOR_PROGRESS_INTERVAL", "0")
    code, _out, err = run_cli(
        capsys,
        "sweep",
        "lathe",
        "--grid",
        "machine.flywheel.inertia=10,20",
        "--jobs",
        "1",
        "--set",
        "scenario.duration=2",
        "--out",
        str(tmp_path),
    )
    assert code == 0
    lines = err.splitlines()
    assert re.fullmatch(r"sweep of 2 points: 2 / 4 s simulated \(50 %\), [0-9.]+ s elapsed, ETA [0-9.]+ s", lines[0])
    assert re.fullmatch(r"sweep of 2 points: done: 4 / 4 s simulated in [0-9.]+ s", lines[-1]), err
    code, _out, err = run_cli(capsys, "flywheel", "lathe", "--delta", "1/60")
    assert code == 0
    assert re.match(r"flywheel for lathe \(J_fw = [0-9.e+-]+ kg m\^2\): 1 dynamic periods simulated, ", err), err
    assert re.search(r"^flywheel for lathe: done: \d+ dynamic periods simulated in ", err, re.M), err
    code, _out, err = run_cli(capsys, "flywheel", "lathe", "--delta", "1/60", "--quiet")
    assert code == 0 and err == ""
