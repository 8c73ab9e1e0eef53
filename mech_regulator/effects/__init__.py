"""Effects: the moments that act on the machine, each reduced to the crank.

An effect is built once from its scene entry into a plain closure
`moment(t, phi, omega, q, dq) -> M [N m]` over constants, where q is the mechanism's output
coordinate (slider position x [m], rocker angle th4 [rad] or shuttle bar position x_C [m]) and dq = dq/dphi its velocity ratio.
A force F on the output link becomes the reduced moment `F dq` (same power, docs/theory.md §2.2).
With several cylinders q and dq are tuples, one entry per piston; only the engine drive reads them then
(loads on "the slider" are refused by the scene).
Only the effects a scene names are built; the right-hand side calls exactly these.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable
from dataclasses import dataclass

from scipy.optimize import brentq

from mech_regulator.effects.tables import clamped_linear, periodic_kinks, periodic_linear
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
    where it jumps [rad]; kink_angles: angles in [0, period) where its slope in phi jumps (the knots of a table in phi,
    the angles where the slider crosses a breakpoint of a table in x) [rad]; segment_moment(anchor, t, phi, omega, q,
    dq): the moment with each table in phi replaced by the line of its segment that holds phi = anchor [rad] (a table
    in x: the segment x keeps between the two kinks around anchor; for a solver between two kinks: smooth, the kink
    met only by restarting on it); None without kinks; formula: what it computes, for `describe`; output_force: for
    an effect acting on the output link, the generalised force Q(t, phi, omega, q, dq) on it (slider force along +x [N],
    rocker moment [N m]) whose reduced moment is `moment` = Q dq, else None (read by the kinetostatics of
    joint friction only); segment_output_force(anchor, t, phi, omega, q, dq): output_force read on the same piece as
    segment_moment (None: output_force has no breakpoints).
    """

    name: str
    role: str
    moment: MomentFunction
    depends_on: frozenset[str]
    formula: str
    period: float | None = None
    switch_angles: tuple[float, ...] = ()
    output_force: MomentFunction | None = None
    kink_angles: tuple[float, ...] = ()
    segment_moment: Callable[..., float] | None = None
    segment_output_force: Callable[..., float] | None = None


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
        angles, period = [math.radians(a) for a in drive.angle_deg], math.radians(drive.period_deg)
        table = periodic_linear(angles, drive.torque, period)
        return Effect("drive", "drive", lambda t, phi, omega, q, dq: table(phi), frozenset({"phi"}),
                      f"table M_d(phi), {len(drive.torque)} points over {drive.period_deg:g} deg",
                      period=period, kink_angles=periodic_kinks(angles, drive.torque, period),
                      segment_moment=lambda anchor, t, phi, omega, q, dq: table(phi, anchor))
    if isinstance(drive, schema.Engine):
        area = math.pi * drive.bore ** 2 / 4.0
        phase = math.radians(drive.phase_deg)
        angles, cycle = [math.radians(a) for a in drive.angle_deg], math.radians(drive.cycle_deg)
        pressure = periodic_linear(angles, drive.pressure, cycle)
        knots = periodic_kinks(angles, drive.pressure, cycle)
        cylinders = mechanism.cylinders if isinstance(mechanism, schema.CrankSlider) else None
        if cylinders is not None:
            return _multi_cylinder_engine(drive, cylinders, area, pressure, knots)
        # Gas pushes the piston towards the crank axis: F_x = -p A, reduced moment F_x dx/dphi.
        return Effect("drive", "drive", lambda t, phi, omega, q, dq: -pressure(phi + phase) * area * dq,
                      frozenset({"phi"}), f"engine: M_d = -p(phi) A dx/dphi, A = {area:.6g} m^2, "
                                          f"{drive.cycle_deg:g} deg cycle", period=cycle,
                      output_force=lambda t, phi, omega, q, dq: -pressure(phi + phase) * area,
                      kink_angles=_shifted_kinks(knots, (phase,), cycle),
                      segment_moment=lambda anchor, t, phi, omega, q, dq: -pressure(phi + phase, anchor + phase)
                      * area * dq,
                      segment_output_force=lambda anchor, t, phi, omega, q, dq: -pressure(phi + phase, anchor + phase)
                      * area)
    raise TypeError(f"no drive effect for {type(drive).__name__}")


def _shifted_kinks(knots: tuple[float, ...], shifts: tuple[float, ...], period: float) -> tuple[float, ...]:
    """The crank angles [rad] in [0, period) where p(phi + shift) has a knot, for every shift: knot - shift."""
    return tuple(sorted({(knot - shift) % period for knot in knots for shift in shifts}))


def _multi_cylinder_engine(drive: schema.Engine, cylinders: list[schema.Cylinder], area: float,
                           pressure: Callable[..., float], knots: tuple[float, ...]) -> Effect:
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

    def segment_moment(anchor: float, t: float, phi: float, omega: float, q, dq) -> float:
        total = 0.0
        for shift, ratio in zip(shifts, dq):
            total += pressure(phi + shift, anchor + shift) * ratio
        return -area * total

    order = "-".join(str(i + 1) for i in sorted(range(len(delays)), key=delays.__getitem__))
    return Effect("drive", "drive", moment, frozenset({"phi"}),
                  f"engine: M_d = -A sum_i p(phi + {drive.phase_deg:g} deg - d_i) dx_i/dphi, {len(cylinders)} cylinders, "
                  f"A = {area:.6g} m^2, "
                  f"{drive.cycle_deg:g} deg cycle, firing {order} at {', '.join(f'{d:g}' for d in sorted(delays))} deg",
                  period=math.radians(drive.cycle_deg), kink_angles=_shifted_kinks(knots, shifts, math.radians(
                      drive.cycle_deg)), segment_moment=segment_moment)


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


def build_load(load: schema.Load, kinematic_period: float | None,
               output_position: Callable[[float], tuple[float, float]] | None = None) -> Effect:
    """A resisting moment or force of a scene's `machine.loads` entry; loads on the output link are
    periodic with the mechanism (kinematic_period [rad]); output_position(phi) -> (q, dq/dphi) of the mechanism
    places the kinks of a slider force table (None: the table has none, a solver steps over its breakpoints)."""
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
        angles, period = [math.radians(a) for a in load.angle_deg], math.radians(load.period_deg)
        table = periodic_linear(angles, load.torque, period)
        return Effect("table", "load", lambda t, phi, omega, q, dq: -table(phi), frozenset({"phi"}),
                      f"table: M_c = -M(phi), {len(load.torque)} points over {load.period_deg:g} deg",
                      period=period, kink_angles=periodic_kinks(angles, load.torque, period),
                      segment_moment=lambda anchor, t, phi, omega, q, dq: -table(phi, anchor))
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
        return _slider_table(load, kinematic_period, output_position)
    raise TypeError(f"no load effect for {type(load).__name__}")


def _slider_table(load: schema.SliderTable, kinematic_period: float | None,
                  output_position: Callable[[float], tuple[float, float]] | None) -> Effect:
    """Slider force table: M = F(x) dx/dphi, F clamped linear in the slider position x [m]. With the mechanism's
    output_position(phi) -> (x [m], dx/dphi [m/rad]), the crank angles where x crosses a breakpoint are its kinks
    (position_kinks), and between two of them segment_moment holds F on the piece of x there (held_positions)."""
    force = clamped_linear(load.position, load.force)
    kinks = position_kinks(load.position, output_position) if output_position and kinematic_period else ()
    segment_moment = segment_force = None
    if kinks:
        positions = held_positions(kinks, output_position)

        def segment_force(anchor: float, t: float, phi: float, omega: float, q: float, dq: float) -> float:
            """F [N] on the piece of x held between the two kinks around the crank angle anchor [rad]."""
            return force(q, positions[bisect.bisect_right(kinks, anchor % kinematic_period)])

        def segment_moment(anchor: float, t: float, phi: float, omega: float, q: float, dq: float) -> float:
            """M = F dx/dphi [N m], F on segment_force's piece."""
            return segment_force(anchor, t, phi, omega, q, dq) * dq

    return Effect("slider_table", "load", lambda t, phi, omega, q, dq: force(q) * dq, frozenset({"phi"}),
                  f"slider force table F(x), {len(load.force)} points: M = F(x) dx/dphi", period=kinematic_period,
                  output_force=lambda t, phi, omega, q, dq: force(q), kink_angles=kinks, segment_moment=segment_moment,
                  segment_output_force=segment_force)


def output_position_of(reduced: Callable[[float], tuple] | None) -> Callable[[float], tuple[float, float]] | None:
    """The output position build_load reads, phi -> (q, dq/dphi) (q [m] or [rad]), taken from a mechanism's
    reduced(phi) = (J_links, dJ/dphi, M_weight, q, dq/dphi) (mechanisms.build_reduced); None without one."""
    return (lambda phi: reduced(phi)[3:5]) if reduced is not None else None


def held_positions(kinks: tuple[float, ...], output_position: Callable[[float], tuple[float, float]]) -> list[float]:
    """A slider position [m] inside the table piece of each interval between consecutive kinks [rad] (sorted, in
    [0, 2 pi)), indexed by bisect_right(kinks, phi mod 2 pi): the interval across 0 first and last. x stays in one
    piece on an interval; the mean of x at its thirds lies strictly inside it even where x touches a breakpoint at
    a dead centre (at the interval's middle for a centred crank-slider)."""
    starts = [kinks[-1] - TWO_PI] + list(kinks)
    ends = list(kinks) + [kinks[0] + TWO_PI]
    return [(output_position((2.0 * a + b) / 3.0)[0] + output_position((a + 2.0 * b) / 3.0)[0]) / 2.0
            for a, b in zip(starts, ends)]


def position_kinks(breakpoints, output_position: Callable[[float], tuple[float, float]],
                   samples: int = 720) -> tuple[float, ...]:
    """The crank angles [rad] in [0, 2 pi) where the output position x(phi) crosses one of the breakpoints [m]:
    x is split into monotone pieces at the roots of dx/dphi (sign changes on `samples` points, refined by brentq),
    and on each piece x - x_k changes sign at most once (root by brentq). A breakpoint that x only touches at a dead
    centre is no kink (F(x(phi)) stays on one segment there)."""
    grid = [TWO_PI * i / samples for i in range(samples + 1)]
    ratios = [output_position(angle)[1] for angle in grid]
    extrema = [a if ra == 0.0 else brentq(lambda angle: output_position(angle)[1], a, b, xtol=1e-15)
               for a, b, ra, rb in zip(grid, grid[1:], ratios, ratios[1:]) if ra == 0.0 or ra * rb < 0.0]
    if not extrema:
        return ()
    ends = extrema + [extrema[0] + TWO_PI]
    kinks = set()
    for a, b in zip(ends, ends[1:]):
        xa, xb = output_position(a)[0], output_position(b)[0]
        for breakpoint in breakpoints:
            if (xa - breakpoint) * (xb - breakpoint) < 0.0:
                root = brentq(lambda angle: output_position(angle)[0] - breakpoint, a, b, xtol=1e-15)
                kinks.add(root % TWO_PI)
    return tuple(sorted(kinks))
