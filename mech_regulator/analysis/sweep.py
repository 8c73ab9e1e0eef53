"""Batch sweeps: many scenes run as independent tasks, one row of plain numbers per scene.

A sweep is a grid over dotted scene keys (the keys of `--set`: `key=start:stop:n` linear, `key=start:stop:n:log`
geometric, `key=v1,v2,v3` a list; several axes make the Cartesian product) and/or a list of scene files. Every
point is validated before anything runs. `run_point` simulates one scene with its own solver settings and
returns its row (a point that fails, or whose scene is refused, is a row with that status, never an exception);
`run_sweep` runs the points in this process, on local worker processes or on a Dask cluster, and returns the
rows in the order of the points, whatever order they complete in.

For a governed scene the row holds the stability verdict by simulation (docs/theory.md §8.7): the cycle-mean
speed omega_bar(t) after the last load change (analysis.cycle_mean_speed) is split into thirds; the
oscillation ratio r = ptp(omega_bar over the last third) / ptp(omega_bar over the middle third) is about
exp(sigma T/3) for a mode growing at sigma [1/s] over a window of T seconds. The point is stable when the last
third stays within the scene's settling band, or when r <= 0.9 (the swing shrinks by at least a tenth per third)
and the sleeve (or servo-motor) came onto a stop at most once in the last third; otherwise unstable: the swing
grows, or a limit cycle holds it, which for a governor with stops means the sleeve keeps striking them (its swing
varies from third to third, so r alone could pass it as stable). Next to it: the linear analysis of
the averaged model at the operating point of the final load (analysis.stability.linear_stability) and, for a
direct governor, Vyshnegradsky's A and B (stable iff A B > 1).
"""

from __future__ import annotations

import copy
import itertools
import logging
import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from mech_regulator.mechanisms.checks import refuse_unbuildable
from mech_regulator.scene.loading import SceneError, apply_override, overridden_scene_data, parse_yaml, validate_scene
from mech_regulator.scene.schema import Scene
from mech_regulator.solvers import auto_path
from mech_regulator.solvers.compiled import fast_path_refusal

DECAY_RATIO = 0.9  # stable by simulation: the cycle-mean speed's swing in the last third <= this x the middle third's
VERDICT_SAMPLES = 3000  # samples of the cycle-mean speed over the window after the last load change
ENGINES = ("local", "dask")
ROW_COLUMNS = (
    "status",
    "message",
    "path",
    "t_end",
    "omega_end",
    "steady",
    "omega_m",
    "omega_average",
    "delta",
    "stable_by_simulation",
    "oscillation_ratio",
    "stop_arrivals",
    "stable_linear",
    "vyshnegradsky_A",
    "vyshnegradsky_B",
    "wall_time",
    "rhs_evaluations",
)
"""The columns of a row after the scene's name and its grid values (None where they do not apply)."""
METRICS = (
    "delta",
    "omega_m",
    "omega_average",
    "omega_end",
    "oscillation_ratio",
    "stop_arrivals",
    "vyshnegradsky_A",
    "vyshnegradsky_B",
    "t_end",
    "wall_time",
    "rhs_evaluations",
)
"""The numeric columns a sweep's picture can draw (--metric)."""


@dataclass(frozen=True)
class GridAxis:
    """One --grid option: the dotted scene key, its values (numbers, or YAML values of a list), the YAML text of
    each value as given to the scene, whether the values are geometric (log axes), and the option as typed."""

    key: str
    values: tuple
    texts: tuple[str, ...]
    geometric: bool
    option: str


@dataclass(frozen=True)
class SweepPoint:
    """One scene of a sweep: the scene file or name it came from, its grid values (key -> value) and its scene
    mapping (overrides applied, validated once when the sweep was built)."""

    source: str
    values: dict
    scene: dict


def parse_grid(spec: str) -> GridAxis:
    """Read `key=start:stop:n` (n values by numpy.linspace), `key=start:stop:n:log` (numpy.geomspace, start and
    stop > 0) or `key=v1,v2,...` (each value read as YAML); SceneError naming the option when it does not parse."""
    option = f"--grid '{spec}'"
    if "=" not in spec:
        raise SceneError(
            f"{option}: expected KEY=START:STOP:N, KEY=START:STOP:N:log or KEY=V1,V2,..., e.g. "
            "governor.damping=20:300:5:log"
        )
    key, text = (part.strip() for part in spec.split("=", 1))
    if not key or not all(key.split(".")):
        raise SceneError(
            f"{option}: the key '{key}' has an empty part; expected a dotted scene key such as machine.flywheel.inertia"
        )
    if ":" not in text:
        texts = tuple(item.strip() for item in text.split(","))
        if not all(texts):
            raise SceneError(f"{option}: an empty value in the list '{text}'; expected V1,V2,... (at least one)")
        return GridAxis(key, tuple(parse_yaml(item, option) for item in texts), texts, False, option)
    parts = text.split(":")
    if len(parts) not in (3, 4) or (len(parts) == 4 and parts[3].strip() != "log"):
        raise SceneError(f"{option}: expected START:STOP:N or START:STOP:N:log after '=', got '{text}'")
    try:
        start, stop = float(parts[0]), float(parts[1])
    except ValueError:
        raise SceneError(f"{option}: START and STOP must be numbers, got '{parts[0]}' and '{parts[1]}'") from None
    if not (math.isfinite(start) and math.isfinite(stop)):
        raise SceneError(f"{option}: START and STOP must be finite numbers, got {start:g} and {stop:g}")
    count_text = parts[2].strip()
    if not count_text.lstrip("-").isdigit() or int(count_text) < 1:
        raise SceneError(f"{option}: N = '{count_text}': expected a whole number of values >= 1")
    geometric = len(parts) == 4
    if geometric and not (start > 0.0 and stop > 0.0):
        raise SceneError(f"{option}: a geometric (log) grid needs START > 0 and STOP > 0, got {start:g} and {stop:g}")
    values = tuple(float(value) for value in (np.geomspace if geometric else np.linspace)(start, stop, int(count_text)))
    return GridAxis(key, values, tuple(repr(value) for value in values), geometric, option)


def sweep_points(
    scenes: list[str], overrides: list[str], axes: list[GridAxis], solver_path: str = "scene"
) -> list[SweepPoint]:
    """Every scene x every combination of the grid values (the Cartesian product, the last axis varying fastest),
    each validated by the scene loading: a value the scene refuses raises SceneError naming the --grid option.
    solver_path 'fast': every point the fast path compiles (solvers.compiled.fast_path_refusal) runs on it, the others on
    the reference path; 'reference': every point on the reference path; 'scene': as each scene's solver.path says
    (auto: solvers.auto_path(), fast unless MECH_REGULATOR_AUTO_PATH says otherwise)."""
    keys = [axis.key for axis in axes]
    repeated = sorted({key for key in keys if keys.count(key) > 1})
    if repeated:
        raise SceneError(f"--grid: the key '{repeated[0]}' is given more than once; give each key one --grid")
    if not scenes:
        raise SceneError("sweep: give a SCENE or --scenes (files or bundled scene names)")
    points = []
    for source in scenes:
        base, path = overridden_scene_data(source, overrides)
        _checked_scene(copy.deepcopy(base), str(path))
        for axis in axes:  # each value alone first, so a refusal names the one option that caused it
            for text in axis.texts:
                data = copy.deepcopy(base)
                apply_override(data, f"{axis.key}={text}", option=axis.option)
                _checked_scene(data, f"{axis.option}: {axis.key} = {text} in scene '{source}'")
        for combination in itertools.product(*(range(len(axis.values)) for axis in axes)):
            data = copy.deepcopy(base)
            for axis, index in zip(axes, combination):
                apply_override(data, f"{axis.key}={axis.texts[index]}", option=axis.option)
            values = {axis.key: axis.values[index] for axis, index in zip(axes, combination)}
            where = ", ".join(f"{key} = {axis.texts[index]}" for key, axis, index in zip(keys, axes, combination))
            scene = _checked_scene(copy.deepcopy(data), f"--grid point {where} in scene '{source}'") if axes else None
            chosen = solver_path
            if chosen == "scene":  # the scene's own path; auto as a command takes it (solvers.auto_path)
                scene = scene or _checked_scene(copy.deepcopy(data), str(path))
                chosen = auto_path() if scene.solver.path == "auto" else "scene"
            if chosen != "scene":
                scene = scene or _checked_scene(copy.deepcopy(data), str(path))
                fast = chosen == "fast" and fast_path_refusal(scene) is None
                data.setdefault("solver", {})["path"] = "fast" if fast else "reference"
            points.append(SweepPoint(source, values, data))
    return points


def _checked_scene(data: dict, source: str) -> Scene:
    """The scene of `data` validated and its mechanisms checked (mechanisms/checks.py), refused as from `source`."""
    return refuse_unbuildable(validate_scene(data, source), source)


def run_point(scene: dict, values: dict | None = None) -> dict:
    """Validate, build and simulate one scene with its own solver settings; its row of plain numbers.

    Columns: scene, the grid values, status ('complete', 'failed', 'interrupted', or 'refused' for a scene the
    model or analysis refuses, 'error' for anything unexpected) and message; path (the solver.path it ran on); t_end [s], omega_end [rad/s];
    steady (the motion repeats over the last dynamic periods), omega_m = (omega_max + omega_min) / 2 and
    omega_average = Phi / (time of the period) [rad/s] and delta = (omega_max - omega_min) / omega_m of the last
    dynamic period (analysis.analyse_steady_state); for a governed scene stable_by_simulation, oscillation_ratio
    and stop_arrivals (see the module's docstring), stable_linear and, for a direct governor, vyshnegradsky_A and
    vyshnegradsky_B; wall_time [s] of the simulation and rhs_evaluations. Never raises for a bad point.
    """
    from mech_regulator.analysis import analyse_steady_state
    from mech_regulator.model import build_model
    from mech_regulator.solvers import simulate

    row: dict[str, Any] = {"scene": scene.get("name"), **(values or {}), **dict.fromkeys(ROW_COLUMNS)}
    try:
        model = build_model(validate_scene(copy.deepcopy(scene), f"scene '{scene.get('name')}'"))
        row["path"] = model.scene.solver.path
        start = time.perf_counter()
        trajectory = simulate(model)
        row["wall_time"] = time.perf_counter() - start
        row["rhs_evaluations"] = trajectory.stats.nfev
        row.update(status=trajectory.status, message=trajectory.message, t_end=float(trajectory.t_end))
        if not trajectory.interpolants:  # refused before its first step
            return row
        row["omega_end"] = float(trajectory(trajectory.t_end)[1])
        steady = analyse_steady_state(model, trajectory)
        row["steady"] = steady.steady
        if steady.last is not None:
            row.update(
                omega_m=float(steady.last.omega_m),
                omega_average=float(steady.last.omega_average),
                delta=float(steady.last.delta),
            )
        if model.governor is not None:
            row.update(governor_stability(model, trajectory))
    except SceneError as error:
        row.update(status="refused", message=str(error))
    except Exception as error:  # noqa: BLE001 - one point's failure is its row, never the end of the sweep
        row.update(status="error", message=f"{type(error).__name__}: {error}")
    return row


def governor_stability(model, trajectory) -> dict:
    """The governed run's stability: by simulation (oscillation_ratio, stable_by_simulation; see the module's
    docstring) and by the linear analysis of the averaged model at the operating point of the load after the last
    load change (stable_linear, Vyshnegradsky A and B for a direct governor)."""
    from mech_regulator.analysis import linear_stability, operating_point

    t_from = max([0.0] + [piece.start for piece in model.load_pieces])
    linear = linear_stability(model, operating_point(model, model.external_load(t_from)))
    answer: dict[str, float | bool | int | None] = {
        "stable_linear": linear.stable,
        "vyshnegradsky_A": None,
        "vyshnegradsky_B": None,
    }
    if linear.vyshnegradsky is not None:
        answer["vyshnegradsky_A"], answer["vyshnegradsky_B"] = (float(value) for value in linear.vyshnegradsky)
    ratio, settled, arrivals = oscillation_measures(model, trajectory, t_from)
    answer["oscillation_ratio"], answer["stop_arrivals"] = ratio, arrivals
    answer["stable_by_simulation"] = (
        None if math.isnan(ratio) else bool(settled or (ratio <= DECAY_RATIO and arrivals <= 1))
    )
    return answer


def oscillation_measures(model, trajectory, t_from: float) -> tuple[float, bool, int]:
    """(r, settled, arrivals) over the window [t_from, t_end] split into thirds: r = ptp(omega_bar) over the last
    third / ptp(omega_bar) over the middle third, omega_bar the cycle-mean speed [rad/s]; settled: the last third
    stays within the scene's settling band (ptp <= settling_band x its mean speed); arrivals: how often the sleeve
    or the servo-motor came onto a stop during the last third (trajectory.modes). r is NaN when the window is
    shorter than three dynamic periods."""
    from mech_regulator.analysis import cycle_mean_speed

    t_to = trajectory.t_end
    third = (t_to - t_from) / 3.0
    modes = trajectory.modes
    arrivals = sum(
        1
        for (_, before), (t, mode) in zip(modes, modes[1:])
        if t >= t_from + 2.0 * third
        for part, previous in zip(mode, before)
        if part in ("low", "high") and part != previous
    )
    cycle_time = model.dynamic_period() / max(abs(float(trajectory(t_to)[1])), 1e-12)
    if t_to - t_from < 3.0 * cycle_time:
        return math.nan, False, arrivals
    times = np.linspace(t_from, t_to, VERDICT_SAMPLES)
    speed = cycle_mean_speed(model, trajectory, times)
    middle = speed[(times >= t_from + third) & (times < t_from + 2.0 * third)]
    last = speed[times >= t_from + 2.0 * third]
    swing_middle, swing_last = np.nanmax(middle) - np.nanmin(middle), np.nanmax(last) - np.nanmin(last)
    settled = bool(swing_last <= model.scene.analysis.settling_band * abs(np.nanmean(last)))
    ratio = swing_last / swing_middle if swing_middle > 0.0 else (0.0 if swing_last == 0.0 else math.inf)
    return float(ratio), settled, arrivals


def check_executor(jobs: int | None, engine: str, scheduler: str | None) -> int:
    """The number of worker processes (default: the number of cores); SceneError for options that do not fit."""
    jobs = (os.cpu_count() or 1) if jobs is None else jobs
    if jobs < 1:
        raise SceneError(f"--jobs {jobs}: expected at least 1 worker process")
    if engine not in ENGINES:
        raise SceneError(f"--engine {engine}: expected one of {', '.join(ENGINES)}")
    if scheduler is not None and engine != "dask":
        raise SceneError(f"--scheduler {scheduler}: a scheduler address needs --engine dask")
    return jobs


def run_sweep(
    points: list[SweepPoint],
    jobs: int | None = None,
    engine: str = "local",
    scheduler: str | None = None,
    progress: Callable[[SweepPoint, dict], None] | None = None,
) -> list[dict]:
    """Run every point and return the rows in the order of the points.

    engine 'local': jobs = 1 runs in this process, jobs > 1 on that many worker processes (default: the number
    of cores); engine 'dask': the points are tasks on a Dask cluster, a LocalCluster of `jobs` single-threaded
    worker processes, or the cluster whose scheduler listens at `scheduler` (e.g. tcp://10.0.0.1:8786).
    progress(point, row) is called as each point completes. On Ctrl-C the points not finished get the row
    status 'not run' and the rows are returned (nothing computed is lost)."""
    jobs = check_executor(jobs, engine, scheduler)
    rows: list[dict | None] = [None] * len(points)

    def finished(index: int, row: dict) -> None:
        rows[index] = row
        if progress is not None:
            progress(points[index], row)

    try:
        if engine == "dask":
            _run_on_dask(points, jobs, scheduler, finished)
        elif jobs == 1 or len(points) == 1:
            for index, point in enumerate(points):
                finished(index, run_point(point.scene, point.values))
        else:
            _run_on_processes(points, jobs, finished)
    except KeyboardInterrupt:
        pass
    return [
        row
        if row is not None
        else {
            "scene": point.scene.get("name"),
            **point.values,
            **dict.fromkeys(ROW_COLUMNS),
            "status": "not run",
            "message": "the sweep was interrupted before this point ran",
        }
        for point, row in zip(points, rows)
    ]


def _run_on_processes(points: list[SweepPoint], jobs: int, finished: Callable[[int, dict], None]) -> None:
    """The points on a pool of `jobs` local worker processes (multiprocessing.Pool), each finished as it
    completes; on Ctrl-C the pool's workers are terminated at once (leaving the `with`)."""
    import multiprocessing

    with multiprocessing.Pool(min(jobs, len(points))) as pool:
        for index, row in pool.imap_unordered(_run_indexed, [(index, point) for index, point in enumerate(points)]):
            finished(index, row)


def _run_indexed(item: tuple[int, SweepPoint]) -> tuple[int, dict]:
    """(index, row) of one point: the task of the process pool, which returns rows in completion order."""
    index, point = item
    return index, run_point(point.scene, point.values)


def _run_on_dask(
    points: list[SweepPoint], jobs: int, scheduler: str | None, finished: Callable[[int, dict], None]
) -> None:
    """The points as tasks on a Dask cluster (client.map, as_completed): a LocalCluster of `jobs` processes with
    one thread each, or the running cluster at the scheduler address."""
    try:
        from dask.distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise SceneError(
            "--engine dask needs Dask distributed: pip install 'mech_regulator[distributed]' "
            "(or pip install 'dask[distributed]')"
        ) from None
    cluster = None
    try:
        if scheduler is None:
            # its workers' logs stay quiet: a Ctrl-C reaches them too, and their shutdown reports are no news
            cluster = LocalCluster(
                n_workers=jobs,
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                silence_logs=logging.CRITICAL,
            )
            client = Client(cluster)
        else:
            try:
                client = Client(scheduler, timeout="10s")
            except (OSError, TimeoutError, ValueError) as error:
                raise SceneError(
                    f"--scheduler {scheduler}: no Dask scheduler answers there ({error}); start one "
                    "with `dask scheduler` and workers with `dask worker ADDRESS`"
                ) from None
        with client:
            futures = client.map(
                run_point, [point.scene for point in points], [point.values for point in points], pure=False
            )
            index_of = {future.key: index for index, future in enumerate(futures)}
            try:
                for future in as_completed(futures):
                    finished(index_of[future.key], future.result())
            finally:
                client.cancel(futures)
    finally:
        if cluster is not None:
            cluster.close()
