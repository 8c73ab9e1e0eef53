"""`mech-regulator engine`'s indicated work and piston extremes are exact, not read off its output grid: the work
against scipy's adaptive quadrature told where the table's kinks are, the extremes against the closed-form
kinematics (v is largest where a = 0; a is largest at the top dead centre of a central crank–slider)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate, optimize

from mech_regulator.analysis.engine import engine_report, indicated_work, piston_table, torque_curves
from mech_regulator.mechanisms.engine import piston_motion
from mech_regulator.model import build_model
from mech_regulator.scene import load_scene


@pytest.mark.parametrize("name", ["engine", "engine_inline4"])
def test_indicated_work_equals_adaptive_quadrature_between_the_kinks(name):
    model = build_model(load_scene(name))
    effect = next(effect for effect in model.effects if effect.role == "drive")
    cycle = math.radians(model.scene.machine.drive.cycle_deg)

    def gas_moment(phi: float) -> float:
        _, _, _, q, dq = model.reduced(phi)
        return effect.moment(0.0, phi, 0.0, q, dq)

    # every table knot of every cylinder lies on the quarter-degree grid of the bundled engines
    knots = np.linspace(0.0, cycle, int(round(model.scene.machine.drive.cycle_deg)) * 4 + 1)
    expected = sum(
        integrate.quad(gas_moment, low, high, epsabs=1e-13, epsrel=1e-13)[0] for low, high in zip(knots[:-1], knots[1:])
    )
    work = indicated_work(model)
    assert work == pytest.approx(expected, rel=1e-11, abs=1e-10)
    grid = torque_curves(model, 100.0)
    assert abs(grid.gas_total.mean() * cycle - expected) > 1e3 * abs(work - expected), (
        "the grid's sum should be the less accurate one"
    )


def test_piston_extremes_are_located_exactly():
    model = build_model(load_scene("engine"))
    mechanism = model.scene.machine.mechanism
    R, l, e = mechanism.crank, mechanism.rod, mechanism.offset
    omega = 200.0
    piston = engine_report(model, omega)["piston"]
    phis, exact, _ = piston_table(model, omega)
    # v is largest where the acceleration vanishes: find that angle near the grid's maximum, independently
    k = int(np.argmax(np.abs(exact[1])))
    step = phis[1] - phis[0]
    root = optimize.brentq(
        lambda phi: piston_motion(phi, omega, R, l, e).a, phis[k] - 2 * step, phis[k] + 2 * step, xtol=1e-15
    )
    assert piston["v_max"] == pytest.approx(abs(piston_motion(root, omega, R, l, e).v), rel=1e-12)
    assert piston["v_max"] > np.abs(exact[1]).max()  # the grid missed the top by a little
    if e == 0.0:  # central: the largest acceleration (source convention) at the top dead centre, R w^2 (1 + R/l)
        assert piston["a_max"] == pytest.approx(R * omega**2 * (1.0 + R / l), rel=1e-12)
