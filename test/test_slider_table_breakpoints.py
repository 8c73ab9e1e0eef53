"""Breakpoints of a slider force table are switches: a table F(x) in the slider position x has a kink in
the crank angle wherever x(phi) crosses one of its breakpoints; effects.position_kinks finds these angles once per
model (x split into monotone pieces at its dead centres), and the solvers restart on them as on the knots of a table
in phi (test_table_knots.py), between two of them seeing F continued along one segment.

Oracle: the compressor scene integrated by scipy's solve_ivp piece by piece between the breakpoint crossings, written
here: on each piece the force is the line of the segment that holds x, put in place of the table by adding
(F_line(x) - F_table(x)) dx/dphi / J to the plain right-hand side's crank acceleration; the crossing of the piece's
breakpoints is located by solve_ivp's events on x(phi) - x_k (not by the package's kink angles) and the state there
taken from a second solve_ivp that ends on it. Cost: about 3 s of CPU on a warm numba cache.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest
from support import simulate_complete
from test_table_knots import assert_meets_rtol, restarted_reference

from mech_regulator.model import build_model
from mech_regulator.scene import load_scene

RUN_TIME = 0.3  # [s]: about 5 turns at 104 rad/s, 6 breakpoint crossings a turn


def compressor_model(*overrides: str):
    """The compressor scene started at 100 rad/s (near its steady speed), for RUN_TIME."""
    return build_model(
        load_scene("compressor", ["scenario.initial.omega=100.0", f"scenario.duration={RUN_TIME}", *overrides])
    )


@functools.cache
def crossing_reference() -> tuple[np.ndarray, np.ndarray]:
    """(times [s], omega [rad/s]) of the compressor at every crossing of a breakpoint of its slider table, by
    solve_ivp (DOP853, rtol 1e-12) between consecutive crossings. The table spans exactly the stroke, so its end
    points are only touched at the dead centres; the interior breakpoints bound each piece."""
    model = compressor_model()
    load = next(load for load in model.scene.machine.loads if load.type == "slider_table")
    positions, forces = np.asarray(load.position), np.asarray(load.force)
    slopes = np.diff(forces) / np.diff(positions)
    plain = model.rhs()

    def slider(phi: float) -> tuple[float, float]:
        _, _, _, x, dx = model.reduced(phi)
        return x, dx

    def piece_rhs(k: int):
        def rhs(t, y):
            x, dx = slider(y[0])
            line = forces[k] + slopes[k] * (x - positions[k])
            omega, epsilon = plain(t, y)
            return [omega, epsilon + (line - np.interp(x, positions, forces)) * dx / model.inertia(y[0])[0]]

        return rhs

    def piece(y):
        ahead = slider(y[0] + 1e-6)[0]  # x just after the restart: which segment the piece is on
        k = int(np.clip(np.searchsorted(positions, ahead, side="right") - 1, 0, len(slopes) - 1))
        events = []
        for x_k, direction in zip(positions[k : k + 2], (-1.0, 1.0)):  # leaving the segment down or up
            if positions[0] < x_k < positions[-1]:

                def event(t, y, x_k=x_k):
                    return slider(y[0])[0] - x_k

                event.terminal, event.direction = True, direction
                events.append(event)
        return piece_rhs(k), events, None

    initial = model.scene.scenario.initial
    return restarted_reference(piece, np.array([initial.phi, initial.omega]), RUN_TIME)


@pytest.mark.parametrize(
    "method, rtol, path",
    [
        ("DOP853", 1e-8, "reference"),
        ("DOP853", 1e-10, "reference"),
        ("Radau", 1e-8, "reference"),
        ("DOP853", 1e-10, "fast"),
    ],
)
def test_a_compressor_meets_its_rtol_against_a_reference_restarted_at_every_breakpoint(method, rtol, path):
    """The compressor (slider force table of 5 points over the stroke, motor, viscous and spring loads) at rtol =
    requested, atol = rtol x 0.01 rad/s: omega at every crossing within 3 rtol of the reference (relative to the mean
    speed). Measured 0.05-0.22 rtol; before, the breakpoints stepped over, 4.6-177 rtol (docs/hard_cases.md, "Tables
    with kinks and steps")."""
    times, reference = crossing_reference()
    assert times.size > 20  # the reference really restarts at every crossing
    assert_meets_rtol(compressor_model, method, rtol, path, times, reference, min_switches=times.size - 2)


def test_the_kink_angles_are_where_the_slider_crosses_an_interior_breakpoint():
    """Closed form of the centred crank-slider, x = R cos phi + sqrt(l^2 - R^2 sin^2 phi): x = x_k at cos phi =
    (x_k^2 + R^2 - l^2) / (2 R x_k), two angles per interior breakpoint (0.20, 0.22, 0.24 m); the end points
    0.15 m and 0.25 m are the dead centres, touched, not crossed, and no kinks."""
    model = compressor_model()
    mechanism = model.scene.machine.mechanism
    R, l = mechanism.crank, mechanism.rod
    effect = next(effect for effect in model.effects if effect.name == "slider_table")
    expected = []
    for x_k in (0.20, 0.22, 0.24):
        angle = math.acos((x_k * x_k + R * R - l * l) / (2.0 * R * x_k))
        expected += [angle, 2.0 * math.pi - angle]
    assert np.allclose(effect.kink_angles, sorted(expected), rtol=0.0, atol=1e-12)


def test_rk4_steps_onto_the_crossings():
    """RK4 with a fixed step of 0.2 ms ends a step on every crossing: omega within 1e-10 of the reference relative to
    the mean speed (measured 1.1e-11; before, stepping over the kinks, 4.5e-7)."""
    times, reference = crossing_reference()
    trajectory = simulate_complete(compressor_model("solver.method=RK4", "solver.step=0.0002"))
    assert trajectory.stats.switches >= times.size - 2
    assert np.max(np.abs(trajectory(times)[1] - reference)) / np.mean(reference) <= 1e-10
