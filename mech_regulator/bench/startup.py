"""What the first result costs (`mech-regulator bench startup`): whole processes as a user meets them, side by side
for the reference path, the fast path and a plain scipy script of the same machine.

Measured for each path, each a fresh process timed from outside (wall time; the CPU time of the process from the
operating system's accounting of the finished child), `repeat` runs, interleaved path by path so that a drift of
the machine's speed touches all alike:

- import: `python -c 'import mech_regulator.cli.main'` (what every command pays first; the script: `import numpy,
  scipy.integrate`, what it imports);
- --help: `mech-regulator --help` (the script has none);
- cold: a first run, `mech-regulator simulate SCENE --quiet --set solver.path=PATH` with empty compile caches
  (MECH_REGULATOR_CACHE and NUMBA_CACHE_DIR pointed at a new empty temporary folder for every run); the script:
  `python script.py`. Python's bytecode caches and the operating system's file cache stay warm: "cold" is about
  the fast path's compile caches, which is where the cost is. A cold fast run is served by the reference path
  while its stepper compiles in the background (solvers/compiled/warm.py): that compile is waited for, not
  counted, before the next run;
- warm: the same run again with the caches filled (the last cold run's; without cold fast runs, the compile caches
  of this machine, filled first by one run that is not counted), each in a process of its own: no command server;
- served: the warm run through the command server (cli/server.py), one server for both paths started with the
  fast path's warm caches (the reference path uses none on the scenes the script can write) in a temporary
  folder of its own, after one uncounted run of each path through it (so that it holds the scene's compiled
  module), stopped at the end. The script has no server: its row is compared with the script's warm run.

Every row but the served one runs with MECH_REGULATOR_SERVER=off: no command starts a server.

The script is written from the scene (script_text): its constants, the crank-slider's closed-form kinematics and
the moments as plain Python, solve_ivp with the scene's method and tolerances, sampled at its sample rate; it
prints the final speed, which is shown next to the command line's as a check that the three compute the same
machine. Its moments are written independently of the package's definitions of the drives and loads
(effects/drives.py, effects/loads.py) on purpose: a script a user would write by hand, standing alone, and a second
spelling that the final speeds check the definitions against; it knows the kinds in LOAD_TYPES and the constant and
linear-motor drives, and script_refusal names any other. Numbers to read, never to assert.
"""

from __future__ import annotations

import dataclasses
import fcntl
import os
import platform
import re
import resource
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

REFERENCE, FAST, SCRIPT = "reference", "fast", "solve_ivp"
PATHS = (REFERENCE, FAST, SCRIPT)
PATH_TITLES = {REFERENCE: "reference", FAST: "fast", SCRIPT: "solve_ivp script"}
MEASURES = ("import", "help", "cold", "warm", "served")
MEASURE_TITLES = {
    "import": "import of the command line",
    "help": "mech-regulator --help",
    "cold": "cold first run (empty caches)",
    "warm": "warm run, no server",
    "served": "warm run through the command server",
}
SCRIPT_MEASURE = {"served": "warm"}  # the script's row a measure is compared with, when not its own
CACHE_VARIABLES = ("MECH_REGULATOR_CACHE", "NUMBA_CACHE_DIR")
SCRIPT_IMPORT = "import numpy, scipy.integrate"
OMEGA_PATTERN = re.compile(r"omega = (\S+) rad/s")


@dataclasses.dataclass
class Timing:
    """The runs of one measurement: wall times [s] and CPU times (user + system of the process) [s]."""

    wall: list[float] = dataclasses.field(default_factory=list)
    cpu: list[float] = dataclasses.field(default_factory=list)

    @property
    def median(self) -> float:
        return statistics.median(self.wall)

    @property
    def minimum(self) -> float:
        return min(self.wall)

    def as_data(self) -> dict:
        return {
            "median_s": self.median,
            "min_s": self.minimum,
            "cpu_median_s": statistics.median(self.cpu),
            "runs_s": list(self.wall),
        }


@dataclasses.dataclass
class StartupBenchmark:
    """Everything measured: per measure and path a Timing (None: not measured, e.g. --help of the script), the
    bare interpreter's start-up, each path's final speed (the check), where it ran."""

    scene: str
    repeat: int
    cold_fast: bool
    timings: dict[str, dict[str, Timing | None]]
    python: Timing
    omega_end: dict[str, float | None]
    environment: dict[str, str]


# ---------------------------------------------------------------------------------------------
# The plain script


def script_refusal(scene) -> str | None:
    """Why script_text cannot write the scene's machine as a plain solve_ivp script (None if it can): it writes a
    constant inertia or a crank-slider, a constant or linear-motor drive and loads that are moments of phi and
    omega, nothing with modes, events or restarts."""
    from mech_regulator.model import build_model

    machine = scene.machine
    model = build_model(scene)
    if (
        model.governor is not None
        or model.driven is not None
        or model.joint_friction is not None
        or model.coupling is not None
        or model.clutch is not None
    ):
        return "a governor, drive train or joint friction has modes and events"
    if model.load_pieces or model.breakpoints():
        return "an external load that changes in time needs restarts"
    if machine.mechanism is not None and machine.mechanism.type != "crank_slider":
        return f"mechanism '{machine.mechanism.type}' (the script knows the crank-slider)"
    if machine.drive is None or machine.drive.type not in ("constant", "linear_motor"):
        return f"drive '{getattr(machine.drive, 'type', None)}' (the script knows constant and linear_motor)"
    for index, load in enumerate(machine.loads):
        if _load_term(load) is None:
            return f"machine.loads[{index}] type '{load.type}' (the script knows {', '.join(LOAD_TYPES)})"
    return None


LOAD_TYPES = ("constant", "viscous", "fan", "cutting", "slider_constant", "slider_viscous", "slider_spring")


def _load_term(load) -> str | None:
    """The load's moment [N m] as a Python expression of phi, omega, x (slider position) and dx (dx/dphi), written
    independently of effects/loads.py (module docstring); None for a kind not in LOAD_TYPES."""
    kind = load.type
    if kind == "constant":
        return f"-{load.torque!r}"
    if kind == "viscous":
        return f"-{load.coefficient!r} * omega"
    if kind == "fan":
        return f"-{load.coefficient!r} * omega * abs(omega)"
    if kind == "cutting":
        return (
            f"cutting(phi, {load.torque!r}, {[[float(a), float(b)] for a, b in load.intervals_deg]!r}, "
            f"{load.period_deg!r})"
        )
    if kind == "slider_constant":
        return f"{load.force!r} * dx"
    if kind == "slider_viscous":
        return f"-{load.coefficient!r} * dx * dx * omega"
    if kind == "slider_spring":
        return f"-{load.stiffness!r} * (x - {load.free_position!r}) * dx"
    return None


def _written_term(load) -> str:
    """_load_term of a load of a scene script_refusal accepts (it refuses a load without a term)."""
    term = _load_term(load)
    assert term is not None, f"script_refusal accepted a load of type '{load.type}' without a term"
    return term


SCRIPT_HEAD = '''"""{scene}: a plain scipy script of the same machine as `mech-regulator simulate {scene}` (written by
`mech-regulator bench startup`): J(phi) d omega/dt + J'(phi) omega^2 / 2 = M(phi, omega), integrated by solve_ivp
(from switch angle to switch angle where a moment jumps with phi: a step across a jump would go unnoticed)."""
import math

import numpy as np
from scipy.integrate import solve_ivp

J0 = {J0!r}  # constant part of the reduced inertia [kg m^2]
SWITCHES = {switches!r}  # (angle, period) [rad] where a moment jumps with phi
'''

CRANK_SLIDER = '''R, L, E = {crank!r}, {rod!r}, {offset!r}  # crank, rod, offset [m]
M_ROD, RHO, J_ROD, M_SLIDER = {rod_mass!r}, {rho!r}, {rod_inertia!r}, {slider_mass!r}
M_CRANK_R = {crank_moment!r}  # crank mass x its centre's distance [kg m]
GX, GY = {gx!r}, {gy!r}  # gravity [m/s^2]


def mechanism(phi):
    """J(phi), dJ/dphi, the weight's moment, slider position x and dx/dphi (closed-form kinematics)."""
    s, c = math.sin(phi), math.cos(phi)
    u, du, ddu = E - R * s, -R * c, R * s
    w = math.sqrt(L * L - u * u)
    dw = -u * du / w
    ddw = -(du * du + u * ddu + dw * dw) / w
    x, dx, ddx = R * c + w, -R * s + dw, -R * c + ddw
    dth, ddth = du / w, (ddu * w - du * dw) / (w * w)
    dsx, dsy = -(1.0 - RHO) * R * s + RHO * dx, (1.0 - RHO) * R * c
    ddsx, ddsy = -(1.0 - RHO) * R * c + RHO * ddx, -(1.0 - RHO) * R * s
    J = J0 + M_ROD * (dsx * dsx + dsy * dsy) + J_ROD * dth * dth + M_SLIDER * dx * dx
    dJ = 2.0 * (M_ROD * (dsx * ddsx + dsy * ddsy) + J_ROD * dth * ddth + M_SLIDER * dx * ddx)
    weight = GX * (-M_CRANK_R * s + M_ROD * dsx + M_SLIDER * dx) + GY * (M_CRANK_R * c + M_ROD * dsy)
    return J, dJ, weight, x, dx
'''

CONSTANT_INERTIA = '''

def mechanism(phi):
    """No mechanism: constant inertia."""
    return J0, 0.0, 0.0, 0.0, 0.0
'''

CUTTING = '''

def cutting(phi, torque, intervals_deg, period_deg):
    """-torque while phi (mod the period, from the first interval's start) lies in one of the intervals
    [start, end), else 0."""
    first = intervals_deg[0][0]
    u = (math.degrees(phi) - first) % period_deg
    return -torque if any(start - first <= u < end - first for start, end in intervals_deg) else 0.0
'''

SCRIPT_TAIL = '''

def switched_moment(phi):
    """The moments that jump with phi."""
    return {switched}


def rhs(t, y, held=None):
    """dy/dt; held: the jumping moments' value between two switch angles (None: taken at phi)."""
    phi, omega = y
    J, dJ, weight, x, dx = mechanism(phi)
    moment = {smooth} + (switched_moment(phi) if held is None else held)
    return [omega, (moment - 0.5 * dJ * omega * omega) / J]


def next_switch(phi):
    """The first switch angle beyond phi."""
    return min(angle + (math.floor((phi - angle) / period + 1e-9) + 1) * period for angle, period in SWITCHES)


if __name__ == "__main__":
    duration = {duration!r}
    times = np.linspace(0.0, duration, int(round(duration * {sample_rate!r})) + 1)
    t, y, nfev, parts = 0.0, np.array([{phi0!r}, {omega0!r}]), 0, []
    while True:
        held, events = None, None
        if SWITCHES:  # on to the next switch angle, the jumping moments held at their value in between
            target = next_switch(y[0])
            held = switched_moment(0.5 * (y[0] + target))
            crossing = lambda t, y, target=target: y[0] - target
            crossing.terminal, crossing.direction = True, 1.0
            events = [crossing]
        solution = solve_ivp(lambda t, y: rhs(t, y, held), (t, duration), y, method={method!r}, rtol={rtol!r},
                             atol={atol!r}, events=events, dense_output=True)
        nfev += solution.nfev
        parts.append(solution.sol(times[times <= solution.t[-1]])[1])
        times = times[times > solution.t[-1]]
        t, y = solution.t[-1], solution.y[:, -1].copy()
        if solution.status != 1:
            break
        y[0] = target
    omega = np.concatenate(parts)
    print(f"{{solution.status}} omega_end {{float(omega[-1])!r}} omega_max {{float(omega.max())!r}} "
          f"omega_min {{float(omega.min())!r}} nfev {{nfev}}")
'''


def script_text(scene) -> str:
    """A standalone Python program (numpy and scipy only) that simulates the scene's machine with solve_ivp
    (script_refusal says which scenes it can write) and prints its final speed."""
    from mech_regulator.model import build_model

    machine, solver, scenario = scene.machine, scene.solver, scene.scenario
    model = build_model(scene)
    switches = [(float(angle), float(period)) for angle, period in model.switch_angles()]
    from mech_regulator.scene.limits import output_stem

    # the name only as a safe stem: a scene's name must not write code into the script (a '"""' in it would)
    text = SCRIPT_HEAD.format(scene=output_stem(scene.name), J0=model.inertia_constant, switches=switches)
    mechanism = machine.mechanism
    if mechanism is None:
        text += CONSTANT_INERTIA
    else:
        gx, gy = (float(g) for g in machine.gravity) if machine.gravity is not None else (0.0, 0.0)
        text += CRANK_SLIDER.format(
            crank=mechanism.crank,
            rod=mechanism.rod,
            offset=mechanism.offset,
            rod_mass=mechanism.rod_mass,
            rho=mechanism.rod_cg / mechanism.rod,
            rod_inertia=mechanism.rod_inertia,
            slider_mass=mechanism.slider_mass,
            crank_moment=mechanism.crank_mass * mechanism.crank_cg,
            gx=gx,
            gy=gy,
        )
    if any(load.type == "cutting" for load in machine.loads):
        text += CUTTING
    drive = machine.drive
    smooth = [
        f"{drive.torque!r}"
        if drive.type == "constant"
        else f"{drive.stall_torque!r} * (1.0 - omega / {drive.no_load_speed!r})"
    ]
    smooth += [_written_term(load) for load in machine.loads if load.type != "cutting"]
    switched = [_written_term(load) for load in machine.loads if load.type == "cutting"] or ["0.0"]
    method = solver.method if solver.method in ("RK23", "RK45", "DOP853", "Radau", "BDF", "LSODA") else "DOP853"
    return text + SCRIPT_TAIL.format(
        smooth=" + ".join(smooth + ["weight"]),
        switched=" + ".join(switched),
        duration=float(scenario.duration),
        sample_rate=float(solver.sample_rate),
        phi0=float(scenario.initial.phi),
        omega0=float(scenario.initial.omega),
        method=method,
        rtol=float(solver.rtol),
        atol=float(solver.atol),
    )


# ---------------------------------------------------------------------------------------------
# Measuring


def cli_command() -> list[str]:
    """How a user starts the command line: the `mech-regulator` script next to this Python (a virtualenv's bin),
    else `python -m mech_regulator`."""
    script = Path(sys.executable).with_name("mech-regulator")
    return [str(script)] if script.is_file() else [sys.executable, "-m", "mech_regulator"]


def run_process(command: list[str], env: dict[str, str]) -> tuple[float, float, str]:
    """Run a command to its end: (wall time [s], CPU time of the process [s], its stdout); RuntimeError with the
    last line of its stderr if it fails."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True, env=env, check=False)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["(no message)"])[-1]
        raise RuntimeError(f"`{' '.join(command)}` ended with exit code {done.returncode}: {last}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, done.stdout


def measure_startup(
    scene_name: str, repeat: int = 3, cold_fast: bool = True, report: Callable[[str], None] = print
) -> StartupBenchmark:
    """Measure (see the module docstring); report(line) is called after every run."""
    from mech_regulator.scene import load_scene
    from mech_regulator.scene.limits import output_stem

    scene = load_scene(scene_name)
    cli = cli_command()
    timings: dict[str, dict[str, Timing | None]] = {measure: {path: Timing() for path in PATHS} for measure in MEASURES}
    timings["help"][SCRIPT] = timings["served"][SCRIPT] = None
    if not cold_fast:
        timings["cold"][FAST] = None
    python = Timing()
    omega_end: dict[str, float | None] = dict.fromkeys(PATHS)

    def simulate_command(path: str) -> list[str]:
        return [*cli, "simulate", scene_name, "--quiet", "--set", f"solver.path={path}"]

    def record(timing: Timing, label: str, command: list[str], env: dict[str, str]) -> str:
        wall, cpu, out = run_process(command, env)
        timing.wall.append(wall)
        timing.cpu.append(cpu)
        report(f"bench startup: {label} run {len(timing.wall)}/{repeat}: {wall:.3g} s wall, {cpu:.3g} s CPU")
        return out

    def measured(measure: str, path: str) -> Timing:
        """The timing of a measure taken on a path (None in `timings` marks one not taken)."""
        timing = timings[measure][path]
        assert timing is not None, f"{measure} is not measured on {path}"
        return timing

    def final_speed(path: str, out: str) -> None:
        found = re.search(r"omega_end (\S+)", out) if path == SCRIPT else OMEGA_PATTERN.search(out)
        if found:
            omega_end[path] = float(found.group(1))

    with tempfile.TemporaryDirectory(prefix="mech-regulator-startup-") as folder:
        script = Path(folder) / f"{output_stem(scene.name)}_solve_ivp.py"
        script.write_text(script_text(scene), encoding="utf-8")
        base = dict(os.environ, MECH_REGULATOR_SERVER="off")
        base.pop("MECH_REGULATOR_PROGRESS_INTERVAL", None)
        commands = {
            "import": {
                REFERENCE: [sys.executable, "-c", "import mech_regulator.cli.main"],
                SCRIPT: [sys.executable, "-c", SCRIPT_IMPORT],
            },
            "help": {REFERENCE: [*cli, "--help"]},
        }
        report("bench startup: one run of each command first, not counted (the files into the system's cache)")
        for command in (
            *(command for measure in commands.values() for command in measure.values()),
            [sys.executable, str(script)],
        ):
            run_process(command, base)
        for _ in range(repeat):
            record(python, "python -c pass", [sys.executable, "-c", "pass"], base)
            for measure in ("import", "help"):
                for path, command in commands[measure].items():
                    record(measured(measure, path), f"{measure} ({PATH_TITLES[path]})", command, base)
        for measure in ("import", "help"):  # one process serves both paths of the command line
            timings[measure][FAST] = timings[measure][REFERENCE]
        warm_caches: dict[str, dict[str, str]] = {}
        for index in range(repeat):
            for path in PATHS:
                if timings["cold"][path] is None:
                    continue
                cache = tempfile.mkdtemp(prefix=f"cold-{path}-{index}-", dir=folder)
                env = dict(base, **{variable: cache for variable in CACHE_VARIABLES})
                command = [sys.executable, str(script)] if path == SCRIPT else simulate_command(path)
                final_speed(path, record(measured("cold", path), f"cold {PATH_TITLES[path]}", command, env))
                warm_caches[path] = env
                if path == FAST:
                    _wait_for_background_compile(cache, report)
        if not cold_fast:
            env = dict(base)
            report("bench startup: filling this machine's compile caches for the warm fast runs (not counted)")
            final_speed(FAST, run_process(simulate_command(FAST), env)[2])
            warm_caches[FAST] = env
        for _ in range(repeat):
            for path in PATHS:
                command = [sys.executable, str(script)] if path == SCRIPT else simulate_command(path)
                final_speed(
                    path, record(measured("warm", path), f"warm {PATH_TITLES[path]}", command, warm_caches[path])
                )
        served = dict(warm_caches[FAST], XDG_RUNTIME_DIR=os.path.join(folder, "servers"))
        served.pop("MECH_REGULATOR_SERVER")
        report("bench startup: starting a command server, one run of each path through it (not counted)")
        server = re.search(r"pid (\d+)", run_process([*cli, "server", "start"], served)[2])
        try:
            for path in (REFERENCE, FAST):
                run_process(simulate_command(path), served)
            for _ in range(repeat):
                for path in (REFERENCE, FAST):
                    final_speed(
                        path,
                        record(
                            measured("served", path),
                            f"warm {PATH_TITLES[path]} through the server",
                            simulate_command(path),
                            served,
                        ),
                    )
        finally:
            _stop_servers(cli, served, int(server[1]) if server else None)
    return StartupBenchmark(scene_name, repeat, cold_fast, timings, python, omega_end, environment())


def _wait_for_background_compile(cache: str, report: Callable[[str], None]) -> None:
    """Wait until the background process compiling the stepper that a cold fast run started (it ran on the
    reference path meanwhile: solvers/compiled/warm.py) has ended — it holds the lock in the cache folder — so that
    it neither slows the runs measured next nor leaves the warm fast runs on the reference path."""
    from mech_regulator.solvers.compiled.locks import lock_path

    lock = Path(cache) / lock_path().name  # this version's lock, in the benchmark's cache folder
    if lock.exists():
        report(
            "bench startup: waiting for the stepper's compile in the background that the cold fast run started "
            "(not counted)"
        )
        with open(lock, "a") as handle:
            fcntl.flock(handle, fcntl.LOCK_EX)


def _stop_servers(cli: list[str], env: dict[str, str], pid: int | None) -> None:
    """`server stop` in the benchmark's folder; the server killed by its pid if it is still there."""
    from mech_regulator.processes import process_alive

    try:
        run_process([*cli, "server", "stop"], env)
    finally:
        if pid is not None and process_alive(pid):
            os.kill(pid, signal.SIGKILL)


def environment() -> dict[str, str]:
    """Where it ran: processor, cores, Python, date."""
    from mech_regulator.bench.accuracy import processor_name

    return {
        "processor": processor_name(),
        "cores": str(os.cpu_count()),
        "python": platform.python_version(),
        "date": time.strftime("%Y-%m-%d"),
    }


# ---------------------------------------------------------------------------------------------
# What was found


def ratios(benchmark: StartupBenchmark) -> dict[str, dict[str, float | None]]:
    """Per measure, each path's median over the script's (its warm run's for the served one; None where either is
    missing)."""
    found: dict[str, dict[str, float | None]] = {}
    for measure, timings in benchmark.timings.items():
        script = benchmark.timings[SCRIPT_MEASURE.get(measure, measure)][SCRIPT]
        found[measure] = {}
        for path in (REFERENCE, FAST):
            timing = timings[path]
            found[measure][f"{path} / {SCRIPT}"] = (
                timing.median / script.median if timing is not None and script is not None else None
            )
    return found


def startup_summary(benchmark: StartupBenchmark) -> dict:
    """Everything as plain data (JSON-ready): times in seconds, per measure and path."""
    return {
        "scene": benchmark.scene,
        "repeat": benchmark.repeat,
        "cold_fast": benchmark.cold_fast,
        "environment": benchmark.environment,
        "python_startup": benchmark.python.as_data(),
        "measures": {
            measure: {path: None if timing is None else timing.as_data() for path, timing in timings.items()}
            for measure, timings in benchmark.timings.items()
        },
        "ratios": ratios(benchmark),
        "omega_end": benchmark.omega_end,
    }


def _cell(timing: Timing | None) -> str:
    return "-" if timing is None else f"{timing.median:.3g} ({timing.minimum:.3g})"


def format_table(benchmark: StartupBenchmark) -> str:
    """The measurements as a markdown table: median (min) wall time per path, the ratios to the script."""
    found = ratios(benchmark)
    lines = [
        f"start-up of {benchmark.scene}: whole processes, wall time [s], median (min) of {benchmark.repeat} "
        f"run(s); {benchmark.environment['processor']}, {benchmark.environment['cores']} cores, Python "
        f"{benchmark.environment['python']}",
        "",
        "| | reference | fast | solve_ivp script | reference / script | fast / script |",
        "| --- | ---: | ---: | ---: | ---: | ---: |",
    ]
    for measure, timings in benchmark.timings.items():
        shown = [f"{value:.3g}" if value is not None else "-" for value in found[measure].values()]
        lines.append(
            f"| {MEASURE_TITLES[measure]} | {_cell(timings[REFERENCE])} | {_cell(timings[FAST])} | "
            f"{_cell(timings[SCRIPT])} | {' | '.join(shown)} |"
        )
    omega = ", ".join(
        f"{PATH_TITLES[path]} {value:.10g}" if value is not None else f"{PATH_TITLES[path]} -"
        for path, value in benchmark.omega_end.items()
    )
    lines += [
        "",
        f"Python itself (python -c pass): {_cell(benchmark.python)} s. The import and --help rows are one "
        "process for both paths of the command line; the script's import row is numpy and scipy.integrate. "
        "The server row's ratios are to the script's warm run (a script has no server); its CPU time (--json) "
        "is the client's alone, the server's child is not the benchmark's.",
        f"final speed omega [rad/s] (the same machine on each): {omega}",
    ]
    if not benchmark.cold_fast:
        lines.append("cold fast runs left out (--skip-cold-fast): the warm fast runs used this machine's caches")
    return "\n".join(lines)
