"""What a newcomer meets (`mech-regulator bench first-run`): a fresh clone of this repository with an empty HOME, each
step timed from outside as the README tells it (wall time, one process each):

- set-up: `./dev run --help` in the clone: the venv made and the main job's packages installed (what `./dev run` does
  first; `run --help` after it takes a tenth of a second and compiles nothing), with no pip cache unless one is given;
- first command: `.venv/bin/mech-regulator scenes` (compiles nothing; starts the command server, as for a user);
- first main job: `./dev run SCENE` (its stepper compiled before the nodes start, then the nodes), its real-time
  factor, start-up and path read from the run's summary and parameter file;
- warm main job: the same again, the caches filled: the pace the first run is compared with.

The clone is `git clone` of this checkout's repository (its committed HEAD); HOME, the cache folders (XDG_CACHE_HOME,
the command server's XDG_RUNTIME_DIR) and pip's cache point into the benchmark's own folder; the variables of this
project (MECH_REGULATOR_*, NUMBA_*), of a venv (VIRTUAL_ENV, PYTHONPATH, PYTHONHOME) and the venv's bin on PATH are
taken away, so that `python3` is the system's, as in a new shell. The folder is removed at the end (about 1.5 GB)
unless kept. Numbers to read, never asserted.
"""

from __future__ import annotations

import dataclasses
import json
import os
import platform
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

DROPPED_PREFIXES = ("MECH_REGULATOR_", "NUMBA_", "PIP_", "XDG_")
DROPPED_VARIABLES = ("VIRTUAL_ENV", "PYTHONPATH", "PYTHONHOME", "CONDA_PREFIX")


@dataclasses.dataclass
class Step:
    """One step of the first run: its title, command (run in folder `cwd`), and once measured its wall time [s], what
    was read off it, and its exit code."""

    title: str
    command: list[str]
    cwd: Path
    wall_s: float | None = None
    found: str = ""
    exit_code: int | None = None
    summary: dict | None = None  # a main job's summary (the recorder's JSON) and "path"


@dataclasses.dataclass
class FirstRun:
    """The steps, where the clone was made, the machine, and whether Ctrl-C cut the benchmark short."""

    folder: Path
    steps: list[Step]
    machine: dict[str, str]
    interrupted: bool = False


def repository_root() -> Path:
    """The git checkout this package runs from (the folder with .git above mech_regulator/); ValueError naming the
    folder if it is none (an installed wheel: nothing to clone)."""
    package = Path(__file__).resolve().parents[1]
    for folder in (package.parent, *package.parent.parents):
        if (folder / ".git").exists() and (folder / "dev").is_file():
            return folder
    raise ValueError(
        f"{package} is not in a git checkout of the project (with ./dev): bench first-run clones the "
        "checkout it runs from; run it from a clone's .venv"
    )


def clean_environment(home: Path, pip_cache: Path | None) -> dict[str, str]:
    """A new user's shell: this environment less the project's, numba's, pip's and XDG's variables and any venv
    (module docstring), HOME=home, XDG_CACHE_HOME and XDG_RUNTIME_DIR under it, and pip's cache off (pip_cache None)
    or that folder."""
    environment = {
        key: value
        for key, value in os.environ.items()
        if not key.startswith(DROPPED_PREFIXES) and key not in DROPPED_VARIABLES
    }
    venv_bin = str(Path(sys.prefix) / "bin")
    if sys.prefix != sys.base_prefix:
        environment["PATH"] = os.pathsep.join(
            part for part in environment.get("PATH", "").split(os.pathsep) if part.rstrip("/") != venv_bin
        )
    environment.update(HOME=str(home), XDG_CACHE_HOME=str(home / ".cache"), XDG_RUNTIME_DIR=str(home / "run"))
    if pip_cache is None:
        environment["PIP_NO_CACHE_DIR"] = "1"
    else:
        environment["PIP_CACHE_DIR"] = str(pip_cache)
    return environment


def plan(folder: Path, scene: str) -> list[Step]:
    """The steps (module docstring) in `folder`: the clone in folder/clone, the runs' outputs in folder/runs."""
    clone = folder / "clone"
    runs = folder / "runs"
    return [
        Step("clone", ["git", "clone", "--quiet", str(repository_root()), str(clone)], folder),
        Step("set-up (./dev's venv, the main job's packages)", ["bash", "./dev", "run", "--help"], clone),
        Step("first command", [".venv/bin/mech-regulator", "scenes"], clone),
        Step(
            "first main job (empty compile caches)",
            ["bash", "./dev", "run", scene, "--out", str(runs / "first" / f"{scene}.rrd")],
            clone,
        ),
        Step(
            "warm main job (the same again)",
            ["bash", "./dev", "run", scene, "--out", str(runs / "warm" / f"{scene}.rrd")],
            clone,
        ),
    ]


def main_job_summary(recording: Path) -> dict | None:
    """The run's summary (the recorder's JSON next to the recording) with "path", the solver path the nodes ran
    (the `solver.path=` override run wrote into the parameter file; `scene's` when there is none); None without
    a summary."""
    import yaml

    try:
        summary = json.loads(recording.with_suffix(".json").read_text(encoding="utf-8"))
        parameters = yaml.safe_load(recording.with_suffix(".params.yaml").read_text(encoding="utf-8"))
    except (OSError, ValueError, yaml.YAMLError):
        return None
    overrides = parameters.get("/**", {}).get("ros__parameters", {}).get("overrides", [])
    paths = [item.split("=", 1)[1] for item in overrides if str(item).startswith("solver.path=")]
    summary["path"] = paths[-1] if paths else "scene's"
    return summary


def describe_run(summary: dict | None) -> str:
    """A main job's line of the table: status, path, real-time factor, start-up."""
    if summary is None:
        return "no summary"
    pace = f"{summary['real_time_factor']:.3g} x real time" if "real_time_factor" in summary else "no pace"
    start_up = f", start-up {summary['start_up_s']:.3g} s" if "start_up_s" in summary else ""
    return f"{summary.get('status')}, {summary['path']} path, {pace}{start_up}"


def measure_first_run(
    folder: Path, scene: str, pip_cache: Path | None, report: Callable[[str], None] = print
) -> FirstRun:
    """Clone, set up and run (module docstring) in `folder` (made here), each step's output in folder/STEP.log;
    report(line) before and after each step. Stops at the first step that fails (its exit code and log kept); Ctrl-C
    stops the step under way and returns what was measured (interrupted)."""
    from mech_regulator.bench.startup import environment as machine

    home = folder / "home"
    home.mkdir(parents=True)
    environment = clean_environment(home, pip_cache)
    steps = plan(folder, scene)
    result = FirstRun(folder, steps, machine())
    for index, step in enumerate(steps):
        log = folder / f"step{index}.log"
        recording = Path(step.command[step.command.index("--out") + 1]) if "--out" in step.command else None
        if recording is not None:
            recording.parent.mkdir(parents=True)  # run refuses a recording whose folder is missing
        report(f"bench first-run: {step.title}: `{' '.join(step.command)}` (output in {log}) ...")
        started = time.perf_counter()
        with open(log, "w") as output:
            process = subprocess.Popen(
                step.command,
                cwd=step.cwd,
                env=environment,
                stdin=subprocess.DEVNULL,
                stdout=output,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )
            try:
                step.exit_code = process.wait()
            except KeyboardInterrupt:
                os.killpg(process.pid, signal.SIGINT)  # as Ctrl-C at a terminal: the run keeps its summary
                process.wait()
                result.interrupted = True
                return result
        step.wall_s = time.perf_counter() - started
        if recording is not None:
            step.summary = main_job_summary(recording)
            step.found = describe_run(step.summary)
        report(
            f"bench first-run: {step.title}: {step.wall_s:.1f} s, exit {step.exit_code}"
            f"{f'; {step.found}' if step.found else ''}"
        )
        if step.exit_code != 0:
            break
    _stop_server(folder / "clone", environment)
    return result


def _stop_server(clone: Path, environment: dict[str, str]) -> None:
    """`mech-regulator server stop` in the clone's environment: the first command started one."""
    command = clone / ".venv" / "bin" / "mech-regulator"
    if command.is_file():
        subprocess.run([str(command), "server", "stop"], cwd=clone, env=environment, capture_output=True, check=False)


def remove(folder: Path) -> None:
    """Remove the benchmark's folder (the clone's venv: about 1.5 GB)."""
    shutil.rmtree(folder, ignore_errors=True)


def warm_ratio(result: FirstRun) -> float | None:
    """The first main job's real-time factor over the warm one's (None unless both have one)."""
    first, warm = (step.summary for step in result.steps[-2:])
    if not first or not warm or "real_time_factor" not in first or "real_time_factor" not in warm:
        return None
    return first["real_time_factor"] / warm["real_time_factor"]


def format_table(result: FirstRun, pip_cache: Path | None) -> str:
    """The steps as a markdown table (wall time, what was read), the machine, the ratio of the first run's pace to
    the warm run's."""
    machine = result.machine
    cache = "no pip cache" if pip_cache is None else f"pip cache {pip_cache}"
    lines = [
        f"first run of a fresh clone, empty HOME, {cache}; {machine['processor']}, {machine['cores']} cores, "
        f"load {os.getloadavg()[0]:.1f} at the end, {platform.system()} {platform.release()}, Python "
        f"{platform.python_version()}, {machine['date']}",
        "",
        "| step | command | wall time [s] | |",
        "| --- | --- | ---: | --- |",
    ]
    for step in result.steps:
        if step.wall_s is None:
            continue
        exit_note = "" if step.exit_code == 0 else f"exit {step.exit_code}; "
        lines.append(f"| {step.title} | `{' '.join(step.command)}` | {step.wall_s:.1f} | {exit_note}{step.found} |")
    ratio = warm_ratio(result)
    if ratio is not None:
        lines += ["", f"the first main job's real-time factor is {ratio:.2f} of the warm run's"]
    if result.interrupted:
        lines += ["", "interrupted: the steps above were measured"]
    return "\n".join(lines)
