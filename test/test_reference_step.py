"""The reference path's step trimmed of overhead (docs/speed.md, "The reference path's step, profiled and trimmed"):
each shortcut gives the number the plain way gives, to the bit. A sensor's formulas read with their numbers bound
once; the crank angle of a DOP853 step's dense output summed alone; the switch counts of several probe angles taken
at once.

Oracles: the plain computations the shortcuts replace. Cost: about 1 s.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate

from mech_regulator.model import build_model
from mech_regulator.scene.loading import load_scene
from mech_regulator.solvers.time_domain import _Shifted, _switch_counts, _switch_counts_at

ARM_ANGLES = np.linspace(0.3, 1.2, 7)


@pytest.mark.parametrize("scene", ["engine_direct", "engine_hartnell"])
def test_a_sensors_bound_formulas_give_the_plain_calls_numbers(scene):
    """sleeve, lift and arm_acceleration through bound_kernels, and the governor's rates in a mode, equal the
    kernels called with kernel_parameters() read anew, bit for bit, on a Porter and a Hartnell sensor."""
    governor = build_model(load_scene(scene, ["solver.path=reference"])).governor
    sensor = governor.sensor
    sleeve, lift, acceleration = sensor.kernels()
    for arm in ARM_ANGLES:
        assert sensor.sleeve(arm) == sleeve(arm, *sensor.kernel_parameters())
        assert sensor.lift(arm, 95.0) == lift(arm, 95.0, *sensor.kernel_parameters())
        plain = acceleration(arm, 0.4, 95.0, -3.0, *sensor.kernel_parameters())
        assert sensor.arm_acceleration(arm, 0.4, 95.0, -3.0) == plain
        state = np.array([1.0, 95.0, arm, 0.4] + [0.5, 0.0][: len(governor.state_names) - 2])
        rates = governor.derivatives(("down", "free") if governor.kind == "indirect" else ("down", ""))(state)
        assert rates[:2] == [0.4, acceleration(arm, 0.4, 95.0, -sensor.kinetic_friction, *sensor.kernel_parameters())]


def dense_outputs(method: str) -> tuple:
    """A step of `method` on a pendulum with a third, growing state: (the step's dense output, its end time [s])."""

    def rates(t, y):
        return [y[1], -9.81 * math.sin(y[0]), y[1] * y[1]]

    solver = getattr(integrate, method)(rates, 0.0, np.array([0.4, 0.0, 0.0]), 10.0, rtol=1e-9, atol=1e-11)
    solver.step()
    return solver.dense_output(), solver.t


@pytest.mark.parametrize("method", ["DOP853", "RK45", "Radau"])
@pytest.mark.parametrize("offset", [0.0, 2.0 * math.pi * 1.6e6])
def test_the_angle_alone_is_the_dense_outputs_first_entry(method, offset):
    """_Shifted.phase(t) is _Shifted(t)[0] to the bit inside a step and at its ends, with and without whole turns
    added (offset): summed alone for DOP853, read off the state for the others."""
    dense, t_end = dense_outputs(method)
    shifted = _Shifted(dense, offset)
    for t in np.linspace(0.0, t_end, 11):
        assert shifted.phase(float(t)) == shifted(float(t))[0]


def test_the_switch_counts_at_several_angles_are_each_angles_plain_floor():
    """_switch_counts_at over probe angles, and _switch_counts at one, equal floor((phi - angle) / period) per switch
    taken one by one, at angles on, beside and far from the switch angles."""
    period = 4.0 * math.pi
    angles = np.array([0.0, 0.3, 2.5, 7.0])
    switches = np.column_stack((angles, np.full(angles.size, period)))
    phis = np.array([-0.1, 0.0, 0.3, 0.3 + 1e-15, 5.0, 12.9, 6.3e6])
    table = _switch_counts_at(phis, switches)
    for phi, counts in zip(phis, table):
        plain = [math.floor((phi - angle) / period) for angle in angles]
        assert counts == plain
        assert _switch_counts(float(phi), [tuple(row) for row in switches]) == plain
