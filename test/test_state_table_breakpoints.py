"""Breakpoints of tables read at the state are switches: a direct governor's valve table throttle(z), z the
sleeve position z = 2 l (1 - cos a) of the arm-angle state, and a nonlinear coupling's characteristic M_m(twist), twist
a state, have kinks wherever z or the twist crosses a breakpoint. The solvers locate each crossing as a guard
value(y) - breakpoint that changes no mode (model.StateTable, time_domain._breakpoint_guards), restart there, and
between two crossings see the table continued along one segment (rhs's anchors).

Oracle, written here: scipy's solve_ivp piece by piece between the crossings. On each piece the table is replaced by
the line of the segment that holds the piece, by adding to the plain right-hand side's rates the difference the line
makes (the throttle's difference times the motor's moment over J for the valve; the coupling moment's difference,
against the crank and for the driven part, for the coupling); the crossings are located by solve_ivp's own events on
z(y) - z_k or twist - twist_k (not by the package's guards), the state there taken from a second solve_ivp that ends
on it. Cost: about 5 s of CPU (both paths, a warm numba cache).
"""

from __future__ import annotations

import functools
import json
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from test_table_knots import assert_meets_rtol

from mech_regulator.model import build_model
from mech_regulator.scene import load_scene

VALVE = {
    "type": "table",
    "sleeve": [0.02, 0.027, 0.028, 0.03, 0.032, 0.08],
    "throttle": [1.0, 0.8, 0.75, 0.62, 0.55, 0.0],
}  # [m] -> [-]: kinks at every point (ends held beyond)
STALL_TORQUE, NO_LOAD_SPEED = 60.0, 400.0  # the governed machine's linear motor [N m], [rad/s]
GOVERNED_TIME = 1.0  # [s]: the sleeve falls from 0.033 m through 0.032, 0.03, 0.028, 0.027 m and back up past two
COUPLING_KINKS = [-0.1, -0.05, 0.05, 0.1]  # press_coupling's table points where the slope jumps [rad] (not 0)
COUPLED_TIME = 0.33  # [s]: the twist crosses 0.05 rad 18 times (it grazes 0.05 at 0.341 s, which solve_ivp misses)


def governed_model(*overrides: str):
    """engine_direct's crank-slider, flywheel and governor with a linear motor (no kinks in phi) and the valve table
    VALVE, the sleeve started at 0.033 m, constant 6 N m load, for GOVERNED_TIME."""
    drive = {"type": "linear_motor", "stall_torque": STALL_TORQUE, "no_load_speed": NO_LOAD_SPEED}
    return build_model(
        load_scene(
            "engine_direct",
            [
                f"scenario.duration={GOVERNED_TIME}",
                "scenario.load_events=[]",
                f"machine.drive={json.dumps(drive)}",
                f"governor.valve={json.dumps(VALVE)}",
                "scenario.initial.sleeve=0.033",
                *overrides,
            ],
        )
    )


def coupled_model(*overrides: str):
    """press_coupling (rubber coupling table of 7 points, kinks at -0.1, -0.05, 0.05, 0.1 rad) started turning at
    150 rad/s untwisted, for COUPLED_TIME."""
    return build_model(
        load_scene("press_coupling", [f"scenario.duration={COUPLED_TIME}", "scenario.initial.omega=150.0", *overrides])
    )


def restarted_reference(model, breaks: list[float], value, correction, t_end: float) -> tuple[np.ndarray, np.ndarray]:
    """(times [s], omega [rad/s]) at every crossing of a breakpoint (and the end) by solve_ivp (DOP853, rtol 1e-12)
    between consecutive crossings: on piece k (between breaks[k - 1] and breaks[k]) the rates are the plain rhs's
    plus correction(k, t, y); value(y) is where the table is read."""
    y = model.initial_state()
    plain = model.rhs(model.piece_at(0.0), None, model.initial_mode(y))
    options = {"method": "DOP853", "rtol": 1e-12, "atol": 1e-12}
    t, piece = 0.0, int(np.searchsorted(breaks, value(y), side="right"))
    times, omegas = [t], [y[1]]
    while t < t_end:

        def rhs(t, y, piece=piece):
            return np.asarray(plain(t, y)) + correction(piece, t, y)

        events = []
        for index, direction in ((piece - 1, -1.0), (piece, 1.0)):  # leaving the piece down or up
            if 0 <= index < len(breaks):

                def event(t, y, level=breaks[index]):
                    return value(y) - level

                event.terminal, event.direction = True, direction
                events.append((event, index))
        found = solve_ivp(rhs, (t, t_end), y, events=[event for event, _ in events], **options)
        hits = [(float(hit[0]), index) for hit, (_, index) in zip(found.t_events, events) if hit.size]
        t_next, crossed = min(hits) if found.status == 1 else (t_end, None)
        y = solve_ivp(rhs, (t, t_next), y, **options).y[:, -1].copy()
        if crossed is not None:
            piece = crossed if crossed == piece - 1 else piece + 1
        t = t_next
        times.append(t)
        omegas.append(y[1])
    return np.array(times), np.array(omegas)


def line(xs: list[float], ys: list[float], segment: int, x: float) -> float:
    """The line of the table's segment `segment` (between xs[segment] and xs[segment + 1]) at x."""
    slope = (ys[segment + 1] - ys[segment]) / (xs[segment + 1] - xs[segment])
    return ys[segment] + slope * (x - xs[segment])


@functools.cache
def valve_reference() -> tuple[np.ndarray, np.ndarray]:
    """The governed machine's crossings (restarted_reference): the valve read at z = 2 l (1 - cos a), piece k is the
    table's segment k - 1 (piece 0 and the last: the held end values), the motor's moment M = stall (1 - omega /
    omega_0) scaled by the throttle, so the line adds (line - table) M / J(phi) to the crank's acceleration."""
    model = governed_model()
    arm = model.scene.governor.arm_length
    sleeve, throttle = VALVE["sleeve"], VALVE["throttle"]

    def z(y):
        return 2.0 * arm * (1.0 - math.cos(y[2]))

    def correction(piece, t, y):
        position = z(y)
        held = (
            throttle[0]
            if piece == 0
            else throttle[-1]
            if piece == len(sleeve)
            else line(sleeve, throttle, piece - 1, position)
        )
        moment = STALL_TORQUE * (1.0 - y[1] / NO_LOAD_SPEED)
        rates = np.zeros(len(y))
        rates[1] = (held - np.interp(position, sleeve, throttle)) * moment / model.inertia(y[0])[0]
        return rates

    return restarted_reference(model, sleeve, z, correction, GOVERNED_TIME)


@functools.cache
def coupling_reference() -> tuple[np.ndarray, np.ndarray]:
    """The coupled press's crossings (restarted_reference): the breaks are COUPLING_KINKS, piece k follows the line
    of the table's segment that holds a twist inside it (end segments continued); the line's difference d in the
    coupling moment acts -d on the crank (over J(phi)) and +d on the driven part (over I2(phi - twist))."""
    model = coupled_model()
    characteristic = model.scene.machine.coupling.characteristic
    twists, moments = characteristic.twist, characteristic.moment

    def segment(twist: float) -> int:
        return int(np.clip(np.searchsorted(twists, twist, side="right") - 1, 0, len(twists) - 2))

    inside = (
        [COUPLING_KINKS[0] - 1.0]
        + [0.5 * (a + b) for a, b in zip(COUPLING_KINKS, COUPLING_KINKS[1:])]
        + [COUPLING_KINKS[-1] + 1.0]
    )

    def correction(piece, t, y):
        difference = line(twists, moments, segment(inside[piece]), y[2]) - line(twists, moments, segment(y[2]), y[2])
        inertia_driven = model.driven.state(y[0] - y[2])[0]
        return np.array([0.0, -difference / model.inertia(y[0])[0], 0.0, difference / inertia_driven])

    return restarted_reference(model, COUPLING_KINKS, lambda y: y[2], correction, COUPLED_TIME)


def test_the_references_cross_the_breakpoints_and_the_coupling_table_has_its_interior_kinks():
    """The oracles really restart (6 sleeve crossings, 18 twist crossings); the model's breaks are the table points
    where the slope jumps: all six valve points (held beyond its ends), the coupling's interior ones but 0 (slope
    3000 N m/rad on both sides)."""
    assert valve_reference()[0].size - 2 == 6
    assert coupling_reference()[0].size - 2 == 18
    assert [table.breaks for table in governed_model().state_tables] == [tuple(VALVE["sleeve"])]
    assert [table.breaks for table in coupled_model().state_tables] == [tuple(COUPLING_KINKS)]


PATHS = [
    ("DOP853", 1e-8, "reference"),
    ("DOP853", 1e-10, "reference"),
    ("Radau", 1e-8, "reference"),
    ("DOP853", 1e-10, "fast"),
]


@pytest.mark.parametrize("method, rtol, path", PATHS)
def test_a_governor_with_a_valve_table_meets_its_rtol_against_a_reference_restarted_at_every_breakpoint(
    method, rtol, path
):
    """The governed machine at rtol = requested, atol = rtol x 0.01: omega at every crossing within 3 rtol of the
    reference (relative to the mean speed); see docs/hard_cases.md "Tables in the state"."""
    times, reference = valve_reference()
    assert_meets_rtol(governed_model, method, rtol, path, times, reference, min_switches=times.size - 2)


@pytest.mark.parametrize("method, rtol, path", PATHS)
def test_a_coupling_table_meets_its_rtol_against_a_reference_restarted_at_every_breakpoint(method, rtol, path):
    """The coupled press at rtol = requested, atol = rtol x 0.01: omega at every crossing within 3 rtol of the
    reference (relative to the mean speed); see docs/hard_cases.md "Tables in the state"."""
    times, reference = coupling_reference()
    assert_meets_rtol(coupled_model, method, rtol, path, times, reference, min_switches=times.size - 2)
