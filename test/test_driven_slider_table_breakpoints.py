"""Breakpoints of a slider table on a coupled driven part's mechanism are switches: a force table F(x) in
the position x of the driven mechanism's slider has a kink in the driven part's angle phi2 = phi - twist wherever
x(phi2) crosses one of its breakpoints. These angles are found as for the main mechanism's slider tables
(effects.position_kinks, now given the driven mechanism's output position); the reference path locates each crossing
as a guard phi2 - kink that changes no mode (a periodic entry of model.MachineModel.state_tables), restarts there and
between two crossings reads F on the piece x keeps there (effects.held_positions); the fast path the same with linear
guards phi - twist - kink (codegen.breakpoint_states) and the same held positions (kernels.held_position).

The driven part's branches carry only constant, viscous and fan loads (effect_keys.BranchLoad) and a driven part
behind a clutch has no angle (machine_keys.Clutch): neither has a table with breakpoints to locate.

Oracle, written here: scipy's solve_ivp piece by piece between the crossings of x through the table's positions,
located by solve_ivp's own events on x(phi2) - x_k (not by the package's kink angles), the table replaced on each
piece by the line of the segment that holds the piece (the difference in the moment (F_line - F) dx/dphi2, over the
driven part's inertia I2(phi2), added to the plain right-hand side's rates). Cost: about 5 s of CPU (a warm numba
cache).
"""

from __future__ import annotations

import functools
import json
import math

import numpy as np
import pytest
from support import simulate_complete
from test_state_table_breakpoints import line, restarted_reference
from test_table_knots import assert_meets_rtol

from mech_regulator.model import build_model
from mech_regulator.scene import load_scene
from mech_regulator.solvers.compiled.codegen import compile_scene
from mech_regulator.solvers.compiled.run import integrate_compiled
from mech_regulator.solvers.time_domain import _anchors

CRANK, ROD = 0.05, 0.2  # the driven crank-slider [m]: x runs over [ROD - CRANK, ROD + CRANK] = [0.15, 0.25]
MECHANISM = {
    "type": "crank_slider",
    "crank": CRANK,
    "rod": ROD,
    "offset": 0.0,
    "rod_mass": 0.3,
    "rod_cg": 0.08,
    "rod_inertia": 0.0015,
    "slider_mass": 0.5,
}
POSITIONS, FORCES = [0.14, 0.18, 0.20, 0.23, 0.26], [0.0, -60.0, -150.0, -200.0, -260.0]  # [m], [N]
TABLE = {"type": "slider_table", "position": POSITIONS, "force": FORCES}  # ends beyond the stroke: 3 breakpoints
DURATION = 0.3  # [s]: phi2 turns about 11 times, 66 breakpoint crossings


def driven_slider_model(*overrides: str):
    """two_mass (elastic coupling 5000 N m/rad, generator rotor 0.1 kg m^2) with a linear motor (60 N m stall, 300
    rad/s no-load) on the engine's crank and, on the generator's shaft, the crank-slider MECHANISM loaded by TABLE
    (its only load), for DURATION."""
    drive = {"type": "linear_motor", "stall_torque": 60.0, "no_load_speed": 300.0}
    return build_model(
        load_scene(
            "two_mass",
            [
                f"scenario.duration={DURATION}",
                "scenario.load_events=[]",
                f"machine.drive={json.dumps(drive)}",
                f"machine.coupling.driven.mechanism={json.dumps(MECHANISM)}",
                f"machine.coupling.driven.loads=[{json.dumps(TABLE)}]",
                *overrides,
            ],
        )
    )


@functools.cache
def driven_slider_reference() -> tuple[np.ndarray, np.ndarray]:
    """The crossings of x(phi2) through the table's positions (restarted_reference, value x): piece k lies between
    POSITIONS[k - 1] and POSITIONS[k] (the ends are never reached), on it F is the line of segment k - 1, whose
    difference from the table acts (F_line - F) dx/dphi2 on the driven part (over I2(phi2))."""
    model = driven_slider_model()
    twist, omega2 = model.state_names().index("twist"), model.state_names().index("omega_driven")
    driven = model.driven

    def slider(y):
        return driven.state(y[0] - y[twist])

    def correction(piece, t, y):
        inertia, _, _, x, dx = slider(y)
        rates = np.zeros(len(y))
        rates[omega2] = (line(POSITIONS, FORCES, piece - 1, x) - np.interp(x, POSITIONS, FORCES)) * dx / inertia
        return rates

    return restarted_reference(model, POSITIONS, lambda y: slider(y)[3], correction, DURATION)


def test_the_kinks_are_the_crank_slider_s_closed_form_crossings_located_on_phi2():
    """The driven part's slider table is one periodic StateTable at phi - twist whose breaks are the angles where
    x = R cos phi2 + sqrt(l^2 - R^2 sin^2 phi2) = x_k, cos phi2 = (x_k^2 + R^2 - l^2) / (2 R x_k), for the three
    positions inside the stroke (to 1e-12 rad); the crank side has none; the oracle crosses them 66 times."""
    model = driven_slider_model()
    y = model.initial_state()
    expected = []
    for x_k in POSITIONS[1:-1]:
        angle = math.acos((x_k * x_k + CRANK * CRANK - ROD * ROD) / (2.0 * CRANK * x_k))
        expected += [angle, 2.0 * math.pi - angle]
    [table] = model.state_tables
    assert table.name == "driven part's slider_table" and table.angular and table.period == 2.0 * math.pi
    assert np.allclose(table.breaks, sorted(expected), rtol=0.0, atol=1e-12)
    assert table.value(y) == y[0] - y[model.coupling_index]
    assert model.kink_angles() == []
    assert driven_slider_reference()[0].size - 2 == 66


@pytest.mark.parametrize(
    "method, rtol, path",
    [
        ("DOP853", 1e-8, "reference"),
        ("DOP853", 1e-10, "reference"),
        ("Radau", 1e-8, "reference"),
        ("RK4", 1e-8, "reference"),
        ("DOP853", 1e-10, "fast"),
        ("RK45", 1e-8, "fast"),
    ],
)
def test_a_slider_table_on_the_driven_mechanism_meets_its_rtol_against_a_reference_restarted_at_every_crossing(
    method, rtol, path
):
    """The two-mass machine at rtol = requested, atol = rtol x 0.01 (RK4: its default step): omega at every crossing
    within 3 rtol of the reference (relative to the mean speed); see docs/hard_cases.md "Tables in the state"."""
    times, reference = driven_slider_reference()
    assert_meets_rtol(driven_slider_model, method, rtol, path, times, reference, min_switches=times.size - 2)


def test_both_paths_restart_on_the_same_crossings():
    """DOP853 at rtol 1e-10 on both paths: the same number of restarts, one per crossing of the oracle, and the
    states at the end within 1e-9 of each other (relative to the state's size)."""
    options = ("solver.method=DOP853", "solver.rtol=1e-10", "solver.atol=1e-12")
    reference = simulate_complete(driven_slider_model(*options, "solver.path=reference"))
    fast = integrate_compiled(driven_slider_model(*options, "solver.path=fast"))
    crossings = driven_slider_reference()[0].size - 2
    assert reference.stats.switches == fast.stats.switches == crossings
    end_reference, end_fast = reference(np.array([DURATION]))[:, -1], fast(np.array([DURATION]))[:, -1]
    assert np.max(np.abs(end_fast - end_reference)) <= 1e-9 * np.max(np.abs(end_reference))


def test_both_paths_continue_the_held_piece_of_x_across_a_breakpoint():
    """With the table held on each of its six pieces a turn in turn (anchors at the pieces' middles), the compiled
    right-hand side equals the model's (1e-12) at states whose phi2 lies anywhere in the turn (x in that piece or
    beyond it: the line continued), and the held line does differ from the table somewhere (the anchor is read)."""
    model = driven_slider_model()
    compiled = compile_scene(model)
    [table] = model.state_tables
    twist, omega2 = model.coupling_index, model.driven_speed_index
    piece, mode = model.piece_at(0.0), model.initial_mode(model.initial_state())
    plain, differs = model.rhs(piece, None, mode), 0.0
    for held in range(1, len(table.breaks) + 1):
        (anchor,) = _anchors((table,), [held])
        for phi2 in np.linspace(0.05, 2.0 * math.pi - 0.05, 9):
            y = model.initial_state()
            y[0] = phi2 + y[twist]
            expected = np.array(model.rhs(piece, None, mode, anchors=(anchor,))(0.1, y), dtype=float)
            p = compiled.parameters_for(piece, mode, None, y[1], [held], y)
            got = np.zeros(len(y))
            compiled.rhs(0.1, y, p, got)
            np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12 * np.max(np.abs(expected)))
            differs = max(differs, abs(expected[omega2] - plain(0.1, y)[omega2]))
    assert differs > 1.0  # [rad/s^2]
