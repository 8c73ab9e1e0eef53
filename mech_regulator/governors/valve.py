"""The valve characteristic of a direct governor: sleeve position [m] -> throttle [0..1]."""

from __future__ import annotations

from collections.abc import Callable

from mech_regulator.effects.tables import clamped_linear, slope_breaks
from mech_regulator.scene import schema

ValveCharacteristic = Callable[[float], float]


def build_valve(valve: schema.Valve) -> tuple[ValveCharacteristic, str, tuple[float, ...]]:
    """The throttle as a function of the sleeve position z (a table's also of an anchor: throttle(z, anchor) continues
    the piece that holds z = anchor [m] to z), a formula for `describe`, and the sleeve positions [m] where a table's
    slope jumps (its breakpoints; () for the linear valve).

    linear: throttle = (closed_at - z) / (closed_at - open_at), clipped to [0, 1];
    table: linear between the points, held at the end values beyond them.
    """
    if isinstance(valve, schema.LinearValve):
        open_at, closed_at = valve.open_at, valve.closed_at
        span = closed_at - open_at

        def linear(z: float) -> float:
            return min(max((closed_at - z) / span, 0.0), 1.0)

        return linear, f"throttle = ({closed_at:g} - z) / ({closed_at:g} - {open_at:g}), clipped to 0..1", ()
    table = clamped_linear(valve.sleeve, valve.throttle)
    formula = f"throttle table over z, {len(valve.sleeve)} points from {valve.sleeve[0]:g} to {valve.sleeve[-1]:g} m"
    return table, formula, slope_breaks(valve.sleeve, valve.throttle, ends=True)
