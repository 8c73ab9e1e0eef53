"""`mech-regulator bench first-run`: its plan and its refusals, and its environment (a new user's shell); the
benchmark itself (minutes, a 1.5 GB venv) is never run by the suite. Times are never asserted."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import yaml
from support import SOURCE_TREE, run_cli

from mech_regulator.bench.first_run import (
    FirstRun,
    Step,
    clean_environment,
    describe_run,
    main_job_summary,
    repository_root,
    warm_ratio,
)


def test_dry_run_prints_each_step_and_its_command_and_makes_nothing(capsys, tmp_path):
    folder = tmp_path / "bench"
    code, out, err = run_cli(capsys, "bench", "first-run", "--dry-run", "--folder", str(folder), "--scene", "lathe")
    assert code == 0 and err == "", err
    assert out.splitlines() == [
        f"clone: (in {folder}) git clone --quiet {SOURCE_TREE} {folder}/clone",
        f"set-up (./dev's venv, the main job's packages): (in {folder}/clone) bash ./dev run --help",
        f"first command: (in {folder}/clone) .venv/bin/mech-regulator scenes",
        f"first main job (empty compile caches): (in {folder}/clone) bash ./dev run lathe --out "
        f"{folder}/runs/first/lathe.rrd",
        f"warm main job (the same again): (in {folder}/clone) bash ./dev run lathe --out {folder}/runs/warm/lathe.rrd",
    ]
    assert not folder.exists()


def test_bad_options_are_refused_with_exit_2_before_anything_is_cloned(capsys, tmp_path):
    code, _, err = run_cli(capsys, "bench", "first-run", "--pip-cache", str(tmp_path / "none"))
    assert code == 2 and f"--pip-cache '{tmp_path / 'none'}': expected an existing folder" in err, err
    code, _, err = run_cli(capsys, "bench", "first-run", "--folder", str(tmp_path))
    assert code == 2 and f"--folder '{tmp_path}': expected a new folder (it exists)" in err, err
    code, _, err = run_cli(capsys, "bench", "first-run", "--scene", "no_such_scene", "--dry-run")
    assert code == 2 and "no_such_scene" in err, err
    assert list(tmp_path.iterdir()) == []


def test_the_clone_is_of_this_checkout():
    assert repository_root() == SOURCE_TREE


def test_a_new_users_environment_has_no_venv_nor_project_variables_and_an_empty_home(monkeypatch, tmp_path):
    monkeypatch.setenv("MECH_REGULATOR_CACHE", "/somewhere")
    monkeypatch.setenv("NUMBA_CACHE_DIR", "/somewhere")
    monkeypatch.setenv("PYTHONPATH", "/somewhere")
    monkeypatch.setenv("PATH", f"{Path(sys.prefix) / 'bin'}:/usr/bin")
    monkeypatch.setattr(sys, "base_prefix", "/usr/lib/python")  # as in a venv, whatever runs the suite
    environment = clean_environment(tmp_path, None)
    assert not {"MECH_REGULATOR_CACHE", "NUMBA_CACHE_DIR", "PYTHONPATH"} & set(environment)
    assert environment["PATH"] == "/usr/bin"
    assert (environment["HOME"], environment["XDG_CACHE_HOME"]) == (str(tmp_path), str(tmp_path / ".cache"))
    assert environment["PIP_NO_CACHE_DIR"] == "1" and "PIP_CACHE_DIR" not in environment
    cached = clean_environment(tmp_path, tmp_path / "pip")
    assert cached["PIP_CACHE_DIR"] == str(tmp_path / "pip") and "PIP_NO_CACHE_DIR" not in cached


def write_run(folder: Path, summary: dict, overrides: list[str]) -> Path:
    """A run's summary and parameter file as `run` and the recorder write them; returns the recording's path."""
    folder.mkdir()
    recording = folder / "run.rrd"
    recording.with_suffix(".json").write_text(json.dumps(summary))
    recording.with_suffix(".params.yaml").write_text(
        yaml.safe_dump({"/**": {"ros__parameters": {"overrides": overrides}}})
    )
    return recording


def test_a_main_jobs_pace_and_path_are_read_off_its_summary_and_parameters(tmp_path):
    first = main_job_summary(
        write_run(
            tmp_path / "first",
            {"status": "complete", "real_time_factor": 4.0, "start_up_s": 3.25},
            ["", "solver.path=fast"],
        )
    )
    assert describe_run(first) == "complete, fast path, 4 x real time, start-up 3.25 s"
    warm = main_job_summary(write_run(tmp_path / "warm", {"status": "complete", "real_time_factor": 5.0}, [""]))
    assert describe_run(warm) == "complete, scene's path, 5 x real time"
    assert main_job_summary(tmp_path / "none" / "run.rrd") is None and describe_run(None) == "no summary"
    steps = [Step("first", [], tmp_path, summary=first), Step("warm", [], tmp_path, summary=warm)]
    assert warm_ratio(FirstRun(tmp_path, steps, {})) == 0.8
    steps[0].summary = None
    assert warm_ratio(FirstRun(tmp_path, steps, {})) is None
