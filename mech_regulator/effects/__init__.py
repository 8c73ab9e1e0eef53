"""Effects: the moments that act on the machine, each reduced to the crank.

Each kind of drive and load is defined once, for both paths, in effects/drives.py or effects/loads.py
(effects/definition.py, docs/effects.md). For the reference path an effect is built once from its scene entry into a
plain closure `moment(t, phi, omega, q, dq) -> M [N m]` over constants, where q is the mechanism's output
coordinate (slider position x [m], rocker angle th4 [rad] or shuttle bar position x_C [m]) and dq = dq/dphi its velocity ratio.
A force F on the output link becomes the reduced moment `F dq` (same power, docs/theory.md §2.2).
With several cylinders q and dq are tuples, one entry per piston; only the engine drive reads them then
(loads on "the slider" are refused by the scene).
Only the effects a scene names are built; the right-hand side calls exactly these.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from scipy.optimize import brentq

from mech_regulator.effects import drives, loads  # noqa: F401  (they register their definitions)
from mech_regulator.effects.definition import (
    CLAMPED,
    INTERVALS,
    PERIODIC,
    Definition,
    check_covered,
    definition_of,
    reference_function,
)
from mech_regulator.effects.tables import (
    clamped_linear,
    held_lookup,
    interval_indicator,
    periodic_kinks,
    periodic_linear,
)
from mech_regulator.scene import effect_keys, mechanism_keys

check_covered(effect_keys.Drive, effect_keys.Load, effect_keys.DrivenLoad, effect_keys.BranchLoad)

OutputCoordinate = float | tuple[float, ...]  # q [m or rad] or dq/dphi; several cylinders: one entry per piston
MomentFunction = Callable[[float, float, float, OutputCoordinate, OutputCoordinate], float]

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
    segment_moment (None: output_force has no breakpoints); definition: what it was built from, the formulas the fast
    path compiles (effects/definition.py; None for an effect derived from others, such as a branch's reduced load).
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
    definition: Definition | None = None

    @property
    def dry(self) -> bool:
        """Whether it is a Coulomb resistance (a constant load: its definition's `dry`); False for an effect
        derived from others."""
        return self.definition is not None and self.definition.dry


def build_drive(drive: effect_keys.Drive, mechanism: mechanism_keys.Mechanism | None = None) -> Effect:
    """The driving moment M_d of a scene's `machine.drive` (an engine reads the mechanism's cylinders)."""
    return build_effect(definition_of(drive, mechanism), None)


def build_load(
    load: effect_keys.Load,
    kinematic_period: float | None,
    output_position: Callable[[float], tuple[float, float]] | None = None,
) -> Effect:
    """A resisting moment or force of a scene's `machine.loads` entry; loads on the output link are
    periodic with the mechanism (kinematic_period [rad]); output_position(phi) -> (q, dq/dphi) of the mechanism
    places the kinks of a slider force table (None: the table has none, a solver steps over its breakpoints)."""
    return build_effect(definition_of(load), kinematic_period, output_position)


def build_effect(
    definition: Definition,
    kinematic_period: float | None,
    output_position: Callable[[float], tuple[float, float]] | None = None,
) -> Effect:
    """The reference path's Effect of a drive's or load's definition (its formulas bound to its numbers,
    definition.reference_function): a periodic table in phi has its knots as kinks (shifted per output), an interval
    table its edges as switches, a clamped table in the output position q the crank angles where q crosses one of its
    breakpoints (position_kinks, with output_position and kinematic_period [rad]; between two of them it is read on
    the piece of q held there, held_positions)."""
    spec = definition.table
    period = (
        spec.period
        if spec is not None and spec.kind != CLAMPED
        else (kinematic_period if definition.on_output else None)
    )
    table = held = None
    kinks: tuple[float, ...] = ()
    switches: tuple[float, ...] = ()
    if spec is not None and spec.kind == PERIODIC:
        table = periodic_linear(spec.xs, spec.ys, spec.period)
        knots = periodic_kinks(spec.xs, spec.ys, spec.period)
        kinks = knots if spec.shifts is None else _shifted_kinks(knots, spec.shifts, spec.period)
    elif spec is not None and spec.kind == INTERVALS:
        table = interval_indicator(spec.xs, spec.period)
        shifts = (0.0,) if spec.shifts is None else spec.shifts  # None: phi itself (Table)
        switches = tuple(sorted({(edge - shift) % spec.period for edge in spec.xs for shift in shifts}))
    elif spec is not None:
        table = clamped_linear(spec.xs, spec.ys)
        if output_position and kinematic_period:
            kinks = position_kinks(spec.xs, output_position)
            if kinks:  # the slider position [m] held on the interval between the two kinks around an anchor [rad]
                held = held_lookup(kinks, kinematic_period, held_positions(kinks, output_position))

    def bound(function: Callable[..., float] | None, anchored: bool) -> Callable[..., float] | None:
        if function is None or (anchored and not kinks):
            return None
        return reference_function(definition, function, table, anchored, held)

    moment = reference_function(definition, definition.moment, table, False, held)
    return Effect(
        definition.name,
        definition.role,
        moment,
        definition.depends_on,
        definition.formula,
        period,
        switches,
        bound(definition.output_force, False),
        kinks,
        bound(definition.moment, True),
        bound(definition.output_force, True),
        definition,
    )


def _shifted_kinks(knots: tuple[float, ...], shifts: tuple[float, ...], period: float) -> tuple[float, ...]:
    """The crank angles [rad] in [0, period) where p(phi + shift) has a knot, for every shift: knot - shift."""
    return tuple(sorted({(knot - shift) % period for knot in knots for shift in shifts}))


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
    return [
        (output_position((2.0 * a + b) / 3.0)[0] + output_position((a + 2.0 * b) / 3.0)[0]) / 2.0
        for a, b in zip(starts, ends)
    ]


def position_kinks(
    breakpoints, output_position: Callable[[float], tuple[float, float]], samples: int = 720
) -> tuple[float, ...]:
    """The crank angles [rad] in [0, 2 pi) where the output position x(phi) crosses one of the breakpoints [m]:
    x is split into monotone pieces at the roots of dx/dphi (sign changes on `samples` points, refined by brentq),
    and on each piece x - x_k changes sign at most once (root by brentq). A breakpoint that x only touches at a dead
    centre is no kink (F(x(phi)) stays on one segment there)."""
    grid = [TWO_PI * i / samples for i in range(samples + 1)]
    ratios = [output_position(angle)[1] for angle in grid]
    extrema = [
        a if ra == 0.0 else brentq(lambda angle: output_position(angle)[1], a, b, xtol=1e-15)
        for a, b, ra, rb in zip(grid, grid[1:], ratios, ratios[1:])
        if ra == 0.0 or ra * rb < 0.0
    ]
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
