"""Engines: piston kinematics (exact and source 002's approximations) and multi-cylinder crankshafts.

Our crank–slider (crank_slider.py): crank pin `B = R (cos phi, sin phi)`, piston (slider) on the line
y = e at `x = R cos phi + sqrt(l^2 - (e - R sin phi)^2)`, phi counter-clockwise from +x, the cylinder
axis along +x. Source 002 (docs/theory.md §4.2) measures the crank angle alpha from the cylinder axis
and the piston displacement from the outer (top) dead centre towards the crank axis, with the offset
a = e. In our geometry this is

    alpha = phi,   x_src = sqrt((l + R)^2 - e^2) - x,   v_src = -v,   j_src = -a,

so alpha is "from top dead centre" exactly only for a central engine (e = 0); with an offset the top
dead centre lies at alpha1 = asin(lambda k / (1 + lambda)), k = e / R, and the bottom one at
alpha = pi + alpha2, alpha2 = asin(lambda k / (1 - lambda)).

A multi-cylinder engine has identical cylinders on one crankshaft. Cylinder i has its crank throw at
angle throw_i from cylinder 1's and its axis (bank) at angle bank_i from +x; in its own frame its crank
angle is `phi_i = phi + throw_i - bank_i`, so its kinematics are the single cylinder's at phi_i. Its
working cycle lags cylinder 1's by its firing delay d_i: cycle angle `theta_i(phi) = theta_1(phi - d_i)`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

from mech_regulator.mechanisms import crank_slider


class PistonMotion(NamedTuple):
    """Piston position x [m] along its cylinder axis, velocity v [m/s] and acceleration a [m/s^2]."""

    x: float
    v: float
    a: float


def piston_motion(
    phi: float, omega: float, crank: float, rod: float, offset: float, epsilon: float = 0.0
) -> PistonMotion:
    """Exact piston motion at crank angle phi [rad], crank speed omega [rad/s] and crank angular
    acceleration epsilon [rad/s^2]: `v = x' omega`, `a = x'' omega^2 + x' epsilon` (x' = dx/dphi)."""
    x, dx, ddx, *_ = crank_slider.slider_kinematics(phi, crank, rod, offset)
    return PistonMotion(x, dx * omega, ddx * omega * omega + dx * epsilon)


def source_approximation(alpha: float, omega: float, crank: float, rod: float, offset: float) -> PistonMotion:
    """Source 002's approximate piston motion, measured from the top dead centre towards the crank axis
    (x_src, v_src, j_src), first order in lambda = R/l (eqs. 1-3..1-5 central, 1-13..1-15 offset):

        x_src ~ R [(1 - cos a) + lambda/4 (1 - cos 2a) - lambda k sin a]
        v_src ~ R omega (sin a + lambda/2 sin 2a - lambda k cos a)
        j_src ~ R omega^2 (cos a + lambda cos 2a + lambda k sin a)

    with k = e / R. The source prints `- lambda k sin a` in j; the derivative of its own v gives `+`
    (docs/theory.md §4.2): this is the corrected form. alpha = phi (module docstring)."""
    lam, k = crank / rod, offset / crank
    sin_a, cos_a = math.sin(alpha), math.cos(alpha)
    sin_2a, cos_2a = math.sin(2.0 * alpha), math.cos(2.0 * alpha)
    return PistonMotion(
        crank * ((1.0 - cos_a) + lam / 4.0 * (1.0 - cos_2a) - lam * k * sin_a),
        crank * omega * (sin_a + lam / 2.0 * sin_2a - lam * k * cos_a),
        crank * omega * omega * (cos_a + lam * cos_2a + lam * k * sin_a),
    )


def source_from_exact(motion: PistonMotion, crank: float, rod: float, offset: float) -> PistonMotion:
    """Exact motion in source 002's convention: displacement from the top dead centre towards the crank
    axis, `x_src = sqrt((l + R)^2 - e^2) - x`, `v_src = -v`, `j_src = -a`."""
    return PistonMotion(math.sqrt((rod + crank) ** 2 - offset**2) - motion.x, -motion.v, -motion.a)


def source_dead_centre_angles(crank: float, rod: float, offset: float) -> tuple[float, float]:
    """Source 002's dead-centre angles (eq. 1-9) [rad]: `alpha1 = asin(lambda k / (1 + lambda))` (top),
    `alpha2 = asin(lambda k / (1 - lambda))` (bottom, measured from alpha = pi). In our geometry the top dead
    centre is at phi = alpha1 and the bottom one at phi = pi + alpha2 (crank_slider.dead_centres)."""
    lam, k = crank / rod, offset / crank
    return math.asin(lam * k / (1.0 + lam)), math.asin(lam * k / (1.0 - lam))


def mean_piston_speed(stroke: float, omega: float) -> float:
    """Mean piston speed [m/s]: `v_m = S n / 30` with n = 30 omega / pi [rpm], i.e. S omega / pi (the piston
    travels 2 S per turn)."""
    return stroke * (30.0 * omega / math.pi) / 30.0


def firing_delays(
    throws_deg: Sequence[float],
    banks_deg: Sequence[float],
    cycle_deg: float,
    firing_order: Sequence[int] | None = None,
    firing_deg: Sequence[float] | None = None,
) -> list[float]:
    """Each cylinder's firing delay d_i after cylinder 1 [deg], in [0, cycle_deg).

    Cylinder i is at a top dead centre when phi_i = 0 (mod 360), i.e. at crank angles `bank_i - throw_i
    (mod 360)` after cylinder 1's; its delay must be one of these within the cycle (one choice in a
    two-stroke, two in a four-stroke). firing_deg gives the delays directly (checked); firing_order (e.g.
    [1, 3, 4, 2]) picks, cylinder after cylinder, the first top dead centre after the previous cylinder
    fired. Raises ValueError naming the cylinder, the value and the angles that would fit.
    """
    count = len(throws_deg)
    tdc = [(bank - throw) % 360.0 for throw, bank in zip(throws_deg, banks_deg)]
    turns = int(round(cycle_deg / 360.0))

    def fitting(i: int) -> list[float]:
        return [tdc[i] + 360.0 * turn for turn in range(turns)]

    def where(i: int) -> str:
        return (
            f"cylinder {i + 1} (throw_deg {throws_deg[i]:g}, bank_deg {banks_deg[i]:g}) is at a top dead centre "
            f"{' or '.join(f'{angle:g}' for angle in fitting(i))} deg after cylinder 1 in the {cycle_deg:g} deg cycle"
        )

    if firing_deg is not None:
        if len(firing_deg) != count:
            raise ValueError(
                f"firing_deg has {len(firing_deg)} entries for {count} cylinders; expected one delay "
                "per cylinder, the first 0"
            )
        if firing_deg[0] != 0.0:
            raise ValueError(f"firing_deg[0] = {firing_deg[0]:g}: cylinder 1 is the reference, expected 0")
        for i, delay in enumerate(firing_deg):
            if not any(abs(delay - angle) < 1e-9 for angle in fitting(i)):
                raise ValueError(f"firing_deg[{i}] = {delay:g} deg does not fit the crankshaft: {where(i)}")
        return list(firing_deg)
    if firing_order is None:
        if count == 1:
            return [0.0]
        raise ValueError(
            f"the engine has {count} cylinders: give drive.firing_order (e.g. "
            f"{[1] + list(range(2, count + 1))}) or drive.firing_deg (each cylinder's firing delay)"
        )
    if sorted(firing_order) != list(range(1, count + 1)) or firing_order[0] != 1:
        raise ValueError(
            f"firing_order = {list(firing_order)}: expected each cylinder number 1..{count} once, starting with 1"
        )
    delays = [0.0] * count
    previous = 0.0
    for number in firing_order[1:]:
        i = number - 1
        later = [angle for angle in fitting(i) if angle > previous + 1e-9]
        if not later:
            order = "-".join(str(n) for n in firing_order)
            raise ValueError(
                f"firing_order {order} does not fit the crankshaft: {where(i)}, none after the previous "
                f"cylinder fires at {previous:g} deg"
            )
        delays[i] = previous = later[0]
    return delays
