"""The governors added through the sensor interface (governors/sensor.py): the spring-loaded Hartnell sensor and the
electronic PI governor (docs/theory.md §8.9, §8.10), against closed forms written here.

Every reference value is computed in this file: Hartnell's equilibrium from the balance of moments about a bell
crank's pivot (the balls' centrifugal forces and weights against half the sleeve's weight and spring), his equation
of motion through the Jacobi integral T2 - T0 + V written out, the PI loop's quadratic from the linearised averaged
machine, and the PI governor's return to its set speed after a load step.

Tolerances as in test_governor_statics.py: closed forms evaluated in a different order agree to a few ulp (1e-13
relative); the sensor alone integrated with DOP853 at rtol 1e-11 keeps its Jacobi integral to ~1e-10 of its terms'
scale (tolerance 1e-9); governed runs settle as the linearised loop's eigenvalues say (here Re < -2 /s over 14 s: a
deviation of ~10 rad/s decays below 1e-11 rad/s), so what is left is the solver's error (rtol 1e-10 on speeds ~100
rad/s: ~1e-8 rad/s; tolerance 1e-6 rad/s); each test checks its measure is far from what a wrong model gives.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy import integrate
from support import model_of, simulate_complete

from mech_regulator.analysis import linear_stability, operating_point
from mech_regulator.scene import SceneError, validate_scene

G = 9.81  # [m/s^2]
M0, W0, C = 200.0, 150.0, 0.3  # linear motor M_d = M0 (1 - omega / W0) [N m], [rad/s]; viscous load C omega [N m s]

HARTNELL = {
    "type": "hartnell",
    "ball_mass": 1.0,
    "ball_arm": 0.1,
    "sleeve_arm": 0.08,
    "pivot_radius": 0.12,
    "sleeve_mass": 2.0,
    "spring": {"stiffness": 3000.0, "free_position": -0.03},
    "damping": 100.0,
    "ratio": 0.2,
    "stroke": [-0.02, 0.03],
    "valve": {"open_at": -0.02, "closed_at": 0.03},
}
PI = {"type": "pi", "set_speed": 100.0, "gain": 2.0, "integral_time": 0.5}  # [rad/s], [-], [s]


def machine_with(governor: dict, scenario: dict | None = None) -> dict:
    """A constant-J machine (linear motor, viscous load) with the given governor."""
    return {
        "machine": {
            "inertia": 0.5,
            "drive": {"type": "linear_motor", "stall_torque": M0, "no_load_speed": W0},
            "loads": [{"type": "viscous", "coefficient": C}],
        },
        "governor": governor,
        "scenario": scenario or {"initial": {"omega": 100.0}, "duration": 1.0, "external_load": 5.0},
        "solver": {"method": "DOP853", "rtol": 1e-10, "atol": 1e-12, "sample_rate": 100.0, "path": "reference"},
    }


def hartnell_speed(governor: dict, z: float) -> float:
    """Crank speed [rad/s] holding the sleeve at z: moments about one bell crank's pivot,
    m omega_g^2 r a cos(t) + m g a sin(t) = (M g + k (z - z_free)) / 2 * b cos(t), sin(t) = z / b, r = r0 + a sin(t)."""
    m, a, b, r0, M = (governor[key] for key in ("ball_mass", "ball_arm", "sleeve_arm", "pivot_radius", "sleeve_mass"))
    k, z_free = governor["spring"]["stiffness"], governor["spring"]["free_position"]
    theta = math.asin(z / b)
    radius = r0 + a * math.sin(theta)
    sleeve_load = M * G + k * (z - z_free)
    moment = 0.5 * sleeve_load * b * math.cos(theta) - m * G * a * math.sin(theta)  # [N m]
    omega_g2 = moment / (m * radius * a * math.cos(theta))
    return math.sqrt(omega_g2) / governor["ratio"]


@pytest.mark.parametrize("z", [-0.02, -0.005, 0.0, 0.012, 0.03])
def test_hartnell_equilibrium_speed_is_the_balance_of_moments_on_the_bell_crank(z):
    sensor = model_of(machine_with(HARTNELL)).governor.sensor
    omega = hartnell_speed(HARTNELL, z)
    assert sensor.equilibrium_speed(z) == pytest.approx(omega, rel=1e-13)
    assert sensor.lift(sensor.arm_angle(z), omega) == pytest.approx(0.0, abs=1e-12 * HARTNELL["sleeve_mass"] * G)
    if z not in HARTNELL["stroke"]:  # inside the stroke: the sleeve's rest position at that speed
        assert sensor.equilibrium_sleeve(omega) == pytest.approx(z, abs=1e-12)
    wrong = hartnell_speed({**HARTNELL, "ball_arm": 1.01 * HARTNELL["ball_arm"]}, z)
    assert abs(wrong - omega) > 1e-5 * omega  # the balance depends on the arms: a wrong lever shows


def jacobi_terms(sensor, theta: float, rate: float, omega: float) -> list[float]:
    """The terms of E = T2 - T0 + V [J] of the Hartnell sensor at constant spindle speed: T2 = (m a^2 + M b^2
    cos^2 t / 2) t'^2, T0 = m r^2 omega_g^2, V = 2 m g a cos t + M g z + k (z - z_free)^2 / 2, z = b sin t."""
    m, a, b, r0, M = sensor.ball_mass, sensor.ball_arm, sensor.sleeve_arm, sensor.pivot_radius, sensor.sleeve_mass
    omega_g, z = sensor.ratio * omega, b * math.sin(theta)
    radius = r0 + a * math.sin(theta)
    return [
        (m * a * a + 0.5 * M * b * b * math.cos(theta) ** 2) * rate * rate,
        -m * radius**2 * omega_g**2,
        2 * m * G * a * math.cos(theta),
        M * G * z,
        0.5 * sensor.stiffness * (z - sensor.free_position) ** 2,
    ]


def jacobi_drift(sensor, acceleration, omega: float, theta0: float, rate0: float) -> tuple[float, np.ndarray]:
    """Largest |E(t) - E(0)| over 2 s relative to the sum of |terms of E| at t = 0, and the angles visited."""
    solution = integrate.solve_ivp(
        lambda t, y: [y[1], acceleration(y[0], y[1])],
        (0.0, 2.0),
        [theta0, rate0],
        method="DOP853",
        rtol=1e-11,
        atol=1e-13,
        dense_output=True,
    )
    assert solution.success
    theta, rate = solution.sol(np.linspace(0.0, 2.0, 2001))
    energies = np.array([sum(jacobi_terms(sensor, t, r, omega)) for t, r in zip(theta, rate)])
    scale = sum(abs(term) for term in jacobi_terms(sensor, theta0, rate0, omega))
    return float(np.max(np.abs(energies - energies[0])) / scale), theta


def test_hartnell_equation_of_motion_conserves_the_jacobi_integral():
    # undamped, frictionless, at the speed that holds the sleeve at z = 0.005 m, started there swinging fast
    sensor = dataclasses.replace(model_of(machine_with(HARTNELL)).governor.sensor, damping=0.0)
    omega, theta0 = hartnell_speed(HARTNELL, 0.005), sensor.arm_angle(0.005)
    drift, angles = jacobi_drift(sensor, lambda t, r: sensor.arm_acceleration(t, r, omega, 0.0), omega, theta0, 5.0)
    assert np.ptp(angles) > 0.3  # it swings widely [rad]
    assert drift < 1e-9

    def without_the_sleeve_inertia_term(theta, rate):  # the same test has power: drop M b^2 sin cos t'^2
        mass = 2 * sensor.ball_mass * sensor.ball_arm**2 + sensor.sleeve_mass * sensor.sleeve_lever(theta) ** 2
        extra = sensor.sleeve_mass * sensor.sleeve_arm**2 * math.sin(theta) * math.cos(theta) * rate * rate
        return sensor.arm_acceleration(theta, rate, omega, 0.0) - extra / mass

    assert jacobi_drift(sensor, without_the_sleeve_inertia_term, omega, theta0, 5.0)[0] > 1e-4


def test_hartnell_outline_keeps_its_arms_and_lifts_the_sleeve_by_z():
    sensor = model_of(machine_with(HARTNELL)).governor.sensor
    for theta in np.linspace(*sensor.stop_angles(), 7):
        outline = sensor.outline(theta, 0.3)
        for side in range(2):
            pivot, ball = outline["upper_arms"][side]
            same_pivot, tip = outline["lower_links"][side]
            assert np.array_equal(pivot, same_pivot)
            assert np.hypot(*(ball - pivot)) == pytest.approx(sensor.ball_arm, abs=1e-12)
            assert np.hypot(*(tip - pivot)) == pytest.approx(sensor.sleeve_arm, abs=1e-12)
            assert np.dot(ball - pivot, tip - pivot) == pytest.approx(0.0, abs=1e-12)  # a bell crank: square arms
            assert abs(ball[0]) == pytest.approx(sensor.pivot_radius + sensor.ball_arm * math.sin(theta), abs=1e-12)
        sleeve_centre = outline["sleeve"][:4].mean(axis=0)
        assert sleeve_centre[1] - outline["upper_arms"][0][0][1] == pytest.approx(sensor.sleeve(theta), abs=1e-12)


def test_pi_governor_leaves_no_speed_error_after_a_load_step():
    scenario = {
        "initial": {"omega": 100.0},
        "duration": 15.0,
        "external_load": 5.0,
        "load_events": [{"time": 1.0, "torque": 20.0}],
    }
    speed = simulate_complete(model_of(machine_with(PI, scenario)))(15.0)[1]
    assert speed == pytest.approx(PI["set_speed"], abs=1e-6)
    # the same law without its integral part (T_i huge) is a proportional governor: it leaves the droop
    # Delta omega = -Delta M / (K_p M_d / omega_s - D), some 6 rad/s here
    proportional = {**PI, "integral_time": 1e9}
    droop = simulate_complete(model_of(machine_with(proportional, scenario)))(15.0)[1] - PI["set_speed"]
    assert droop < -1.0


def test_pi_operating_point_is_the_set_speed_and_its_loop_the_closed_form_quadratic():
    model = model_of(machine_with(PI))
    point = operating_point(model, 5.0)
    omega_s, gain, integral_time = PI["set_speed"], PI["gain"], PI["integral_time"]
    drive = M0 * (1.0 - omega_s / W0)
    throttle = (C * omega_s + 5.0) / drive  # the balance throttle M_d + M_c = 0
    assert point.speed == omega_s and point.throttle == pytest.approx(throttle, rel=1e-12) and not point.limited
    regulation = -throttle * M0 / W0 - C  # D = d(throttle M_d + M_c)/d omega at a fixed throttle [N m s]
    a1 = (gain * drive / omega_s - regulation) / 0.5
    a0 = gain * drive / (omega_s * integral_time * 0.5)
    linear = linear_stability(model, point)
    np.testing.assert_allclose(linear.pi_loop, [a1, a0], rtol=1e-6)  # D by central differences
    np.testing.assert_allclose(linear.polynomial, [1.0, a1, a0], rtol=1e-6)  # the numerical Jacobian agrees
    assert linear.stable


def test_pi_operating_point_beyond_the_valve_s_travel_sits_on_its_stop():
    model = model_of(machine_with(PI))
    point = operating_point(model, 60.0)  # needs more than the full throttle at 100 rad/s
    assert point.limited.startswith("valve on its high stop") and point.throttle == 1.0
    assert M0 * (1.0 - point.speed / W0) - C * point.speed - 60.0 == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize(
    "governor, key, expected",
    [
        ({**HARTNELL, "stroke": [-0.02, 0.09]}, "stroke", "-sleeve_arm < z_low < z_high < sleeve_arm"),
        ({**HARTNELL, "pivot_radius": 0.05}, "pivot_radius", "expected more than ball_arm"),
        (
            {**HARTNELL, "sleeve_mass": 0.1, "spring": {"stiffness": 1000.0, "free_position": 0.05}},
            "spring",
            "does not hold the sleeve down",
        ),
        ({**PI, "travel": [0.5, 0.2]}, "travel", "expected 0 <= low < high <= 1"),
    ],
    ids=["hartnell stroke", "hartnell pivot", "hartnell spring", "pi travel"],
)
def test_bad_governor_entries_are_named(governor, key, expected):
    with pytest.raises(SceneError) as error:
        validate_scene(machine_with(governor))
    assert key in str(error.value) and expected in str(error.value)


def test_a_pi_governor_refuses_an_initial_sleeve():
    data = machine_with(PI, {"initial": {"omega": 100.0, "sleeve": 0.03}, "duration": 1.0})
    with pytest.raises(SceneError, match="scenario.initial.sleeve is set but the governor is 'pi'"):
        validate_scene(data)
