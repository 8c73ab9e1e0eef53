"""Knots of a table load on the driven part of a two-mass machine are switches: a table in the driven
part's own angle phi2 = phi - twist has kinks wherever phi2 crosses a knot. The reference path locates each crossing
as a guard phi2 - knot that changes no mode (periodic entries of model.MachineModel.state_tables), restarts there,
and between two crossings sees the table continued along one segment (rhs's anchors); the fast path the same with
linear guards phi - twist - knot (codegen.breakpoint_states).

Oracle, written here: scipy's solve_ivp piece by piece between the crossings, the table replaced on each piece by the
line of the segment that holds the piece (the difference the line makes in the driven part's moment, over its
inertia, added to the plain right-hand side's rates); the crossings are located by solve_ivp's own events on
phi - twist - knot. Cost: about 3 s of CPU (a warm numba cache).

Far out (docs/hard_cases.md, "Long runs"): the same machine started a whole number of dynamic periods on is the same
run, its knots crossed at the same instants; the solvers read phi2 on the phase they carry, not on phi.
"""

from __future__ import annotations

import functools
import json
import math

import numpy as np
import pytest
from test_long_runs import far_start
from test_state_table_breakpoints import restarted_reference
from test_table_knots import assert_meets_rtol

from mech_regulator.model import build_model
from mech_regulator.scene import load_scene
from mech_regulator.solvers import simulate

KNOTS_DEG, TORQUES = [0.0, 60.0, 150.0, 250.0], [2.0, 9.0, 4.0, 6.0]  # the driven part's load M(phi2) [deg], [N m]
TABLE = {"type": "table", "angle_deg": KNOTS_DEG, "torque": TORQUES, "period_deg": 360.0}
DURATION = 0.3  # [s]: phi2 turns about 11 times, 44 knot crossings
TURNS = 16  # whole turns of phi2 the oracle's breakpoint list covers (phi2 stays in [0, 16 x 2 pi) over DURATION)


def driven_table_model(*overrides: str):
    """two_mass (elastic coupling 5000 N m/rad, generator rotor 0.1 kg m^2) with a linear motor (60 N m stall, 300
    rad/s no-load) on the engine's crank and the table TABLE as the generator's only load, for DURATION."""
    drive = {"type": "linear_motor", "stall_torque": 60.0, "no_load_speed": 300.0}
    return build_model(
        load_scene(
            "two_mass",
            [
                f"scenario.duration={DURATION}",
                "scenario.load_events=[]",
                f"machine.drive={json.dumps(drive)}",
                f"machine.coupling.driven.loads=[{json.dumps(TABLE)}]",
                *overrides,
            ],
        )
    )


def table_line(segment_at: float, phi2: float) -> float:
    """The load torque M [N m] of the table's segment that holds the angle segment_at [rad], continued to phi2 [rad]
    (the wrap from the last knot to the first plus 360 deg is a segment too)."""
    knots = [math.radians(a) for a in KNOTS_DEG] + [2.0 * math.pi]
    values = TORQUES + [TORQUES[0]]
    turn = math.floor(segment_at / (2.0 * math.pi))
    j = int(np.searchsorted(knots, segment_at - turn * 2.0 * math.pi, side="right")) - 1
    start = knots[j] + turn * 2.0 * math.pi
    return values[j] + (values[j + 1] - values[j]) / (knots[j + 1] - knots[j]) * (phi2 - start)


@functools.cache
def driven_table_reference() -> tuple[np.ndarray, np.ndarray]:
    """The crossings of phi2 through the knots (restarted_reference): piece k lies between breaks[k - 1] and
    breaks[k], the knots of TURNS turns unrolled; on it the table is the line of the segment holding the piece's
    middle, whose difference d in the load torque acts -d on the driven part (over its inertia)."""
    model = driven_table_model()
    twist, omega2 = model.state_names().index("twist"), model.state_names().index("omega_driven")
    breaks = [math.radians(a) + 2.0 * math.pi * turn for turn in range(-1, TURNS) for a in KNOTS_DEG]
    inertia = model.scene.machine.coupling.driven.inertia

    def phi2(y):
        return y[0] - y[twist]

    def correction(piece, t, y):
        middle = 0.5 * (breaks[piece - 1] + breaks[piece])
        rates = np.zeros(len(y))
        rates[omega2] = -(table_line(middle, phi2(y)) - table_line(phi2(y), phi2(y))) / inertia
        return rates

    return restarted_reference(model, breaks, phi2, correction, DURATION)


def test_the_reference_crosses_the_knots_and_the_model_locates_them_on_phi2():
    """The oracle really restarts (44 crossings); the driven part's table is one periodic StateTable at phi - twist
    with all four knots; the crank side has none."""
    assert driven_table_reference()[0].size - 2 == 44
    model = driven_table_model()
    y = model.initial_state()
    assert [(table.breaks, table.period, table.value(y)) for table in model.state_tables] == [
        (tuple(math.radians(a) for a in KNOTS_DEG), 2.0 * math.pi, y[0] - y[2])
    ]
    assert model.kink_angles() == []


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
def test_a_table_load_on_the_driven_part_meets_its_rtol_against_a_reference_restarted_at_every_knot(method, rtol, path):
    """The two-mass machine at rtol = requested, atol = rtol x 0.01 (RK4: its default step): omega at every crossing
    within 3 rtol of the reference (relative to the mean speed); see docs/hard_cases.md "Tables in the state"."""
    times, reference = driven_table_reference()
    assert_meets_rtol(driven_table_model, method, rtol, path, times, reference, min_switches=times.size - 2)


@pytest.mark.parametrize("path", ["fast", "reference"])
@pytest.mark.parametrize("far", [1e7, 1e9])
def test_a_table_load_on_the_driven_part_started_far_out_crosses_its_knots_as_near_0(far, path):
    """Started K whole dynamic periods on, at phi of about 1e7 rad (10 000 s of an engine) and 1e9 rad (where a
    double's last place, 1.2e-7 rad, is 20 times the 1e-9 of a period the pieces' slack allows), the two-mass machine
    with the driven part's table is the run started at 0: the same 44 knot crossings, steps and restarts, every state
    but phi bit for bit, phi K periods on to two last places. (Compared on phi itself, a knot at 1e9 rad is only
    known to 1.2e-7 rad: the run restarted on it without end.) Both start from the same twist: the static twist
    solved at phi far out differs in its last places."""
    model = driven_table_model()
    twist = f"scenario.initial.twist={model.initial_state()[2]:.17g}"
    near = simulate(driven_table_model(f"solver.path={path}", twist))
    start = far_start(model.dynamic_period(), far)
    far_run = simulate(driven_table_model(f"solver.path={path}", twist, f"scenario.initial.phi={start!r}"))
    assert near.status == far_run.status == "complete", (near.message, far_run.message)
    assert near.stats.switches >= 44 and far_run.stats == near.stats, (near.stats, far_run.stats)
    times = np.linspace(0.0, DURATION, 301)
    near_states, far_states = near(times), far_run(times)
    np.testing.assert_array_equal(far_states[1:], near_states[1:])
    last_place = math.ulp(start + near_states[0].max())
    np.testing.assert_allclose(far_states[0] - start, near_states[0], rtol=0.0, atol=2.0 * last_place)
