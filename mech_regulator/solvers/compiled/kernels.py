"""Scalar numba kernels of the compiled fast path, called by the right-hand side the code generator writes for a
scene (solvers/compiled/codegen.py): the drives', loads', valves' and servo's formulas themselves, compiled from
their one definition (`compiled`, effects/definition.py), as are the tables' lookups (effects/tables.py) and joint
friction's Newton solve (effects.joint_friction.friction_acceleration), and, for the pieces not yet defined once, a
transcription of the pure-Python original (named in its docstring, with the same equation): the drive train. Tables
are read from the parameter vector p at (offset, length), so no number of a scene is compiled into the code. All
arguments and results are SI, as in the originals.

The generated module's cache name includes this file's source and the formulas' modules' (codegen writes their hash
into the module): numba's own cache would not notice a changed kernel.
"""

from __future__ import annotations

import functools
import importlib

from numba import njit

from mech_regulator import numba_cache
from mech_regulator.effects import tables

numba_cache.install()  # before the first njit(cache=True): keyed on the package's source


@functools.cache
def compiled(module: str, name: str):
    """The function `name` of `module` (a definition's formula, effects/definition.py, or joint friction's Newton solve:
    a plain function) compiled by numba, once per process (numba's disk cache beside the module keeps the machine
    code)."""
    return njit(cache=True)(getattr(importlib.import_module(module), name))


# ---------------------------------------------------------------------------------------------------------------
# Tables: effects/tables.py's lookups compiled, read from p (xs at p[offset : offset + n], ys at
# p[offset + n : offset + 2 n]); an anchor NaN reads the table itself

periodic_linear = compiled(tables.__name__, "periodic_value")  # (x, anchor, p, offset, n, period)
clamped_linear = compiled(tables.__name__, "clamped_value")  # (x, anchor, p, offset, n)
extrapolated_linear = compiled(tables.__name__, "extrapolated_value")  # (x, anchor, p, offset, n)
inside_intervals = compiled(tables.__name__, "interval_value")  # (x, p, offset, n, period)
held_position = compiled(tables.__name__, "held_value")  # (anchor, p, offset, n)


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
