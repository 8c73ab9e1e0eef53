"""Flywheel design for a permitted coefficient of speed fluctuation [delta] (docs/theory.md §3, source 000).

Three answers, side by side:

1. energy swing (constant J): `J_fw = dE_max / (omega_m^2 [delta]) - J0`, with J0 the mean reduced inertia of
   the machine when J varies (then it is the constant-J approximation);
2. Wittenbauer, exact numerical form of the E(J) construction: with `k_max,min = omega_m^2 (1 +- [delta]) / 2`,
   `J_fw = (max_phi[k_min J(phi) - dE(phi)] - min_phi[k_max J(phi) - dE(phi)]) / (k_max - k_min)`,
   J(phi) the machine's reduced inertia without a flywheel and dE(phi) = integral (M_d + M_c) dphi over the
   dynamic period (moments that read omega evaluated at omega_m). It rests on
   omega_max,min^2 ~ omega_m^2 (1 +- [delta]), an O([delta]^2) approximation;
3. refined: the flywheel whose periodic steady motion, simulated with the project's solver, has exactly
   delta = (omega_max - omega_min) / omega_m = [delta] (scipy brentq on J_fw).

Each proposal is checked by simulating the machine with it on its periodic steady motion. When the moments do
not read omega, the mean speed is neutral: the run starts at the energy level that puts
omega_m = (omega_max + omega_min) / 2 at the target. When they do (a motor characteristic), the machine sets its
own mean speed: the periodic orbit is found by shooting over one dynamic period (brentq on the speed at phi = 0).

The flywheel may sit on a shaft x turning at a fixed ratio N = omega_x / omega: `J_x = J_fw (omega / omega_x)^2
= J_fw / N^2`; the runs use exactly the scene format's `machine.flywheel: {inertia: J_x, ratio: N}`.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy import integrate, optimize

from mech_regulator.analysis.energy import energy_swing, flywheel_for_constant_inertia
from mech_regulator.analysis.periodic import PeriodSpeeds, analyse_steady_state
from mech_regulator.model import MachineModel, build_model
from mech_regulator.model.steady import balance_speed
from mech_regulator.scene.loading import SceneError, validate_scene
from mech_regulator.scene.scenario_keys import InitialState, Scenario
from mech_regulator.scene.schema import Scene
from mech_regulator.solvers import Trajectory, simulate


@dataclass(frozen=True)
class MachineClass:
    """A class of machines and the range of [delta] it permits: loosest and strictest value [-]."""

    name: str
    description: str
    loosest: float
    strictest: float


# docs/theory.md §3.1: the list in source 000 is garbled in the OCR; these are the common textbook ranges
# quoted there (Artobolevsky's table and its Vietnamese copies).
MACHINE_CLASSES = {
    machine.name: machine
    for machine in (
        MachineClass("pump", "pumps", 1 / 5, 1 / 30),
        MachineClass("agricultural", "agricultural machines", 1 / 5, 1 / 50),
        MachineClass("machine_tool", "machine tools", 1 / 20, 1 / 50),
        MachineClass("engine", "internal combustion engines", 1 / 80, 1 / 150),
        MachineClass("generator", "electric generators", 1 / 100, 1 / 300),
    )
}

VERIFY_RTOL, VERIFY_ATOL = 1e-10, 1e-12  # the verification runs tighten an adaptive solver to at least these
REFINE_RTOL = 1e-9  # brentq's relative tolerance on J_fw (delta to ~1e-9 relative)
SHOOTING_XTOL = 1e-12  # brentq's relative tolerance on the orbit's speed at phi = 0
PERIOD_MARGIN = 1.05  # a run lasts this times the predicted time of one dynamic period

Progress = Callable[[str], None]


@dataclass(frozen=True)
class EnergyDiagram:
    """The machine without a flywheel over one dynamic period from phi = 0 at the design speed omega_m [rad/s]:
    crank angles phi [rad], reduced inertia J(phi) [kg m^2] and energy swing dE(phi) = integral_0^phi
    (M_d + M_c) dphi [J] (the E(J) curve is (J, dE)); mean_inertia [kg m^2]: J averaged over the period."""

    phi: np.ndarray
    inertia: np.ndarray
    energy: np.ndarray
    omega_m: float
    mean_inertia: float

    @property
    def swing(self) -> float:
        """dE_max = max dE - min dE over the period [J]."""
        return float(np.max(self.energy) - np.min(self.energy))


@dataclass(frozen=True)
class WittenbauerConstruction:
    """The E(J) construction for [delta]: the ray of slope k_max = omega_m^2 (1 + [delta]) / 2 touches the curve
    from above at tangent_max and cuts the E axis (J = 0) at a; the ray of slope k_min = omega_m^2 (1 - [delta]) / 2
    touches from below at tangent_min and cuts it at b; they meet at O' = (-J_fw, a - k_max J_fw), the origin of
    the true kinetic energy; `J_fw = (a - b) / (k_max - k_min)`. Slopes [J/(kg m^2)], intercepts [J], tangent
    points (phi [rad], J [kg m^2], dE [J])."""

    k_max: float
    k_min: float
    a: float
    b: float
    tangent_max: tuple[float, float, float]
    tangent_min: tuple[float, float, float]
    flywheel: float

    @property
    def origin(self) -> tuple[float, float]:
        """O' = (J, E) where the two rays meet: zero kinetic energy of the machine with the flywheel."""
        return -self.flywheel, self.a - self.k_max * self.flywheel


@dataclass(frozen=True)
class SteadyRun:
    """The simulated periodic steady motion with a flywheel of flywheel [kg m^2] reduced to the crank: the
    speed at phi = 0 on the orbit [rad/s], the speeds over one dynamic period (delta, omega_m, ...), and omega
    [rad/s] against the crank angle phi [rad] from 0 over the period (for pictures)."""

    flywheel: float
    omega_start: float
    speeds: PeriodSpeeds
    phi: np.ndarray
    omega: np.ndarray


@dataclass(frozen=True)
class FlywheelDesign:
    """Everything the flywheel command reports. delta: the requested [delta]; ratio N = omega_x / omega of the
    flywheel's shaft; speed_dependent: the moments read omega (the machine sets its own mean speed);
    energy_swing, wittenbauer (with its construction) and refined: J_fw reduced to the crank [kg m^2];
    runs: simulated steady motion by name ('none' without flywheel, 'scene' with the scene's flywheel,
    'energy_swing', 'wittenbauer', 'refined'), absent when a run is impossible (see notes)."""

    scene: str
    delta: float
    omega_m: float
    omega_m_source: str
    ratio: float
    speed_dependent: bool
    diagram: EnergyDiagram
    construction: WittenbauerConstruction
    energy_swing: float
    refined: float | None
    scene_flywheel: float | None
    runs: dict[str, SteadyRun]
    notes: list[str] = field(default_factory=list)

    @property
    def wittenbauer(self) -> float:
        return self.construction.flywheel

    def on_shaft(self, flywheel: float) -> float:
        """J_x = J_fw (omega / omega_x)^2 [kg m^2] of a flywheel J_fw reduced to the crank, on the ratio-N shaft."""
        return flywheel / self.ratio**2


def energy_diagram(model: MachineModel, omega_m: float) -> EnergyDiagram:
    """J(phi) of the model's machine (build it without a flywheel) and its energy swing dE(phi) at omega_m
    [rad/s] over one dynamic period from phi = 0 (analysis.energy.energy_swing)."""
    phi, energy = energy_swing(model, omega_m)
    inertia = np.array([model.inertia(angle)[0] for angle in phi])
    return EnergyDiagram(phi, inertia, energy, omega_m, model.mean_crank_inertia)


def wittenbauer(diagram: EnergyDiagram, delta: float) -> WittenbauerConstruction:
    """The exact numerical form of the Wittenbauer construction (docs/theory.md §3.4):
    a = max_phi[dE - k_max J], b = min_phi[dE - k_min J], J_fw = (a - b) / (k_max - k_min)."""
    k_max = diagram.omega_m**2 * (1.0 + delta) / 2.0
    k_min = diagram.omega_m**2 * (1.0 - delta) / 2.0
    above = diagram.energy - k_max * diagram.inertia
    below = diagram.energy - k_min * diagram.inertia
    i_max, i_min = int(np.argmax(above)), int(np.argmin(below))
    a, b = float(above[i_max]), float(below[i_min])

    def point(i: int) -> tuple[float, float, float]:
        return float(diagram.phi[i]), float(diagram.inertia[i]), float(diagram.energy[i])

    return WittenbauerConstruction(k_max, k_min, a, b, point(i_max), point(i_min), (a - b) / (k_max - k_min))


def design_flywheel(
    scene: Scene,
    delta: float,
    omega_m: float | None = None,
    ratio: float | None = None,
    progress: Progress | None = None,
) -> FlywheelDesign:
    """Size the flywheel of a one-mass machine for [delta] three ways and verify each by simulation.

    omega_m [rad/s]: the design mean speed; None = the machine's own (see `design_speed`). ratio: N of the
    flywheel's shaft; None = the scene's flywheel's ratio, else 1. progress(stage) is called after every
    simulated dynamic period. Raises SceneError for a machine that cannot be designed for (governor, coupling,
    no steady motion, a bad delta, speed or ratio).
    """
    _check_designable(scene, delta, ratio)
    ratio = ratio if ratio is not None else (scene.machine.flywheel.ratio if scene.machine.flywheel else 1.0)
    bare = _without_flywheel(scene)
    model = build_model(bare)
    speed_dependent = "omega" in model.depends_on()
    notes = []
    if scene.scenario.load_events:
        notes.append(
            f"designed for the external load at t = 0 ({scene.scenario.external_load:g} N m); "
            "the scenario's load events are left out"
        )
    if not speed_dependent:
        _check_balanced(energy_swing(model, 1.0)[1])  # omega is not read: any speed gives the same swing
    omega_m, source = design_speed(scene, model, omega_m)
    diagram = energy_diagram(model, omega_m)
    construction = wittenbauer(diagram, delta)
    by_energy_swing = flywheel_for_constant_inertia(diagram.swing, omega_m, delta, diagram.mean_inertia)
    motion = PeriodicMotion(bare, diagram, ratio, speed_dependent, progress)
    scene_flywheel = (
        scene.machine.flywheel.inertia * scene.machine.flywheel.ratio**2 if scene.machine.flywheel else None
    )
    runs: dict[str, SteadyRun] = {}
    for name, flywheel in (
        ("none", 0.0),
        ("scene", scene_flywheel),
        ("energy_swing", by_energy_swing),
        ("wittenbauer", construction.flywheel),
    ):
        if flywheel is None:
            continue
        if flywheel < 0.0:
            notes.append(
                f"{name.replace('_', ' ')}: J_fw = {flywheel:.6g} kg m^2 < 0: by this formula the "
                "machine needs no flywheel; not simulated"
            )
            continue
        run = motion.run(flywheel)
        if run is None:
            notes.append(
                f"{'without a flywheel' if name == 'none' else name.replace('_', ' ')}: the machine has "
                "no periodic steady motion near omega_m (its kinetic energy cannot carry it through the "
                "energy swing: it stalls or turns back); not simulated"
            )
        else:
            runs[name] = run
    refined = motion.refine(delta, construction.flywheel, runs)
    if refined is None:
        notes.append("refinement: no flywheel of positive inertia gives the requested delta in simulation")
    elif refined == 0.0:
        notes.append("refinement: the machine without a flywheel already has delta <= [delta]: no flywheel needed")
    refined_run = motion.run(refined) if refined is not None else None
    if refined_run is not None:
        runs["refined"] = refined_run
    return FlywheelDesign(
        scene.name or "scene",
        delta,
        omega_m,
        source,
        ratio,
        speed_dependent,
        diagram,
        construction,
        by_energy_swing,
        refined,
        scene_flywheel,
        runs,
        notes,
    )


def design_speed(scene: Scene, model: MachineModel, omega_m: float | None) -> tuple[float, str]:
    """The design mean speed omega_m [rad/s] and where it comes from.

    Moments that read omega (a motor characteristic, viscous or fan loads) fix the machine's mean speed: it is
    the speed at which the cycle-mean moments balance, and a requested omega_m is refused. Otherwise the mean
    speed is free: the requested one, else omega_m = (omega_max + omega_min) / 2 of the scene's own steady
    motion through its initial state with its flywheel, omega^2 = 2 (E0 + dE(phi) - dE(phi0)) / J(phi).
    """
    if "omega" in model.depends_on():
        balance = balance_speed(model)
        if omega_m is not None:
            raise SceneError(
                f"--omega-m {omega_m:g}: the moments of scene '{scene.name}' depend on omega, so the "
                f"machine sets its own mean speed ({balance:.6g} rad/s, where the cycle-mean moments "
                "balance); change the drive or the loads to move it"
            )
        return balance, "the speed at which the cycle-mean moments balance (the motor's characteristic sets it)"
    if omega_m is not None:
        if not (math.isfinite(omega_m) and omega_m > 0.0):
            raise SceneError(f"--omega-m {omega_m:g}: expected a mean speed > 0 rad/s")
        return omega_m, "--omega-m"
    initial = scene.scenario.initial
    with_flywheel = build_model(scene)
    diagram = energy_diagram(with_flywheel, 1.0)  # omega is not read: any speed gives the same swing
    J0 = with_flywheel.inertia(initial.phi)[0]
    start = 0.5 * J0 * initial.omega**2 - np.interp(initial.phi % diagram.phi[-1], diagram.phi, diagram.energy)
    kinetic = start + diagram.energy
    if initial.omega <= 0.0 or np.min(kinetic) <= 0.0:
        raise SceneError(
            f"scene '{scene.name}' starts at omega = {initial.omega:g} rad/s and does not turn steadily "
            "through its initial state: give the design mean speed with --omega-m"
        )
    omega = np.sqrt(2.0 * kinetic / diagram.inertia)
    return 0.5 * float(
        omega.max() + omega.min()
    ), "the mean speed of the scene's own steady motion through its initial state (moments independent of omega)"


class PeriodicMotion:
    """Periodic steady runs of a machine with flywheels of various sizes, by the project's solver.

    bare: the scene without a flywheel; diagram: its energy diagram at the design speed; ratio: N of the
    flywheel's shaft; speed_dependent: whether the moments read omega (then the orbit is found by shooting)."""

    def __init__(
        self, bare: Scene, diagram: EnergyDiagram, ratio: float, speed_dependent: bool, progress: Progress | None = None
    ):
        self.bare = bare
        self.diagram = diagram
        self.ratio = ratio
        self.speed_dependent = speed_dependent
        self.progress = progress
        self.period = float(diagram.phi[-1])
        self._cache: dict[float, SteadyRun | None] = {}

    def model(self, flywheel: float) -> MachineModel:
        """The machine with a flywheel J_fw [kg m^2] reduced to the crank, written as the scene format does:
        machine.flywheel = {inertia: J_fw / N^2, ratio: N}; the solver tightened for the verification."""
        data = self.bare.model_dump(exclude_none=True)
        data["machine"]["flywheel"] = {"inertia": flywheel / self.ratio**2, "ratio": self.ratio}
        solver = data["solver"]
        if solver["method"] not in ("RK4", "energy"):
            solver["rtol"], solver["atol"] = min(solver["rtol"], VERIFY_RTOL), min(solver["atol"], VERIFY_ATOL)
        return build_model(validate_scene(data, "flywheel design"))

    def run(self, flywheel: float) -> SteadyRun | None:
        """The periodic steady motion with flywheel J_fw [kg m^2] and its speeds over one dynamic period, or None
        if the machine has none (it stops or turns back)."""
        if flywheel not in self._cache:
            self._cache[flywheel] = self._steady_run(flywheel)
        return self._cache[flywheel]

    def refine(self, delta: float, start: float, runs: dict[str, SteadyRun]) -> float | None:
        """J_fw [kg m^2] whose simulated delta equals [delta] (brentq from the bracket around `start`); 0 if the
        machine without a flywheel already meets it; None if no flywheel can."""
        if "none" in runs and runs["none"].speeds.delta <= delta:
            return 0.0

        def excess(flywheel: float) -> float:
            run = self.run(flywheel)
            return math.inf if run is None else run.speeds.delta - delta

        low = max(start, 0.0)
        mismatch = excess(low)
        if mismatch == 0.0:
            return low
        # delta ~ C / (J_fw + J_m) near the answer: a first guess, then the bracket widens until delta crosses
        guess = (low + self.diagram.mean_inertia) * (1.0 + mismatch / delta) - self.diagram.mean_inertia
        step = guess - low if math.isfinite(guess) and guess != low else max(low, self.diagram.mean_inertia)
        high = low + 1.5 * step
        for _ in range(40):
            high = max(high, 0.0)
            if excess(high) * mismatch < 0.0:
                break
            if high == 0.0:  # even without a flywheel the machine stays below [delta]
                return 0.0
            step *= 2.0
            high = low + step
        else:
            return None
        low, high = sorted((low, high))
        return optimize.brentq(excess, low, high, xtol=1e-15 * max(high, 1.0), rtol=REFINE_RTOL)

    def _steady_run(self, flywheel: float) -> SteadyRun | None:
        model = self.model(flywheel)
        total = self.diagram.inertia + flywheel
        if np.min(total) <= 0.0:
            return None
        if self.speed_dependent:
            omega_start = self._shoot(model, flywheel)
        else:
            omega_start = self._level(total)
        if omega_start is None:
            return None
        trajectory = self._one_period(model, flywheel, omega_start)
        if trajectory is None:
            return None
        speeds = analyse_steady_state(model, trajectory).last
        if speeds is None:
            return None
        times = np.linspace(speeds.t_start, speeds.t_end, 2001)
        phi, omega = trajectory(times)[:2]
        return SteadyRun(flywheel, omega_start, speeds, phi - phi[0], omega)

    def _predicted(self, total: np.ndarray, start_energy: float) -> np.ndarray:
        """omega(phi) [rad/s] from the energy relation omega^2 = 2 (E0 + dE(phi)) / J(phi) (NaN where E <= 0)."""
        kinetic = start_energy + self.diagram.energy
        return np.sqrt(np.where(kinetic > 0.0, 2.0 * kinetic / total, np.nan))

    def _level(self, total: np.ndarray) -> float | None:
        """Moments independent of omega: omega at phi = 0 [rad/s] of the orbit whose (omega_max + omega_min) / 2
        equals omega_m (brentq on the kinetic energy E0 at phi = 0 in the energy relation)."""
        target = self.diagram.omega_m
        lowest = -float(np.min(self.diagram.energy))  # E0 below this: the machine stops inside the period

        def mean_error(start_energy: float) -> float:
            omega = self._predicted(total, start_energy)
            return 0.5 * (np.max(omega) + np.min(omega)) - target

        high = 0.5 * float(np.max(total)) * target**2 + max(lowest, 0.0) + self.diagram.swing
        low = max(lowest, 0.0) * (1.0 + 1e-12) + 1e-300
        if mean_error(low) >= 0.0:
            return None
        start_energy = optimize.brentq(mean_error, low, high, xtol=1e-14 * high, rtol=1e-15)
        return math.sqrt(2.0 * start_energy / total[0])

    def _shoot(self, model: MachineModel, flywheel: float) -> float | None:
        """Moments that read omega: omega at phi = 0 [rad/s] of the periodic orbit, the fixed point of the map
        over one dynamic period omega(0) -> omega(Phi) (brentq on P(omega) - omega, bracket from the energy
        relation's guess)."""
        guess = self._level(self.diagram.inertia + flywheel)
        if guess is None:
            return None

        @functools.cache  # brentq starts by re-evaluating the bracket's ends
        def gain(omega_start: float) -> float:
            trajectory = self._one_period(model, flywheel, omega_start)
            if trajectory is None:  # stopped within the period: it loses speed
                return -omega_start
            t_end = optimize.brentq(lambda t: trajectory(t)[0] - self.period, 0.0, trajectory.t_end, xtol=1e-14)
            return float(trajectory(t_end)[1]) - omega_start

        width = 0.01 * guess
        low, high = guess - width, guess + width
        for _ in range(20):
            if gain(low) > 0.0 > gain(high):
                return optimize.brentq(gain, low, high, xtol=1e-300, rtol=SHOOTING_XTOL)
            width *= 2.0
            low, high = max(guess - width, 1e-3 * guess), guess + width
        return None

    def _one_period(self, model: MachineModel, flywheel: float, omega_start: float) -> Trajectory | None:
        """Simulate from phi = 0 at omega_start [rad/s] a little longer than one dynamic period (the energy
        relation predicts its time); None if the machine does not get round (stops or turns back)."""
        total = self.diagram.inertia + flywheel
        omega = self._predicted(total, 0.5 * total[0] * omega_start**2)
        predicted = integrate.trapezoid(1.0 / omega, self.diagram.phi) if np.all(omega > 0.0) else math.nan
        duration = PERIOD_MARGIN * (predicted if math.isfinite(predicted) else 2.0 * self.period / omega_start)
        for _ in range(3):
            scene = model.scene
            scenario = Scenario(
                initial=InitialState(phi=0.0, omega=omega_start),
                duration=duration,
                external_load=scene.scenario.external_load,
            )
            # the same model with another scenario: the solver reads the initial state and duration from the scene
            timed = dataclasses.replace(model, scene=scene.model_copy(update={"scenario": scenario}))
            trajectory = simulate(timed)
            if self.progress is not None:
                self.progress(f"J_fw = {flywheel:.6g} kg m^2")
            if trajectory.status != "complete":
                return None
            phi, omega_end = trajectory(trajectory.t_end)[:2]
            if phi >= self.period:
                return trajectory
            if omega_end <= 0.0:
                return None
            duration *= 2.0
        return None


def _without_flywheel(scene: Scene) -> Scene:
    """The scene's machine without its flywheel and with a plain scenario: the external load at t = 0."""
    machine = scene.machine.model_copy(update={"flywheel": None})
    scenario = scene.scenario.model_copy(update={"load_events": []})
    return scene.model_copy(update={"machine": machine, "scenario": scenario})


def _check_designable(scene: Scene, delta: float, ratio: float | None) -> None:
    """Refuse, with the reason, what the flywheel design does not cover."""
    if not (math.isfinite(delta) and 0.0 < delta < 1.0):
        raise SceneError(f"[delta] = {delta:g}: expected 0 < delta < 1 (e.g. 1/80 = 0.0125)")
    if ratio is not None and not (math.isfinite(ratio) and ratio != 0.0):
        raise SceneError(f"--ratio {ratio:g}: expected omega_x / omega, a finite non-zero number")
    if scene.governor is not None:
        raise SceneError(
            f"scene '{scene.name}' has a governor: a flywheel is sized for the machine alone at a fixed "
            "drive; remove the governor (--set governor=null) or design on the ungoverned scene"
        )
    if scene.machine.coupling is not None:
        raise SceneError(
            f"scene '{scene.name}' is a two-mass machine (machine.coupling): the flywheel design covers "
            "one-mass machines reduced to the crank"
        )


def _check_balanced(energy: np.ndarray) -> None:
    """Moments independent of omega: steady motion needs A_d = A_c over the dynamic period; refuse a machine whose
    net work energy[-1] [J] (of the energy swing dE(phi) [J] from phi = 0) is not zero."""
    net = float(energy[-1])
    scale = max(float(np.ptp(energy)), 1e-300)
    if abs(net) > 1e-6 * scale:
        raise SceneError(
            f"the net work of the moments over the dynamic period is {net:.6g} J (A_d != A_c): the machine "
            f"{'accelerates' if net > 0 else 'slows down'} and has no periodic steady motion; balance "
            "the drive against the loads"
        )
