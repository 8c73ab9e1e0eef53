"""The drives (a scene's `machine.drive`), each defined once for both paths (effects/definition.py): its formula, a
plain function numba compiles unchanged, its numbers and its table. Positive moments drive the crank [N m]."""

from __future__ import annotations

import math
from dataclasses import replace

from mech_regulator.effects.definition import PERIODIC, Definition, Table, define
from mech_regulator.mechanisms.engine import firing_delays
from mech_regulator.scene import effect_keys, mechanism_keys


def constant_drive(torque):
    """Constant drive: M_d = torque [N m]."""
    return torque


def linear_motor(omega, stall, no_load):
    """Linear motor: M_d = M_stall (1 - omega / omega_0) [N m]."""
    return stall * (1.0 - omega / no_load)


def table_drive(table):
    """Table drive: M_d = M(phi), the periodic table read at phi [N m]."""
    return table


def engine_gas_force(table, area):
    """The gas force on the piston along +x, F = -p A: the gas pushes the piston towards the crank axis (table: the
    pressure p(phi + phase) [Pa], area A [m^2]) [N]."""
    return -table * area


def engine_gas(table, dq, area):
    """One cylinder's gas moment on the crank, M_d = -p A dx/dphi (engine_gas_force reduced to the crank) [N m]."""
    return -table * area * dq


@define(effect_keys.ConstantDrive)
def _constant(drive: effect_keys.ConstantDrive, mechanism=None) -> Definition:
    return Definition(
        "drive", "drive", f"constant: M_d = {drive.torque:g} N m", constant_drive, {"torque": drive.torque}
    )


@define(effect_keys.LinearMotor)
def _linear_motor(drive: effect_keys.LinearMotor, mechanism=None) -> Definition:
    return Definition(
        "drive",
        "drive",
        f"linear motor: M_d = {drive.stall_torque:g} (1 - omega / {drive.no_load_speed:g}) N m",
        linear_motor,
        {"stall": drive.stall_torque, "no_load": drive.no_load_speed},
        frozenset({"omega"}),
    )


@define(effect_keys.TableDrive)
def _table(drive: effect_keys.TableDrive, mechanism=None) -> Definition:
    return Definition(
        "drive",
        "drive",
        f"table M_d(phi), {len(drive.torque)} points over {drive.period_deg:g} deg",
        table_drive,
        depends_on=frozenset({"phi"}),
        table=Table(
            PERIODIC,
            tuple(math.radians(a) for a in drive.angle_deg),
            tuple(drive.torque),
            math.radians(drive.period_deg),
        ),
    )


@define(effect_keys.Engine)
def _engine(drive: effect_keys.Engine, mechanism=None) -> Definition:
    """An engine's cylinders on the crank: `M_d = -A sum_i p(phi + phase - d_i) x_i'` with cylinder i's firing delay
    d_i (mechanisms.engine.firing_delays, 0 for a single cylinder) and its piston's x_i' = dx_i/dphi (the
    mechanism's output i)."""
    area = math.pi * drive.bore**2 / 4.0
    cylinders = mechanism.cylinders if isinstance(mechanism, mechanism_keys.CrankSlider) else None
    pressure = Table(
        PERIODIC, tuple(math.radians(a) for a in drive.angle_deg), tuple(drive.pressure), math.radians(drive.cycle_deg)
    )
    cycle = f"{drive.cycle_deg:g} deg cycle"
    if cylinders is None:
        return Definition(
            "drive",
            "drive",
            f"engine: M_d = -p(phi) A dx/dphi, A = {area:.6g} m^2, {cycle}",
            engine_gas,
            {"area": area},
            frozenset({"phi"}),
            replace(pressure, shifts=(math.radians(drive.phase_deg),)),
            output_force=engine_gas_force,
            on_output=True,
        )
    delays = firing_delays(
        [c.throw_deg for c in cylinders],
        [c.bank_deg for c in cylinders],
        drive.cycle_deg,
        drive.firing_order,
        drive.firing_deg,
    )
    order = "-".join(str(i + 1) for i in sorted(range(len(delays)), key=delays.__getitem__))
    return Definition(
        "drive",
        "drive",
        f"engine: M_d = -A sum_i p(phi + {drive.phase_deg:g} deg - d_i) dx_i/dphi, "
        f"{len(cylinders)} cylinders, A = {area:.6g} m^2, {cycle}, firing {order} at "
        f"{', '.join(f'{d:g}' for d in sorted(delays))} deg",
        engine_gas,
        {"area": area},
        frozenset({"phi"}),
        replace(pressure, shifts=tuple(math.radians(drive.phase_deg - delay) for delay in delays)),
        on_output=True,
    )
