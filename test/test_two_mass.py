"""The full two-mass machine of source 003 (docs/theory.md §7): nonlinear coupling characteristic,
position-dependent driven part, periods of motion with the largest coupling moment, and the inverse problem.

Oracles: the `stiffness` coupling (a linear table must give the same numbers); scipy's solve_ivp on the two-mass
equations written out here, with the exact cubic characteristic and the crank-slider's inertia from its own
closed-form position; conservation of energy; the closed-form motion of a linear coupling started from rest
(twist = tw_s (1 - cos w_n t)); the prescribed speed law of the inverse problem.
"""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest
import yaml
from scipy import integrate
from support import model_of, run_cli, scene, simulate_complete, write_scene

from mech_regulator.analysis import analyse_steady_state, energy_balance, motion_periods, required_coupling
from mech_regulator.scene import load_scene

J1, I2 = 0.5, 0.2  # [kg m^2]


def two_mass(
    coupling: dict, driven_loads: list, duration: float = 0.3, drive: float = 40.0, omega: float = 10.0, **driven
) -> dict:
    """Constant drive on J1, a viscous load on the crank, the driven part with `driven_loads`."""
    return {
        "name": "two_mass_test",
        "machine": {
            "inertia": J1,
            "drive": {"type": "constant", "torque": drive},
            "loads": [{"type": "viscous", "coefficient": 0.05}],
            "coupling": {**coupling, "driven": {"inertia": I2, "loads": driven_loads, **driven}},
        },
        "scenario": {"initial": {"omega": omega, "twist": 0.0}, "duration": duration},
        "solver": {"method": "DOP853", "rtol": 1e-10, "atol": 1e-12},
    }


def cubic_table(k1: float, k3: float, span: float = 0.1, points: int = 2001) -> dict:
    """The hardening characteristic M = k1 twist + k3 twist^3 sampled on `points` twists over +-span [rad]."""
    twist = np.linspace(-span, span, points)
    return {"twist": twist.tolist(), "moment": (k1 * twist + k3 * twist**3).tolist()}


def test_linear_table_gives_the_stiffness_run():
    """A table through (-1, -k), (0, 0), (1, k) is the linear coupling: same trajectory to solver tolerance."""
    loads = [{"type": "viscous", "coefficient": 0.1}, {"type": "constant", "torque": 10.0}]
    linear = model_of(two_mass({"stiffness": 2e4, "damping": 3.0}, loads))
    table = model_of(
        two_mass({"characteristic": {"twist": [-1.0, 0.0, 1.0], "moment": [-2e4, 0.0, 2e4]}, "damping": 3.0}, loads)
    )
    times = np.linspace(0.0, 0.3, 301)
    a, b = simulate_complete(linear)(times), simulate_complete(table)(times)
    assert np.max(np.abs(a - b), axis=1) == pytest.approx(np.zeros(4), abs=1e-9)
    assert np.ptp(a[2]) > 1e-4  # the twist does vary: the comparison means something


def test_hardening_characteristic_against_an_independent_ode():
    """Cubic characteristic M = k1 tw + k3 tw^3 tabulated on 2001 points against solve_ivp with the exact cubic:
    speeds and twist agree to the table's interpolation error (h = 1e-4 rad: h^2 / 8 |M''| ~ 1e-5 of the
    moment, so 1e-4 of the range), E_elastic = k1 tw^2 / 2 + k3 tw^4 / 4 (oracle: its integral), and the energy
    balance closes with it."""
    k1, k3, c, c2, load = 500.0, 5e5, 2.0, 0.1, 10.0
    model = model_of(
        two_mass(
            {"characteristic": cubic_table(k1, k3), "damping": c},
            [{"type": "viscous", "coefficient": c2}, {"type": "constant", "torque": load}],
        )
    )
    trajectory = simulate_complete(model)

    def exact(t, y):
        phi, omega, twist, omega2 = y
        passed = k1 * twist + k3 * twist**3 + c * (omega - omega2)
        return [omega, (40.0 - 0.05 * omega - passed) / J1, omega - omega2, (passed - c2 * omega2 - load) / I2]

    times = np.linspace(0.0, 0.3, 301)
    reference = integrate.solve_ivp(
        exact, (0.0, 0.3), [0.0, 10.0, 0.0, 10.0], method="DOP853", t_eval=times, rtol=1e-11, atol=1e-13
    ).y
    states = trajectory(times)
    assert np.max(np.abs(states[2] - reference[2])) < 1e-4 * np.ptp(reference[2])
    assert np.max(np.abs(states[3] - reference[3])) < 1e-4 * np.ptp(reference[3])
    assert np.max(np.abs(reference[2])) > 0.02  # the cubic term matters: k3 tw^2 / k1 > 0.4
    twist = model.columns(times, states)["twist"]
    energy = model.columns(times, states)["E_elastic"]
    assert np.max(np.abs(energy - (k1 * twist**2 / 2 + k3 * twist**4 / 4))) < 1e-5 * np.max(energy)
    assert abs(energy_balance(model, trajectory).relative_residual) < 1e-8


def crank_slider_inertia(phi2: np.ndarray, crank: float, rod: float, mass: float) -> tuple[np.ndarray, np.ndarray]:
    """A central crank-slider with a massless rod: the slider's x = R cos phi + sqrt(l^2 - R^2 sin^2 phi) and
    its reduced inertia m (dx/dphi)^2 with the velocity ratio dx/dphi by central differences of x (written here
    from the geometry, independently of mechanisms/)."""

    def position(angle):
        return crank * np.cos(angle) + np.sqrt(rod**2 - (crank * np.sin(angle)) ** 2)

    h = 1e-5
    ratio = (position(phi2 + h) - position(phi2 - h)) / (2 * h)
    return mass * ratio**2, ratio


def test_position_dependent_driven_part_against_an_independent_ode_and_the_energy_balance():
    """A crank-slider on the driven shaft (slider mass only) with a viscous load on the slider and a hardening
    coupling: I2(phi2) domega2/dt + 1/2 I2' omega2^2 = M_m - c_s (dx/dphi2)^2 omega2 - load (solve_ivp with
    the inertia from the slider's position, I2' by central differences); the energy balance closes with the
    nonlinear elastic energy, the varying kinetic energy and the slider's work."""
    crank, rod, mass, c_slider, k1, k3 = 0.1, 0.4, 30.0, 400.0, 500.0, 5e5
    mechanism = {"type": "crank_slider", "crank": crank, "rod": rod, "slider_mass": mass}
    loads = [{"type": "slider_viscous", "coefficient": c_slider}, {"type": "constant", "torque": 5.0}]
    data = two_mass({"characteristic": cubic_table(k1, k3)}, loads, duration=0.4, mechanism=mechanism)
    model = model_of(data)
    trajectory = simulate_complete(model)

    def inertia(angle: float) -> float:  # scalar form of crank_slider_inertia, for speed
        ratio = (
            math.cos(angle + 1e-5) * crank
            + math.sqrt(rod**2 - (crank * math.sin(angle + 1e-5)) ** 2)
            - math.cos(angle - 1e-5) * crank
            - math.sqrt(rod**2 - (crank * math.sin(angle - 1e-5)) ** 2)
        ) / 2e-5
        return mass * ratio * ratio

    def exact(t, y):
        phi, omega, twist, omega2 = y
        phi2 = phi - twist
        links = inertia(phi2)
        slope = (inertia(phi2 + 1e-4) - inertia(phi2 - 1e-4)) / 2e-4
        passed = k1 * twist + k3 * twist**3
        driven = passed - c_slider * links / mass * omega2 - 5.0 - 0.5 * slope * omega2**2
        return [omega, (40.0 - 0.05 * omega - passed) / J1, omega - omega2, driven / (I2 + links)]

    times = np.linspace(0.0, 0.4, 201)
    reference = integrate.solve_ivp(
        exact, (0.0, 0.4), [0.0, 10.0, 0.0, 10.0], method="DOP853", t_eval=times, rtol=1e-9, atol=1e-11
    ).y
    states = trajectory(times)
    assert np.max(np.abs(states[3] - reference[3])) < 1e-4 * np.max(np.abs(reference[3]))
    assert np.max(np.abs(states[2] - reference[2])) < 1e-4 * np.ptp(reference[2])  # the table's h^2 error
    columns = model.columns(times, states)
    inertia = I2 + crank_slider_inertia(columns["phi_driven"], crank, rod, mass)[0]
    assert np.max(np.abs(columns["I2"] - inertia)) < 1e-8  # I2 varies by some 0.3 kg m^2 over a turn
    assert np.ptp(columns["I2"]) > 0.2
    balance = energy_balance(model, trajectory)
    assert abs(balance.relative_residual) < 1e-8
    assert balance.works["driven_slider_viscous"] < 0.0 and "driven_constant" in balance.works


def start_from_rest(stiffness: float, driven_loads: list, drive: float = 40.0, duration: float = 0.2) -> dict:
    """Both parts at rest, twist 0, no crank load: the start-up of period 1."""
    data = two_mass({"stiffness": stiffness}, driven_loads, duration=duration, drive=drive, omega=0.0)
    data["machine"]["loads"] = []
    return data


def test_period_1_ends_at_the_break_away_closed_form():
    """Constant drive M on J1, constant resistance Mc on I2 (a Coulomb resistance: it holds the driven part at
    exactly omega2 = 0), undamped linear coupling, from rest. While held, J1 phi'' = M - k phi: the twist is
    (M / k) (1 - cos(w1 t)), w1 = sqrt(k / J1), and period 1 ends when k twist reaches Mc,
    t_b = acos(1 - Mc / M) / w1. Then both move: J_r tw'' + k tw = J_r (M / J1 + Mc / I2) = k tw_s from
    tw(t_b) = Mc / k, tw'(t_b) = omega1(t_b), so the largest coupling moment is k (tw_s + sqrt(A^2 + B^2)),
    A = Mc / k - tw_s, B = tw'(t_b) / w_n, at t_b + atan2(B, A) / w_n (w_n = sqrt(k / J_r)), in period 2."""
    k, drive, load = 2e4, 40.0, 15.0
    model = model_of(start_from_rest(k, [{"type": "constant", "torque": load}], drive))
    trajectory = simulate_complete(model)
    periods = motion_periods(model, trajectory, analyse_steady_state(model, trajectory))
    w1 = math.sqrt(k / J1)
    t_b = math.acos(1.0 - load / drive) / w1
    assert periods.start_up_end == pytest.approx(t_b, rel=1e-9)
    assert np.all(trajectory(np.linspace(0.0, 0.99 * t_b, 50))[3] == 0.0)  # held exactly, no roll-back
    natural = math.sqrt(k * (J1 + I2) / (J1 * I2))
    carried = (I2 * drive + J1 * load) / (J1 + I2)
    a, b = load / k - carried / k, drive / k * w1 * math.sin(w1 * t_b) / natural
    assert periods.peak.moment == pytest.approx(carried + k * math.hypot(a, b), rel=1e-7)
    phase = (periods.peak.time - t_b - math.atan2(b, a) / natural) * natural / (2.0 * math.pi)
    assert phase == pytest.approx(round(phase), abs=1e-4)  # undamped: the peak repeats once per relative period
    assert periods.peak.period == 2 and periods.steady_from is None  # the speed keeps growing: never steady


def test_held_driven_mechanism_with_a_branch_breaks_away_and_balances_energy():
    """The two-mass features composed with the drive train's: a driven crank-slider (slider load, no gravity)
    with a branch, held at rest by its Coulomb resistances R = Mc + M_n / i_1n. While held, the slider load
    reads omega2 = 0, so the coupling alone pushes and the break-away is the closed form of the rotor case,
    t_b = acos(1 - R / M) / w1. After it: epsilon_driven = central differences of omega_driven, the branch's
    section torque M_n + (I_n / i_1n) epsilon_driven, and the energy balance closes with I2(phi2)."""
    k, drive, load, branch_load, ratio, branch_inertia = 2e4, 40.0, 5.0, 12.0, 2.0, 0.4
    mechanism = {"type": "crank_slider", "crank": 0.1, "rod": 0.4, "slider_mass": 30.0}
    data = start_from_rest(
        k, [{"type": "constant", "torque": load}, {"type": "slider_viscous", "coefficient": 50.0}], drive, duration=0.3
    )
    data["machine"]["coupling"]["driven"].update(
        mechanism=mechanism,
        branches=[
            {
                "name": "feed",
                "inertia": branch_inertia,
                "ratio": ratio,
                "loads": [{"type": "constant", "torque": branch_load}],
            }
        ],
    )
    model = model_of(data)
    trajectory = simulate_complete(model)
    resistance = load + branch_load / ratio
    t_b = math.acos(1.0 - resistance / drive) / math.sqrt(k / J1)
    periods = motion_periods(model, trajectory, analyse_steady_state(model, trajectory))
    assert periods.start_up_end == pytest.approx(t_b, rel=1e-9)
    times = np.linspace(t_b + 0.005, 0.295, 100)
    columns = model.columns(times, trajectory(times))
    h = 1e-6
    differences = (trajectory(times + h)[3] - trajectory(times - h)[3]) / (2 * h)
    assert np.max(np.abs(columns["epsilon_driven"] - differences)) < 1e-5 * np.max(np.abs(differences))
    assert np.ptp(columns["I2"]) > 0.1  # the mechanism matters: I2 from 0.3 to about 0.6 kg m^2
    section = branch_load + branch_inertia / ratio * columns["epsilon_driven"]
    assert np.max(np.abs(columns["M_section_feed"] - section)) < 1e-9 * np.max(np.abs(section))
    assert abs(energy_balance(model, trajectory).relative_residual) < 1e-8


@pytest.mark.parametrize(
    "driven, message",
    [
        (
            {"mechanism": {"type": "crank_slider", "crank": 0.1, "rod": 0.4, "slider_mass": 3.0}},
            "clutch.driven.mechanism (crank_slider)",
        ),
        (
            {
                "loads": [{"type": "table", "angle_deg": [0.0, 180.0], "torque": [1.0, 2.0]}],
            },
            "clutch.driven.loads[0] type 'table' reads the driven part's angle",
        ),
    ],
)
def test_clutch_refuses_an_angle_dependent_driven_part(tmp_path, capsys, driven, message):
    """Behind a clutch the driven part has no angle state: its mechanism and angle loads are refused by name."""
    data = {
        "name": "clutch_angle",
        "machine": {
            "inertia": 0.5,
            "drive": {"type": "constant", "torque": 40.0},
            "clutch": {"static_torque": 30.0, "kinetic_torque": 25.0, "driven": {"inertia": 1.0, **driven}},
        },
        "scenario": {"duration": 0.1},
    }
    code, _, err = run_cli(capsys, "simulate", str(write_scene(tmp_path, yaml.safe_dump(data))), "--quiet")
    assert code == 2 and message in err


def test_branch_loads_are_rotor_loads_only(tmp_path, capsys):
    """A branch is reduced by its ratio alone: a table in the driven angle on a branch is refused by the schema."""
    data = two_mass(
        {"stiffness": 1e3},
        [],
        branches=[
            {
                "name": "b",
                "inertia": 1.0,
                "ratio": 2.0,
                "loads": [{"type": "table", "angle_deg": [0.0, 180.0], "torque": [1.0, 2.0]}],
            }
        ],
    )
    code, _, err = run_cli(capsys, "simulate", str(write_scene(tmp_path, yaml.safe_dump(data))), "--quiet")
    assert code == 2 and "branches" in err and "table" in err


def test_no_period_1_when_the_driven_part_moves_at_once():
    """A driven part with only a viscous load starts forward at once from rest: period 1 has no length."""
    model = model_of(start_from_rest(2e4, [{"type": "viscous", "coefficient": 0.5}]))
    trajectory = simulate_complete(model)
    periods = motion_periods(model, trajectory, analyse_steady_state(model, trajectory))
    assert periods.start_up_end == 0.0
    assert np.all(trajectory(np.linspace(1e-4, 0.2, 50))[3] > 0.0)


def test_largest_coupling_moment_is_located_on_the_dense_output():
    """The peak of M_m found by the summary is the maximum of M_m on a 100x finer grid around it, to 1e-9."""
    model = model_of(
        start_from_rest(2e4, [{"type": "viscous", "coefficient": 0.5}, {"type": "constant", "torque": 5.0}])
    )
    trajectory = simulate_complete(model)
    peak = motion_periods(model, trajectory, analyse_steady_state(model, trajectory)).peak
    fine = np.linspace(peak.time - 1e-3, peak.time + 1e-3, 20001)
    passed = -model.columns(fine, trajectory(fine))["M_coupling"]
    assert peak.moment == pytest.approx(np.max(passed), rel=1e-9)
    coarse = np.linspace(0.0, 0.2, 2001)
    assert peak.moment >= np.max(-model.columns(coarse, trajectory(coarse))["M_coupling"]) - 1e-9


# ----------------------------------------------------------------------------------------------------------------
# The inverse problem

MOTOR_SCENE = {
    "name": "motor_two_mass",
    "machine": {
        "inertia": 5.0,
        "drive": {"type": "linear_motor", "stall_torque": 200.0, "no_load_speed": 120.0},
        "coupling": {"stiffness": 1000.0, "driven": {"inertia": 0.2, "loads": [{"type": "constant", "torque": 20.0}]}},
    },
    "scenario": {"duration": 4.0},
    "solver": {"rtol": 1e-10, "atol": 1e-12},
}


@pytest.fixture(scope="module")
def inverse():
    """The inverse problem on MOTOR_SCENE: run-up 1 s, delta 0.05."""
    model = model_of(MOTOR_SCENE)
    return model, required_coupling(model, 1.0, 0.05)


def test_inverse_problem_run_forward_reproduces_the_law(inverse):
    """A motor with a large rotor drives a constant resistance; the law's omega_m is the motor's balance speed
    200 (1 - w / 120) = 20, w = 108 rad/s, k = omega_m, A = 2.7 rad/s. The tabulated steady characteristic, run
    forward from the state at t_from, gives omega_driven = the law to 1 % of A over five periods: the tolerance
    covers the remaining loop (the motor's damping lags the driving speed, ~1e-4 of the moment range), the
    201-point table and the undamped relative mode this excites."""
    model, result = inverse
    assert result.law.omega_m == pytest.approx(108.0, rel=1e-10)
    assert result.law.amplitude == pytest.approx(2.7, rel=1e-10)
    assert result.realisable and result.stretch == "steady motion"
    assert result.jump == pytest.approx(0.2 * (2.7 * 108.0 - 108.0 / 1.0), rel=1e-9)  # I2 (A k - omega_m / T)
    forward = scene(
        MOTOR_SCENE,
        machine__coupling={
            "characteristic": {"twist": result.table_twist.tolist(), "moment": result.table_moment.tolist()},
            "driven": MOTOR_SCENE["machine"]["coupling"]["driven"],
        },
        scenario={"duration": 5 * 2 * math.pi / 108.0, "initial": result.initial},
    )
    forward_model = model_of(forward)
    trajectory = simulate_complete(forward_model)
    times = np.linspace(0.0, forward["scenario"]["duration"], 501)
    _, law_speed, _ = result.law(times + result.t_from)
    assert np.max(np.abs(trajectory(times)[3] - law_speed)) < 0.01 * 2.7
    phi_driven = forward_model.columns(times[:1], trajectory(times[:1]))["phi_driven"][0]
    assert phi_driven == pytest.approx(result.law(result.t_from)[0], rel=1e-12)  # the law's angle (phi2 = 0 at t = 0)


def test_inverse_problem_characteristic_is_the_reduced_stiffness(inverse):
    """With a constant resistance and a heavy rotor the steady characteristic is about linear with slope
    J_r k^2 (J_r = J1 I2 / (J1 + I2)): the driven part and the rotor swing against each other at k."""
    _, result = inverse
    twist, moment = result.table_twist, result.table_moment
    slope = np.ptp(moment[1:]) / np.ptp(twist[1:])
    assert slope == pytest.approx(5.0 * 0.2 / 5.2 * 108.0**2, rel=0.01)


def test_inverse_problem_with_a_viscous_driven_load_needs_more_than_a_spring():
    """A viscous load on the driven part takes energy in phase with omega2 over the sine: no elastic coupling
    (no loop-free characteristic) can give it; the answer says so and names the paper's flywheel."""
    data = scene(MOTOR_SCENE, scenario={"duration": 1.0})
    data["machine"]["coupling"]["driven"]["loads"].append({"type": "viscous", "coefficient": 1.0})
    result = required_coupling(model_of(data), 0.5, 0.05)
    assert not result.realisable and result.loop_width > 1e-3 * np.ptp(result.table_moment)
    assert any("flywheel" in note for note in result.notes)


def test_coupling_command_end_to_end(tmp_path, capsys):
    """coupling writes the table, a scene that uses it (it loads and runs), the picture and JSON."""
    path = write_scene(tmp_path, yaml.safe_dump(MOTOR_SCENE))
    table, forward, picture = tmp_path / "table.csv", tmp_path / "forward.yaml", tmp_path / "inverse.png"
    code, out, err = run_cli(
        capsys,
        "coupling",
        str(path),
        "--run-up",
        "1",
        "--delta",
        "0.05",
        "--out",
        str(table),
        "--scene-out",
        str(forward),
        "--plot",
        str(picture),
        "--json",
    )
    assert code == 0, err
    answer = json.loads(out)
    assert answer["realisable"] and answer["law"]["omega_m"] == pytest.approx(108.0)
    rows = list(csv.reader(table.open()))
    assert rows[0] == ["twist", "moment"] and len(rows) == len(answer["characteristic"]["twist"]) + 1
    assert picture.stat().st_size > 10_000
    written = load_scene(str(forward), ["scenario.duration=0.05"])
    assert written.machine.coupling.characteristic is not None and written.machine.coupling.stiffness is None
    code, out, _ = run_cli(capsys, "simulate", str(forward), "--quiet", "--set", "scenario.duration=0.05")
    assert code == 0 and "periods: 1 start-up none" in out and "largest coupling moment" in out


@pytest.mark.parametrize(
    "options, message",
    [
        (["--delta", "3"], "--delta 3: expected a value between 0 and 2"),
        (["--run-up", "-1"], "--run-up -1"),
        (["--points", "2"], "--points 2"),
    ],
)
def test_coupling_command_bad_options(tmp_path, capsys, options, message):
    path = write_scene(tmp_path, yaml.safe_dump(MOTOR_SCENE))
    arguments = {"--run-up": "1", "--delta": "0.05"}
    for name, value in zip(options[::2], options[1::2]):
        arguments[name] = value
    code, _, err = run_cli(capsys, "coupling", str(path), *[x for pair in arguments.items() for x in pair])
    assert code == 2 and message in err


def test_coupling_command_refuses_scenes_it_does_not_cover(capsys):
    code, _, err = run_cli(capsys, "coupling", "engine", "--run-up", "1", "--delta", "0.05")
    assert code == 2 and "no machine.coupling" in err
    code, _, err = run_cli(capsys, "coupling", "two_mass", "--run-up", "1", "--delta", "0.05")
    assert code == 2 and "crank angle" in err and "motor" in err


@pytest.mark.parametrize(
    "characteristic, message",
    [
        ({"twist": [0.0, 0.1, 0.05], "moment": [0.0, 1.0, 2.0]}, "must be strictly increasing"),
        ({"twist": [0.01, 0.1], "moment": [1.0, 2.0]}, "expected the point twist 0 -> moment 0"),
        ({"twist": [0.0, 0.1, 0.2], "moment": [0.0, 5.0, 4.0]}, "does not rise from twist 0.1 to 0.2"),
        ({"twist": [0.0, 0.1, 0.2], "moment": [0.0, 1.0]}, "expected one moment per twist"),
    ],
)
def test_bad_characteristic_tables_get_clear_messages(tmp_path, capsys, characteristic, message):
    data = two_mass({"characteristic": characteristic}, [])
    path = write_scene(tmp_path, yaml.safe_dump(data))
    code, _, err = run_cli(capsys, "simulate", str(path), "--quiet")
    assert code == 2 and message in err and "characteristic" in err


def test_coupling_needs_exactly_one_characteristic_and_fitting_driven_loads(tmp_path, capsys):
    both = two_mass({"stiffness": 1e3, "characteristic": {"twist": [0.0, 1.0], "moment": [0.0, 1.0]}}, [])
    code, _, err = run_cli(capsys, "simulate", str(write_scene(tmp_path, yaml.safe_dump(both))))
    assert code == 2 and "both of stiffness and characteristic" in err
    slider = two_mass({"stiffness": 1e3}, [{"type": "slider_viscous", "coefficient": 1.0}])
    code, _, err = run_cli(capsys, "simulate", str(write_scene(tmp_path, yaml.safe_dump(slider), "b.yaml")))
    assert code == 2 and "driven.loads[0] type 'slider_viscous'" in err and "driven.mechanism.type" in err
    shuttle = two_mass({"stiffness": 1e3}, [{"type": "shuttle_constant", "force": 3.0}])
    code, _, err = run_cli(capsys, "simulate", str(write_scene(tmp_path, yaml.safe_dump(shuttle), "c.yaml")))
    assert code == 2 and "driven.loads[0] type 'shuttle_constant'" in err and "walking_beam" in err


def test_press_scene_summary_reports_the_periods(capsys):
    """The bundled press (shortened): JSON summary with the periods: its friction holds the press at rest first
    (period 1 of a few ms, reported as a held stretch by the drive train), the largest coupling moment lies in
    the start-up transient, above the running moment."""
    code, out, _ = run_cli(capsys, "simulate", "press_coupling", "--json", "--quiet", "--set", "scenario.duration=0.3")
    assert code == 0
    periods = json.loads(out)["two_mass"]
    assert 0.0 < periods["start_up_end"] < 0.02
    assert json.loads(out)["drive_train"]["held"] == [[0.0, pytest.approx(periods["start_up_end"], rel=1e-12)]]
    assert periods["peak"]["period"] == 2 and periods["peak"]["moment"] > 500.0
