"""The textbook energy (table) method: fixed steps in the crank angle (docs/theory.md §2.6).

    E_{i+1} = E_i + 1/2 (M_i + M_{i+1}) (phi_{i+1} - phi_i),    omega_{i+1} = sqrt(2 E_{i+1} / J_{i+1}),
    t_{i+1} = t_i + 2 (phi_{i+1} - phi_i) / (omega_i + omega_{i+1}),

with E = 1/2 J omega^2 and M the net moment without the J' term (the energy form accounts for it).
Moments that read omega or t make the step implicit; it is solved by fixed-point iteration. A step that would pass
a switch or kink angle (model.switch_grid: a jump of the cutting load, a knot of a table in phi) ends on it, and the
step's moments are those of the interval between two such angles (model.rhs's window: jumps held, tables continued
along one segment), so the trapezoid rule never straddles a corner and integrates a table's segment exactly. A start
from rest (omega_0 = 0) is exact for a constant net moment; a machine that stops or turns back
(E reaching 0) cannot be followed in phi, and the method stops there with a clear message.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import optimize
from scipy.interpolate import CubicHermiteSpline

from mech_regulator.model import MachineModel
from mech_regulator.scene.limits import MAX_SPEED, MAX_STEPS
from mech_regulator.solvers.time_domain import fail_blown_up, fail_too_many_steps, switch_window, turns_and_phase
from mech_regulator.solvers.trajectory import Progress, Stream, Trajectory

MAX_ITERATIONS = 100


def integrate_energy_method(
    model: MachineModel, progress: Progress | None = None, stream: Stream | None = None
) -> Trajectory:
    """Step the scene in phi until its duration is reached; returns the (possibly partial) trajectory (stream: its
    Trajectory.stream).

    Load events in time are resolved only to the phi step (the method has no time breakpoints).
    """
    scenario = model.scene.scenario
    dphi = math.radians(model.scene.solver.phi_step_deg)
    implicit = bool(model.depends_on() & {"omega", "t"})
    t, phi, omega = 0.0, scenario.initial.phi, scenario.initial.omega
    trajectory = Trajectory(method="energy", t_start=0.0, y_start=np.array([phi, omega]), stream=stream)
    if omega < 0.0:
        trajectory.status = "failed"
        trajectory.message = (
            f"energy method: initial omega = {omega} rad/s; the method steps forward in phi and "
            "needs omega >= 0 (use a time-domain method such as DOP853)"
        )
        return trajectory

    grid, period = np.array(model.switch_grid(), dtype=float), model.dynamic_period()
    right_hand_sides: dict = {}

    def moment_and_derivative(
        t: float, phase: float, omega: float, window: tuple | None = None
    ) -> tuple[float, float, float]:
        """(net moment M [N m], J [kg m^2], epsilon [rad/s^2]) from the model's right-hand side:
        M = J epsilon + 1/2 J' omega^2; within a window (lo, hi) [rad] between two switch or kink angles, at the
        crank's phase (phi less whole dynamic periods [rad], the window's coordinates: the machine is periodic in
        them)."""
        key = (model.piece_at(t), window)
        if key not in right_hand_sides:
            right_hand_sides[key] = model.rhs(*key)
        _, epsilon = right_hand_sides[key](t, (phase, omega))
        J, dJ = model.inertia(phase)
        trajectory.stats.nfev += 1
        return J * epsilon + 0.5 * dJ * omega * omega, J, epsilon

    # the crank angle as whole periods and the phase within them (time_domain.turns_and_phase), carried exactly: the
    # steps end on switch angles of the phase, and phi = turns period + phase is only written out
    turns, phase = turns_and_phase(phi, period)
    M, J, epsilon = moment_and_derivative(t, phase, omega)
    energy = 0.5 * J * omega * omega
    times, states, slopes = [t], [(phi, omega)], [(omega, epsilon)]
    window = None
    try:
        while t < scenario.duration:
            whole = math.floor(phase / period)
            turns, phase = turns + whole, phase - whole * period
            phase_next = phase + dphi
            if grid.size:  # end the step on the next switch or kink angle; the moments of the interval it is in
                window_before, window = window, switch_window(grid, period, phase, forward=True)
                phase_next = min(phase_next, window[1])
                if window != window_before:  # the moment on the far side of the angle just reached
                    M, _, _ = moment_and_derivative(t, phase, omega, window)
            step = phase_next - phase
            J_next, _ = model.inertia(phase_next)

            def energy_after(speed: float) -> tuple[float, float, float]:
                """(E_{i+1} [J], M_{i+1} [N m], epsilon_{i+1}) if the step ends at speed [rad/s]."""
                M_next, _, epsilon_next = moment_and_derivative(
                    t + 2.0 * step / (omega + speed), phase_next, speed, window
                )
                return energy + 0.5 * (M + M_next) * step, M_next, epsilon_next

            step_end = _step_end(energy_after, J_next, omega, energy + M * step, implicit)
            if step_end is None:
                raise _Stopped(t, phi, omega)
            omega_next, energy_next, M_next, epsilon_next = step_end
            t = t + 2.0 * step / (omega + omega_next)
            phase, omega, M, energy = phase_next, omega_next, M_next, energy_next
            phi = turns * period + phase
            if implicit:  # the slope at the accepted time and speed
                M, _, epsilon_next = moment_and_derivative(t, phase, omega, window)
            times.append(t)
            states.append((phi, omega))
            slopes.append((omega, epsilon_next))
            trajectory.stats.steps += 1
            if not abs(omega) <= MAX_SPEED:  # a blow-up (limits.py): stop here, keeping the run
                fail_blown_up(model, trajectory, t, (phi, omega), "omega", omega)
                break
            if trajectory.stats.steps >= MAX_STEPS:
                fail_too_many_steps(model, trajectory, t, (phi, omega))
                break
            if progress is not None and trajectory.stats.steps % 1000 == 0:
                progress(min(t, scenario.duration))
    except _Stopped as stop:
        trajectory.status = "failed"
        if stop.omega == 0.0:
            what = (
                f"the net moment at rest (M = {M:.6g} N m at t = {stop.t:.6g} s, phi = {stop.phi:.6g} rad) "
                "does not start the machine; stepping in phi cannot follow a machine that stays at rest or "
                "turns back"
            )
        else:
            what = (
                f"the machine stops (kinetic energy reaches 0) just after t = {stop.t:.6g} s, phi = {stop.phi:.6g} "
                f"rad, omega = {stop.omega:.6g} rad/s; stepping in phi cannot follow a stop or a reversal"
            )
        trajectory.message = f"energy method: {what}: use a time-domain method such as DOP853"
    except _NoConvergence:
        trajectory.status = "failed"
        trajectory.message = (
            f"energy method: no end speed satisfies the step's energy equation at phi = {phi:.6g} rad "
            f"(t = {t:.6g} s); use a smaller solver.phi_step_deg or a time-domain method"
        )
    except KeyboardInterrupt:
        trajectory.status = "interrupted"
        trajectory.message = f"interrupted by the user at t = {t:.6g} s"
    if len(times) > 1:
        trajectory.add_piece(
            times[0],
            min(times[-1], scenario.duration),
            CubicHermiteSpline(np.array(times), np.array(states).T, np.array(slopes).T, axis=1),
        )
    return trajectory


def _step_end(
    energy_after, J_next: float, omega: float, explicit_energy: float, implicit: bool
) -> tuple[float, float, float, float] | None:
    """The end of a step, (omega_{i+1} [rad/s], E_{i+1} [J], M_{i+1} [N m], epsilon_{i+1} [rad/s^2]):
    omega_{i+1} is the positive root of 1/2 J_{i+1} w^2 = E_{i+1}(w), the trapezoidal energy with the moment
    at the step's end evaluated at w (and at the time the step ends at). None when no positive speed
    satisfies it: the machine stops.

    Fixed-point iteration from the explicit guess w = sqrt(2 (E_i + M_i dphi) / J_{i+1}) converges in a few
    iterations for moderate steps; when it does not (a step long against the machine's time constant
    overshoots), the root is bracketed and found by Brent's method, so a too-long step is never taken for
    a stop. Raises _NoConvergence if the root cannot be bracketed."""
    guess = math.sqrt(max(2.0 * explicit_energy, 0.0) / J_next) if omega == 0.0 else omega
    for _ in range(MAX_ITERATIONS if implicit else 1):
        if omega + guess <= 0.0:
            break
        energy_next, M_next, epsilon_next = energy_after(guess)
        if energy_next <= 0.0:
            break
        omega_next = math.sqrt(2.0 * energy_next / J_next)
        if not implicit or abs(omega_next - guess) <= 1e-14 * omega_next:
            return omega_next, energy_next, M_next, epsilon_next
        guess = omega_next
    if not implicit:
        return None

    def surplus(speed: float) -> float:
        return energy_after(speed)[0] - 0.5 * J_next * speed * speed

    low = 1e-9 * max(omega, abs(guess)) or 1e-12  # [rad/s]; from rest, a speed the step's time stays finite at
    if not surplus(low) > 0.0:
        return None
    high = max(omega, abs(guess), 2.0 * low)
    for _ in range(200):
        if surplus(high) < 0.0:
            omega_next = optimize.brentq(surplus, low, high, xtol=1e-15 * high, rtol=4 * np.finfo(float).eps)
            return (omega_next, *energy_after(omega_next))
        high *= 2.0
    raise _NoConvergence


class _NoConvergence(Exception):
    pass


class _Stopped(Exception):
    def __init__(self, t: float, phi: float, omega: float):
        super().__init__()
        self.t, self.phi, self.omega = t, phi, omega
