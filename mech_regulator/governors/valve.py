"""The valve characteristic of a direct governor: sleeve position [m] -> throttle [0..1], each kind defined once for
both paths (effects/definition.py): its formula, a plain function numba compiles unchanged, reads the sleeve
position z and its table."""

from __future__ import annotations

from typing import Protocol

from mech_regulator.effects.definition import (
    CLAMPED,
    Definition,
    Table,
    check_covered,
    define,
    definition_of,
    reference_closure,
)
from mech_regulator.effects.tables import clamped_linear, slope_breaks
from mech_regulator.scene import governor_keys


class ValveCharacteristic(Protocol):
    """throttle(z, anchor=None) -> throttle 0..1 at sleeve position z [m]; a table's continued along the piece that
    holds z = anchor [m] (build_valve)."""

    def __call__(self, z: float, anchor: float | None = None) -> float: ...


def linear_valve(z, open_at, closed_at):
    """Linear valve: throttle = (z_closed - z) / (z_closed - z_open), clipped to [0, 1]."""
    return min(max((closed_at - z) / (closed_at - open_at), 0.0), 1.0)


def table_valve(table):
    """Table valve: the throttle table read at the sleeve position z, held at its end values beyond them."""
    return table


@define(governor_keys.LinearValve)
def _linear(valve: governor_keys.LinearValve, mechanism=None) -> Definition:
    return Definition(
        "valve",
        "valve",
        f"throttle = ({valve.closed_at:g} - z) / ({valve.closed_at:g} - {valve.open_at:g}), clipped to 0..1",
        linear_valve,
        {"open_at": valve.open_at, "closed_at": valve.closed_at},
    )


@define(governor_keys.TableValve)
def _table(valve: governor_keys.TableValve, mechanism=None) -> Definition:
    return Definition(
        "valve",
        "valve",
        f"throttle table over z, {len(valve.sleeve)} points from {valve.sleeve[0]:g} to {valve.sleeve[-1]:g} m",
        table_valve,
        table=Table(CLAMPED, tuple(valve.sleeve), tuple(valve.throttle)),
    )


check_covered(governor_keys.Valve)


def build_valve(valve: governor_keys.Valve) -> tuple[ValveCharacteristic, str, tuple[float, ...]]:
    """The throttle as a function of the sleeve position z (a table's also of an anchor: throttle(z, anchor) continues
    the piece that holds z = anchor [m] to z), a formula for `describe`, and the sleeve positions [m] where a table's
    slope jumps (its breakpoints; () without a table): the valve's definition bound to its numbers, as the fast path
    calls it (definition.reference_closure)."""
    definition = definition_of(valve)
    spec = definition.table
    table = clamped_linear(spec.xs, spec.ys) if spec is not None else None
    throttle = reference_closure(
        definition,
        definition.moment,
        "z, anchor=None",
        lambda i: {"z": "z", "table": "table(z, anchor)"},
        {"table": table},
    )
    return throttle, definition.formula, slope_breaks(spec.xs, spec.ys, ends=True) if spec is not None else ()
