"""The textbook energy method (solver.method: energy): fixed steps in phi with
E_{i+1} = E_i + 1/2 (M_i + M_{i+1}) dphi, omega = sqrt(2 E / J), t_{i+1} = t_i + 2 dphi / (omega_i + omega_{i+1}).

Reference solutions are DOP853 runs at rtol 1e-12 (error ~1e-10, far below the energy method's
O(dphi^2) error ~1e-4 .. 1e-6 at the steps used), or closed forms.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from mech_regulator.cli.main import main
from mech_regulator.model import build_model
from mech_regulator.scene import validate_scene
from mech_regulator.solvers import simulate

CRANK_SLIDER = {
    "type": "crank_slider",
    "crank": 0.08,
    "rod": 0.3,
    "offset": 0.01,
    "rod_mass": 1.2,
    "rod_cg": 0.11,
    "rod_inertia": 0.01,
    "slider_mass": 2.5,
}

TABLE_AND_SPRING = {
    "inertia": 0.05,
    "mechanism": CRANK_SLIDER,
    "drive": {"type": "table", "angle_deg": [0, 90, 180, 270], "torque": [40.0, 10.0, 25.0, 5.0]},
    "loads": [
        {"type": "slider_spring", "stiffness": 2000.0, "free_position": 0.3},
        {"type": "constant", "torque": 20.0},
    ],
}
MOTOR_AND_VISCOUS = {
    "inertia": 0.05,
    "mechanism": CRANK_SLIDER,
    "drive": {"type": "linear_motor", "stall_torque": 30.0, "no_load_speed": 100.0},
    "loads": [{"type": "viscous", "coefficient": 0.05}, {"type": "slider_viscous", "coefficient": 3.0}],
}


def make_model(machine: dict, scenario: dict, solver: dict):
    return build_model(validate_scene({"machine": machine, "scenario": scenario, "solver": solver}))


def energy_nodes(trajectory):
    """The energy method's own nodes: times t_i and states (phi_i, omega_i)."""
    assert trajectory.status == "complete", trajectory.message
    assert len(trajectory.interpolants) == 1
    times = np.asarray(trajectory.interpolants[0].x)
    return times, trajectory(times)


def errors_against_dop853(machine: dict, scenario: dict, steps_deg):
    reference = simulate(make_model(machine, scenario, {"method": "DOP853", "rtol": 1e-12, "atol": 1e-12}))
    assert reference.status == "complete", reference.message
    errors = []
    for step in steps_deg:
        tr = simulate(make_model(machine, scenario, {"method": "energy", "phi_step_deg": step}))
        times, (phi, omega) = energy_nodes(tr)
        assert tr.t_end == pytest.approx(scenario["duration"], abs=1e-12)
        # nodes lie on the phi grid exactly (up to accumulated round-off of the sum of steps)
        np.testing.assert_allclose(np.diff(phi), math.radians(step), rtol=1e-9)
        inside = times <= reference.t_end
        ref_phi, ref_omega = reference(times[inside])
        errors.append(max(np.max(np.abs(omega[inside] - ref_omega)), np.max(np.abs(phi[inside] - ref_phi))))
    return errors


@pytest.mark.parametrize(
    "machine, omega0",
    [(TABLE_AND_SPRING, 30.0), (MOTOR_AND_VISCOUS, 10.0)],
    ids=["omega-independent", "omega-dependent"],
)
def test_converges_second_order_to_time_domain_solution(machine, omega0):
    scenario = {"initial": {"phi": 0.0, "omega": omega0}, "duration": 1.0}
    errors = errors_against_dop853(machine, scenario, [2.0, 1.0, 0.5])
    orders = [math.log2(a / b) for a, b in zip(errors, errors[1:])]
    # trapezoid in phi for E and for t = int dphi / omega: O(dphi^2) globally. The table's knots (every
    # 90 deg) lie on the grid for all steps, so no kink degrades the order; omega-dependent moments make the
    # step implicit, iterated to convergence (1e-14), so the scheme keeps its second order.
    assert all(1.8 < order < 2.2 for order in orders), (errors, orders)
    # "small": at 0.5 deg the error is a small fraction of omega (10-30 rad/s)
    assert errors[-1] < 1e-3


def test_start_from_rest_with_constant_moment_is_exact():
    J, M = 2.0, 6.0
    model = make_model(
        {"inertia": J, "drive": {"type": "constant", "torque": 10.0}, "loads": [{"type": "constant", "torque": 4.0}]},
        {"initial": {"phi": 0.0, "omega": 0.0}, "duration": 3.0},
        {"method": "energy", "phi_step_deg": 5.0},
    )
    tr = simulate(model)
    times, (phi, omega) = energy_nodes(tr)
    assert times.size > 50
    # t(phi) = sqrt(2 phi J / M): the sum of 2 dphi / (omega_i + omega_{i+1}) telescopes exactly for
    # omega = sqrt(2 M phi / J); only round-off (~1e-15 per step, ~1e2 steps) remains
    np.testing.assert_allclose(times, np.sqrt(2.0 * phi * J / M), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(omega, np.sqrt(2.0 * M * phi / J), rtol=1e-12, atol=1e-15)
    assert tr.t_end == pytest.approx(3.0, abs=1e-12)


RUN_DOWN = {"inertia": 1.0, "loads": [{"type": "viscous", "coefficient": 0.1}, {"type": "constant", "torque": 5.0}]}


def test_refuses_to_follow_a_stop():
    # omega(t) = (omega0 + M/c) exp(-c t / J) - M/c reaches 0 at t = J/c ln(1 + c omega0 / M) = 1.823 s
    t_stop = 1.0 / 0.1 * math.log(1.0 + 0.1 * 10.0 / 5.0)
    model = make_model(
        RUN_DOWN, {"initial": {"omega": 10.0}, "duration": 5.0}, {"method": "energy", "phi_step_deg": 1.0}
    )
    tr = simulate(model)
    assert tr.status == "failed"
    assert "stops" in tr.message and "time-domain" in tr.message
    # nothing computed is lost: the trajectory reaches within a few steps of the stop (dt per step grows
    # like sqrt(dphi) near the stop: 1 deg at epsilon ~ 5 rad/s^2 -> ~0.2 s)
    assert t_stop - 0.3 < tr.t_end < t_stop


def test_refuses_negative_initial_speed():
    model = make_model(RUN_DOWN, {"initial": {"omega": -3.0}, "duration": 1.0}, {"method": "energy"})
    tr = simulate(model)
    assert tr.status == "failed"
    assert "omega" in tr.message and "-3" in tr.message and "DOP853" in tr.message


def test_cli_exit_code_message_and_csv_on_failure(tmp_path, capsys):
    scene = {
        "name": "run_down",
        "machine": RUN_DOWN,
        "scenario": {"initial": {"omega": 10.0}, "duration": 5.0},
        "solver": {"method": "energy", "phi_step_deg": 1.0, "sample_rate": 100.0},
    }
    path = tmp_path / "run_down.yaml"
    path.write_text(yaml.safe_dump(scene))
    out = tmp_path / "run.csv"
    code = main(["simulate", str(path), "--out", str(out), "--quiet"])
    captured = capsys.readouterr()
    assert code == 1
    assert "stops" in captured.err and "time-domain" in captured.err
    data = np.genfromtxt(out, delimiter=",", names=True)
    assert data.size > 100  # ~1.7 s at 100 Hz
    assert data["t"][0] == 0.0 and 1.5 < data["t"][-1] < 1.83  # up to just before the stop (see above)
    assert np.all(data["omega"] > 0) and data["omega"][0] == pytest.approx(10.0)


def test_cli_negative_initial_speed_exits_with_code_1(tmp_path, capsys):
    scene = {
        "machine": RUN_DOWN,
        "scenario": {"initial": {"omega": -3.0}, "duration": 1.0},
        "solver": {"method": "energy"},
    }
    path = tmp_path / "negative.yaml"
    path.write_text(yaml.safe_dump(scene))
    code = main(["simulate", str(path), "--out", str(tmp_path / "run.csv"), "--quiet"])
    assert code == 1
    assert "initial omega" in capsys.readouterr().err
