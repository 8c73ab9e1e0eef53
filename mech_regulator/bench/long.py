"""The long-run matrix (`mech-regulator bench long`): bundled scenes x paths x methods, each through `simulate` (the
monolithic run) and through the in-process co-simulation (`simulate --exchange-step`, what the nodes compute), for a
long simulated time (docs/hard_cases.md, "Long runs").

Each row runs the scene as it is (its load events kept, and the `--set` changes asked for) made to last `duration` s
with solver.path and solver.method set, and prints how it ended (complete, failed, refused before the start with the
refusal's message, or stopped when its wall-time budget ran out), its wall time (the run, its probe and its analysis),
its steps (the co-simulation: its exchanges), the energy balance's relative residual (the monolithic run; the
co-simulation keeps no dense output) and the steady-state figures of its last dynamic period (cycle-mean speed omega_m
and coefficient of fluctuation delta) against the same row run for the scene's own duration (16 s for most). A
`simulate` row is the `simulate` command's run, streamed as it streams (analysis/stream.py: its dense output is not kept
whole), its figures its summary's. A row that a path does not run (Radau and the energy method on the fast path) is left
out. Numbers to read, never asserted. The solvers load when a row runs.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable

PATHS = ("fast", "reference")
METHODS = ("DOP853", "RK45", "RK4", "Radau", "energy")
MODES = ("simulate", "cosim")
REFERENCE_ONLY = ("Radau", "energy")  # the methods the fast path does not run (solvers/compiled)
EXCHANGE_STEP = 0.02  # [s] of the co-simulated rows: the nodes' default (scenario_keys.DEFAULT_EXCHANGE_STEP)


@dataclasses.dataclass(frozen=True)
class Row:
    """One run of the matrix: its scene, path, method and mode (simulate or cosim); how it ended (status, message),
    the wall time [s] (the run with its probe and analysis; the budget stops the run itself), steps (the co-simulation:
    exchanges), the relative energy residual [-] (None: not worked out) and the last dynamic period's omega_m [rad/s]
    and delta [-] of this run and of the scene's own duration (None: not steady or not run)."""

    scene: str
    path: str
    method: str
    mode: str
    status: str
    message: str
    wall: float
    steps: int | None = None
    residual: float | None = None
    omega_m: float | None = None
    delta: float | None = None
    omega_m_short: float | None = None
    delta_short: float | None = None


class _Budget:
    """A progress callback that stops a run (KeyboardInterrupt, which the solvers end `interrupted` on) once its wall
    time passes `seconds`, and remembers that it did; else hands the simulated time t [s] on to `report`."""

    def __init__(self, seconds: float, report: Callable[[float], None] | None = None):
        self.deadline, self.spent, self.report = time.monotonic() + seconds, False, report

    def __call__(self, t: float) -> None:
        if time.monotonic() > self.deadline:
            self.spent = True
            raise KeyboardInterrupt
        if self.report is not None:
            self.report(t)


def matrix(
    scenes: list[str] | None = None,
    paths: tuple[str, ...] = PATHS,
    methods: tuple[str, ...] = METHODS,
    modes: tuple[str, ...] = MODES,
) -> list[tuple[str, str, str, str]]:
    """The rows asked for, (scene, path, method, mode), every bundled scene by default; the methods a path does not
    run are left out."""
    from mech_regulator.scene import bundled_scenes

    return [
        (scene, path, method, mode)
        for scene in (scenes or list(bundled_scenes()))
        for path in paths
        for method in methods
        for mode in modes
        if not (path == "fast" and method in REFERENCE_ONLY)
    ]


def run_row(
    scene: str,
    path: str,
    method: str,
    mode: str,
    duration: float,
    budget: float,
    overrides: tuple[str, ...] = (),
    progress: Callable[[float], None] | None = None,
) -> Row:
    """The row (scene, path, method, mode) run for `duration` [s] of simulated time within `budget` [s] of wall time,
    and again for the scene's own duration for its steady figures; overrides: `KEY=VALUE` scene changes (`--set`)
    applied to both, before the row's path and method; progress: called with the long run's simulated time [s] as it
    goes (not the short run's)."""
    from mech_regulator.model import build_model
    from mech_regulator.scene import SceneError, load_scene

    settings = [*overrides, f"solver.path={path}", f"solver.method={method}"]
    started = time.monotonic()
    try:
        model = build_model(load_scene(scene, settings + [f"scenario.duration={duration!r}"]))
        short = build_model(load_scene(scene, settings))
        stopper = _Budget(budget, progress)
        run = _run(model, mode, stopper)
    except SceneError as refusal:
        return Row(scene, path, method, mode, "refused", str(refusal), time.monotonic() - started)
    wall = time.monotonic() - started
    status, message = run["status"], run["message"]
    if stopper.spent:
        status, message = "stopped (wall-time budget)", f"at t = {run['t_end']:.6g} s"
    figures = _run(short, mode, _Budget(budget)) if run["steady"] is not None else {"steady": None}
    return Row(
        scene,
        path,
        method,
        mode,
        status,
        message,
        wall,
        run["steps"],
        run["residual"],
        *(run["steady"] or (None, None)),
        *(figures["steady"] or (None, None)),
    )


def _run(model, mode: str, progress: Callable[[float], None]) -> dict:
    """Run the model by simulate (streamed, its figures its summary's, as the `simulate` command's) or by the
    co-simulation; its status, message, end [s], steps (exchanges), relative energy residual and last period's
    (omega_m, delta) when steady. Refusals raise SceneError."""
    from mech_regulator.analysis import analyse_steady_state, cosimulation_ending, simulate_streamed, summarise
    from mech_regulator.scene import SceneError
    from mech_regulator.solvers.cosim import cosimulate

    if mode == "simulate":
        summary = summarise(model, *simulate_streamed(model, progress))
        energy, steady = summary["energy"], summary["steady"]
        last = steady["last_period"] if steady is not None and steady["steady"] else None
        return {
            "status": summary["status"],
            "message": summary["message"],
            "t_end": summary["t_end"],
            "steps": summary["solver"]["steps"],
            "residual": energy["relative_residual"] if energy is not None else None,
            "steady": (last["omega_m"], last["delta"]) if last is not None else None,
        }
    try:
        run = cosimulate(model, EXCHANGE_STEP, progress=progress)
    except ValueError as error:  # a scene the co-simulation does not take
        raise SceneError(str(error)) from None
    trajectory = run.trajectory(model)
    status, message = cosimulation_ending(run)
    periods = analyse_steady_state(model, trajectory) if trajectory.t_end > trajectory.t_start else None
    last_period = periods.last if periods is not None and periods.steady else None
    return {
        "status": status,
        "message": message,
        "t_end": trajectory.t_end,
        "steps": int(run.times.size) - 1,
        "residual": None,
        "steady": (last_period.omega_m, last_period.delta) if last_period is not None else None,
    }


def format_header(duration: float) -> str:
    """The table's header (Markdown), for rows of `duration` [s]."""
    return (
        f"| scene | path | method | mode | status ({duration:g} s) | wall [s] | steps | energy residual | "
        "omega_m [rad/s] | vs own duration | delta | vs own duration |\n"
        "|---|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|"
    )


def format_row(row: Row) -> str:
    """A row of the table (Markdown), on one line: the figures against the short run's as differences relative to
    them; a message of several lines (a scene's problems) is joined, its first 90 characters shown."""

    def number(value: float | None, spec: str) -> str:
        return "-" if value is None else format(value, spec)

    def relative(value: float | None, short: float | None) -> str:
        return "-" if value is None or short is None or short == 0.0 else f"{value / short - 1.0:+.1e}"

    status = row.status if row.status == "complete" else f"{row.status}: {' '.join(row.message.split())[:90]}"
    return (
        f"| {row.scene} | {row.path} | {row.method} | {row.mode} | {status} | {row.wall:.0f} | "
        f"{number(row.steps, 'd')} | {number(row.residual, '.1e')} | {number(row.omega_m, '.6g')} | "
        f"{relative(row.omega_m, row.omega_m_short)} | {number(row.delta, '.4g')} | "
        f"{relative(row.delta, row.delta_short)} |"
    )
