"""Effects: the moments that act on the machine, each reduced to the crank.

An effect is built once from its scene entry into a plain closure
`moment(t, phi, omega, q, dq) -> M [N m]` over constants, where q is the mechanism's output
coordinate (slider position x [m], rocker angle th4 [rad] or shuttle bar position x_C [m]) and dq = dq/dphi its velocity ratio.
A force F on the output link becomes the reduced moment `F dq` (same power, physics.md section 1).
With several cylinders q and dq are tuples, one entry per piston; only the engine drive reads them then
(loads on "the slider" are refused by the scene).
Only the effects a scene names are built; the right-hand side calls exactly these.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass
from typing import Callable

from mech_regulator.effects.tables import clamped_linear, periodic_linear
from mech_regulator.mechanisms.engine import firing_delays
from mech_regulator.scene import schema

MomentFunction = Callable[[float, float, float, float, float], float]

TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class Effect:
    """One moment acting on the machine, ready for the hot path.

    name: column name in outputs; role: 'drive' or 'load'; moment: the closure;
    depends_on: which of 't', 'phi', 'omega' it reads ('phi' includes the output coordinate);
    period: its period in phi [rad] if it depends on phi; switch_angles: angles in [0, period)
    where it jumps [rad]; formula: what it computes, for `describe`; output_force: for an effect acting
    on the output link, the generalised force Q(t, phi, omega, q, dq) on it (slider force along +x [N],
    rocker moment [N m]) whose reduced moment is `moment` = Q dq, else None (read by the kinetostatics of
    joint friction only).
    """

    name: str
    role: str
    moment: MomentFunction
    depends_on: frozenset[str]
    formula: str
    period: float | None = None
    switch_angles: tuple[float, ...] = ()
    output_force: MomentFunction | None = None


def build_drive(drive: schema.Drive, mechanism: schema.Mechanism | None = None) -> Effect:
    """The driving moment M_d of a scene's `machine.drive` (an engine reads the mechanism's cylinders)."""
    if isinstance(drive, schema.ConstantDrive):
        torque = drive.torque
        return Effect("drive", "drive", lambda t, phi, omega, q, dq: torque, frozenset(),
                      f"constant: M_d = {torque:g} N m")
    if isinstance(drive, schema.LinearMotor):
        stall, no_load = drive.stall_torque, drive.no_load_speed
        return Effect("drive", "drive", lambda t, phi, omega, q, dq: stall * (1.0 - omega / no_load),
                      frozenset({"omega"}), f"linear motor: M_d = {stall:g} (1 - omega / {no_load:g}) N m")
    if isinstance(drive, schema.TableDrive):
        table = periodic_linear([math.radians(a) for a in drive.angle_deg], drive.torque, math.radians(drive.period_deg))
        return Effect("drive", "drive", lambda t, phi, omega, q, dq: table(phi), frozenset({"phi"}),
                      f"table M_d(phi), {len(drive.torque)} points over {drive.period_deg:g} deg",
                      period=math.radians(drive.period_deg))
    if isinstance(drive, schema.Engine):
        area = math.pi * drive.bore ** 2 / 4.0
        phase = math.radians(drive.phase_deg)
        pressure = periodic_linear([math.radians(a) for a in drive.angle_deg], drive.pressure,
                                   math.radians(drive.cycle_deg))
        cylinders = mechanism.cylinders if isinstance(mechanism, schema.CrankSlider) else None
        if cylinders is not None:
            return _multi_cylinder_engine(drive, cylinders, area, pressure)
        # Gas pushes the piston towards the crank axis: F_x = -p A, reduced moment F_x dx/dphi.
        return Effect("drive", "drive", lambda t, phi, omega, q, dq: -pressure(phi + phase) * area * dq,
                      frozenset({"phi"}), f"engine: M_d = -p(phi) A dx/dphi, A = {area:.6g} m^2, "
                                          f"{drive.cycle_deg:g} deg cycle", period=math.radians(drive.cycle_deg),
                      output_force=lambda t, phi, omega, q, dq: -pressure(phi + phase) * area)
    raise TypeError(f"no drive effect for {type(drive).__name__}")


def _multi_cylinder_engine(drive: schema.Engine, cylinders: list[schema.Cylinder], area: float,
                           pressure: Callable[[float], float]) -> Effect:
    """Gas moment of identical cylinders on one crankshaft: `M_d = -A sum_i p(phi + phase - d_i) x_i'`, with
    cylinder i's firing delay d_i (mechanisms.engine.firing_delays) and its piston's x_i' = dx_i/dphi, which
    the multi-cylinder mechanism passes as the tuple dq. Linear in each x_i': cylinder i's share is the
    moment with the other ratios set to zero."""
    delays = firing_delays([c.throw_deg for c in cylinders], [c.bank_deg for c in cylinders], drive.cycle_deg,
                           drive.firing_order, drive.firing_deg)
    shifts = tuple(math.radians(drive.phase_deg - delay) for delay in delays)

    def moment(t: float, phi: float, omega: float, q, dq) -> float:
        total = 0.0
        for shift, ratio in zip(shifts, dq):
            total += pressure(phi + shift) * ratio
        return -area * total

    order = "-".join(str(i + 1) for i in sorted(range(len(delays)), key=delays.__getitem__))
    return Effect("drive", "drive", moment, frozenset({"phi"}),
                  f"engine: M_d = -A sum_i p(phi + {drive.phase_deg:g} deg - d_i) dx_i/dphi, {len(cylinders)} cylinders, "
                  f"A = {area:.6g} m^2, "
                  f"{drive.cycle_deg:g} deg cycle, firing {order} at {', '.join(f'{d:g}' for d in sorted(delays))} deg",
                  period=math.radians(drive.cycle_deg))


def _cutting(load: schema.CuttingLoad) -> Effect:
    """On-off load: -torque while (phi mod period) lies in one of the intervals [start, end)."""
    period = math.radians(load.period_deg)
    start = math.radians(load.intervals_deg[0][0])
    bounds = [math.radians(edge) - start for interval in load.intervals_deg for edge in interval]
    torque = load.torque

    def moment(t: float, phi: float, omega: float, q: float, dq: float) -> float:
        u = math.fmod(phi - start, period)
        if u < 0.0:
            u += period
        return -torque if bisect.bisect_right(bounds, u) % 2 == 1 else 0.0

    switches = tuple(sorted({(edge + start) % period for edge in bounds}))
    return Effect("cutting", "load", moment, frozenset({"phi"}),
                  f"cutting: M_c = -{torque:g} N m over {load.intervals_deg} deg", period=period,
                  switch_angles=switches)


def build_load(load: schema.Load, kinematic_period: float | None) -> Effect:
    """A resisting moment or force of a scene's `machine.loads` entry; loads on the output link are
    periodic with the mechanism (kinematic_period [rad])."""
    if isinstance(load, schema.ConstantLoad):
        torque = load.torque
        return Effect("constant", "load", lambda t, phi, omega, q, dq: -torque, frozenset(),
                      f"constant: M_c = -{torque:g} N m")
    if isinstance(load, schema.ViscousLoad):
        c = load.coefficient
        return Effect("viscous", "load", lambda t, phi, omega, q, dq: -c * omega, frozenset({"omega"}),
                      f"viscous: M_c = -{c:g} omega")
    if isinstance(load, schema.FanLoad):
        k = load.coefficient
        return Effect("fan", "load", lambda t, phi, omega, q, dq: -k * omega * abs(omega), frozenset({"omega"}),
                      f"fan: M_c = -{k:g} omega |omega|")
    if isinstance(load, schema.TableLoad):
        table = periodic_linear([math.radians(a) for a in load.angle_deg], load.torque, math.radians(load.period_deg))
        return Effect("table", "load", lambda t, phi, omega, q, dq: -table(phi), frozenset({"phi"}),
                      f"table: M_c = -M(phi), {len(load.torque)} points over {load.period_deg:g} deg",
                      period=math.radians(load.period_deg))
    if isinstance(load, schema.CuttingLoad):
        return _cutting(load)
    on = {"slider": "slider", "rocker": "rocker", "shuttle": "shuttle bar"}[load.type.split("_")[0]]
    if isinstance(load, (schema.SliderConstant, schema.RockerConstant)):
        value = load.force if isinstance(load, schema.SliderConstant) else load.torque
        return Effect(load.type, "load", lambda t, phi, omega, q, dq: value * dq, frozenset({"phi"}),
                      f"constant on the {on}: M = {value:g} dq/dphi", period=kinematic_period,
                      output_force=lambda t, phi, omega, q, dq: value)
    if isinstance(load, schema.OutputViscous):
        c = load.coefficient
        return Effect(load.type, "load", lambda t, phi, omega, q, dq: -c * dq * dq * omega,
                      frozenset({"phi", "omega"}), f"viscous on the {on}: M = -{c:g} (dq/dphi)^2 omega",
                      period=kinematic_period, output_force=lambda t, phi, omega, q, dq: -c * dq * omega)
    if isinstance(load, schema.OutputSpring):
        k, free = load.stiffness, load.free_position
        return Effect(load.type, "load", lambda t, phi, omega, q, dq: -k * (q - free) * dq, frozenset({"phi"}),
                      f"spring on the {on}: M = -{k:g} (q - {free:g}) dq/dphi", period=kinematic_period,
                      output_force=lambda t, phi, omega, q, dq: -k * (q - free))
    if isinstance(load, schema.SliderTable):
        force = clamped_linear(load.position, load.force)
        return Effect("slider_table", "load", lambda t, phi, omega, q, dq: force(q) * dq, frozenset({"phi"}),
                      f"slider force table F(x), {len(load.force)} points: M = F(x) dx/dphi",
                      period=kinematic_period, output_force=lambda t, phi, omega, q, dq: force(q))
    raise TypeError(f"no load effect for {type(load).__name__}")
