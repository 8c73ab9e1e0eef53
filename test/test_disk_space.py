"""A command's outputs estimated before the run and compared with the free disk (cli/report/outputs.py,
check_free_space; docs/ros.md, "Outputs against the free disk"): refused with exit code 2 when they do not fit,
announced when large, and the estimate against a real short run's files."""

from __future__ import annotations

from collections import namedtuple

import pytest
from support import refused_line, run_cli

from mech_regulator.cli.report import outputs
from mech_regulator.cli.simulate import output_column_count
from mech_regulator.model import build_model
from mech_regulator.scene import SceneError, load_scene

ESTIMATE_FACTOR = 3.0  # docs/ros.md: a file takes between 1/3 of its estimate and the estimate

Usage = namedtuple("Usage", "total used free")


def with_free_disk(monkeypatch, free: int) -> None:
    """shutil.disk_usage, as outputs.check_free_space calls it, says `free` bytes are free."""
    monkeypatch.setattr(outputs.shutil, "disk_usage", lambda folder: Usage(10**12, 10**12 - free, free))


def test_simulate_s_outputs_beyond_the_free_disk_are_refused_before_the_run(capsys, monkeypatch, tmp_path):
    with_free_disk(monkeypatch, 1000)
    csv, recording = tmp_path / "x.csv", tmp_path / "x.rrd"
    line = refused_line(*run_cli(capsys, "simulate", "lathe", "--out", str(csv), "--record", str(recording)))
    assert f"not enough free disk for '{csv}' (" in line and f"'{recording}' (" in line, line
    assert "rows of 10 columns (10 s at solver.sample_rate 2000 Hz)" in line, line
    assert f"the file system of '{tmp_path}' has 1 kB free" in line, line
    assert "expected a shorter scenario.duration, a lower solver.sample_rate" in line, line
    assert list(tmp_path.iterdir()) == []


def test_run_s_outputs_beyond_the_free_disk_are_refused_before_any_node_starts(capsys, monkeypatch, tmp_path):
    import importlib.util

    if importlib.util.find_spec("rclpy") is None:
        pytest.skip("run needs rclpy")
    with_free_disk(monkeypatch, 10**6)
    recording = tmp_path / "x.rrd"
    line = refused_line(*run_cli(capsys, "run", "lathe", "--out", str(recording), "--duration", "1000"))
    for name in (f"'{recording}'", f"'{tmp_path / 'x.csv'}'", "the recorder's spool"):
        assert name in line, line
    assert "(1000 s at --exchange-step 0.02 s)" in line, line
    assert "has 1 MB free; expected a shorter --duration" in line, line
    assert list(tmp_path.iterdir()) == []  # no node started: no log, no parameter file


def test_outputs_on_one_file_system_add_up_and_large_ones_are_announced(capsys, monkeypatch, tmp_path):
    sizes = [outputs.OutputSize("'a'", tmp_path, 6e8), outputs.OutputSize("'b'", tmp_path, 6e8)]
    with_free_disk(monkeypatch, 10**9)  # each fits alone, not both
    with pytest.raises(SceneError, match="some 1.2 GB"):
        outputs.check_free_space(sizes, "the rows", "less")
    with_free_disk(monkeypatch, 10**10)
    outputs.check_free_space(sizes, "the rows", "less")
    assert (
        capsys.readouterr().err
        == "mech-regulator: the outputs will take some 1.2 GB for the rows: 'a' (600 MB), 'b' (600 MB)\n"
    )
    outputs.check_free_space([outputs.OutputSize("'a'", tmp_path, outputs.LARGE_OUTPUTS_BYTES)], "the rows", "less")
    assert capsys.readouterr().err == ""


def test_the_estimate_bounds_a_short_run_s_files_within_the_stated_factor(capsys, tmp_path):
    csv, recording = tmp_path / "lathe.csv", tmp_path / "lathe.rrd"
    code, _, err = run_cli(
        capsys,
        "simulate",
        "lathe",
        "--set",
        "solver.path=reference",
        "--set",
        "scenario.duration=2",
        "--out",
        str(csv),
        "--record",
        str(recording),
        "--quiet",
    )
    assert code == 0, err
    assert "outputs will take" not in err  # small outputs: nothing new said
    model = build_model(load_scene("lathe", ["scenario.duration=2"]))
    samples = 2 * model.scene.solver.sample_rate + 1
    for estimate in outputs.output_sizes(
        output_column_count(model), samples, (csv, 12), (recording, outputs.RECORDING_BYTES_PER_COLUMN), None
    ):
        size = (tmp_path / estimate.name.strip("'")).stat().st_size
        assert estimate.size / ESTIMATE_FACTOR <= size <= estimate.size, (estimate, size)
