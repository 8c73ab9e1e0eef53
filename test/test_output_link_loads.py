"""Forces on the slider and moments on the rocker reduce to the crank with the right sign and factor:
a conservative output-link load keeps kinetic + potential energy constant, a dissipative one drains
exactly the power c v^2."""

import numpy as np
import pytest

from mech_regulator.model import build_model
from mech_regulator.scene import validate_scene
from mech_regulator.solvers import simulate

CRANK_SLIDER = {
    "type": "crank_slider",
    "crank": 0.05,
    "rod": 0.2,
    "offset": 0.01,
    "rod_mass": 1.0,
    "rod_cg": 0.07,
    "rod_inertia": 0.004,
    "slider_mass": 1.5,
}
FOUR_BAR = {
    "type": "four_bar",
    "crank": 0.04,
    "coupler": 0.12,
    "rocker": 0.08,
    "frame": 0.1,
    "coupler_mass": 0.5,
    "coupler_cg": 0.06,
    "coupler_inertia": 6e-4,
    "rocker_mass": 0.4,
    "rocker_cg": 0.04,
    "rocker_inertia": 2e-4,
}
POSITIONS = [0.14, 0.18, 0.22, 0.26]
FORCES = [50.0, -120.0, 80.0, 300.0]


def _potential_slider_table(x):
    """V(x) = -integral F dx of the clamped piecewise-linear force table (independent of the package)."""
    fine = np.linspace(0.10, x, 20001)
    force = np.interp(fine, POSITIONS, FORCES)
    return -np.trapezoid(force, fine)


CASES = [
    (
        CRANK_SLIDER,
        {"type": "slider_spring", "stiffness": 3000.0, "free_position": 0.2},
        lambda q: 0.5 * 3000.0 * (q - 0.2) ** 2,
    ),
    (CRANK_SLIDER, {"type": "slider_constant", "force": -400.0}, lambda q: 400.0 * q),
    (
        CRANK_SLIDER,
        {"type": "slider_table", "position": POSITIONS, "force": FORCES},
        lambda q: np.array([_potential_slider_table(x) for x in np.atleast_1d(q)]),
    ),
    (FOUR_BAR, {"type": "rocker_spring", "stiffness": 4.0, "free_position": 1.5}, lambda q: 0.5 * 4.0 * (q - 1.5) ** 2),
    (FOUR_BAR, {"type": "rocker_constant", "torque": 2.0}, lambda q: -2.0 * q),
]


def _run(mechanism, load, duration, samples):
    """Simulate the mechanism coasting from 30 rad/s against one output-link load; the output columns."""
    scene = validate_scene(
        {
            "machine": {"inertia": 0.02, "mechanism": mechanism, "loads": [load]},
            "scenario": {"initial": {"omega": 30.0}, "duration": duration},
            "solver": {"rtol": 1e-11, "atol": 1e-12},
        }
    )
    model = build_model(scene)
    trajectory = simulate(model)
    times = np.linspace(0.0, trajectory.t_end, samples)
    return times, model.columns(times, trajectory(times))


@pytest.mark.parametrize("mechanism, load, potential", CASES, ids=[c[1]["type"] for c in CASES])
def test_conservative_output_load_keeps_energy(mechanism, load, potential):
    _, columns = _run(mechanism, load, duration=1.0, samples=400)
    q = columns["x_slider"] if "x_slider" in columns else columns["theta4"]
    energy = columns["E_kinetic"] + potential(q)
    swing = np.ptp(columns["E_kinetic"])
    assert swing > 1e-2 * columns["E_kinetic"][0]  # the load does exchange energy with the machine
    # rtol 1e-11 over ~5 turns; the slider_table potential comes from a 20001-point trapezoid (~1e-7 J)
    assert np.ptp(energy) < 1e-6 * columns["E_kinetic"][0] + 1e-6


@pytest.mark.parametrize(
    "mechanism, load, speed_column",
    [
        (CRANK_SLIDER, {"type": "slider_viscous", "coefficient": 40.0}, "v_slider"),
        (FOUR_BAR, {"type": "rocker_viscous", "coefficient": 0.2}, "omega4"),
    ],
)
def test_viscous_output_load_dissipates_c_v_squared(mechanism, load, speed_column):
    times, columns = _run(mechanism, load, duration=0.5, samples=20001)
    power = columns[f"M_{load['type']}"] * columns["omega"]
    np.testing.assert_allclose(power, -load["coefficient"] * columns[speed_column] ** 2, rtol=1e-12, atol=1e-12)
    dissipated = -np.trapezoid(power, times)
    assert dissipated > 0.05 * columns["E_kinetic"][0]  # a real drain, not a rounding
    # the kinetic energy lost equals the work dissipated (trapezoid on 20001 points: ~1e-6 relative)
    assert abs(columns["E_kinetic"][0] - columns["E_kinetic"][-1] - dissipated) < 1e-5 * dissipated
