"""Joint friction (docs/theory.md §6): kinetostatics against the reduced moment and an independent
Newton–Euler system, the friction formulas against closed forms and quadrature, the energy the friction
dissipates, closed-form run-downs, break-away and self-locking, and scenes without joint friction unchanged."""

from __future__ import annotations

import cmath
import math

import numpy as np
import pytest
from scipy import integrate, optimize
from support import model_of, run_cli, simulate_complete

from mech_regulator.analysis.energy import energy_balance
from mech_regulator.effects.joint_friction import (
    friction_circle_radius,
    reduced_friction_coefficient,
    thrust_collar_moment,
)
from mech_regulator.mechanisms import build_kinetostatics, build_reduced
from mech_regulator.mechanisms.crank_slider import slider_kinematics
from mech_regulator.mechanisms.four_bar import link_angles
from mech_regulator.model import build_model
from mech_regulator.scene import load_scene, mechanism_keys
from mech_regulator.solvers.cosim import GovernorStepper

GRAVITY = (0.7, -9.81)
CRANK_SLIDER = mechanism_keys.CrankSlider(
    type="crank_slider",
    crank=0.05,
    rod=0.2,
    offset=0.012,
    crank_mass=1.1,
    crank_cg=0.02,
    rod_mass=1.2,
    rod_cg=0.08,
    rod_inertia=0.006,
    slider_mass=2.0,
)
FOUR_BAR = mechanism_keys.FourBar(
    type="four_bar",
    crank=0.04,
    coupler=0.12,
    rocker=0.08,
    frame=0.10,
    frame_angle_deg=12.0,
    crank_mass=0.2,
    crank_cg=0.02,
    coupler_mass=0.5,
    coupler_cg=0.05,
    coupler_inertia=6e-4,
    rocker_mass=0.4,
    rocker_cg=0.03,
    rocker_inertia=2.1e-4,
)


def random_states(count: int, seed: int):
    """(phi [rad], omega [rad/s], epsilon [rad/s^2], output force Q) at random."""
    rng = np.random.default_rng(seed)
    return zip(
        rng.uniform(0, 2 * math.pi, count),
        rng.uniform(-80, 80, count),
        rng.uniform(-3000, 3000, count),
        rng.uniform(-800, 800, count),
    )


# ----------------------------------------------------------------------------------------------
# kinetostatics


@pytest.mark.parametrize("mechanism", [CRANK_SLIDER, FOUR_BAR], ids=["crank_slider", "four_bar"])
def test_balancing_moment_equals_the_reduced_moment(mechanism):
    """M_b from the joint reactions = J_links epsilon + 1/2 J_links' omega^2 - M_weight - Q dq/dphi."""
    loads, _ = build_kinetostatics(mechanism, GRAVITY)
    reduced = build_reduced(mechanism, GRAVITY)
    for phi, omega, epsilon, force in random_states(200, 1):
        parts = loads(phi, omega, force)
        J, dJ, weight, _, dq = reduced(phi)
        expected = J * epsilon + 0.5 * dJ * omega**2 - weight - force * dq
        balancing = parts.balancing[0] + parts.balancing[1] * epsilon
        assert balancing == pytest.approx(expected, rel=1e-9, abs=1e-9)


def _accelerations(positions, phi: float, omega: float, epsilon: float, h: float = 1e-5):
    """Positions and second time derivatives (central differences) of positions(phi) along phi(t) = phi +
    omega t + epsilon t^2 / 2 at t = 0."""
    at = [np.asarray(positions(phi + omega * t + 0.5 * epsilon * t * t)) for t in (-h, 0.0, h)]
    return at[1], (at[0] - 2 * at[1] + at[2]) / h**2


def _newton_euler(links, unknown_count: int) -> np.ndarray:
    """Solve the links' Newton–Euler equations for the unknowns. links: (m, J_S, S, a_S, alpha, forces, moments,
    gravity) with forces a list of (point, 2 x unknown_count matrix, known force vector) and moments a list of
    (row of coefficients, known moment); each link gives sum F + m g = m a_S and, about S,
    sum (P - S) x F + M = J_S alpha (3 equations, or 2 for a particle: J_S None)."""
    rows, rhs = [], []
    for m, J_S, S, a_S, alpha, forces, moments, g in links:
        force_rows = np.zeros((2, unknown_count))
        known = np.zeros(2)
        moment_row = np.zeros(unknown_count)
        known_moment = 0.0
        for point, matrix, constant in forces:
            force_rows += matrix
            known += constant
            arm = np.asarray(point) - S
            moment_row += arm[0] * matrix[1] - arm[1] * matrix[0]
            known_moment += arm[0] * constant[1] - arm[1] * constant[0]
        for row, constant in moments:
            moment_row += row
            known_moment += constant
        rows += list(force_rows)
        rhs += list(m * (np.asarray(a_S) - g) - known)
        if J_S is not None:
            rows.append(moment_row)
            rhs.append(J_S * alpha - known_moment)
    return np.linalg.solve(np.array(rows), np.array(rhs))


def _unknown(index: int, count: int, sign: float = 1.0) -> np.ndarray:
    """The 2 x count matrix picking the force vector of unknowns index, index + 1 (times sign)."""
    matrix = np.zeros((2, count))
    matrix[0, index] = matrix[1, index + 1] = sign
    return matrix


def _crank(mass: float, S1, a_S1, B, balancing_row, n: int, g):
    """The crank's equations, moments about A: its rotational inertia about A (J_S1 + m1 |S1|^2) belongs to the
    machine's J0, so only its weight acts at S1; its inertia force -m1 a_S1 loads the bearing (applied at A)."""
    return (
        0.0,
        0.0,
        np.zeros(2),
        np.zeros(2),
        0.0,
        [
            ((0, 0), _unknown(0, n), -mass * np.asarray(a_S1)),
            (B, _unknown(2, n, -1.0), np.zeros(2)),
            (S1, np.zeros((2, n)), mass * g),
        ],
        [(balancing_row, 0.0)],
        g,
    )


def test_crank_slider_reactions_match_newton_euler_system():
    """Unknowns F_01, F_12, F_23 (2 each), N, M_b: 8 equations (crank and rod 3, slider 2), accelerations by
    finite differences of the positions from the closed-form geometry, solved with numpy.linalg.solve."""
    spec = CRANK_SLIDER
    R, l, e = spec.crank, spec.rod, spec.offset
    g = np.array(GRAVITY)
    loads, names = build_kinetostatics(spec, GRAVITY)
    assert names == ("crank_bearing", "crank_pin", "wrist_pin", "guide")

    def positions(phi):
        B = np.array([R * math.cos(phi), R * math.sin(phi)])
        C = np.array([B[0] + math.sqrt(l * l - (e - B[1]) ** 2), e])
        theta = math.atan2(C[1] - B[1], C[0] - B[0])
        return [*(spec.crank_cg / R * B), *(B + spec.rod_cg / l * (C - B)), *C, theta]

    n = 8
    for phi, omega, epsilon, force in random_states(40, 2):
        p, a = _accelerations(positions, phi, omega, epsilon)
        S1, S2, C, B = p[0:2], p[2:4], p[4:6], np.array([R * math.cos(phi), R * math.sin(phi)])
        normal = np.zeros((2, n))
        normal[1, 6] = 1.0
        balancing = np.zeros(n)
        balancing[7] = 1.0
        crank = _crank(spec.crank_mass, S1, a[0:2], B, balancing, n, g)
        rod = (
            spec.rod_mass,
            spec.rod_inertia,
            S2,
            a[2:4],
            a[6],
            [(B, _unknown(2, n), np.zeros(2)), (C, _unknown(4, n, -1.0), np.zeros(2))],
            [],
            g,
        )
        slider = (spec.slider_mass, None, C, a[4:6], 0.0, [(C, _unknown(4, n) + normal, np.array([force, 0.0]))], [], g)
        solution = _newton_euler([crank, rod, slider], n)
        expected = [complex(*solution[0:2]), complex(*solution[2:4]), complex(*solution[4:6]), 1j * solution[6]]
        parts = loads(phi, omega, force)
        for r0, r1, reference in zip(parts.constant, parts.per_epsilon, expected):
            assert abs(r0 + r1 * epsilon - reference) <= 1e-5 * (abs(reference) + 10.0)
        assert parts.balancing[0] + parts.balancing[1] * epsilon == pytest.approx(solution[7], rel=1e-5, abs=1e-4)


def test_four_bar_reactions_match_newton_euler_system():
    """Unknowns F_01, F_12, F_23, F_03 (2 each), M_b: 9 equations (3 per link); the coupler and rocker angles
    from the loop closure solved by fsolve, accelerations by finite differences, numpy.linalg.solve."""
    spec = FOUR_BAR
    a_, b, c, d, th1 = spec.crank, spec.coupler, spec.rocker, spec.frame, math.radians(spec.frame_angle_deg)
    D = np.array([d * math.cos(th1), d * math.sin(th1)])
    g = np.array(GRAVITY)
    loads, names = build_kinetostatics(spec, GRAVITY)
    assert names == ("crank_bearing", "crank_pin", "rocker_pin", "rocker_bearing")

    def angles(phi, guess):
        def closure(x):
            th3, th4 = x
            return [
                a_ * math.cos(phi) + b * math.cos(th3) - d * math.cos(th1) - c * math.cos(th4),
                a_ * math.sin(phi) + b * math.sin(th3) - d * math.sin(th1) - c * math.sin(th4),
            ]

        return optimize.fsolve(closure, guess, xtol=1e-12)

    n = 9
    for phi, omega, epsilon, moment in random_states(30, 3):
        start = link_angles(phi, a_, b, c, d, th1, -1.0)  # only to pick the branch: fsolve starts off it
        start = [start[0] + 0.01, start[3] - 0.01]

        def positions(angle):
            th3, th4 = angles(angle, start)
            B = np.array([a_ * math.cos(angle), a_ * math.sin(angle)])
            return [
                *(spec.crank_cg / a_ * B),
                *(B + spec.coupler_cg * np.array([math.cos(th3), math.sin(th3)])),
                *(D + spec.rocker_cg * np.array([math.cos(th4), math.sin(th4)])),
                th3,
                th4,
            ]

        p, acc = _accelerations(positions, phi, omega, epsilon)
        th3 = p[6]
        B = np.array([a_ * math.cos(phi), a_ * math.sin(phi)])
        C = B + b * np.array([math.cos(th3), math.sin(th3)])
        S1, S3, S4 = p[0:2], p[2:4], p[4:6]
        balancing = np.zeros(n)
        balancing[8] = 1.0
        rocker_moment = np.zeros(n)
        crank = _crank(spec.crank_mass, S1, acc[0:2], B, balancing, n, g)
        coupler = (
            spec.coupler_mass,
            spec.coupler_inertia,
            S3,
            acc[2:4],
            acc[6],
            [(B, _unknown(2, n), np.zeros(2)), (C, _unknown(4, n, -1.0), np.zeros(2))],
            [],
            g,
        )
        rocker = (
            spec.rocker_mass,
            spec.rocker_inertia,
            S4,
            acc[4:6],
            acc[7],
            [(C, _unknown(4, n), np.zeros(2)), (D, _unknown(6, n), np.zeros(2))],
            [(rocker_moment, moment)],
            g,
        )
        solution = _newton_euler([crank, coupler, rocker], n)
        expected = [complex(*solution[i : i + 2]) for i in (0, 2, 4, 6)]
        parts = loads(phi, omega, moment)
        for r0, r1, reference in zip(parts.constant, parts.per_epsilon, expected):
            assert abs(r0 + r1 * epsilon - reference) <= 1e-5 * (abs(reference) + 10.0)
        assert parts.balancing[0] + parts.balancing[1] * epsilon == pytest.approx(solution[8], rel=1e-5, abs=1e-4)


def test_relative_speed_ratios_by_finite_differences():
    """The ratios omega_rel / omega of the joints (and dx/dphi of the guide) against differences of the angles: a
    revolute joint's is theta_first' - theta_second', its first link the outer one (mechanisms/presets.py), so the
    pins' are the rod's (coupler's) turn less the crank's and the piston's (rocker's) less the rod's (coupler's)."""
    h = 1e-6
    for spec in (CRANK_SLIDER, FOUR_BAR):
        loads, _ = build_kinetostatics(spec, None)
        for phi in np.linspace(0.1, 6.2, 13):
            ratios = loads(phi, 0.0, 0.0).ratios
            if spec is CRANK_SLIDER:

                def angle(p):
                    x, _, _, theta, _, _ = slider_kinematics(p, spec.crank, spec.rod, spec.offset)
                    return np.array([p, theta - p, -theta, x])
            else:

                def angle(p):
                    th3, _, _, th4, _, _ = link_angles(p, 0.04, 0.12, 0.08, 0.10, math.radians(12.0), -1.0)
                    return np.array([p, th3 - p, th4 - th3, th4])

            difference = (angle(phi + h) - angle(phi - h)) / (2 * h)
            assert np.allclose(ratios, difference, rtol=1e-6, atol=1e-7)


# ----------------------------------------------------------------------------------------------
# friction formulas


def test_friction_circle_factors():
    """rho = lambda_p f' r with lambda_p 1, pi/2, 4/pi; f' = f / sqrt(1 + f^2) (f = 0.75 gives 0.6)."""
    assert reduced_friction_coefficient(0.75) == pytest.approx(0.6, rel=1e-15)
    radius = 0.02
    for fit, factor in (("clearance", 1.0), ("new", math.pi / 2), ("run_in", 4 / math.pi)):
        assert friction_circle_radius(0.75, radius, fit) == pytest.approx(factor * 0.6 * radius, rel=1e-15)


@pytest.mark.parametrize("inner, outer", [(0.0, 0.04), (0.02, 0.04), (0.039, 0.04)])
def test_thrust_collar_against_quadrature(inner, outer):
    """New: uniform pressure p = Q / (pi (r2^2 - r1^2)); run-in: uniform wear p r = Q / (2 pi (r2 - r1));
    M = integral f p r 2 pi r dr over the ring."""
    f, Q = 0.12, 1500.0
    uniform = Q / (math.pi * (outer**2 - inner**2))
    new = integrate.quad(lambda r: f * uniform * r * 2 * math.pi * r, inner, outer)[0]
    worn = Q / (2 * math.pi * (outer - inner))
    run_in = integrate.quad(lambda r: f * worn / r * r * 2 * math.pi * r, inner, outer)[0]
    assert thrust_collar_moment(f, Q, inner, outer, "new") == pytest.approx(new, rel=1e-12)
    assert thrust_collar_moment(f, Q, inner, outer, "run_in") == pytest.approx(run_in, rel=1e-12)


def test_thrust_collar_limits():
    """r1 -> r2: both states tend to f Q r (a thin ring); r1 = 0: new 2/3 f Q r2, run-in 1/2 f Q r2."""
    f, Q, r = 0.1, 1000.0, 0.05
    for state in ("new", "run_in"):
        assert thrust_collar_moment(f, Q, r * (1 - 1e-7), r, state) == pytest.approx(f * Q * r, rel=1e-6)
    assert thrust_collar_moment(f, Q, 0.0, r, "new") == pytest.approx(2 / 3 * f * Q * r, rel=1e-15)
    assert thrust_collar_moment(f, Q, 0.0, r, "run_in") == pytest.approx(0.5 * f * Q * r, rel=1e-15)


# ----------------------------------------------------------------------------------------------
# the implicit equation, energy and closed forms

COLLAR = {"inner_radius": 0.02, "outer_radius": 0.04, "axial_load": 1000.0, "state": "run_in"}


def collar_machine(omega: float = 10.0, duration: float = 2.0, **machine) -> dict:
    return {
        "machine": {"inertia": 0.5, "joint_friction": {"coefficient": 0.1, "thrust_collar": COLLAR}, **machine},
        "scenario": {"initial": {"omega": omega}, "duration": duration},
    }


def test_thrust_collar_run_down_in_closed_form_time_then_rest():
    """Constant friction moment M = f Q (r1 + r2)/2 = 3 N m: the machine stops at t = J omega0 / M = 5/3 s
    after phi = J omega0^2 / (2 M), and stays there (omega exactly 0) to the end."""
    model = model_of(collar_machine())
    trajectory = simulate_complete(model)
    stop_time = 0.5 * 10.0 / 3.0
    assert [name for _, name in trajectory.events] == ["crank stops"]
    assert trajectory.events[0][0] == pytest.approx(stop_time, abs=1e-9)
    phi, omega = trajectory(np.array([1.0, stop_time + 0.01, 2.0]))
    assert omega[0] == pytest.approx(10.0 - 3.0 / 0.5 * 1.0, rel=1e-10)
    assert omega[1] == omega[2] == 0.0
    assert phi[1] == phi[2] == pytest.approx(0.5 * 100.0 / (2 * 3.0), rel=1e-9)
    columns = model.columns(np.array([1.0]), trajectory(np.array([1.0])))
    assert columns["M_joint_friction"][0] == pytest.approx(-3.0, rel=1e-12)
    assert columns["friction_thrust_collar"][0] == pytest.approx(3.0, rel=1e-12)


def test_crank_bearing_carrying_the_crank_weight_runs_down_in_closed_form_time():
    """A crank–slider whose only mass is a crank centred on its axis (crank_cg = 0), massless rod and slider:
    the crank bearing carries the weight m1 g whatever the motion, so M_f = (pi/2) f' r m1 g (new fit) is
    constant and the constant-J machine stops at t = J omega0 / M_f."""
    m1, r, f, J, omega0 = 20.0, 0.03, 0.2, 0.05, 30.0
    data = {
        "machine": {
            "inertia": J,
            "gravity": [0.0, -9.81],
            "mechanism": {"type": "crank_slider", "crank": 0.05, "rod": 0.2, "crank_mass": m1},
            "joint_friction": {"coefficient": f, "joints": {"crank_bearing": {"radius": r, "fit": "new"}}},
        },
        "scenario": {"initial": {"omega": omega0}, "duration": 1.0},
    }
    model = model_of(data)
    trajectory = simulate_complete(model)
    moment = math.pi / 2 * f / math.sqrt(1 + f * f) * r * m1 * 9.81
    assert trajectory.events[0] == (pytest.approx(J * omega0 / moment, rel=1e-9), "crank stops")
    columns = model.columns(np.array([0.1]), trajectory(np.array([0.1])))
    assert columns["reaction_crank_bearing"][0] == pytest.approx(m1 * 9.81, rel=1e-12)
    assert columns["friction_crank_bearing"][0] == pytest.approx(moment, rel=1e-12)


def test_epsilon_solves_the_implicit_equation_with_reactions_of_that_epsilon():
    """At random states of the bundled compressor_friction: J eps = M - sign(omega) F(eps), F from the
    reactions at that very eps (recomputed from the kinetostatics), and the columns agree with the rhs."""
    model = build_model(load_scene("compressor_friction"))
    friction = model.joint_friction
    rhs = model.rhs()
    rng = np.random.default_rng(4)
    states = np.vstack([rng.uniform(0, 2 * math.pi, 50), rng.uniform(1.0, 150.0, 50)])
    columns = model.columns(np.zeros(50), states)
    for i in range(50):
        phi, omega = states[:, i]
        epsilon = rhs(0.0, states[:, i])[1]
        assert columns["epsilon"][i] == pytest.approx(epsilon, rel=1e-12, abs=1e-9)
        J = columns["J"][i]
        other = (
            columns["M_drive"][i]
            + columns["M_load"][i]
            - columns["M_joint_friction"][i]
            + columns["M_weight"][i]
            - 0.5 * columns["dJ_dphi"][i] * omega**2
        )
        force = (
            -4000.0 * (columns["x_slider"][i] - 0.2)
            - 5.0 * columns["v_slider"][i]
            + np.interp(columns["x_slider"][i], [0.15, 0.20, 0.22, 0.24, 0.25], [0.0, -300.0, -900.0, -2000.0, -2600.0])
        )
        _, _, reduced = friction.joint_values(phi, omega, epsilon, force)
        assert J * epsilon == pytest.approx(other - reduced, rel=1e-12, abs=1e-9)
        assert reduced > friction.collar


def test_joint_friction_dissipates_the_work_of_the_joint_moments():
    """Over a run of compressor_friction: the energy balance closes with the friction's work, and that work
    equals -integral sum_j M_fj |omega_rel,j| dt (+ guide f |N| |v| + collar |omega|) with the relative speeds
    from differences of the link angles and slider positions of the closed-form geometry."""
    model = build_model(load_scene("compressor_friction", ["scenario.duration=0.3"]))
    trajectory = simulate_complete(model)
    balance = energy_balance(model, trajectory)
    assert abs(balance.relative_residual) < 1e-6
    dissipated = -balance.works["joint_friction"]
    assert dissipated > 0.05 * balance.works["drive"]
    t = np.linspace(0.0, 0.3, 15001)
    columns = model.columns(t, trajectory(t))
    R, l = 0.05, 0.20
    phi = columns["phi"]
    x = R * np.cos(phi) + np.sqrt(l**2 - (R * np.sin(phi)) ** 2)
    theta = np.unwrap(np.arctan2(-R * np.sin(phi), x - R * np.cos(phi)))
    omega, omega_rod, v = columns["omega"], np.gradient(theta, t), np.gradient(x, t)
    power = (
        columns["friction_crank_bearing"] * np.abs(omega)
        + columns["friction_crank_pin"] * np.abs(omega - omega_rod)
        + columns["friction_wrist_pin"] * np.abs(omega_rod)
        + columns["friction_guide"] * np.abs(v)
        + columns["friction_thrust_collar"] * np.abs(omega)
    )
    assert integrate.trapezoid(power, t) == pytest.approx(dissipated, rel=2e-5)
    assert np.all(columns["M_joint_friction"] * omega <= 0.0)


def test_machine_below_break_away_stays_at_rest_and_above_it_starts():
    """At rest the friction holds any moment up to F(0): a drive of 0.9 F(0) leaves phi and omega exactly as
    they were; 1.1 F(0) starts the machine with epsilon = 0.1 F(0) / J. F(0) of a crank–slider at rest in
    gravity comes from its static reactions: the collar's 3 N m plus the crank bearing's friction under the
    crank's weight (at phi = 0 the massless rod carries nothing: the slider's weight rests on the guide)."""
    base = {
        "machine": {
            "inertia": 0.2,
            "gravity": [0.0, -9.81],
            "mechanism": {"type": "crank_slider", "crank": 0.05, "rod": 0.2, "crank_mass": 30.0, "slider_mass": 2.0},
            "joint_friction": {
                "coefficient": 0.1,
                "thrust_collar": COLLAR,
                "joints": {"crank_bearing": {"radius": 0.03}},
            },
        },
        "scenario": {"initial": {"phi": 0.0, "omega": 0.0}, "duration": 0.5},
    }
    probe = model_of(base)
    at_rest = probe.joint_friction.joint_values(0.0, 0.0, 0.0, 0.0)[2]
    assert at_rest == pytest.approx(3.0 + 0.1 / math.sqrt(1.01) * 0.03 * 30.0 * 9.81, rel=1e-12)
    held = model_of({**base, "machine": {**base["machine"], "drive": {"type": "constant", "torque": 0.9 * at_rest}}})
    trajectory = simulate_complete(held)
    assert np.all(trajectory(np.linspace(0, 0.5, 11)) == 0.0)
    assert trajectory.events == []
    moving = model_of({**base, "machine": {**base["machine"], "drive": {"type": "constant", "torque": 1.1 * at_rest}}})
    assert moving.rhs()(0.0, np.array([0.0, 0.0]))[1] == pytest.approx(0.1 * at_rest / 0.2, rel=1e-9)
    trajectory = simulate_complete(moving)
    assert trajectory.events[0][1] == "crank starts" and trajectory(np.array([0.5]))[1, 0] > 0.0


def test_self_locking_machine_is_refused_with_a_clear_message(capsys):
    """Journals so large that the friction grows with epsilon faster than the inertia: exit 2, the key named."""
    code, _, err = run_cli(
        capsys,
        "simulate",
        "compressor_friction",
        "--set",
        "machine.inertia=0.0",
        "--set",
        "machine.flywheel=null",
        "--set",
        "machine.joint_friction.coefficient=1.0",
        "--set",
        "machine.joint_friction.joints.crank_pin.radius=0.045",
        "--set",
        "machine.joint_friction.joints.wrist_pin.radius=0.045",
    )
    assert code == 2
    assert "machine.joint_friction: the machine self-locks at phi =" in err and "expected smaller joint radii" in err


@pytest.mark.parametrize(
    "setting, message",
    [
        ("machine.joint_friction.joints.rocker_pin={radius: 0.01}", "does not have; expected some of ['crank_bearing'"),
        ("machine.joint_friction.joints.crank_pin.fit=loose", "'clearance', 'new' or 'run_in'"),
        ("machine.joint_friction.thrust_collar.inner_radius=0.05", "inner_radius = 0.05 m must be smaller"),
        ("machine.joint_friction={coefficient: 0.1}", "no joints, no guide and no thrust_collar"),
    ],
)
def test_bad_joint_friction_keys_name_key_value_and_expectation(capsys, setting, message):
    code, _, err = run_cli(capsys, "describe", "compressor_friction", "--set", setting)
    assert code == 2 and message in err, err


def test_guide_needs_a_crank_slider(capsys):
    code, _, err = run_cli(
        capsys, "describe", "four_bar_rocker", "--set", "machine.joint_friction={coefficient: 0.1, guide: 0.1}"
    )
    assert code == 2 and "only a crank_slider has a guide" in err, err


ENGINE_JOINT_FRICTION = (
    "machine.joint_friction={coefficient: 0.02, joints: {crank_bearing: {radius: 0.025, fit: "
    "run_in}, crank_pin: {radius: 0.02, fit: run_in}}, guide: 0.02}"
)
COLLAR_ONLY = (
    "machine.joint_friction={coefficient: 0.1, thrust_collar: {inner_radius: 0.01, outer_radius: 0.02, "
    "axial_load: 100.0, state: new}}"
)


@pytest.mark.parametrize("name", ["walking_beam", "engine_inline4"])
def test_mechanisms_without_kinetostatics_take_a_thrust_collar_but_no_journals(capsys, name):
    """The walking beam and a multi-cylinder crank-slider have no kinetostatics: their journals are refused with
    a message, a thrust collar alone is the constant moment 2/3 f Q (r2^3 - r1^3) / (r2^2 - r1^2)."""
    code, _, err = run_cli(
        capsys,
        "describe",
        name,
        "--set",
        "machine.joint_friction={coefficient: 0.1, joints: {crank_bearing: {radius: 0.01, fit: new}}}",
    )
    assert code == 2 and "joint reactions of a" in err and "only a thrust_collar can have friction" in err, err
    model = build_model(load_scene(name, [COLLAR_ONLY, "scenario.duration=0.02"]))
    trajectory = simulate_complete(model)
    moment = model.columns(np.array([trajectory.t_end]), trajectory(np.array([trajectory.t_end])))["M_joint_friction"]
    assert moment[0] == pytest.approx(-2.0 / 3.0 * 0.1 * 100.0 * (0.02**3 - 0.01**3) / (0.02**2 - 0.01**2), rel=1e-12)


def test_governor_stepper_of_a_machine_with_joint_friction_holds_the_crank_speed():
    """The co-simulation's governor (the ROS governor node's stepper) integrates the governor alone with the
    crank speed held: a machine's joint friction must not act there, so its governor answers exactly as the
    frictionless machine's does."""
    frictionless = build_model(load_scene("engine_direct", ["scenario.load_events=[]"]))
    with_friction = build_model(load_scene("engine_direct", ["scenario.load_events=[]", ENGINE_JOINT_FRICTION]))
    answers = []
    for model in (frictionless, with_friction):
        stepper = GovernorStepper(model)
        answers.append([stepper.answer(0.01 * k, 224.17 + 2.0 * k) for k in range(20)] + list(stepper.state))
    assert answers[0] == answers[1]


# ----------------------------------------------------------------------------------------------
# scenes without joint friction


@pytest.mark.parametrize(
    "name, overrides, expected",
    [
        ("compressor", ["scenario.duration=0.3"], ["0x1.1e97e20db19b5p+3", "0x1.9fed43e1f9d82p+5"]),
        (
            "engine_direct",
            ["scenario.duration=0.1", "scenario.load_events=[]"],
            ["0x1.643cad47dec89p+4", "0x1.c3df427415441p+7", "0x1.8cd15065eee4ap-2", "-0x1.ae450b2b7a6b0p-11"],
        ),
    ],
)
def test_scenes_without_joint_friction_run_bit_for_bit_as_before(name, overrides, expected):
    """The final state of short runs, bit for bit as main (9c13bc8) computed it before joint friction existed,
    and their right-hand side is the frictionless closure itself. (Both pinned again when the knots of tables became
    switches: engine_direct's indicator diagram moved its state by 1e-7 relative at rtol 1e-8, the
    compressor's slider table by 2.4e-8 at rtol 1e-9, the kinks' old errors — test_table_knots.py and
    test_slider_table_breakpoints.py check the new runs against references restarted at every knot; and in their last
    bits when the reference path took its switch angles from the model's switch grid, rounded to 1e-12 rad, as the
    fast path does; and when every mechanism became a linkage run by generated code: the crank–slider's J
    and its derivatives from the linkage's closed forms differ in their last bits, the final states by 2e-16 to 4e-16
    relative, the governor's servo, crossing zero, by 1.3e-12 of its size; and when the solvers began to carry the
    crank's phase across their restarts instead of reading it back off phi, docs/hard_cases.md "Long runs": a
    restart on a switch now starts exactly on its angle, not an ulp of phi beside it, and the final states moved by 1
    to 2 units in the last place, the servo by 1.1e-12 of its size; and when the governor's sensor became one
    function both paths run, governors/sensor.py: phi by 1 unit in the last place, omega by 4, the sleeve's rate,
    near zero, by 3e-12 of its size.)"""
    model = build_model(load_scene(name, overrides))
    rhs = model.rhs(None, None, model.initial_mode(model.initial_state()))
    assert model.joint_friction is None and rhs.__qualname__ == "MachineModel._right_hand_side.<locals>.machine"
    trajectory = simulate_complete(model)
    assert [float(value).hex() for value in trajectory(np.array([trajectory.t_end]))[:, 0]] == expected
    assert "M_joint_friction" not in model.columns(np.array([0.0]), model.initial_state()[:, None])


def test_describe_lists_joint_friction(capsys):
    code, out, _ = run_cli(capsys, "describe", "compressor_friction")
    assert code == 0
    assert (
        "joint friction (kinetostatics per right-hand side; epsilon solved from the implicit equation): f = 0.05: "
        "thrust collar 0.275 N m (run_in), crank_bearing rho = 1.272 mm (run_in)"
    ) in out


# ----------------------------------------------------------------------------------------------
# joint friction on a general linkage (its reactions from the kinetostatics by groups)


def test_slotted_lever_friction_is_that_of_its_reactions_and_sliding_speeds():
    """The shaper with journals at O2, A, O4 and guide friction in its slot S and the ram's guide G: at constant
    speed (epsilon = 0) the friction reduced to the crank is sum rho_j |R_j| |k_j| + f |N_P| |s_P'| with the
    reactions of the kinetostatics by groups (linkage.make_kinetostatics: a revolute joint's force, a prismatic
    joint's normal force), the relative angular speeds k_j from differences of the link angles and the sliding
    speeds s' from differences of the block's distance from O4 along the lever and of the ram's x. The lever's own
    coordinates are moved 0.05 m off its slot line (the same mechanism), so that the guide's turning, the term
    -theta_g' Im((P_s - r_g) conj w) of the sliding speed, counts."""
    from mech_regulator.mechanisms import mechanism_geometry
    from mech_regulator.mechanisms.linkage import make_kinetostatics, solve

    f, radii = 0.1, {"O2": 0.02, "A": 0.01, "O4": 0.015}
    data = load_scene("shaper").model_dump(exclude_none=True)
    lever = data["machine"]["mechanism"]["links"]["lever"]
    lever["points"] = {name: [x, y + 0.05] for name, (x, y) in lever["points"].items()}
    lever["centre"] = [lever["centre"][0], lever["centre"][1] + 0.05]
    data["machine"]["joint_friction"] = {
        "coefficient": f,
        "guide": 0.12,
        "journals": {key: {"radius": value} for key, value in radii.items()},
    }
    model = model_of(data)
    friction = model.joint_friction
    assert set(friction.names) == {"O2", "A", "O4", "S", "G"}
    core, structure = mechanism_geometry(model.scene.machine.mechanism)
    loads = make_kinetostatics(core, structure, (0.0, -9.81))
    h, omega, force = 1e-6, 6.0, -700.0

    def geometry(phi):
        poses = solve(core, structure, phi, derivatives=False)
        A = poses["crank"][0] + 0.1 * cmath.exp(1j * phi)
        return (
            {"crank": phi, "block": poses["block"][1], "lever": poses["lever"][1]},
            abs(A - complex(0.0, -0.3)),
            poses["ram"][0].real,
        )

    for phi in np.linspace(0.0, 2.0 * math.pi, 9)[:-1] + 0.2:
        (angles_1, s_1, x_1), (angles_2, s_2, x_2) = geometry(phi - h), geometry(phi + h)
        rate = {name: (angles_2[name] - angles_1[name]) / (2 * h) for name in angles_1}
        k = {"O2": rate["crank"], "A": rate["crank"] - rate["block"], "O4": rate["lever"]}
        reactions = loads(phi, omega, 0.0, force).reactions
        expected = sum(friction_circle_radius(f, radii[j], "clearance") * abs(reactions[j]) * abs(k[j]) for j in k)
        expected += 0.12 * (abs(reactions["S"][0]) * abs(s_2 - s_1) + abs(reactions["G"][0]) * abs(x_2 - x_1)) / (2 * h)
        assert friction.joint_values(phi, omega, 0.0, force)[2] == pytest.approx(expected, rel=1e-8)


def test_linkage_journals_must_name_its_revolute_joints(capsys):
    code, _, err = run_cli(
        capsys,
        "describe",
        "shaper",
        "--set",
        "machine.joint_friction={coefficient: 0.1, journals: {S: {radius: 0.01}, Q: {radius: 0.01}}}",
    )
    assert (
        code == 2
        and "joint_friction.journals names ['S', 'Q'], which are not revolute joints of the linkage; "
        "expected some of ['O2', 'A', 'O4', 'B', 'C']"
        in err
    ), err
    code, _, err = run_cli(
        capsys,
        "describe",
        "shaper",
        "--set",
        "machine.joint_friction={coefficient: 0.1, joints: {crank_pin: {radius: 0.01}}}",
    )
    assert code == 2 and "a linkage's journals are joint_friction.journals" in err, err
    code, _, err = run_cli(
        capsys,
        "describe",
        "four_bar_rocker",
        "--set",
        "machine.joint_friction={coefficient: 0.1, journals: {A: {radius: 0.01}}}",
    )
    assert code == 2 and "journals by joint name are a linkage's" in err, err
