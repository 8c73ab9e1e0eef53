"""The fast path prints and writes what the reference path does: on every bundled scene the summary of
`mech-regulator simulate --json` (analysis.summarise: energy works and residual, steady-motion figures, the governor's
load responses, the two-mass and drive-train figures) and the sampled columns `--out` writes agree field by field,
and the runs change mode at the same events.

The bound. Two runs of a scene at the same tolerances differ by their integration errors, and at the bundled scenes'
tolerances these are not rtol-sized: DOP853's error estimate passes steps across the kinks of an engine's pressure
table with errors far above rtol (engine_inline4, rtol 1e-10: one step of the fast run errs by 6e-5 rad/s), and
which path is the luckier changes from scene to scene. So each run's own error is measured: the same path at a tenth
of the tolerances is several times more accurate, and |x - x'| (x' from that run) estimates the error of x. A figure
agrees when

    |x_reference - x_fast| <= 10 (|x_reference - x_reference'| + |x_fast - x_fast'|) + 10 rtol scale(x),

scale(x) the largest work [J] for the energy figures, the duration for event times, |x| otherwise (for a sampled
column its largest |value|); a figure read off a sampling grid (a load response's peak and settling times, a
section's peak time) may differ by one grid step more. Measured, the differences stay below 0.3 of this bound. A fault
of one path that does not shrink with the tolerance breaks it: before the paths were held equal the fast path integrated
the works over whole compiled calls of up to 2000 steps (startup's residual 8.1 J against 2.4e-9 J). Text (numbers in a
note aside), flags and counts are equal. The energy residual, zero for the exact motion, stays below RESIDUAL_LIMIT of
the largest work on both paths (measured: at most 5e-6; the fault above made it 5e-3 to 3 on the 16 scenes it touched).

The slow reference runs are shortened (SHORTENED; the load changes that end within the shortened run are kept): the
104 runs and their summaries take some 90 s of CPU, a cold DOP853 stepper some 45 s more (docs/speed.md). The
solver's statistics (steps, evaluations) are not compared: the step sequences of the two paths part at round-off.
"""

from __future__ import annotations

import functools
import json
import math
import re
from dataclasses import dataclass

import numpy as np
import pytest

from mech_regulator.analysis import summarise
from mech_regulator.model import build_model
from mech_regulator.scene import Scene, bundled_scenes, load_scene
from mech_regulator.solvers import simulate
from mech_regulator.solvers.compiled import fast_path_refusal

SHORTENED = {
    "engine": 4.5,
    "engine_direct": 3.0,
    "engine_hartnell": 4.5,  # the load step at 2 s and its response (settled in about 2 s), not the rejection at 9 s
    "engine_pi": 4.5,
    "engine_indirect_isodromic": 3.0,
    "engine_indirect_none": 3.0,
    "engine_indirect_rigid": 3.0,
    "compressor": 3.0,
    "two_mass": 1.5,
}  # durations [s]
TIGHTER = 10.0  # the error-measuring runs use rtol / TIGHTER and atol / TIGHTER
MARGIN = 10.0  # allowed: MARGIN times the runs' measured errors, plus MARGIN rtol times the figure's scale
RESIDUAL_LIMIT = 1e-4  # largest |energy residual| / largest |work|
LOAD_RESPONSE_GRID = 1.0 / 2000.0  # [s] the grid analysis.load_response reads a response's times off
NUMBER = re.compile(r"[-+]?\d+(\.\d*)?([eE][-+]?\d+)?")
# The bundled scenes the fast path compiles (solvers/compiled/__init__.py fast_path_refusal: all of them, the general
# linkages included).
SCENES = [name for name in bundled_scenes() if fast_path_refusal(load_scene(name)) is None]


@dataclass(frozen=True)
class Run:
    """What one run of a scene prints and writes: the scene as run, its summary (as `simulate --json` prints it), the
    columns `simulate --out` writes (at the scene's sample rate), its mode changes (time [s], what) and the number
    of pieces of its trajectory."""

    scene: Scene
    summary: dict
    columns: dict[str, np.ndarray]
    events: list[tuple[float, str]]
    pieces: int


def shortening(name: str) -> list[str]:
    """--set overrides that run a bundled scene for its SHORTENED duration, with the load changes ending by then."""
    if name not in SHORTENED:
        return []
    duration = SHORTENED[name]
    events = [
        event.model_dump(exclude_none=True)
        for event in load_scene(name).scenario.load_events
        if event.time + (event.ramp or 0.0) <= duration
    ]
    return [f"scenario.duration={duration}", f"scenario.load_events={json.dumps(events)}"]


@functools.cache
def run(name: str, path: str, tighter: float = 1.0) -> Run:
    """The bundled scene `name` (shortened) on `path`, 'reference' or 'fast', at its tolerances divided by tighter."""
    solver = load_scene(name).solver
    tolerances = [f"solver.rtol={solver.rtol / tighter}", f"solver.atol={solver.atol / tighter}"]
    model = build_model(load_scene(name, [*shortening(name), f"solver.path={path}", *tolerances]))
    trajectory = simulate(model)
    times = trajectory.samples(model.scene.solver.sample_rate)
    return Run(
        model.scene,
        summarise(model, trajectory),
        model.columns(times, trajectory(times)),
        trajectory.events,
        len(trajectory.interpolants),
    )


def runs(name: str) -> tuple[Run, Run, Run, Run]:
    """(reference, fast, reference at the tighter tolerances, fast at the tighter tolerances)."""
    return run(name, "reference"), run(name, "fast"), run(name, "reference", TIGHTER), run(name, "fast", TIGHTER)


def allowed(
    reference: float,
    fast: float,
    reference_tight: float,
    fast_tight: float,
    scale: float,
    rtol: float,
    grid: float = 0.0,
) -> float:
    """The bound of the module docstring for one figure, from its values on both paths at the scene's tolerances and
    at the tighter ones, its scale, the scene's rtol and the step [s] of the grid it is read off (0: none)."""
    measured = abs(reference - reference_tight) + abs(fast - fast_tight)
    return MARGIN * measured + MARGIN * rtol * scale + grid


def leaves(tree, path: str = "") -> dict[str, object]:
    """The figures of a summary by their path, e.g. 'energy.works.drive', 'governor.load_responses.0.peak_time'."""
    if isinstance(tree, dict):
        return {key: value for name, child in tree.items() for key, value in leaves(child, f"{path}.{name}").items()}
    if isinstance(tree, (list, tuple)):
        return {key: value for i, child in enumerate(tree) for key, value in leaves(child, f"{path}.{i}").items()}
    return {path.lstrip("."): tree}


def grid_step(scene: Scene, key: str) -> float:
    """The step [s] of the sampling grid a figure is read off; 0 for one located on the dense output."""
    if re.fullmatch(r"governor\.load_responses\.\d+\.(peak_time|settling_time)", key):
        return LOAD_RESPONSE_GRID
    if re.fullmatch(r"drive_train\.sections\.\w+\.time", key):
        return 1.0 / scene.solver.sample_rate
    return 0.0


def disagreement(key: str, values: list, scene: Scene, energy_scale: float) -> str | None:
    """Why the figure `key` of the reference and fast runs disagrees, None when it agrees (values: the reference
    run's, the fast run's, then both at the tighter tolerances): numbers within the bound of the module docstring,
    text equal but for its numbers, anything else equal."""
    reference, fast = values[:2]
    if isinstance(reference, float) and isinstance(fast, float):
        scale = energy_scale if key.startswith("energy.") else abs(reference)
        bound = allowed(*values, scale, scene.solver.rtol, grid_step(scene, key))
        if abs(reference - fast) <= bound or math.isnan(reference) and math.isnan(fast):
            return None
        return f"{key}: reference {reference!r}, fast {fast!r}, allowed {bound:.3g}"
    if isinstance(reference, str) and isinstance(fast, str):
        same = NUMBER.sub("#", reference) == NUMBER.sub("#", fast)
    else:
        same = reference == fast and type(reference) is type(fast)
    return None if same else f"{key}: reference {reference!r}, fast {fast!r}"


def largest_work(summary: dict) -> float:
    """The largest |work| of a run's energy balance [J]."""
    return max(abs(work) for work in summary["energy"]["works"].values())


def test_shortened_scenes_are_bundled():
    assert set(SHORTENED) <= set(SCENES)


@pytest.mark.parametrize("name", SCENES)
def test_summary_field_by_field(name):
    reference, fast, reference_tight, fast_tight = runs(name)
    # the fast path's pieces are compiled calls of many steps, the reference path's single steps
    assert fast.pieces < fast.summary["solver"]["steps"]
    figures = [
        leaves({key: value for key, value in run.summary.items() if key != "solver"})
        for run in (reference, fast, reference_tight, fast_tight)
    ]
    assert figures[0].keys() == figures[1].keys() == figures[2].keys() == figures[3].keys()
    energy_scale = largest_work(reference.summary)
    failures = [disagreement(key, [tree[key] for tree in figures], reference.scene, energy_scale) for key in figures[0]]
    assert not any(failures), "\n".join(failure for failure in failures if failure)


@pytest.mark.parametrize("name", SCENES)
def test_energy_balance_closes_on_both_paths(name):
    for run in runs(name)[:2]:
        residual, work = run.summary["energy"]["residual"], largest_work(run.summary)
        path = run.scene.solver.path
        assert abs(residual) <= RESIDUAL_LIMIT * work, f"{path}: residual {residual:.3g} J, largest work {work:.3g} J"


@pytest.mark.parametrize("name", SCENES)
def test_events_in_the_same_order_at_the_same_times(name):
    reference, fast, *_ = runs(name)
    assert [what for _, what in fast.events] == [what for _, what in reference.events]
    duration, rtol = reference.scene.scenario.duration, reference.scene.solver.rtol
    for times in zip(*([time for time, _ in run.events] for run in runs(name))):
        assert abs(times[0] - times[1]) <= allowed(*times, duration, rtol), times


@pytest.mark.parametrize("name", SCENES)
def test_sampled_columns(name):
    reference, fast, reference_tight, fast_tight = runs(name)
    assert list(fast.columns) == list(reference.columns)
    rtol = reference.scene.solver.rtol
    failures = []
    for column, values in reference.columns.items():
        difference = np.max(np.abs(values - fast.columns[column]))
        measured = np.max(np.abs(values - reference_tight.columns[column])) + np.max(
            np.abs(fast.columns[column] - fast_tight.columns[column])
        )
        bound = MARGIN * measured + MARGIN * rtol * np.max(np.abs(values))
        if not difference <= bound:
            failures.append(f"{column}: differs by {difference:.3g}, allowed {bound:.3g}")
    assert not failures, "\n".join(failures)
