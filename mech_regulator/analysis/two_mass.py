"""The two-mass machine of source 003 (docs/theory.md §7.2-§7.3): the periods of a run and its largest coupling
moment, and the paper's inverse problem, the coupling characteristic a prescribed driven speed law needs.

Periods of motion: 1, start-up, until the driven part starts to move forward (the coupling moment first
overcomes its resistance; no length if it moves at once); 2, transient; 3, steady motion, from when the
motion repeats over the dynamic period (analysis/periodic.py).

Inverse problem: the driven part's speed law is prescribed, a linear run-up from rest to omega_m in T, then
`omega2 = omega_m + A sin(k (t - T))` with `A = delta omega_m / 2`. The driven part's equation gives the
coupling moment it needs,

    M_m(t) = I2(phi2) domega2/dt + 1/2 I2'(phi2) omega2^2 - M_c2(t, phi2, omega2) + M_external,

the driving part's equation `J1 domega1/dt = M_d(omega1) + M_c1(omega1) - M_m(t)` its motion, and the twist
`phi1 - phi2` (up to a constant) with the elastic moment `M_m - c (omega1 - omega2)` the characteristic, when
one twist gives one moment (single-valued) and the moment rises with the twist (no elastic coupling has a
negative stiffness).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy import integrate, optimize

from mech_regulator.analysis.energy import planned_samples, step_chunks, step_edges
from mech_regulator.analysis.periodic import SteadyState
from mech_regulator.model import MachineModel
from mech_regulator.model.drivetrain import FORWARD
from mech_regulator.model.machine import CouplingModel
from mech_regulator.model.steady import balance_speed
from mech_regulator.scene import SceneError
from mech_regulator.solvers import Trajectory

LOOP_TOLERANCE = 1e-3  # a characteristic is single-valued when moments at one twist differ by less than this
#                        fraction of its moment range [-]


@dataclass(frozen=True)
class CouplingPeak:
    """The largest coupling moment of a run: M_m [N m] (signed; largest in magnitude), its time [s], the period
    (1, 2 or 3) it falls in, the mean M_m over the last dynamic period of steady motion [N m] and their ratio
    [-] (None when the run does not reach steady motion)."""

    moment: float
    time: float
    period: int
    steady_mean: float | None
    ratio: float | None


@dataclass(frozen=True)
class MotionPeriods:
    """Periods of a two-mass run: end of period 1 [s] (0: the driven part moves at once; None: it never moves
    forward), start of period 3 [s] (None: not steady), the largest coupling moment, the twist's range [rad]
    and a note (e.g. the twist left the characteristic's table)."""

    start_up_end: float | None
    steady_from: float | None
    peak: CouplingPeak
    twist_min: float
    twist_max: float
    note: str


@dataclass
class CouplingSoFar:
    """The coupling's figures of a run read so far (read_coupling), chunk by chunk: the largest |M_m| [N m] on the
    grid (step edges and output samples), the refined extremum near it (time [s], M_m [N m]; NaN before any chunk)
    and the twist's range [rad]."""

    largest: float = -math.inf
    time: float = math.nan
    moment: float = math.nan
    twist_min: float = math.inf
    twist_max: float = -math.inf


def read_coupling(
    model: MachineModel, trajectory: Trajectory, chunk: np.ndarray, following: float | None, so_far: CouplingSoFar
) -> None:
    """Add to so_far the coupling's grid over a chunk of solver steps (chunk: their edges [s]; following: the next
    grid edge after it, None at the run's end): the step edges and the planned output samples after its first edge
    (from the run's start on the first chunk). A larger |M_m| than any before (the first one on a tie, as one argmax
    over the run) is refined on the dense output between its neighbours on the grid."""
    low, high = float(chunk[0]), float(chunk[-1])
    times = np.union1d(chunk, planned_samples(model, trajectory, low, high))
    if following is not None:
        after = planned_samples(model, trajectory, high, following)
        times = np.append(times, min([following, *after[after > high][:1]]))
    owned = slice(0 if low <= trajectory.t_start else 1, np.searchsorted(times, high, side="right"))
    columns = model.columns(times[owned], trajectory(times[owned]))
    twist = columns["twist"]
    so_far.twist_min, so_far.twist_max = (
        min(so_far.twist_min, float(twist.min())),
        max(so_far.twist_max, float(twist.max())),
    )
    passed = np.abs(columns["M_coupling"])
    i = int(np.argmax(passed))
    if passed[i] > so_far.largest:
        so_far.largest = float(passed[i])
        so_far.time, so_far.moment = _refine_peak(model, trajectory, times, owned.start + i)


def motion_periods(
    model: MachineModel,
    trajectory: Trajectory,
    steady: SteadyState,
    so_far: CouplingSoFar | None = None,
    steps_done: int = 0,
) -> MotionPeriods:
    """The periods of a coupled run and its largest coupling moment, located on the dense output, read chunk by
    chunk (step_chunks; so_far: what a streamed run read of its first steps_done solver steps, analysis/stream.py)."""
    assert model.coupling is not None, "motion_periods is for a model with a coupling"
    so_far = dataclasses.replace(so_far) if so_far is not None else CouplingSoFar()
    edges = step_edges(trajectory)
    for chunk, following in step_chunks(trajectory, edges, steps_done):
        read_coupling(model, trajectory, chunk, following, so_far)
    t1 = _start_up_end(model, trajectory)
    t3 = steady.t_steady if steady.steady else None
    time, moment = so_far.time, so_far.moment
    period = 1 if t1 is None or time < t1 else 2 if t3 is None or time < t3 else 3
    mean = None
    if t3 is not None and steady.last is not None:
        window = np.linspace(steady.last.t_start, steady.last.t_end, 2001)
        mean = float(
            integrate.trapezoid(-model.columns(window, trajectory(window))["M_coupling"], window)
            / (window[-1] - window[0])
        )
    ratio = moment / mean if mean else None
    note = ""
    table = model.coupling.table
    if table is not None and (so_far.twist_min < table[0][0] or so_far.twist_max > table[0][-1]):
        note = (
            f"the twist ranged over {so_far.twist_min:.4g} to {so_far.twist_max:.4g} rad, beyond the characteristic's "
            f"table ({table[0][0]:g} to {table[0][-1]:g} rad): its end slopes were continued"
        )
    return MotionPeriods(
        t1, t3, CouplingPeak(moment, time, period, mean, ratio), so_far.twist_min, so_far.twist_max, note
    )


def _start_up_end(model: MachineModel, trajectory: Trajectory) -> float | None:
    """End of period 1 [s]: when the driven part's mode first becomes 'forward' (model/drivetrain.py: held at rest
    by its Coulomb resistances until the coupling moment breaks it away, or rolling back until it comes to rest
    and moves on), located exactly by the solver's guards; 0 when it turns forward from the start, None when
    it never does."""
    for time, mode in trajectory.modes:
        if model.train_mode_of(mode)[-1] == FORWARD:
            return 0.0 if time <= trajectory.t_start else float(time)
    return None


def _refine_peak(model: MachineModel, trajectory: Trajectory, times: np.ndarray, index: int) -> tuple[float, float]:
    """The extremum of M_m(t) near times[index], by bounded scalar minimisation of -|M_m| on the dense output;
    returns (time [s], M_m [N m])."""

    def passed(t: float) -> float:
        return float(-model.columns(np.array([t]), trajectory(np.array([t])))["M_coupling"][0])

    lo, hi = times[max(index - 1, 0)], times[min(index + 1, times.size - 1)]
    sampled = (float(times[index]), passed(times[index]))
    if hi == lo:
        return sampled
    result = optimize.minimize_scalar(
        lambda tau: -abs(passed(lo + tau)),
        bounds=(0.0, hi - lo),
        method="bounded",
        options={"xatol": 1e-10 * (hi - lo)},
    )
    refined = (float(lo + result.x), passed(lo + result.x))
    return refined if abs(refined[1]) > abs(sampled[1]) else sampled


# --------------------------------------------------------------------------------------------------------------
# The inverse problem


@dataclass(frozen=True)
class SpeedLaw:
    """The prescribed driven speed: omega2 = omega_m t / T for t < T (run-up from rest), then omega_m + A sin(k
    (t - T)); omega_m [rad/s], run_up T [s], amplitude A [rad/s], frequency k [rad/s]."""

    omega_m: float
    run_up: float
    amplitude: float
    frequency: float

    def __call__(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(angle turned since t = 0 [rad], omega2 [rad/s], domega2/dt [rad/s^2]) at times t [s]."""
        t = np.asarray(t, dtype=float)
        a, T, A, k = self.omega_m / self.run_up, self.run_up, self.amplitude, self.frequency
        after = np.maximum(t - T, 0.0)
        running = t < T
        angle = np.where(
            running, 0.5 * a * t * t, 0.5 * a * T * T + self.omega_m * after + A / k * (1.0 - np.cos(k * after))
        )
        omega = np.where(running, a * t, self.omega_m + A * np.sin(k * after))
        epsilon = np.where(running, a, A * k * np.cos(k * after))
        return angle, omega, epsilon


@dataclass(frozen=True)
class RequiredCoupling:
    """The answer of the inverse problem.

    law: the prescribed speed law; times [s] with the driving and driven speeds [rad/s], the twist [rad] (on
    the table's origin), the coupling moment M_m and its elastic part M_m - c (omega1 - omega2) [N m] there;
    stretch: 'whole run' or 'steady motion' (the last period of the law), what the table covers, from
    t_from [s]; table_twist [rad], table_moment [N m]: the characteristic, through (0, 0) (the part below the
    stretch continued with its secant stiffness); loop_width, whole_loop_width [N m]: the largest difference
    of the elastic moment at one twist within the stretch and over the whole run; jump: the step of the
    needed moment at t = T [N m]; realisable: single-valued and rising over the stretch; initial: the state
    (phi, omega, twist) at t_from with the two speeds equal, for a forward run of the characteristic;
    driving_delta: the driving speed's (max - min) / mean over the last period [-]; notes: what to do;
    periodic_from: index of the first sample of the last period, where the driving part's periodic motion
    (computed directly) replaces its transient.
    """

    law: SpeedLaw
    times: np.ndarray
    omega_driving: np.ndarray
    omega_driven: np.ndarray
    twist: np.ndarray
    moment: np.ndarray
    elastic: np.ndarray
    stretch: str
    t_from: float
    table_twist: np.ndarray
    table_moment: np.ndarray
    loop_width: float
    whole_loop_width: float
    jump: float
    realisable: bool
    initial: dict
    driving_delta: float
    notes: tuple[str, ...]
    periodic_from: int


def required_coupling(
    model: MachineModel,
    run_up: float,
    delta: float,
    frequency: float | None = None,
    speed: float | None = None,
    points: int = 201,
) -> RequiredCoupling:
    """Solve the inverse problem (module docstring) over the scene's duration; the driven part starts at rest at
    phi_driven = scenario.initial.phi, the driving part at rest. speed: omega_m [rad/s] (None: the speed at
    which the cycle-averaged drive balances all loads); frequency: k [rad/s] (None: once per dynamic period at
    omega_m); points: table points over the stretch."""
    coupling = _inverse_coupling(model)
    omega_m = speed if speed is not None else balance_speed(model, "; give the mean speed with --speed")
    frequency = frequency if frequency is not None else omega_m * 2.0 * math.pi / model.dynamic_period()
    law = SpeedLaw(omega_m, run_up, 0.5 * delta * omega_m, frequency)
    period = 2.0 * math.pi / frequency
    duration = model.scene.scenario.duration
    if duration < run_up + 2.0 * period:
        raise SceneError(
            f"scenario.duration = {duration:g} s is too short for the inverse problem: expected at least "
            f"the run-up plus two periods of the law, {run_up + 2 * period:.4g} s"
        )
    external = model.external_load(0.0)
    phi2_start = model.scene.scenario.initial.phi

    def needed(t: float | np.ndarray) -> np.ndarray:
        """M_m(t) from the driven part's equation [N m]."""
        angle, omega2, epsilon2 = law(np.atleast_1d(t))
        return np.array(
            [
                coupling.driven.state(phi2_start + a)[0] * e + coupling.required_moment(ti, phi2_start + a, w, external)
                for ti, a, w, e in zip(np.atleast_1d(t), angle, omega2, epsilon2)
            ]
        )

    driving = dataclasses.replace(model, coupling=None, load_pieces=())
    rates, inertia = driving.rhs(), driving.inertia_constant

    def motion(t: float, y: np.ndarray) -> list[float]:
        omega, epsilon = rates(t, y)
        return [omega, epsilon - needed(t)[0] / inertia]

    def drive(y: np.ndarray, start: float, end: float, at: ArrayLike, dense: bool = False):
        """The driving part's (phi1, omega1) at times `at` within [start, end] from y at start (and its dense
        output)."""
        solution = integrate.solve_ivp(
            motion,
            (start, end),
            y,
            method="DOP853",
            t_eval=at,
            rtol=1e-11,
            atol=1e-12,
            max_step=period / 20.0,
            dense_output=dense,
        )
        return (solution.y, solution.sol) if dense else solution.y

    samples = max(4000, int(200 * (duration - run_up) / period))
    times = np.union1d(np.linspace(0.0, run_up, 400), np.linspace(run_up, duration - period, samples))
    run_up_part = drive(np.zeros(2), 0.0, run_up, times[times <= run_up])  # no step across the law's kink at T
    phi1, omega1 = np.hstack(
        [run_up_part, drive(run_up_part[:, -1], run_up, duration - period, times[times >= run_up])[:, 1:]]
    )
    # The last period of the law: the driving part's periodic motion (omega1 repeats over it), by the secant
    # method on its speed at the period's start, in place of a transient that may decay slowly.
    start = times[-1]
    repeat = optimize.newton(
        lambda w: drive(np.array([phi1[-1], w]), start, duration, [duration])[1, -1] - w,
        omega1[-1],
        tol=1e-12 * law.omega_m,
    )
    steady_times = np.linspace(start, duration, 201)
    (steady_phi1, steady_omega1), dense = drive(np.array([phi1[-1], repeat]), start, duration, steady_times, True)
    times = np.concatenate([times, steady_times])  # start appears twice: the transient's end, the periodic start
    phi1, omega1 = np.concatenate([phi1, steady_phi1]), np.concatenate([omega1, steady_omega1])
    angle, omega2, _ = law(times)
    twist = phi1 - angle
    moment = needed(times)
    elastic = moment - coupling.damping * (omega1 - omega2)
    jump = coupling.driven.state(phi2_start + law(np.array([run_up]))[0][0])[0] * (
        law.amplitude * frequency - omega_m / run_up
    )
    scale = float(np.ptp(elastic)) or 1.0
    whole_grid, whole_curve, whole_width = _characteristic(twist, elastic, points)
    whole_rising = bool(np.all(np.diff(whole_curve) > 0.0))
    whole_ok = whole_width <= LOOP_TOLERANCE * scale and abs(jump) <= LOOP_TOLERANCE * scale and whole_rising
    last = np.arange(times.size) >= times.size - steady_times.size
    if whole_ok:
        stretch, grid, curve, width, start = "whole run", whole_grid, whole_curve, whole_width, 0
    else:
        stretch, (grid, curve, width) = "steady motion", _characteristic(twist[last], elastic[last], points)
        start = _equal_speeds(omega1 - omega2, times.size - steady_times.size)
        if start > times.size - steady_times.size:  # the crossing between samples, on the dense output
            t_equal = optimize.brentq(lambda t: dense(t)[1] - law(t)[1], times[start - 1], times[start], xtol=1e-14)
            times[start] = t_equal
            (phi1[start], omega1[start]), (angle[start], omega2[start], _) = dense(t_equal), law(t_equal)
            twist[start], moment[start] = phi1[start] - angle[start], needed(t_equal)[0]
            elastic[start] = moment[start] - coupling.damping * (omega1[start] - omega2[start])
    looped = width > LOOP_TOLERANCE * (float(np.ptp(curve)) or 1.0)
    rising = bool(np.all(np.diff(curve) > 0.0))
    shift, table_twist, table_moment = _through_origin(grid, curve)
    initial = {
        "phi": float(phi2_start + angle[start] + twist[start] + shift),
        "omega": float(omega2[start]),
        "twist": float(twist[start] + shift),
    }
    driving_delta = float(np.ptp(omega1[last]) / np.mean(omega1[last]))
    notes = () if whole_ok else _whole_run_advice(law, jump, scale, whole_width, whole_rising)
    notes += _advice(width, looped, rising, driving_delta)
    return RequiredCoupling(
        law,
        times,
        omega1,
        omega2,
        twist + shift,
        moment,
        elastic,
        stretch,
        float(times[start]),
        table_twist,
        table_moment,
        width,
        whole_width,
        jump,
        not looped and rising,
        initial,
        driving_delta,
        notes,
        times.size - steady_times.size,
    )


def _inverse_coupling(model: MachineModel) -> CouplingModel:
    """The model's coupling, whose characteristic the inverse problem computes; refuse, with a message naming the
    key, a scene the inverse problem does not cover."""
    scene = model.scene
    if model.coupling is None:
        raise SceneError(
            f"scene '{scene.name}' has no machine.coupling: the inverse problem computes a coupling's "
            "characteristic between a driving and a driven part"
        )
    if model.governor is not None:
        raise SceneError(
            f"scene '{scene.name}' has a governor: the inverse problem takes the drive as it is "
            "(remove the governor with --set governor=null)"
        )
    if model.reduced is not None or any("phi" in effect.depends_on for effect in model.effects):
        raise SceneError(
            f"scene '{scene.name}': the driving part's moments or inertia depend on the crank angle "
            "(machine.mechanism, a table or engine drive, a table or cutting load); the inverse "
            "problem takes the driving part as a motor with its rotor: moments of omega only"
        )
    if scene.scenario.load_events:
        raise SceneError(
            f"scene '{scene.name}' has scenario.load_events: the inverse problem takes a constant "
            "external load (scenario.external_load)"
        )
    return model.coupling


def _characteristic(twist: np.ndarray, moment: np.ndarray, points: int) -> tuple[np.ndarray, np.ndarray, float]:
    """The moment as a function of the twist from samples along time: the samples split into stretches where the
    twist moves one way, each interpolated onto a grid of `points` twists; returns (grid [rad], mean moment
    there [N m], largest difference between stretches at one twist [N m], 0 for a single-valued curve)."""
    direction = np.sign(np.diff(twist))
    turns = [i + 1 for i in range(1, direction.size) if direction[i] != 0 and direction[i] != direction[i - 1]]
    edges = [0] + turns + [twist.size - 1]
    grid = np.linspace(twist.min(), twist.max(), points)
    stretches = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        x, y = twist[lo : hi + 1], moment[lo : hi + 1]
        order = np.argsort(x)
        x, y = x[order], y[order]
        if x[-1] > x[0]:
            stretches.append(np.where((grid >= x[0]) & (grid <= x[-1]), np.interp(grid, x, y), np.nan))
    curves = np.array(stretches)
    width = float(np.nanmax(np.nanmax(curves, axis=0) - np.nanmin(curves, axis=0)))
    return grid, np.nanmean(curves, axis=0), width


def _through_origin(grid: np.ndarray, curve: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Shift the twist origin so that the characteristic passes through (0, 0) (only twist differences enter
    the motion): at the zero of the moment when the curve crosses it, else the curve's secant stiffness
    continued to zero moment. Returns (shift [rad], table twists [rad], table moments [N m])."""
    low, high = curve[0], curve[-1]
    secant = (high - low) / (grid[-1] - grid[0])
    secant = secant if secant > 0.0 else 1.0
    if low < 0.0 < high:
        shift = -float(np.interp(0.0, curve, grid))
    elif low >= 0.0:
        shift = low / secant - grid[0]
    else:
        shift = high / secant - grid[-1]
    twist = grid + shift
    keep = np.abs(twist) > 1e-12 * np.ptp(twist)
    twist, moment = np.append(twist[keep], 0.0), np.append(curve[keep], 0.0)
    order = np.argsort(twist)
    return shift, twist[order], moment[order]


def _equal_speeds(relative: np.ndarray, start: int) -> int:
    """Index of the first sample from index `start` at which omega1 - omega2 changes sign (a twist extremum,
    where a forward run can start with both parts at one speed)."""
    crossings = np.flatnonzero(np.sign(relative[start:-1]) != np.sign(relative[start + 1 :]))
    return start + (int(crossings[0]) + 1 if crossings.size else 0)


def _whole_run_advice(
    law: SpeedLaw, jump: float, scale: float, whole_width: float, whole_rising: bool
) -> tuple[str, ...]:
    """Why the whole run (run-up and transient) has no characteristic, so that only steady motion is tabulated."""
    reasons = []
    if abs(jump) > LOOP_TOLERANCE * scale:
        continuous = 2.0 / ((2.0 * law.amplitude / law.omega_m) * law.frequency)
        reasons.append(
            f"the needed moment jumps by {jump:.4g} N m at the end of the run-up (the acceleration jumps "
            f"from omega_m / T to A k) while the twist cannot; run-up T = 2 / (delta k) = "
            f"{continuous:.4g} s makes it continuous"
        )
    if whole_width > LOOP_TOLERANCE * scale:
        reasons.append(f"one twist needs moments up to {whole_width:.4g} N m apart")
    if not whole_rising:
        reasons.append(
            "the needed moment falls somewhere as the twist moves on (the driving part's own run-up, "
            "not the law, sets the twist)"
        )
    return (f"the whole run has no characteristic: {'; '.join(reasons)}; only the steady motion is tabulated",)


def _advice(width: float, looped: bool, rising: bool, driving_delta: float) -> tuple[str, ...]:
    """Why no elastic coupling gives the steady law, and the paper's remedy (none when one does)."""
    if not looped and rising:
        return ()
    why = " and ".join(
        ([f"one twist needs moments up to {width:.4g} N m apart (a loop)"] if looped else [])
        + ([] if rising else ["the moment falls somewhere as the twist grows (negative stiffness)"])
    )
    return (
        f"no elastic coupling gives this law: {why}; the driving part's speed fluctuates by {driving_delta:.3g} "
        "of its mean. The paper's remedy: a flywheel on one shaft (e.g. --set machine.flywheel.inertia=...) "
        "steadies the driving part so that the twist follows the law",
    )
