"""The servo-motor of an indirect governor and its feedback, defined once for both paths: plain functions that numba
compiles unchanged (as the effects' formulas, effects/definition.py), called by governors.mechanical.Governor on the reference
path and by the fast path's generated right-hand side (solvers/compiled/codegen.py)."""

from __future__ import annotations

import math


def servo_command(opening, gain, max_speed, dead_band):
    """Servo speed the pilot valve asks for [1/s]: s' = -gain * opening [m], the opening less the dead band [m],
    clipped to +-max_speed [1/s]."""
    if dead_band > 0.0:
        opening = math.copysign(max(abs(opening) - dead_band, 0.0), opening)
    return min(max(-gain * opening, -max_speed), max_speed)


def rigid_feedback(gain, servo, reference):
    """Rigid feedback's share of the pilot opening: rho (s - s_ref) [m] (gain rho [m], servo position s and its
    reference s_ref [-])."""
    return gain * (servo - reference)


def isodromic_rate(gain, servo_rate, shift, time_constant):
    """The isodromic dashpot's shift rate [m/s], from T_i zeta' + zeta = rho T_i s': zeta' = rho s' - zeta / T_i (gain
    rho [m], servo speed s' [1/s], shift zeta [m], time constant T_i [s])."""
    return gain * servo_rate - shift / time_constant
