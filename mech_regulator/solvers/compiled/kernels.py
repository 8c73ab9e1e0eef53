"""Scalar numba kernels of the compiled fast path: one per physics piece, each a transcription of its pure-Python
original (named in its docstring, with the same equation), called by the right-hand side the code generator writes
for a scene (solvers/compiled/codegen.py). Tables are read from the parameter vector p at (offset, length), so no
number of a scene is compiled into the code. All arguments and results are SI, as in the originals.

The generated module's cache name includes this file's source: numba's own cache would not notice a changed kernel.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# ---------------------------------------------------------------------------------------------------------------
# Tables (effects/tables.py) read from p: xs at p[offset : offset + n], ys at p[offset + n : offset + 2 n]


@njit(cache=True)
def periodic_linear(x, anchor, p, offset, n, period):
    """effects.tables.periodic_linear: y(x) linear between the n points, periodic with `period`, the last point
    joined to the first plus one period (np.interp(x, xs, ys, period=period)), here the line of the segment that holds
    `anchor` continued to x (anchor = x: the table itself)."""
    x0 = p[offset]
    u = np.fmod(anchor - x0, period)
    if u < 0.0:
        u += period
    i = n - 1
    while i > 0 and p[offset + i] - x0 > u:
        i -= 1
    lo = p[offset + i] - x0
    y_lo = p[offset + n + i]
    if i + 1 < n:
        hi, y_hi = p[offset + i + 1] - x0, p[offset + n + i + 1]
    else:
        hi, y_hi = period, p[offset + n]
    return y_lo + (y_hi - y_lo) / (hi - lo) * (u - lo + (x - anchor))


@njit(cache=True)
def clamped_linear(x, p, offset, n, anchor=np.nan):
    """effects.tables.clamped_linear: y(x) linear between the n points, held at the end values beyond them; with an
    anchor (not NaN), the piece that holds the anchor continued to x (an anchor on an end point: the end segment)."""
    at = x if np.isnan(anchor) else anchor
    if at < p[offset]:
        return p[offset + n]
    if at > p[offset + n - 1]:
        return p[offset + 2 * n - 1]
    i = n - 2
    while p[offset + i] > at:
        i -= 1
    return p[offset + n + i] + (p[offset + n + i + 1] - p[offset + n + i]) / (p[offset + i + 1] - p[offset + i]) * (
        x - p[offset + i])


@njit(cache=True)
def extrapolated_linear(x, p, offset, n, anchor=np.nan):
    """effects.tables.extrapolated_linear: y(x) linear between the n points, the end segments continued; with an
    anchor (not NaN), the segment that holds the anchor continued to x."""
    at = x if np.isnan(anchor) else anchor
    i = n - 2
    while i > 0 and p[offset + i] > at:
        i -= 1
    return p[offset + n + i] + (p[offset + n + i + 1] - p[offset + n + i]) / (p[offset + i + 1] - p[offset + i]) * (
        x - p[offset + i])


# ---------------------------------------------------------------------------------------------------------------
# Effects (effects/__init__.py): moments on the crank [N m]


@njit(cache=True)
def linear_motor(omega, stall, no_load):
    """Linear motor: M_d = M_stall (1 - omega / omega_0)."""
    return stall * (1.0 - omega / no_load)


@njit(cache=True)
def table_drive(phi, anchor, p, offset, n, period):
    """Table drive: M_d = M(phi), periodic linear table (on the segment that holds anchor)."""
    return periodic_linear(phi, anchor, p, offset, n, period)


@njit(cache=True)
def engine_gas_force(phi, anchor, p, offset, n, cycle, phase, area):
    """The gas force on the piston along +x: F = -p(phi + phase) A (it pushes the piston towards the crank) [N]
    (p on the segment that holds anchor + phase)."""
    return -periodic_linear(phi + phase, anchor + phase, p, offset, n, cycle) * area


@njit(cache=True)
def engine_gas(phi, anchor, dq, p, offset, n, cycle, phase, area):
    """Single-cylinder engine: M_d = -p(phi + phase) A dx/dphi (engine_gas_force reduced to the crank)."""
    return engine_gas_force(phi, anchor, p, offset, n, cycle, phase, area) * dq


@njit(cache=True)
def viscous_load(omega, c):
    """Viscous load: M_c = -c omega."""
    return -c * omega


@njit(cache=True)
def fan_load(omega, k):
    """Fan load: M_c = -k omega |omega|."""
    return -k * omega * abs(omega)


@njit(cache=True)
def table_load(phi, anchor, p, offset, n, period):
    """Table load: M_c = -M(phi), periodic linear table (on the segment that holds anchor)."""
    return -periodic_linear(phi, anchor, p, offset, n, period)


@njit(cache=True)
def cutting_load(phi, p, offset, n, period, start, torque):
    """Cutting (on-off) load: M_c = -torque while (phi - start) mod period lies in an interval [start_k, end_k);
    the n interval edges (relative to start, ascending) are at p[offset : offset + n]."""
    u = np.fmod(phi - start, period)
    if u < 0.0:
        u += period
    count = 0  # bisect_right(bounds, u)
    while count < n and p[offset + count] <= u:
        count += 1
    return -torque if count % 2 == 1 else 0.0


@njit(cache=True)
def output_constant(dq, value):
    """Constant force (slider) or moment (rocker) on the output link: M = Q dq/dphi."""
    return value * dq


@njit(cache=True)
def output_viscous(omega, dq, c):
    """Viscous force on the output link: M = -c (dq/dphi)^2 omega."""
    return -c * dq * dq * omega


@njit(cache=True)
def output_viscous_force(omega, dq, c):
    """The viscous force itself, Q = -c dq/dphi omega (what the joint friction's kinetostatics reads) [N or N m]."""
    return -c * dq * omega


@njit(cache=True)
def output_spring_force(q, k, free):
    """The spring's force on the output link: Q = -k (q - q_free) [N or N m]."""
    return -k * (q - free)


@njit(cache=True)
def output_spring(q, dq, k, free):
    """Spring on the output link: M = -k (q - q_free) dq/dphi (output_spring_force reduced to the crank)."""
    return output_spring_force(q, k, free) * dq


@njit(cache=True)
def held_position(anchor, p, offset, n):
    """effects.held_positions looked up: the n - 1 kink angles [rad] in [0, 2 pi) at p[offset:], then 2 pi, and the n
    held slider positions [m] after them; the one of the interval that holds anchor mod 2 pi."""
    u = np.fmod(anchor, p[offset + n - 1])
    if u < 0.0:
        u += p[offset + n - 1]
    j = 0  # bisect_right(kinks, u)
    while j < n - 1 and p[offset + j] <= u:
        j += 1
    return p[offset + n + j]


@njit(cache=True)
def slider_table(q, q_anchor, dq, p, offset, n):
    """Slider force table: M = F(x) dx/dphi, F clamped linear in x (on the piece that holds x = q_anchor [m])."""
    return clamped_linear(q, p, offset, n, q_anchor) * dq


# ---------------------------------------------------------------------------------------------------------------
# Joint friction (effects/joint_friction.py): reactions as complex Fx + i Fy [N] from the linkage kinetostatics


@njit(cache=True)
def joint_friction_acceleration(omega, moment, inertia, collar, arms, ratios, constant, per_epsilon, with_joints,
                                tolerance, iterations, ratio_signs, normal_signs):
    """JointFrictionModel.acceleration: epsilon [rad/s^2] solving J epsilon = M - sign(omega) F(epsilon),
    F = M_collar + sum_j rho_j |k_j| |R0_j + R1_j epsilon| by Newton's method from the friction at rest; at rest
    (omega = 0) 0 while |M| <= F(0), else breaking away in the direction of M; NaN without convergence.
    arms: rho_j [m] (f_guide for a guide) of the mechanism's linkage's joints, 0 for a
    joint without friction (its terms add exact zeros); with_joints False: the collar alone (no kinetostatics).
    Between two corners (docs/theory.md §6.5): ratio_signs s_j (0: |k_j|) read rho_j s_j k_j, normal_signs s_N
    (0: |R|) a guide's |N| (its reaction i N) as s_N N, per joint (0 for every joint but the guides)."""
    at_rest = 0.0
    if with_joints:
        for j in range(len(arms)):
            at_rest += arms[j] * _friction_weight(ratios[j], ratio_signs[j]) * _reaction_size(constant[j],
                                                                                              normal_signs[j])
    at_rest = collar + at_rest
    if omega > 0.0:
        sign = 1.0
    elif omega < 0.0:
        sign = -1.0
    elif abs(moment) <= at_rest:
        return 0.0
    else:
        sign = 1.0 if moment > 0.0 else -1.0
    epsilon = (moment - sign * at_rest) / inertia
    if not with_joints:
        return epsilon
    for _ in range(iterations):
        friction, slope = collar, 0.0
        for j in range(len(arms)):
            weight = arms[j] * _friction_weight(ratios[j], ratio_signs[j])
            reaction = constant[j] + per_epsilon[j] * epsilon
            size = _reaction_size(reaction, normal_signs[j])
            friction += weight * size
            if normal_signs[j] != 0.0:
                slope += weight * normal_signs[j] * per_epsilon[j].imag
            elif size > 0.0:
                slope += weight * (per_epsilon[j].real * reaction.real + per_epsilon[j].imag * reaction.imag) / size
        step = (inertia * epsilon - moment + sign * friction) / (inertia + sign * slope)
        epsilon -= step
        if abs(step) <= tolerance * (abs(epsilon) + (abs(moment) + friction) / inertia):
            return epsilon
    return math.nan


@njit(cache=True)
def _friction_weight(ratio, sign):
    """|k_j| [-], or s_j k_j continued across its sign change when sign s_j is +-1 (JointFrictionModel._terms)."""
    return abs(ratio) if sign == 0.0 else sign * ratio


@njit(cache=True)
def _reaction_size(reaction, normal_sign):
    """|R_j| [N], or for a guide (reaction i N) s_N N continued across N = 0 when normal_sign s_N is +-1
    (JointFrictionModel.acceleration)."""
    return normal_sign * reaction.imag if normal_sign != 0.0 else abs(reaction)


# ---------------------------------------------------------------------------------------------------------------
# Governor (valve.py, governors/__init__.py; the sensors' formulas are their own modules' functions, codegen)


@njit(cache=True)
def linear_valve(z, open_at, closed_at):
    """governors.valve linear: throttle = (z_closed - z) / (z_closed - z_open), clipped to [0, 1]."""
    return min(max((closed_at - z) / (closed_at - open_at), 0.0), 1.0)


@njit(cache=True)
def rigid_feedback(gain, servo, reference):
    """Rigid feedback's share of the pilot opening: rho (s - s_ref) [m]."""
    return gain * (servo - reference)


@njit(cache=True)
def servo_command(opening, gain, max_speed, dead_band):
    """Governor.servo_command: s' = -gain * opening, the opening less the dead band, clipped to +-max_speed [1/s]."""
    if dead_band > 0.0:
        opening = math.copysign(max(abs(opening) - dead_band, 0.0), opening)
    return min(max(-gain * opening, -max_speed), max_speed)


# ---------------------------------------------------------------------------------------------------------------
# Drive train behind an elastic coupling (model/machine.py _train, model/drivetrain.py)


@njit(cache=True)
def driven_acceleration(direction, passed, weight, smooth, dI, omega2, I2, resistance):
    """domega2/dt of a turning driven part: (M_weight + M_m - s R - 1/2 I2' omega2^2 + M_smooth) / I2, s = +1
    forward, -1 backward (R: Coulomb resistances and the external load) [rad/s^2]."""
    total = weight + (passed - direction * resistance - 0.5 * dI * omega2 * omega2)
    return (total + smooth) / I2


@njit(cache=True)
def clutch_forces(clutch, part, F1, J, smooth, resistance, inertia, kinetic):
    """model.drivetrain.ClutchModel.forces in a train mode (clutch: 0 stuck, 1 slipping with the motor ahead, -1
    with the machine ahead; part: 0 forward, 1 backward, 2 held): stuck and held, everything at rest and the clutch
    passing F1; stuck and turning, (J + I) epsilon = F1 + M_smooth - s R and T = F1 - J epsilon; slipping,
    T = +-kinetic_torque, epsilon = (F1 - T) / J and I epsilon2 = T + M_smooth - s R (0 held). Returns (epsilon,
    epsilon2 [rad/s^2], T, push = T + M_smooth [N m])."""
    if clutch == 0.0:
        if part == 2.0:
            return 0.0, 0.0, F1, F1 + smooth
        s = 1.0 if part == 0.0 else -1.0
        acceleration = (F1 + smooth - s * resistance) / (J + inertia)
        torque = F1 - J * acceleration
        return acceleration, acceleration, torque, torque + smooth
    torque = kinetic if clutch == 1.0 else -kinetic
    driven = 0.0
    if part != 2.0:
        driven = (torque + smooth - (1.0 if part == 0.0 else -1.0) * resistance) / inertia
    return (F1 - torque) / J, driven, torque, torque + smooth


@njit(cache=True)
def driven_margin(passed, weight, smooth, dI, omega2, resistance, sign):
    """The holding margin of a driven part at rest, R + sign * push, push = M_m + M_weight + M_smooth
    - 1/2 I2' omega2^2 (MachineModel.drive_train_at, drivetrain._margin) [N m]."""
    return resistance + sign * (passed + (weight + smooth - 0.5 * dI * omega2 * omega2))
