"""Work–precision benchmark: the accuracy each solver achieves on reference scenes, and what it costs.

For every reference scene (SCENES) and method, one setting is swept: the requested tolerance rtol of
scipy's adaptive methods (atol = rtol x the scene's state scale), the step of RK4, the crank-angle step
of the energy method (machines without a governor or coupling) and the exchange step of the nodes'
lockstep co-simulation (governed scenes). Each run gives its CPU time (time.process_time of the
integration alone, median of repeats), its right-hand-side evaluations and steps, and the error it
ACHIEVED against a reference solution:

- reference: the closed form where there is one (`startup`), else DOP853 at rtol 1e-13 checked by
  Radau at rtol 1e-12; the two references' disagreement is the reference's own error, and a run whose
  headline error lies below it is flagged (its error is not resolved by the reference);
- errors per state component, at the end point and as RMS over a uniform time grid of GRID_RATE
  (the dense output; the co-simulation, which has no dense output, over its exchange times): speeds
  (omega...) relative to max |omega_ref|; angles (phi...) absolute in rad, since they grow; every other
  state (the governor's, a coupling's twist) relative to its range over the reference run;
- headline error of a run: omega's RMS error relative to max |omega_ref|.

Runs are spread over worker processes (`jobs`); CPU time is per process, so workers do not count
each other's work. Nothing here imports rerun or matplotlib (the pictures are in viz.work_precision).
"""

from __future__ import annotations

import contextlib
import math
import multiprocessing
import multiprocessing.connection
import platform
import signal
import statistics
import threading
import time
from collections.abc import Callable, Generator, Iterator
from dataclasses import dataclass, field
from multiprocessing.connection import Connection
from pathlib import Path
from typing import TypeVar

import numpy as np

from mech_regulator.model import MachineModel, build_model
from mech_regulator.scene import SceneError, load_scene
from mech_regulator.scene.effect_keys import ViscousLoad
from mech_regulator.solvers import Trajectory, simulate
from mech_regulator.solvers.cosim import CoSimulation, cosimulate

ADAPTIVE = ("RK45", "DOP853", "Radau", "BDF", "LSODA")
IMPLICIT = ("Radau", "BDF")
COSIM = "co-simulation"
METHODS = ADAPTIVE + ("RK4", "energy", COSIM)

TOLERANCES = tuple(10.0**-k for k in range(3, 11))  # requested rtol of the explicit adaptive methods [-]
IMPLICIT_TIGHTEST = 1e-9  # Radau and BDF stop here: tighter costs minutes
QUICK_TOLERANCES = (1e-4, 1e-6, 1e-8)
RK4_HALVINGS, QUICK_RK4_HALVINGS = 5, 3  # RK4 steps: the scene's rk4_step halved this often
PHI_STEPS_DEG = (2.0, 1.0, 0.5, 0.25, 0.125)  # energy method [deg]
QUICK_PHI_STEPS_DEG = (1.0, 0.5, 0.25)
EXCHANGE_STEPS = (0.01, 0.005, 0.002, 0.001, 0.0005)  # co-simulation [s]
QUICK_EXCHANGE_STEPS = (0.004, 0.002, 0.001)
REFERENCE_METHOD, REFERENCE_RTOL = "DOP853", 1e-13
CHECK_METHOD, CHECK_RTOL = "Radau", 1e-12
QUICK_CHECK_RTOL = 1e-10
COSIM_RTOL = 1e-10  # rtol of the subsystems' own DOP853 inside the co-simulation: far below its hold error
GRID_RATE = 20_000.0  # [Hz] of the uniform time grid on which dense outputs are compared
MIN_GRID_POINTS = 2001
REPEAT_BUDGET_S, MAX_REPEATS = 1.0, 15  # a run is repeated to about this much CPU time [s], at most this often


def startup_closed_form(model: MachineModel) -> Callable[[np.ndarray], np.ndarray]:
    """The exact motion of a constant-J machine driven by a linear motor against viscous loads only.

    J omega' = M0 (1 - omega / omega0) - c omega, so with k = M0 / omega0 + c, omega_inf = M0 / k and
    T = J / k: omega(t) = omega_inf + (omega_i - omega_inf) exp(-t / T) and
    phi(t) = phi_i + omega_inf t + (omega_i - omega_inf) T (1 - exp(-t / T)) (from rest, omega_i = 0:
    omega_inf (1 - exp(-t / T)) and omega_inf (t - T (1 - exp(-t / T)))). Returns the function
    t [s] (array) -> states (phi [rad], omega [rad/s]), shape 2 x n.
    """
    scene = model.scene
    machine = scene.machine
    drive = machine.drive
    viscous = [load for load in machine.loads if isinstance(load, ViscousLoad)]
    if (
        model.reduced is not None
        or model.governor is not None
        or model.load_pieces
        or machine.coupling is not None
        or drive is None
        or drive.type != "linear_motor"
        or len(viscous) != len(machine.loads)
    ):
        raise ValueError(
            f"scene '{scene.name}': the closed form needs a constant J, a linear motor, viscous loads "
            "only, no external load, no governor and no coupling"
        )
    k = drive.stall_torque / drive.no_load_speed + sum(load.coefficient for load in viscous)
    omega_inf, T = drive.stall_torque / k, model.inertia_constant / k
    phi_i, omega_i = scene.scenario.initial.phi, scene.scenario.initial.omega

    def states(t: np.ndarray) -> np.ndarray:
        decay = np.exp(-np.asarray(t) / T)
        return np.vstack(
            [
                phi_i + omega_inf * t + (omega_i - omega_inf) * T * (1.0 - decay),
                omega_inf + (omega_i - omega_inf) * decay,
            ]
        )

    return states


def power_of_ten(value: float) -> str:
    """A number in short scientific notation: 1e-6, 2e-10."""
    mantissa, exponent = f"{value:.0e}".split("e")
    return f"{mantissa}e{int(exponent)}"


def _load_step(at: float, torque: float) -> str:
    """Override replacing a scene's load events by one step of the external load to torque [N m] at `at` [s]."""
    return f"scenario.load_events=[{{time: {at}, torque: {torque}}}]"


@dataclass(frozen=True)
class BenchScene:
    """A reference scene: a bundled scene with overrides (and more for --quick), what it shows, the state
    scale [units of the states] giving atol = rtol x state_scale, RK4's largest step [s], and its closed
    form (t -> states) where it has one."""

    name: str
    scene: str
    overrides: tuple[str, ...]
    quick: tuple[str, ...]
    what: str
    state_scale: float
    rk4_step: float
    closed_form: Callable[[MachineModel], Callable[[np.ndarray], np.ndarray]] | None = None

    def load(self, quick: bool, extra: tuple[str, ...] = ()):
        """The scene with the benchmark's overrides, then --quick's, then `extra`."""
        return load_scene(self.scene, [*self.overrides, *(self.quick if quick else ()), *extra])


SCENES = (
    BenchScene(
        "startup",
        "startup",
        (),
        ("scenario.duration=0.5",),
        "start-up from rest over 2 s",
        1.0,
        0.04,
        startup_closed_form,
    ),
    # 150.2347 rad/s: the speed at phi = 2 pi k on the periodic orbit, from a 40 s run from rest (rtol 1e-12)
    BenchScene(
        "compressor",
        "compressor",
        ("scenario.initial.omega=150.2347", "scenario.duration=1.0"),
        ("scenario.duration=0.1",),
        "steady motion (started on its periodic orbit) for 1 s; the gas force is "
        "a table in the slider position, linear between points, so the moment has kinks in phi that the solvers "
        "step over (breakpoints in x are not located; those of tables in phi are)",
        1.0,
        1e-3,
    ),
    BenchScene(
        "engine_direct",
        "engine_direct",
        ("scenario.duration=2.0", _load_step(0.5, 8.0)),
        ("scenario.duration=0.2", _load_step(0.1, 8.0)),
        "direct governor, load step 6 -> 8 N m at 0.5 s, "
        "2 s; the indicator diagram is a table in phi (kinks every 15 deg)",
        1e-2,
        1e-3,
    ),
    BenchScene(
        "engine_indirect_isodromic",
        "engine_indirect_isodromic",
        ("scenario.duration=1.0", _load_step(0.25, 8.0)),
        ("scenario.duration=0.2", _load_step(0.1, 8.0)),
        "indirect governor with isodromic feedback, load step 6 -> 8 N m at 0.25 s, 1 s",
        1e-2,
        1e-3,
    ),
    BenchScene(
        "two_mass",
        "two_mass",
        ("scenario.duration=1.0", _load_step(0.3, 8.0)),
        ("scenario.duration=0.2", _load_step(0.1, 8.0)),
        "engine and generator on an elastic coupling (the "
        "engine's indicator-diagram table), load step 6 -> 8 N m at 0.3 s, 1 s",
        1e-3,
        1e-3,
    ),
    BenchScene(
        "two_mass_stiff",
        "two_mass",
        (
            "scenario.duration=1.0",
            _load_step(0.3, 8.0),
            "machine.coupling.stiffness=1e7",
            "machine.coupling.damping=400.0",
        ),
        ("scenario.duration=0.2", _load_step(0.1, 8.0)),
        "two_mass with a stiff steel shaft, k = 1e7 N m/rad, "
        "c = 400 N m s/rad: relative mode at 1.2e4 rad/s, damping ratio 0.23, which limits the explicit "
        "methods' step for stability",
        1e-3,
        1e-4,
    ),
)


def select_scenes(names: list[str] | None) -> list[BenchScene]:
    """The reference scenes named (all if names is None); an unknown one is a SceneError naming the choices."""
    if names is None:
        return list(SCENES)
    by_name = {bench.name: bench for bench in SCENES}
    unknown = [name for name in names if name not in by_name]
    if unknown:
        raise SceneError(f"--scenes: no reference scene '{unknown[0]}'; choose from {', '.join(by_name)}")
    return [by_name[name] for name in dict.fromkeys(names)]


@dataclass(frozen=True)
class Setting:
    """One run of a sweep: a method and the value of its accuracy setting: rtol [-] (adaptive methods),
    step [s] (RK4), phi_step_deg [deg] (energy method) or exchange_step [s] (co-simulation)."""

    method: str
    value: float

    @property
    def parameter(self) -> str:
        """Name of the setting swept: rtol, step, phi_step_deg or exchange_step."""
        return {"RK4": "step", "energy": "phi_step_deg", COSIM: "exchange_step"}.get(self.method, "rtol")

    @property
    def label(self) -> str:
        """The setting for a picture: 1e-6 (rtol), 0.5 ms (steps), 0.25° (crank-angle step)."""
        if self.parameter == "rtol":
            return power_of_ten(self.value)
        if self.parameter == "phi_step_deg":
            return f"{self.value:g}°"
        return f"{self.value * 1e3:g} ms"

    def overrides(self, state_scale: float) -> list[str]:
        """Scene overrides that select the method and setting (atol = rtol x state_scale)."""
        if self.method == "RK4":
            return ["solver.method=RK4", f"solver.step={self.value!r}"]
        if self.method == "energy":
            return ["solver.method=energy", f"solver.phi_step_deg={self.value!r}"]
        method, rtol = ("DOP853", COSIM_RTOL) if self.method == COSIM else (self.method, self.value)
        return [f"solver.method={method}", f"solver.rtol={rtol!r}", f"solver.atol={rtol * state_scale!r}"]


def sweep(bench: BenchScene, model: MachineModel, quick: bool) -> list[Setting]:
    """The runs of one scene: every adaptive method over the tolerances (Radau and BDF down to
    IMPLICIT_TIGHTEST), RK4 over halvings of the scene's rk4_step, the energy method where it applies
    (no governor, no coupling) and the co-simulation for governed scenes."""
    tolerances = QUICK_TOLERANCES if quick else TOLERANCES
    settings = [
        Setting(method, rtol)
        for method in ADAPTIVE
        for rtol in tolerances
        if method not in IMPLICIT or rtol >= IMPLICIT_TIGHTEST
    ]
    halvings = QUICK_RK4_HALVINGS if quick else RK4_HALVINGS
    settings += [Setting("RK4", bench.rk4_step / 2**k) for k in range(halvings)]
    if model.governor is None and model.scene.machine.coupling is None:
        settings += [Setting("energy", step) for step in (QUICK_PHI_STEPS_DEG if quick else PHI_STEPS_DEG)]
    if model.governor is not None:
        settings += [Setting(COSIM, step) for step in (QUICK_EXCHANGE_STEPS if quick else EXCHANGE_STEPS)]
    return settings


def time_grid(duration: float) -> np.ndarray:
    """Uniform comparison times [s] over [0, duration] at GRID_RATE (at least MIN_GRID_POINTS)."""
    return np.linspace(0.0, duration, max(MIN_GRID_POINTS, int(round(duration * GRID_RATE)) + 1))


def error_kind(name: str) -> str:
    """How a state's error is given: 'rad' (absolute, for the growing angles phi...) or 'rel' (relative)."""
    return "rad" if name.startswith("phi") else "rel"


def error_scale(name: str, reference: np.ndarray) -> float:
    """The divisor of a state's error given its reference values: 1 for an angle (absolute error in rad),
    max |omega_ref| for a speed (omega...), else the state's range over the run (its largest magnitude if
    it does not move; 1 if it is identically 0)."""
    if error_kind(name) == "rad":
        return 1.0
    largest = float(np.max(np.abs(reference)))
    spread = largest if name.startswith("omega") else float(np.ptp(reference))
    return spread if spread > 0.0 else largest if largest > 0.0 else 1.0


def achieved_errors(
    names: tuple[str, ...], scales: np.ndarray, states: np.ndarray, reference: np.ndarray
) -> dict[str, tuple[float, float]]:
    """Per state: (RMS error over the samples, error at the last sample), each divided by its scale
    (see error_scale); states and reference of shape n_states x n at the same times."""
    difference = np.abs(states - reference) / scales[:, None]
    rms = np.sqrt(np.mean(difference**2, axis=1))
    return {name: (float(rms[i]), float(difference[i, -1])) for i, name in enumerate(names)}


# ---------------------------------------------------------------------------------------------
# Measuring (in worker processes)


@dataclass(frozen=True)
class Task:
    """What a worker runs: a setting on a reference scene, as a timed run ('run') or as the scene's
    reference ('reference', its trajectory kept) or the reference's check ('check'), both run once."""

    scene: str
    quick: bool
    setting: Setting
    role: str = "run"


@dataclass
class Measurement:
    """The outcome of a task: status ('complete', 'failed') and why, median CPU time [s] of `repeats`
    runs, RHS evaluations (None for the co-simulation, whose solver statistics cosimulate does not
    return), steps (co-simulation: exchange steps), the states at `times` [s] (the uniform grid, or the
    exchange times of the co-simulation; empty if the run failed) and, for a reference, its trajectory."""

    task: Task
    status: str
    message: str
    cpu: float
    repeats: int
    nfev: int | None
    steps: int
    times: np.ndarray
    states: np.ndarray
    trajectory: Trajectory | None = None


def _scene_named(name: str) -> BenchScene:
    return next(bench for bench in SCENES if bench.name == name)


Result = TypeVar("Result")


def timed(run: Callable[[], Result]) -> tuple[Result, float]:
    """(run's result, its CPU time [s])."""
    start = time.process_time()
    result = run()
    return result, time.process_time() - start


def measure(task: Task) -> Measurement:
    """Run one task: build the scene with the setting, integrate (timing only the integration: a run is
    repeated until REPEAT_BUDGET_S of CPU time is spent, at most MAX_REPEATS times, and the median taken;
    references and --quick runs run once) and sample the states. A run the user interrupts raises
    KeyboardInterrupt."""
    bench = _scene_named(task.scene)
    setting = task.setting
    model = build_model(bench.load(task.quick, tuple(setting.overrides(bench.state_scale))))

    def run() -> CoSimulation | Trajectory:
        return cosimulate(model, setting.value) if setting.method == COSIM else simulate(model)

    result, cpu = timed(run)
    if result.status == "interrupted":
        raise KeyboardInterrupt
    times = [cpu]
    if task.role == "run" and not task.quick:
        repeats = min(MAX_REPEATS, math.ceil(REPEAT_BUDGET_S / max(cpu, 1e-9)))
        times += [timed(run)[1] for _ in range(repeats - 1)]
    complete = result.status == "complete"
    if isinstance(result, CoSimulation):
        sample_times, states = result.times, result.states
        nfev, steps = None, len(result.times) - 1
    else:
        sample_times = time_grid(model.scene.scenario.duration)
        states = result(sample_times) if complete else np.zeros((len(model.state_names()), 0))
        nfev, steps = result.stats.nfev, result.stats.steps
    return Measurement(
        task,
        result.status,
        result.message,
        statistics.median(times),
        len(times),
        nfev,
        steps,
        sample_times if complete else np.zeros(0),
        states,
        result if task.role == "reference" and isinstance(result, Trajectory) else None,
    )


def _ignore_interrupts() -> None:
    """Workers leave Ctrl-C to the parent, which stops them and keeps what was measured."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


INTERRUPT_POLL_S = 0.1  # [s] how often the parent looks for a Ctrl-C while it waits for the workers
STOP_WAIT_S = 5.0  # [s] of wall time the killed workers are given to end before they are left to the system


@contextlib.contextmanager
def _ctrl_c_as_flag() -> Iterator[threading.Event]:
    """Within the block, Ctrl-C sets the event instead of raising KeyboardInterrupt wherever the main thread is
    (in the middle of receiving a measurement, say): the parent stops between two measurements."""
    pressed = threading.Event()
    previous = signal.signal(signal.SIGINT, lambda number, frame: pressed.set())
    try:
        yield pressed
    finally:
        signal.signal(signal.SIGINT, previous)


def _work(connection: Connection) -> None:
    """A worker process: measure each task received on `connection` and send back its Measurement (or the exception
    it raised), until the parent kills it (_stop_workers)."""
    _ignore_interrupts()
    while True:
        task = connection.recv()
        try:
            result: Measurement | Exception = measure(task)
        except Exception as error:  # raised in the parent, as by a call there
            result = error
        connection.send(result)


def _measured(tasks: list[Task], jobs: int) -> Generator[Measurement, None, None]:
    """Measurements of the tasks as they finish, in `jobs` worker processes (in this process if 1), each given its
    next task as it sends a measurement back; the workers are stopped when the iteration ends or is abandoned, and a
    Ctrl-C raises KeyboardInterrupt here, between two measurements (_ctrl_c_as_flag). Each worker has a pipe of its
    own, which nothing else writes to: a worker stopped in the middle of sending a measurement (160-340 kB, several
    times a pipe's buffer) leaves no lock held that the parent needs (multiprocessing.Pool's workers share one result
    queue, whose write lock such a worker held; Pool.terminate() then waited for it for ever)."""
    if jobs == 1:
        yield from map(measure, tasks)
        return
    waiting = list(reversed(tasks))
    workers: dict[Connection, multiprocessing.Process] = {}
    try:
        with _ctrl_c_as_flag() as pressed:
            for _ in range(min(jobs, len(tasks))):
                parent_end, worker_end = multiprocessing.Pipe()
                worker = multiprocessing.Process(target=_work, args=(worker_end,), daemon=True)
                worker.start()
                worker_end.close()  # the worker's only: its end closes with it (EOFError here, not a hang)
                workers[parent_end] = worker
                parent_end.send(waiting.pop())
            for _ in tasks:
                ready: list = []
                while not ready:
                    if pressed.is_set():
                        raise KeyboardInterrupt
                    ready = multiprocessing.connection.wait(list(workers), timeout=INTERRUPT_POLL_S)
                connection = ready[0]
                try:
                    result = connection.recv()
                except EOFError:
                    workers[connection].join(STOP_WAIT_S)
                    raise RuntimeError(
                        f"a benchmark worker ended while measuring (exit code {workers[connection].exitcode})"
                    ) from None
                if isinstance(result, Exception):
                    raise result
                if waiting:
                    connection.send(waiting.pop())
                yield result
    finally:
        _stop_workers(workers)


def _stop_workers(workers: dict[Connection, multiprocessing.Process]) -> None:
    """Kill the workers (idle, or measuring, or sending a measurement: nothing they hold is the parent's), wait for
    each to end, STOP_WAIT_S of wall time at most in all, and close their pipes."""
    for worker in workers.values():
        worker.kill()
    deadline = time.monotonic() + STOP_WAIT_S
    for connection, worker in workers.items():
        worker.join(max(deadline - time.monotonic(), 0.0))
        connection.close()


# ---------------------------------------------------------------------------------------------
# Results


@dataclass
class Run:
    """A measured run: its setting, status, median CPU time [s] over `repeats`, RHS evaluations (None:
    not reported), steps, and its achieved errors per state, (RMS, endpoint), as error_kind and
    error_scale say (empty until the reference is known, or if the run failed)."""

    setting: Setting
    status: str
    message: str
    cpu: float
    repeats: int
    nfev: int | None
    steps: int
    errors: dict[str, tuple[float, float]] = field(default_factory=dict)

    @property
    def error(self) -> float:
        """Headline error: omega's RMS error relative to max |omega_ref| (nan if not known)."""
        return self.errors["omega"][0] if "omega" in self.errors else math.nan


@dataclass
class SceneResult:
    """A reference scene's outcome: its description, duration [s], state names, what the reference is,
    the reference's own error per state (RMS, endpoint: the disagreement of its check; None for a closed
    form or before the check is in) and the runs."""

    bench: BenchScene
    description: str
    duration: float
    state_names: tuple[str, ...]
    reference: str
    reference_errors: dict[str, tuple[float, float]] | None = None
    runs: list[Run] = field(default_factory=list)

    @property
    def reference_error(self) -> float:
        """The reference's own headline error (0 for a closed form, nan while unknown)."""
        if self.bench.closed_form is not None:
            return 0.0
        return self.reference_errors["omega"][0] if self.reference_errors else math.nan

    def below_reference(self, run: Run) -> bool:
        """Whether a run's headline error lies below the reference's own error (not resolved)."""
        return run.error < self.reference_error

    def runs_of(self, method: str) -> list[Run]:
        """The completed runs of a method with a known error, loosest setting first."""
        return [
            run
            for run in self.runs
            if run.setting.method == method and run.status == "complete" and math.isfinite(run.error)
        ]


@dataclass
class Benchmark:
    """The whole benchmark: one SceneResult per scene, whether it ran --quick, with how many worker
    processes, on what (environment), and whether the user interrupted it."""

    scenes: list[SceneResult]
    quick: bool
    jobs: int
    environment: dict[str, str]
    interrupted: bool = False


class _Collector:
    """Turns measurements into runs with errors as they arrive; a run that arrives before its scene's
    reference waits for it."""

    def __init__(self, scenes: list[SceneResult], models: dict[str, MachineModel]):
        self.scenes = {result.bench.name: result for result in scenes}
        self.reference: dict[str, Callable[[np.ndarray], np.ndarray]] = {}
        self.scales: dict[str, np.ndarray] = {}
        self.waiting: dict[str, list[Measurement]] = {name: [] for name in self.scenes}
        for name, result in self.scenes.items():
            if result.bench.closed_form is not None:
                self._set_reference(name, result.bench.closed_form(models[name]))

    def _set_reference(self, name: str, reference: Callable[[np.ndarray], np.ndarray]) -> None:
        result = self.scenes[name]
        values = reference(time_grid(result.duration))
        self.reference[name] = reference
        self.scales[name] = np.array([error_scale(state, values[i]) for i, state in enumerate(result.state_names)])

    def add(self, measurement: Measurement) -> str:
        """Take a measurement; returns the line to show for it."""
        task = measurement.task
        name, setting = task.scene, task.setting
        result = self.scenes[name]
        if measurement.status != "complete":
            if task.role != "run":
                raise RuntimeError(
                    f"{name}: the reference run {setting.method} rtol {setting.value:g} "
                    f"{measurement.status}: {measurement.message}"
                )
            result.runs.append(self._run(measurement))
            return f"{name:<26} {setting.method:<13} {setting.label:>8}  {measurement.status}: {measurement.message}"
        if task.role == "reference":
            assert measurement.trajectory is not None, "measure keeps a reference run's trajectory"
            self._set_reference(name, measurement.trajectory)
            while self.waiting[name]:
                self._add_measured(self.waiting[name].pop())
            return (
                f"{name:<26} reference {setting.method} rtol {setting.value:g}: {measurement.steps} steps, "
                f"CPU {measurement.cpu:.3g} s"
            )
        if name not in self.reference:
            self.waiting[name].append(measurement)
            what = (
                f"check {setting.method} rtol {setting.value:g}"
                if task.role == "check"
                else f"{setting.method:<13} {setting.label:>8} "
            )
            return f"{name:<26} {what} CPU {measurement.cpu:.4g} s (compared when the reference is in)"
        return self._add_measured(measurement)

    def _add_measured(self, measurement: Measurement) -> str:
        task = measurement.task
        name, setting = task.scene, task.setting
        result = self.scenes[name]
        reference = self.reference[name](measurement.times)
        errors = achieved_errors(result.state_names, self.scales[name], measurement.states, reference)
        if task.role == "check":
            result.reference_errors = errors
            return (
                f"{name:<26} check {setting.method} rtol {setting.value:g}: the references differ by "
                f"{errors['omega'][0]:.2g} (omega RMS, relative), CPU {measurement.cpu:.3g} s"
            )
        run = self._run(measurement, errors)
        result.runs.append(run)
        return (
            f"{name:<26} {setting.method:<13} {setting.label:>8}  error {run.error:9.3g}  CPU {run.cpu:9.4g} s  "
            f"{run.steps} steps"
        )

    def _run(self, measurement: Measurement, errors: dict | None = None) -> Run:
        return Run(
            measurement.task.setting,
            measurement.status,
            measurement.message,
            measurement.cpu,
            measurement.repeats,
            measurement.nfev,
            measurement.steps,
            errors or {},
        )

    def finish(self) -> None:
        """Keep the runs still waiting for a reference (without errors) and sort every scene's runs by
        method, then from the loosest setting to the finest."""
        for name, waiting in self.waiting.items():
            self.scenes[name].runs += [
                self._run(measurement) for measurement in waiting if measurement.task.role == "run"
            ]
        for result in self.scenes.values():
            result.runs.sort(key=lambda run: (METHODS.index(run.setting.method), -run.setting.value))


def processor_name() -> str:
    """The processor's model name (Linux's /proc/cpuinfo), else what the platform module says."""
    processor = platform.processor() or platform.machine()
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.is_file():
        names = [
            line.split(":", 1)[1].strip() for line in cpuinfo.read_text().splitlines() if line.startswith("model name")
        ]
        processor = names[0] if names else processor
    return processor


def environment(jobs: int) -> dict[str, str]:
    """Where the benchmark ran: processor, Python, numpy and scipy versions, worker processes, date."""
    import scipy

    processor = processor_name()
    return {
        "processor": processor,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "jobs": str(jobs),
        "date": time.strftime("%Y-%m-%d"),
    }


def run_benchmark(
    scenes: list[BenchScene], quick: bool = False, jobs: int = 2, report: Callable[[str], None] = print
) -> Benchmark:
    """Measure every scene's sweep (see the module docstring) in `jobs` worker processes; report(line)
    is called once per finished run. Ctrl-C stops the workers and returns what was measured, with
    `interrupted` set."""
    models, results, tasks = {}, [], []
    check_rtol = QUICK_CHECK_RTOL if quick else CHECK_RTOL
    for bench in scenes:
        scene = bench.load(quick)
        models[bench.name] = model = build_model(scene)
        reference = (
            "closed form"
            if bench.closed_form is not None
            else f"{REFERENCE_METHOD} rtol {REFERENCE_RTOL:g}, checked by {CHECK_METHOD} rtol {check_rtol:g}"
        )
        results.append(
            SceneResult(
                bench,
                " ".join((scene.description or "").split()),
                scene.scenario.duration,
                model.state_names(),
                reference,
            )
        )
        if bench.closed_form is None:
            tasks += [
                Task(bench.name, quick, Setting(REFERENCE_METHOD, REFERENCE_RTOL), "reference"),
                Task(bench.name, quick, Setting(CHECK_METHOD, check_rtol), "check"),
            ]
    runs = [Task(bench.name, quick, setting) for bench in scenes for setting in sweep(bench, models[bench.name], quick)]
    tasks += sorted(runs, key=_expected_cost, reverse=True)
    collector = _Collector(results, models)
    benchmark = Benchmark(results, quick, jobs, environment(jobs))
    width = len(str(len(tasks)))
    try:
        with contextlib.closing(_measured(tasks, jobs)) as measurements:
            for done, measurement in enumerate(measurements, start=1):
                report(f"[{done:>{width}}/{len(tasks)}] {collector.add(measurement)}")
    except KeyboardInterrupt:
        benchmark.interrupted = True
    collector.finish()
    return benchmark


def _expected_cost(task: Task) -> tuple[int, float]:
    """Sort key putting the costly runs first, so the cheap ones fill the workers at the end: implicit
    methods first, then the finest settings."""
    setting = task.setting
    return setting.method in IMPLICIT, -math.log10(setting.value)


__all__ = [
    "Benchmark",
    "BenchScene",
    "Run",
    "SCENES",
    "SceneResult",
    "Setting",
    "run_benchmark",
    "select_scenes",
    "startup_closed_form",
    "timed",
]
