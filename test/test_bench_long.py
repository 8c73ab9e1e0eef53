"""`mech-regulator bench long` (bench/long.py): a row per run of the matrix, parsed; its options checked before
anything runs. A short duration here: what the rows mean is in docs/hard_cases.md, "Long runs"."""

from __future__ import annotations

from support import run_cli


def test_bench_long_prints_a_row_per_run_with_its_figures(capsys):
    code, out, err = run_cli(
        capsys,
        "bench",
        "long",
        "--scenes",
        "lathe",
        "--paths",
        "reference",
        "--methods",
        "DOP853,Radau",
        "--modes",
        "simulate",
        "--duration",
        "2",
    )
    assert code == 0, err
    header, rule, *rows = out.splitlines()
    assert header.startswith("| scene | path | method | mode | status (2 s) |") and rule.startswith("|---|")
    assert [row.split(" | ")[:5] for row in rows] == [
        ["| lathe", "reference", method, "simulate", "complete"] for method in ("DOP853", "Radau")
    ]
    for row in rows:
        cells = row.strip("| ").split(" | ")
        assert int(cells[6]) > 10 and abs(float(cells[7])) < 1e-6, row  # steps, energy residual
        assert cells[8] != "-" and abs(float(cells[9])) < 1e-3, row  # omega_m against the scene's own duration


def test_bench_long_refuses_an_unknown_name_before_anything_runs(capsys):
    code, out, err = run_cli(capsys, "bench", "long", "--methods", "DOP853,Euler")
    assert code == 2 and out == ""
    assert "--methods 'DOP853,Euler': Euler is not one of DOP853, RK45, RK4, Radau, energy" in err


def test_a_refusal_of_several_lines_is_one_row_of_the_table():
    from mech_regulator.bench.long import Row, format_row

    message = "lathe.yaml: 2 problems:\n  solver.step = 0.0001 s would take 1e+08 steps\n  solver.sample_rate = ..."
    line = format_row(Row("lathe", "fast", "RK4", "simulate", "refused", message, 0.1))
    assert "\n" not in line and line.count(" | ") == 11
    assert "refused: lathe.yaml: 2 problems: solver.step = 0.0001 s would take 1e+08 steps" in line


def test_bench_long_applies_set_to_every_row_and_refuses_what_the_rows_set(capsys):
    """`--set` reaches each row (the lathe at 5000 Hz over 10 000 s is refused for its 5e7 output samples, before it
    runs; the budget of 5 s would stop the row that ran without it); a key the rows set themselves, or one a scene
    does not take, is refused before anything runs."""
    options = ["bench", "long", "--scenes", "lathe", "--paths", "fast", "--methods", "DOP853", "--modes", "simulate"]
    code, out, err = run_cli(
        capsys, *options, "--duration", "10000", "--budget", "5", "--set", "solver.sample_rate=5000"
    )
    assert code == 0, err
    assert "| lathe | fast | DOP853 | simulate | refused: " in out and "solver.sample_rate = 5000 Hz" in out
    code, out, err = run_cli(capsys, *options, "--set", "solver.path=reference")
    assert code == 2 and out == ""
    assert "--set 'solver.path=reference': each row sets solver.path; choose it with --paths" in err
    code, out, err = run_cli(capsys, *options, "--set", "machine.flywheel.inertia=-1")
    assert code == 2 and out == "" and "machine.flywheel.inertia" in err


def test_bench_long_shows_each_row_s_progress_on_stderr_in_a_log(capsys, monkeypatch):
    # a row can run for an hour: its progress goes to stderr (here not a terminal: plain lines, one at every update
    # with the interval 0), the table alone to stdout
    monkeypatch.setenv("MECH_REGULATOR_PROGRESS_INTERVAL", "0")
    options = ["--scenes", "lathe", "--paths", "fast", "--methods", "DOP853", "--modes", "simulate,cosim"]
    code, out, err = run_cli(capsys, "bench", "long", *options, "--duration", "2")
    assert code == 0, err
    assert len(out.splitlines()) == 4 and "t = " not in out, out
    for mode in ("simulate", "cosim"):
        lines = [line for line in err.splitlines() if line.startswith(f"lathe fast DOP853 {mode}: ")]
        assert len(lines) >= 2 and " t = " in lines[0] and "/ 2 s (" in lines[0], err  # as the run goes
        assert lines[-1].startswith(f"lathe fast DOP853 {mode}: done: t = 2 / 2 s in "), err
