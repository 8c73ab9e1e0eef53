"""Scalar numba kernels of the compiled fast path, called by the right-hand side the code generator writes for a
scene (solvers/compiled/codegen.py): the drives', loads', valves' and servo's formulas themselves, compiled from
their one definition (`compiled`, effects/definition.py) as is joint friction's Newton solve
(effects.joint_friction.friction_acceleration), and, for the pieces not yet defined once, a transcription of the
pure-Python original (named in its docstring, with the same equation): the tables' lookups, the sensor, the drive
train. Tables are read from the parameter vector p at (offset, length), so no
number of a scene is compiled into the code. All arguments and results are SI, as in the originals.

The generated module's cache name includes this file's source and the formulas' modules' (codegen writes their hash
into the module): numba's own cache would not notice a changed kernel.
"""

from __future__ import annotations

import functools
import importlib

import numpy as np
from numba import njit

from mech_regulator import numba_cache

numba_cache.install()  # before the first njit(cache=True): keyed on the package's source


@functools.cache
def compiled(module: str, name: str):
    """The function `name` of `module` (a definition's formula, effects/definition.py, or joint friction's Newton solve:
    a plain function) compiled by numba, once per process (numba's disk cache beside the module keeps the machine
    code)."""
    return njit(cache=True)(getattr(importlib.import_module(module), name))


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
        x - p[offset + i]
    )


@njit(cache=True)
def extrapolated_linear(x, p, offset, n, anchor=np.nan):
    """effects.tables.extrapolated_linear: y(x) linear between the n points, the end segments continued; with an
    anchor (not NaN), the segment that holds the anchor continued to x."""
    at = x if np.isnan(anchor) else anchor
    i = n - 2
    while i > 0 and p[offset + i] > at:
        i -= 1
    return p[offset + n + i] + (p[offset + n + i + 1] - p[offset + n + i]) / (p[offset + i + 1] - p[offset + i]) * (
        x - p[offset + i]
    )


@njit(cache=True)
def inside_intervals(x, p, offset, n, period):
    """effects.tables.interval_indicator: 1.0 while x mod period lies in one of the intervals [e_2k, e_2k+1) of the n
    edges at p[offset : offset + n] (from 0, ascending), else 0.0."""
    u = np.fmod(x, period)
    if u < 0.0:
        u += period
    count = 0  # bisect_right(edges, u)
    while count < n and p[offset + count] <= u:
        count += 1
    return 1.0 if count % 2 == 1 else 0.0


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
