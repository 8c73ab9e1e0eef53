"""The centrifugal governor (docs/theory.md §8.2-§8.3) against closed forms and independent derivations:
the Porter sensor's static characteristic, its equation of motion (Jacobi integral and dissipation),
the insensitivity band and statism, the valve, the operating points of direct and indirect action,
and short simulations that settle on the operating points the statics predict.

Every reference value is computed here, from the textbook formulas written out in this file (cone
height h = l cos a = l - z/2, omega_g^2 = pull / (m h)), by scipy root finding on hand-written
balances, or by an energy argument; the package's own functions are only the things under test.

Tolerance conventions:
- closed forms evaluated by the package and by the test in a different order of operations agree to
  a few ulp; 1e-13 relative leaves margin for the square root and the division by the ratio;
- root finds (the package's brentq and the test's brentq with xtol 1e-15) agree to ~1e-12 relative;
  1e-9 relative on operating points is the brief's requirement and leaves three orders of margin;
- integrations of the sensor alone use solve_ivp DOP853 at rtol 1e-11, atol 1e-13: the global error
  over a few oscillation periods (2 s) is a few rtol, so the Jacobi integral stays constant to ~1e-10
  of the sum of the magnitudes of its terms (observed 1e-13 to 1e-10); 1e-9 is the tolerance. A wrong
  factor on the sleeve-inertia term drifts by > 1e-1 on the same measure (checked in a test);
- the dissipation identity dE/dt = -(c z' + F) z' holds pointwise: 1e-12 of the magnitude of its terms;
- governed simulations settle towards the operating point with the eigenvalues of the linearised
  averaged model (linear_stability's Jacobian, eigen-decomposed here): a deviation dx0 decays at most
  as sum_k |V[i, k] (V^-1 dx0)_k| exp(Re lambda_k t). The tolerance is twice that linear envelope
  (the deviations are ~1-2 % of the state, so nonlinear corrections are a few % of the linear
  response) plus a solver floor of 1e-6 rad/s (rtol 1e-9 on speeds ~100 rad/s gives ~1e-7).
  Each test also checks its tolerance is far below the effect it measures, so it cannot pass vacuously.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy import integrate, optimize
from support import simulate_complete

from mech_regulator.analysis import droop, linear_stability, load_responses, operating_point, static_characteristic
from mech_regulator.model import build_model
from mech_regulator.scene import SceneError, validate_scene

G = 9.81  # [m/s^2]

# The machine of the governor notes: constant J, linear motor M_d = M0 (1 - omega / W0), viscous load C omega.
M0, W0, C = 200.0, 150.0, 0.3  # [N m], [rad/s], [N m s]

PORTER = {
    "type": "direct",
    "ball_mass": 1.0,
    "arm_length": 0.2,
    "sleeve_mass": 5.0,  # [kg], [m], [kg]
    "damping": 200.0,
    "friction": 0.0,
    "ratio": 0.16,
    "stroke": [0.02, 0.08],  # [N s/m], [N], [-], [m]
    "valve": {"open_at": 0.02, "closed_at": 0.08},
}  # [m]
SPRUNG = {
    **PORTER,
    "sleeve_mass": 2.0,
    "spring": {"stiffness": 800.0, "free_position": 0.01},  # [kg], [N/m], [m]
    "ratio": 0.2,
}
WATT = {**PORTER, "sleeve_mass": 0.0, "ratio": 0.05}


def governed_model(governor: dict, inertia: float = 0.5, scenario: dict | None = None, solver: dict | None = None):
    """A constant-J machine (linear motor, viscous load) with the given governor."""
    scene = {
        "machine": {
            "inertia": inertia,
            "drive": {"type": "linear_motor", "stall_torque": M0, "no_load_speed": W0},
            "loads": [{"type": "viscous", "coefficient": C}],
        },
        "governor": governor,
        "scenario": scenario or {"initial": {"omega": 100.0}, "duration": 1.0},
        "solver": solver or {"method": "DOP853", "rtol": 1e-9, "atol": 1e-11},
    }
    return build_model(validate_scene(scene))


def spring_of(governor: dict) -> tuple[float, float]:
    spring = governor.get("spring") or {"stiffness": 0.0, "free_position": 0.0}
    return spring["stiffness"], spring["free_position"]


def pull(governor: dict, z: float, friction: float = 0.0) -> float:
    """Downward force on the sleeve the balls must hold [N]: weights, spring, friction."""
    k, z_free = spring_of(governor)
    return (governor["ball_mass"] + governor["sleeve_mass"]) * G + k * (z - z_free) + friction


def speed_closed_form(governor: dict, z: float, friction: float = 0.0) -> float:
    """Crank speed [rad/s] holding the sleeve at z: the cone height h = l cos a = l - z/2 (z = 2 l (1 - cos a)),
    m h omega_g^2 = pull, omega = omega_g / ratio."""
    height = governor["arm_length"] - 0.5 * z
    return math.sqrt(pull(governor, z, friction) / (governor["ball_mass"] * height)) / governor["ratio"]


def linear_valve(z: float, open_at: float, closed_at: float) -> float:
    """Throttle 1 at open_at, 0 at closed_at, linear between, clipped (written as an interpolation)."""
    lo, hi = sorted((open_at, closed_at))
    u = (min(max(z, lo), hi) - open_at) / (closed_at - open_at)  # 0 at open_at, 1 at closed_at
    return 1.0 - u


def motor_surplus(throttle: float, omega: float, load: float) -> float:
    """Net moment on the crank [N m] in steady running."""
    return throttle * M0 * (1.0 - omega / W0) - C * omega - load


def full_throttle_speed(load: float) -> float:
    """M0 (1 - w / W0) = C w + L solved for w [rad/s]."""
    return (M0 - load) / (M0 / W0 + C)


def balance_throttle(omega: float, load: float) -> float:
    """Throttle at which the motor balances viscous + external load at omega [-]."""
    return (C * omega + load) / (M0 * (1.0 - omega / W0))


def valve_of(governor: dict):
    """The throttle(z) of a governor's valve entry, written independently (np.interp for a table)."""
    valve = governor["valve"]
    if valve.get("type", "linear") == "table":
        return lambda z: float(np.interp(z, valve["sleeve"], valve["throttle"]))
    return lambda z: linear_valve(z, valve["open_at"], valve["closed_at"])


def hand_direct_point(governor: dict, load: float) -> tuple[float, float, float]:
    """(speed, sleeve, throttle) of a direct governor: root in z of valve(z) M0 (1 - w(z)/W0) - C w(z) - L,
    w(z) from the closed form."""
    valve = valve_of(governor)

    def balance(z: float) -> float:
        return motor_surplus(valve(z), speed_closed_form(governor, z), load)

    z_low, z_high = governor["stroke"]
    z = optimize.brentq(balance, z_low, z_high, xtol=1e-15, rtol=4 * np.finfo(float).eps)
    return speed_closed_form(governor, z), z, valve(z)


def envelope(jacobian: np.ndarray, dx0: np.ndarray, t: float, index: int = 0) -> float:
    """Bound on |x_index(t)| of the linear system x' = jacobian x from x(0) = dx0: the sum over the
    eigenmodes of |V[index, k] c_k| exp(Re lambda_k t), c = V^-1 dx0."""
    values, vectors = np.linalg.eig(jacobian)
    coefficients = np.linalg.solve(vectors, dx0.astype(complex))
    return float(np.sum(np.abs(vectors[index] * coefficients) * np.exp(values.real * t)))


# ---------------------------------------------------------------------------------------------
# 1. Static characteristic


@pytest.mark.parametrize("governor", [PORTER, SPRUNG, WATT], ids=["porter", "spring", "watt"])
def test_equilibrium_speed_matches_closed_form_over_the_stroke(governor):
    sensor = governed_model(governor).governor.sensor
    m, l, ratio = governor["ball_mass"], governor["arm_length"], governor["ratio"]
    for z in np.linspace(*governor["stroke"], 7):
        omega = speed_closed_form(governor, z)
        assert sensor.equilibrium_speed(z) == pytest.approx(omega, rel=1e-13)
        # the sleeve is in equilibrium there: the lift (scale: the pull, ~10-60 N) vanishes to round-off
        a = sensor.arm_angle(z)
        assert math.cos(a) == pytest.approx(1.0 - z / (2 * l), rel=1e-14)
        assert abs(sensor.lift(a, omega)) <= 1e-12 * pull(governor, z)
        # and the lift grows with omega as m l cos a omega_g^2: at 1 % more speed it is m h ratio^2 omega^2 (1.01^2 - 1)
        expected = m * (l - z / 2) * (ratio * omega) ** 2 * (1.01**2 - 1.0)
        assert sensor.lift(a, 1.01 * omega) == pytest.approx(expected, rel=1e-10)
        # the inverse: the sleeve position for that speed
        assert sensor.equilibrium_sleeve(omega) == pytest.approx(z, abs=1e-12)
    if governor["sleeve_mass"] == 0.0 and "spring" not in governor:
        # Watt: the cone height is h = g / omega_g^2 whatever the ball mass
        z = 0.05
        omega_g = ratio * sensor.equilibrium_speed(z)
        assert G / omega_g**2 == pytest.approx(l - z / 2, rel=1e-13)


def test_equilibrium_sleeve_is_clipped_to_the_stroke():
    sensor = governed_model(PORTER).governor.sensor
    z_low, z_high = PORTER["stroke"]
    assert sensor.equilibrium_sleeve(0.9 * speed_closed_form(PORTER, z_low)) == z_low
    assert sensor.equilibrium_sleeve(1.1 * speed_closed_form(PORTER, z_high)) == z_high


def test_static_characteristic_arrays_match_closed_form():
    governor = {**SPRUNG, "friction": 2.0, "static_friction": 3.0}  # [N]
    characteristic = static_characteristic(governed_model(governor).governor.sensor, points=11)
    np.testing.assert_allclose(characteristic.sleeve, np.linspace(0.02, 0.08, 11), rtol=0, atol=1e-15)
    for i, z in enumerate(characteristic.sleeve):
        assert characteristic.speed[i] == pytest.approx(speed_closed_form(governor, z), rel=1e-13)


# ---------------------------------------------------------------------------------------------
# 2. The sensor's equation of motion: Jacobi integral and dissipation
#
# Lagrangian at a constant spindle speed omega_g (balls: T = m l^2 a'^2 + m l^2 omega_g^2 sin^2 a;
# sleeve: M z'^2 / 2 = 2 M l^2 sin^2 a a'^2; V = -2 m g l cos a + 2 M g l (1 - cos a) + k/2 (z - z_free)^2).
# The Lagrangian does not depend on time, so the Jacobi integral E = T2 - T0 + V is conserved without
# damping and friction, and dE/dt = Q a' = -(c z' + F) z' with them (Q: generalised non-conservative force).


def jacobi_terms(sensor, a: float, a_dot: float, omega: float) -> list[float]:
    """The terms of E = T2 - T0 + V [J]; E is their sum, their absolute values give E's scale."""
    m, l, M, k = sensor.ball_mass, sensor.arm_length, sensor.sleeve_mass, sensor.stiffness
    g, omega_g = sensor.gravity, sensor.ratio * omega
    z = 2 * l * (1 - math.cos(a))
    s = math.sin(a)
    return [
        (m * l**2 + 2 * M * l**2 * s**2) * a_dot**2,
        -m * l**2 * omega_g**2 * s**2,
        -2 * m * g * l * math.cos(a),
        2 * M * g * l * (1 - math.cos(a)),
        0.5 * k * (z - sensor.free_position) ** 2,
    ]


def jacobi_rate(sensor, a: float, a_dot: float, a_ddot: float, omega: float) -> tuple[float, float]:
    """dE/dt = dE/da a' + dE/da' a'' (partial derivatives written out), and a scale of its terms."""
    m, l, M, k = sensor.ball_mass, sensor.arm_length, sensor.sleeve_mass, sensor.stiffness
    g, omega_g = sensor.gravity, sensor.ratio * omega
    s, c = math.sin(a), math.cos(a)
    z = 2 * l * (1 - c)
    dE_da = (
        4 * M * l**2 * s * c * a_dot**2
        - 2 * m * l**2 * omega_g**2 * s * c
        + 2 * m * g * l * s
        + 2 * M * g * l * s
        + k * (z - sensor.free_position) * 2 * l * s
    )
    dE_dadot = 2 * (m * l**2 + 2 * M * l**2 * s**2) * a_dot
    return dE_da * a_dot + dE_dadot * a_ddot, abs(dE_da * a_dot) + abs(dE_dadot * a_ddot)


def energy_drift(
    sensor, acceleration, omega: float, a0: float, a_dot0: float, duration: float
) -> tuple[float, np.ndarray]:
    """Largest |E(t) - E(0)| relative to the sum of |terms of E| at t = 0, and the arm angles visited."""
    solution = integrate.solve_ivp(
        lambda t, y: [y[1], acceleration(y[0], y[1])],
        (0.0, duration),
        [a0, a_dot0],
        method="DOP853",
        rtol=1e-11,
        atol=1e-13,
        dense_output=True,
    )
    assert solution.success
    t = np.linspace(0.0, duration, 2001)
    a, a_dot = solution.sol(t)
    energies = np.array([sum(jacobi_terms(sensor, ai, adi, omega)) for ai, adi in zip(a, a_dot)])
    scale = sum(abs(term) for term in jacobi_terms(sensor, a0, a_dot0, omega))
    return float(np.max(np.abs(energies - energies[0])) / scale), a


# a Porter governor with a stiff spring holds the arms inside (0, pi/2) even at a' ~ 10 rad/s (sleeve speed
# ~2 m/s), where the sleeve's inertia term 2 M l^2 sin(2a) a'^2 dominates the dynamics
STIFF = {**PORTER, "spring": {"stiffness": 20000.0, "free_position": 0.03}, "ratio": 0.4}  # [N/m], [m], [-]
JACOBI_CASES = [(PORTER, 1.0), (SPRUNG, 3.0), (WATT, 0.5), (STIFF, 10.0)]  # initial a' [rad/s], from mid-stroke


@pytest.mark.parametrize("governor, a_dot0", JACOBI_CASES, ids=["porter", "spring", "watt", "stiff"])
def test_arm_acceleration_conserves_the_jacobi_integral(governor, a_dot0):
    # frictionless and undamped, at the constant crank speed that holds the sleeve at mid-stroke, started
    # there with arm rate a_dot0: E(t) must stay at E(0) to the integration accuracy
    sensor = dataclasses.replace(governed_model(governor).governor.sensor, damping=0.0)
    omega, a0 = speed_closed_form(governor, 0.05), sensor.arm_angle(0.05)

    def acceleration(a, a_dot):
        return sensor.arm_acceleration(a, a_dot, omega, 0.0)

    drift, angles = energy_drift(sensor, acceleration, omega, a0, a_dot0, 2.0)
    assert 0.05 < angles.min() and angles.max() < 0.5 * math.pi  # stays a governor (arms neither hang nor flip)
    assert np.ptp(angles) > 0.2  # and swings widely [rad]
    assert drift < 1e-9


def test_jacobi_test_catches_a_wrong_factor_on_the_sleeve_inertia_term():
    # the same check applied to an acceleration with 4 M l^2 sin(2a) a'^2 (only d/dt of dT/da', forgetting
    # dT/da) instead of 2 M l^2 sin(2a) a'^2 must fail by orders of magnitude: the test above has power
    governor, a_dot0 = JACOBI_CASES[-1]
    sensor = dataclasses.replace(governed_model(governor).governor.sensor, damping=0.0)
    m, l, M = sensor.ball_mass, sensor.arm_length, sensor.sleeve_mass
    omega, a0 = speed_closed_form(governor, 0.05), sensor.arm_angle(0.05)

    def wrong(a, a_dot):
        right = sensor.arm_acceleration(a, a_dot, omega, 0.0)
        mass = 2 * m * l**2 + 4 * M * l**2 * math.sin(a) ** 2
        return right - 2 * M * l**2 * math.sin(2 * a) * a_dot**2 / mass

    drift, _ = energy_drift(sensor, wrong, omega, a0, a_dot0, 2.0)
    assert drift > 1e-3


@pytest.mark.parametrize("governor", [PORTER, SPRUNG, WATT], ids=["porter", "spring", "watt"])
def test_arm_acceleration_dissipation_is_damping_and_friction_power(governor):
    # dE/dt = -(c z' + F) z' exactly at every state (this fixes a'' uniquely wherever a' != 0):
    # checks the sign and factor of the damping term and of the signed friction force
    c = 150.0  # [N s/m]
    sensor = dataclasses.replace(governed_model(governor).governor.sensor, damping=c)
    rng = np.random.default_rng(3)
    for _ in range(50):
        a, a_dot = rng.uniform(0.2, 1.2), rng.uniform(-10.0, 10.0)  # [rad], [rad/s]
        omega = rng.uniform(60.0, 140.0)  # [rad/s]
        z_dot = 2 * sensor.arm_length * math.sin(a) * a_dot
        friction = math.copysign(rng.uniform(0.0, 20.0), z_dot)  # opposing the motion [N]
        rate, scale = jacobi_rate(sensor, a, a_dot, sensor.arm_acceleration(a, a_dot, omega, friction), omega)
        assert rate == pytest.approx(-(c * z_dot + friction) * z_dot, abs=1e-12 * scale)
        assert rate < 0.0


# ---------------------------------------------------------------------------------------------
# 3, 4. Insensitivity band and statism


@pytest.mark.parametrize("governor", [PORTER, SPRUNG], ids=["porter", "spring"])
def test_insensitivity_band_uses_static_friction(governor):
    F_k, F_s = 2.0, 3.0  # kinetic and static sleeve friction [N]
    governor = {**governor, "friction": F_k, "static_friction": F_s}
    characteristic = static_characteristic(governed_model(governor).governor.sensor, points=7)
    for i, z in enumerate(characteristic.sleeve):
        assert characteristic.speed_high[i] == pytest.approx(speed_closed_form(governor, z, +F_s), rel=1e-13)
        assert characteristic.speed_low[i] == pytest.approx(speed_closed_form(governor, z, -F_s), rel=1e-13)
        # relative band: sqrt(1 + x) - sqrt(1 - x) = x + x^3/8 + 7 x^5/128 + ..., x = F_s / pull
        # (pull = (m + M) g without a spring): first order is x, the next term is +x^3/8 (a relative
        # correction x^2/8 ~ 3e-4 here), all further terms are positive and below x^5
        x = F_s / pull(governor, z)
        band = characteristic.insensitivity[i]
        assert x**3 / 8 * (1 - 1e-6) <= band - x <= x**3 / 8 + x**5
    if "spring" not in governor:
        x = F_s / ((governor["ball_mass"] + governor["sleeve_mass"]) * G)
        np.testing.assert_allclose(characteristic.insensitivity, x, rtol=x**2 / 8 + x**4)


@pytest.mark.parametrize("governor", [PORTER, SPRUNG, WATT], ids=["porter", "spring", "watt"])
def test_statism_matches_closed_form(governor):
    z_low, z_high = governor["stroke"]
    low, high = speed_closed_form(governor, z_low), speed_closed_form(governor, z_high)
    expected = (high - low) / (0.5 * (high + low))
    characteristic = static_characteristic(governed_model(governor).governor.sensor)
    assert characteristic.statism == pytest.approx(expected, rel=1e-12)
    assert characteristic.statism > 0.0


# ---------------------------------------------------------------------------------------------
# 5. Valve


def throttle_at(governor, z: float) -> float:
    """The governor's throttle for a state with the sleeve at z (crank speed irrelevant for direct action)."""
    return governor.throttle(np.array([0.0, 100.0, governor.sensor.arm_angle(z), 0.0]))


@pytest.mark.parametrize("open_at, closed_at", [(0.03, 0.07), (0.07, 0.03)], ids=["normal", "reversed"])
def test_linear_valve(open_at, closed_at):
    governor = governed_model({**PORTER, "valve": {"open_at": open_at, "closed_at": closed_at}}).governor
    assert throttle_at(governor, open_at) == pytest.approx(1.0, abs=1e-12)
    assert throttle_at(governor, closed_at) == pytest.approx(0.0, abs=1e-12)
    span = closed_at - open_at
    for fraction in (0.1, 0.25, 0.5, 0.9):  # linear between: fraction of the way from open to closed
        assert throttle_at(governor, open_at + fraction * span) == pytest.approx(1.0 - fraction, abs=1e-12)
    beyond_open, beyond_closed = open_at - 0.25 * span, closed_at + 0.25 * span  # clipped outside
    assert governor.valve(beyond_open) == 1.0
    assert governor.valve(beyond_closed) == 0.0
    assert governor.valve(open_at - span) == 1.0 and governor.valve(closed_at + span) == 0.0


def test_linear_valve_needs_two_positions():
    with pytest.raises(SceneError, match="open_at"):
        governed_model({**PORTER, "valve": {"open_at": 0.05, "closed_at": 0.05}})


def test_table_valve_interpolates_and_holds_end_values():
    sleeve, throttle = [0.03, 0.045, 0.06, 0.07], [1.0, 0.9, 0.3, 0.0]  # [m], [-]
    governor = governed_model({**PORTER, "valve": {"type": "table", "sleeve": sleeve, "throttle": throttle}}).governor
    for z in np.linspace(0.01, 0.09, 33):
        assert governor.valve(z) == pytest.approx(float(np.interp(z, sleeve, throttle)), abs=1e-12)
    assert governor.valve(0.0375) == pytest.approx(0.95, abs=1e-12)
    with pytest.raises(SceneError, match="strictly increasing"):
        governed_model({**PORTER, "valve": {"type": "table", "sleeve": [0.03, 0.03], "throttle": [1.0, 0.0]}})
    with pytest.raises(SceneError, match="between 0 and 1"):
        governed_model({**PORTER, "valve": {"type": "table", "sleeve": [0.03, 0.05], "throttle": [1.2, 0.0]}})


def test_drive_is_scaled_by_the_valve():
    model = governed_model({**PORTER, "valve": {"open_at": 0.03, "closed_at": 0.07}})
    z, omega = 0.04, 110.0  # [m], [rad/s]
    y = np.array([[0.0], [omega], [model.governor.sensor.arm_angle(z)], [0.0]])
    columns = model.columns(np.array([0.0]), y)
    assert columns["throttle"][0] == pytest.approx(0.75, abs=1e-12)
    assert columns["M_drive"][0] == pytest.approx(0.75 * M0 * (1 - omega / W0), rel=1e-12)
    assert columns["sleeve"][0] == pytest.approx(z, abs=1e-15)


# ---------------------------------------------------------------------------------------------
# 6. Operating point of a direct governor


TABLE_VALVE = {"type": "table", "sleeve": [0.02, 0.04, 0.06, 0.08], "throttle": [1.0, 0.8, 0.3, 0.0]}  # [m], [-]


@pytest.mark.parametrize(
    "governor",
    [PORTER, {**SPRUNG, "valve": {"open_at": 0.03, "closed_at": 0.07}}, {**WATT, "ratio": 0.07, "valve": TABLE_VALVE}],
    ids=["porter", "spring-narrow-valve", "watt-table-valve"],
)
@pytest.mark.parametrize("load", [0.0, 5.0, 10.0])  # [N m]
def test_direct_operating_point_matches_hand_solution(governor, load):
    model = governed_model(governor)
    speed, sleeve, throttle = hand_direct_point(governor, load)
    point = operating_point(model, load)
    assert point.limited == ""
    assert point.speed == pytest.approx(speed, rel=1e-9)
    assert point.sleeve == pytest.approx(sleeve, rel=1e-9)
    assert point.throttle == pytest.approx(throttle, rel=1e-9)
    assert math.isnan(point.servo)
    assert point.mean_inertia == 0.5
    assert abs(motor_surplus(throttle, speed, load)) < 1e-9  # the hand solution really balances


def test_droop_slope_matches_implicit_derivative():
    # f(z, L) = v(z) M0 (1 - w(z)/W0) - C w(z) - L = 0 gives dz/dL = 1 / f_z and d omega / dL = w'(z) / f_z, with
    # w ~ h^(-1/2), h = l - z/2: w' = w / (4 h); v' = -1 / (closed_at - open_at). droop() takes a central
    # difference over +-1e-3 N m: its error is ~(1e-3)^2 relative to the curvature scale, far below 1e-6.
    load = 4.0  # [N m]
    model = governed_model(PORTER, scenario={"initial": {"omega": 110.0}, "duration": 1.0, "external_load": load})
    speed, z, throttle = hand_direct_point(PORTER, load)
    dw_dz = speed / (4.0 * (PORTER["arm_length"] - 0.5 * z))
    dv_dz = -1.0 / (PORTER["valve"]["closed_at"] - PORTER["valve"]["open_at"])
    f_z = dv_dz * M0 * (1.0 - speed / W0) - (throttle * M0 / W0 + C) * dw_dz
    assert droop(model).per_unit_load == pytest.approx(dw_dz / f_z, rel=1e-6)


@pytest.mark.parametrize(
    "load, stop, throttle",
    [
        (25.0, "low", 1.0),  # [N m]: more than the motor carries at the speed that lifts the sleeve off its low stop
        (-40.0, "high", 0.0),  # [N m]: an overhauling load; throttle 0 leaves C w = -L
    ],
)
def test_direct_operating_point_on_a_stop(load, stop, throttle):
    model = governed_model(PORTER)
    stroke_end = PORTER["stroke"][0 if stop == "low" else 1]
    expected = full_throttle_speed(load) if stop == "low" else -load / C  # M0 (1 - w/W0) = C w + L, or C w = -L
    beyond = (
        expected < speed_closed_form(PORTER, stroke_end)
        if stop == "low"
        else expected > speed_closed_form(PORTER, stroke_end)
    )
    assert beyond
    point = operating_point(model, load)
    assert point.limited == f"sleeve on its {stop} stop"
    assert point.throttle == throttle
    assert point.sleeve == stroke_end
    assert point.speed == pytest.approx(expected, rel=1e-9)


# ---------------------------------------------------------------------------------------------
# 7. Direct action leaves the static error the statics predict


def test_direct_governor_settles_with_the_predicted_static_error():
    load_0, load_1, t_step, duration = 0.0, 10.0, 5.0, 10.0  # [N m], [N m], [s], [s]
    speed_0, sleeve_0, _ = hand_direct_point(PORTER, load_0)
    speed_1, sleeve_1, _ = hand_direct_point(PORTER, load_1)
    kick = 2.0  # start 2 rad/s fast with the sleeve where it belongs at the operating point [rad/s]
    model = governed_model(
        PORTER,
        scenario={
            "initial": {"omega": speed_0 + kick, "sleeve": sleeve_0},
            "duration": duration,
            "external_load": load_0,
            "load_events": [{"time": t_step, "torque": load_1}],
        },
    )
    trajectory = simulate_complete(model)
    assert trajectory.events == []  # frictionless and well inside the stroke: no stops, no mode changes

    point_0, point_1 = operating_point(model, load_0), operating_point(model, load_1)
    linear_0, linear_1 = linear_stability(model, point_0), linear_stability(model, point_1)
    assert linear_0.stable and linear_1.stable and linear_1.dominant.real < -1.0
    arm_0, arm_1 = model.governor.sensor.arm_angle(sleeve_0), model.governor.sensor.arm_angle(sleeve_1)
    tol_0 = 2 * envelope(linear_0.jacobian, np.array([kick, 0.0, 0.0]), t_step) + 1e-6
    tol_1 = (
        2 * envelope(linear_1.jacobian, np.array([speed_0 - speed_1, arm_0 - arm_1, 0.0]), duration - t_step)
        + tol_0
        + 1e-6
    )
    static_error = speed_1 - speed_0  # about -1.47 rad/s
    assert tol_0 < 1e-2 * abs(static_error) and tol_1 < 1e-2 * abs(static_error)

    before, after = trajectory(t_step)[1], trajectory(duration)[1]
    assert before == pytest.approx(speed_0, abs=tol_0)
    assert after == pytest.approx(speed_1, abs=tol_1)
    assert point_1.speed - point_0.speed == pytest.approx(static_error, rel=1e-9)

    response = load_responses(model, trajectory)[0]
    assert response.static_error == pytest.approx(static_error, abs=tol_0 + tol_1)
    assert response.predicted_static_error == pytest.approx(static_error, rel=1e-9)
    assert droop(model).per_event == pytest.approx([static_error], rel=1e-9)


# ---------------------------------------------------------------------------------------------
# 8. Indirect action


INDIRECT = {
    "type": "indirect",
    "ball_mass": 1.0,
    "arm_length": 0.2,
    "sleeve_mass": 5.0,  # [kg], [m], [kg]
    "damping": 100.0,
    "friction": 0.0,
    "ratio": 0.16,
    "stroke": [0.02, 0.08],  # [N s/m], [N], [-], [m]
    "pilot_neutral": 0.04,
    "servo": {"gain": 200.0},
}  # [m], [1/(m s)]
ISODROMIC = {**INDIRECT, "feedback": {"type": "isodromic", "gain": 0.2, "time_constant": 0.5}}  # [m], [s]
RIGID = {**INDIRECT, "feedback": {"type": "rigid", "gain": 0.2}}  # [m]
NO_FEEDBACK = {**INDIRECT, "feedback": {"type": "none"}}
INDIRECT_J = 0.2  # a light machine [kg m^2]: fast enough that the isodromic loop settles in a few seconds


def set_speed_closed_form() -> float:
    return speed_closed_form(INDIRECT, INDIRECT["pilot_neutral"])


def hand_rigid_point(rho: float, reference: float, load: float) -> tuple[float, float, float]:
    """(speed, sleeve, servo) with rigid feedback: the pilot closes where z - z_n + rho (s - s_ref) = 0 and s
    balances the load at the speed w(z); one equation in z."""
    z_n = INDIRECT["pilot_neutral"]

    def servo(z: float) -> float:
        return reference - (z - z_n) / rho

    def balance(z: float) -> float:
        return motor_surplus(servo(z), speed_closed_form(INDIRECT, z), load)

    z = optimize.brentq(balance, *INDIRECT["stroke"], xtol=1e-15, rtol=4 * np.finfo(float).eps)
    return speed_closed_form(INDIRECT, z), z, servo(z)


@pytest.mark.parametrize("governor", [NO_FEEDBACK, ISODROMIC], ids=["none", "isodromic"])
def test_astatic_operating_point_is_the_set_speed_for_every_load(governor):
    model = governed_model(governor, inertia=INDIRECT_J)
    set_speed = set_speed_closed_form()
    assert model.governor.set_speed() == pytest.approx(set_speed, rel=1e-13)
    for load in (0.0, 4.0, 8.0, 12.0):  # [N m]
        point = operating_point(model, load)
        assert point.limited == ""
        assert point.speed == pytest.approx(set_speed, rel=1e-12)
        assert point.sleeve == pytest.approx(INDIRECT["pilot_neutral"], abs=1e-15)
        assert point.servo == pytest.approx(balance_throttle(set_speed, load), rel=1e-12)
        assert point.throttle == point.servo


def test_astatic_operating_point_with_servo_saturated():
    # 20 N m needs a throttle above 1 at the set speed: the servo sits on its high stop and the machine
    # runs at its own full-throttle balance
    model = governed_model(ISODROMIC, inertia=INDIRECT_J)
    assert balance_throttle(set_speed_closed_form(), 20.0) > 1.0
    point = operating_point(model, 20.0)
    assert point.limited == "servo on its high stop"
    assert point.servo == 1.0
    assert point.speed == pytest.approx(full_throttle_speed(20.0), rel=1e-9)


@pytest.mark.parametrize("reference", [None, 0.8], ids=["default-reference", "reference-0.8"])
def test_rigid_feedback_droop_matches_hand_solution(reference):
    rho, initial_load = RIGID["feedback"]["gain"], 2.0  # [m], [N m]
    feedback = {**RIGID["feedback"], **({"reference": reference} if reference is not None else {})}
    model = governed_model(
        {**RIGID, "feedback": feedback},
        inertia=INDIRECT_J,
        scenario={"initial": {"omega": 110.0}, "duration": 1.0, "external_load": initial_load},
    )
    set_speed = set_speed_closed_form()
    if reference is None:  # default: the throttle that balances the initial load at the set speed
        reference = balance_throttle(set_speed, initial_load)
        assert operating_point(model, initial_load).speed == pytest.approx(set_speed, rel=1e-12)
    assert model.governor.feedback_reference == pytest.approx(reference, rel=1e-13)
    speeds = []
    for load in (initial_load, 8.0):  # [N m]
        speed, sleeve, servo = hand_rigid_point(rho, reference, load)
        point = operating_point(model, load)
        assert point.limited == ""
        assert point.speed == pytest.approx(speed, rel=1e-9)
        assert point.sleeve == pytest.approx(sleeve, rel=1e-9)
        assert point.servo == pytest.approx(servo, rel=1e-9)
        speeds.append(point.speed)
    assert speeds[1] < speeds[0] - 0.5  # a real droop [rad/s]


def indirect_run(governor: dict, load_0: float, load_1: float, t_step: float, duration: float):
    """A run that starts at rest in the operating point of load_0 and steps to load_1."""
    model = governed_model(
        governor,
        inertia=INDIRECT_J,
        scenario={
            "initial": {"omega": set_speed_closed_form()},
            "duration": duration,
            "external_load": load_0,
            "load_events": [{"time": t_step, "torque": load_1}],
        },
    )
    return model, simulate_complete(model)


def test_isodromic_feedback_returns_to_the_set_speed():
    load_0, load_1, t_step, duration = 2.0, 8.0, 1.0, 8.0  # [N m], [N m], [s], [s]
    model, trajectory = indirect_run(ISODROMIC, load_0, load_1, t_step, duration)
    assert trajectory.events == []  # no stops reached
    set_speed = set_speed_closed_form()
    servo_0, servo_1 = balance_throttle(set_speed, load_0), balance_throttle(set_speed, load_1)
    linear = linear_stability(model, operating_point(model, load_1))
    assert linear.stable and linear.dominant.real < -1.0  # about -2.1 1/s
    # the step leaves every state but the servo at its new equilibrium: x = [omega, a, a', s, zeta]
    dx0 = np.array([0.0, 0.0, 0.0, servo_0 - servo_1, 0.0])
    remaining = duration - t_step
    tol_speed = 2 * envelope(linear.jacobian, dx0, remaining, index=0) + 1e-6
    tol_servo = 2 * envelope(linear.jacobian, dx0, remaining, index=3) + 1e-8

    t = np.linspace(t_step, duration, 1401)
    speed = trajectory(t)[1]
    dip = set_speed - speed.min()
    assert dip > 0.1  # the load step does pull the speed down [rad/s]
    assert tol_speed < 1e-3 * dip
    end = trajectory(duration)
    assert end[1] == pytest.approx(set_speed, abs=tol_speed)  # no static error
    assert end[4] == pytest.approx(servo_1, abs=tol_servo)  # the servo carries the new load
    assert abs(end[5]) < 2 * envelope(linear.jacobian, dx0, remaining, index=4) + 1e-9  # dashpot relaxed [m]
    assert trajectory(t_step)[1] == pytest.approx(set_speed, abs=1e-6)  # it started in equilibrium


def test_rigid_feedback_run_settles_at_the_predicted_droop():
    load_0, load_1, t_step, duration = 2.0, 8.0, 1.0, 8.0  # [N m], [N m], [s], [s]
    model, trajectory = indirect_run(RIGID, load_0, load_1, t_step, duration)
    assert trajectory.events == []
    rho = RIGID["feedback"]["gain"]
    reference = balance_throttle(set_speed_closed_form(), load_0)
    speed_0, sleeve_0, servo_0 = hand_rigid_point(rho, reference, load_0)
    speed_1, sleeve_1, servo_1 = hand_rigid_point(rho, reference, load_1)
    linear = linear_stability(model, operating_point(model, load_1))
    assert linear.stable and linear.dominant.real < -1.0  # about -2.7 1/s
    sensor = model.governor.sensor
    dx0 = np.array([speed_0 - speed_1, sensor.arm_angle(sleeve_0) - sensor.arm_angle(sleeve_1), 0.0, servo_0 - servo_1])
    tol = 2 * envelope(linear.jacobian, dx0, duration - t_step) + 1e-6
    tol_servo = 2 * envelope(linear.jacobian, dx0, duration - t_step, index=3) + 1e-8
    assert tol < 1e-3 * abs(speed_1 - speed_0)
    assert trajectory(t_step)[1] == pytest.approx(speed_0, abs=1e-6)
    assert trajectory(duration)[1] == pytest.approx(speed_1, abs=tol)
    assert trajectory(duration)[4] == pytest.approx(servo_1, abs=tol_servo)


def test_a_load_event_within_the_first_cycle_is_not_analysed():
    """engine_direct with load changes at 0.05 s (inside its first dynamic cycle of 4 pi rad, some 56 ms: no
    cycle-mean speed before it), 0.09 s and 0.13 s: the first has no response (it used to end the summary in a
    traceback, an all-NaN argmax), the two others have theirs, at their times."""
    from mech_regulator.scene import load_scene

    model = build_model(
        load_scene(
            "engine_direct",
            [
                "scenario.duration=0.5",
                "scenario.load_events=[{time: 0.05, torque: 8.0}, {time: 0.09, torque: 6.0}, "
                "{time: 0.13, torque: 8.0}]",
            ],
        )
    )
    assert model.dynamic_period() / 224.0 > 0.05
    responses = load_responses(model, simulate_complete(model))
    assert [response.time for response in responses] == [0.09, 0.13]
    assert all(math.isfinite(response.peak_deviation) for response in responses)
