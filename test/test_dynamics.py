"""Simulations against closed forms of the equation of motion

    J(phi) domega/dt + 1/2 J'(phi) omega^2 = M_d + M_c

(constant and variable J, omega-dependent moments, load events in time, weights, springs, an engine's
indicator diagram, the lathe of source 000, energy balance and steady-state detection).

Tolerance conventions: EPS is the double-precision unit round-off. Where the exact solution is a
polynomial in t of degree <= 3, every Runge-Kutta method of order >= 3 reproduces it to round-off,
so tolerances there are ~1e-10 (round-off accumulated over ~1e3 steps, with margin); elsewhere the
tolerance is a small multiple of the solver's rtol/atol (global error ~ a few rtol per unit time for
these non-stiff, non-chaotic problems) or of the truncation error of RK4 (~h^4).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate, optimize
from support import simulate_complete

from mech_regulator.analysis import analyse_steady_state, energy_balance, energy_swing, flywheel_for_constant_inertia
from mech_regulator.model import build_model
from mech_regulator.scene import load_scene, validate_scene
from mech_regulator.solvers import simulate

ADAPTIVE = ["DOP853", "RK45", "Radau", "LSODA"]
METHODS = ADAPTIVE + ["RK4"]


def make_model(machine: dict, scenario: dict, solver: dict | None = None):
    return build_model(validate_scene({"machine": machine, "scenario": scenario, "solver": solver or {}}))


def solver_settings(method: str, rtol: float = 1e-11, atol: float = 1e-12, step: float = 1e-3) -> dict:
    if method == "RK4":
        return {"method": "RK4", "step": step}
    return {"method": method, "rtol": rtol, "atol": atol}


# ---------------------------------------------------------------------------------------------
# 1-3: constant J, closed-form speed laws


@pytest.mark.parametrize("method", METHODS)
def test_constant_moments_give_uniform_acceleration(method):
    J, M_d, M_c, omega0, phi0 = 2.0, 10.0, 4.0, 3.0, 0.5
    model = make_model(
        {"inertia": J, "drive": {"type": "constant", "torque": M_d}, "loads": [{"type": "constant", "torque": M_c}]},
        {"initial": {"phi": phi0, "omega": omega0}, "duration": 2.0},
        solver_settings(method, step=0.01),
    )
    tr = simulate_complete(model)
    t = np.linspace(0.0, 2.0, 201)
    phi, omega = tr(t)
    eps = (M_d - M_c) / J
    # quadratic phi(t): reproduced by every RK of order >= 2 to round-off; the implicit / multistep
    # methods (Radau's Newton iteration, LSODA's order-1 start) are only exact to their tolerances
    # (rtol 1e-11, atol 1e-12 on values ~10: 1e-8 leaves margin for the accumulation over 2 s).
    # Explicit RK: round-off over <= 200 steps of values ~10, 1e-11.
    tol = 1e-11 if method in ("DOP853", "RK45", "RK4") else 1e-8
    np.testing.assert_allclose(omega, omega0 + eps * t, rtol=0, atol=tol)
    np.testing.assert_allclose(phi, phi0 + omega0 * t + 0.5 * eps * t**2, rtol=0, atol=tol)


@pytest.mark.parametrize("method", METHODS)
def test_linear_motor_with_viscous_load_exponential_run_up(method):
    J, M0, w0, c = 0.5, 60.0, 150.0, 0.3
    denominator = M0 / w0 + c
    omega_ss, tau = M0 / denominator, J / denominator  # 85.714..., 0.714... s
    duration = 3.0
    model = make_model(
        {
            "inertia": J,
            "drive": {"type": "linear_motor", "stall_torque": M0, "no_load_speed": w0},
            "loads": [{"type": "viscous", "coefficient": c}],
        },
        {"initial": {"phi": 0.0, "omega": 0.0}, "duration": duration},
        solver_settings(method, rtol=1e-10, atol=1e-10, step=1e-3),
    )
    tr = simulate_complete(model)
    t = np.linspace(0.0, duration, 301)
    phi, omega = tr(t)
    omega_exact = omega_ss * (1.0 - np.exp(-t / tau))
    phi_exact = omega_ss * (t - tau * (1.0 - np.exp(-t / tau)))
    # global error ~ few x rtol x magnitude (~100 rad/s, ~200 rad) for the adaptive methods; RK4 with
    # h = 1e-3, tau ~ 0.7: truncation ~ (h/tau)^4 x 100 ~ 1e-10 -- 1e-6 absolute catches any wrong term.
    np.testing.assert_allclose(omega, omega_exact, rtol=0, atol=1e-6)
    np.testing.assert_allclose(phi, phi_exact, rtol=0, atol=1e-6)


@pytest.mark.parametrize("method", METHODS)
def test_fan_alone_hyperbolic_run_down(method):
    J, k, omega0 = 0.4, 2e-3, 120.0
    duration = 4.0
    model = make_model(
        {"inertia": J, "loads": [{"type": "fan", "coefficient": k}]},
        {"initial": {"phi": 0.0, "omega": omega0}, "duration": duration},
        solver_settings(method, rtol=1e-10, atol=1e-10, step=1e-3),
    )
    tr = simulate_complete(model)
    t = np.linspace(0.0, duration, 301)
    phi, omega = tr(t)
    a = k * omega0 / J  # 0.6 1/s
    # as above: a few rtol x magnitude (<= 120 rad/s, ~300 rad); RK4 (a h)^4 x omega0 ~ 1e-11.
    np.testing.assert_allclose(omega, omega0 / (1.0 + a * t), rtol=0, atol=1e-6)
    np.testing.assert_allclose(phi, J / k * np.log1p(a * t), rtol=0, atol=1e-6)


# ---------------------------------------------------------------------------------------------
# 4: external load events (breakpoints in time)


def _events_closed_form(t, J, M_d, omega0, t1, L1, t2, ramp, L2):
    """omega(t), phi(t) for M = M_d - L(t), L = 0 before t1, L1 on [t1, t2), a ramp to L2 on [t2, t2 + ramp)."""
    t = np.asarray(t, dtype=float)
    omega = np.empty_like(t)
    phi = np.empty_like(t)
    t3 = t2 + ramp
    # piece 0
    e0 = M_d / J
    w1, p1 = omega0 + e0 * t1, omega0 * t1 + 0.5 * e0 * t1**2
    e1 = (M_d - L1) / J
    w2, p2 = w1 + e1 * (t2 - t1), p1 + w1 * (t2 - t1) + 0.5 * e1 * (t2 - t1) ** 2
    s = (L2 - L1) / ramp  # load slope on the ramp [N m/s]

    def ramp_state(u):  # u = t - t2 on the ramp
        return (w2 + e1 * u - s * u**2 / (2 * J), p2 + w2 * u + 0.5 * e1 * u**2 - s * u**3 / (6 * J))

    w3, p3 = ramp_state(ramp)
    e3 = (M_d - L2) / J
    for i, ti in enumerate(t):
        if ti < t1:
            omega[i], phi[i] = omega0 + e0 * ti, omega0 * ti + 0.5 * e0 * ti**2
        elif ti < t2:
            u = ti - t1
            omega[i], phi[i] = w1 + e1 * u, p1 + w1 * u + 0.5 * e1 * u**2
        elif ti < t3:
            omega[i], phi[i] = ramp_state(ti - t2)
        else:
            u = ti - t3
            omega[i], phi[i] = w3 + e3 * u, p3 + w3 * u + 0.5 * e3 * u**2
    return omega, phi


@pytest.mark.parametrize("method", ["DOP853", "RK45", "RK4"])
@pytest.mark.parametrize("t1,t2", [(1.0, 2.0), (1.2345678, 2.3456789)], ids=["on-grid", "mid-step"])
def test_load_step_and_ramp_piecewise_closed_form(method, t1, t2):
    J, M_d, omega0, L1, ramp, L2, duration = 2.0, 10.0, 5.0, 4.0, 0.75, 16.0, 4.0
    model = make_model(
        {"inertia": J, "drive": {"type": "constant", "torque": M_d}},
        {
            "initial": {"omega": omega0},
            "duration": duration,
            "load_events": [{"time": t1, "torque": L1}, {"time": t2, "torque": L2, "ramp": ramp}],
        },
        # RK4 step 0.1 does not divide the "mid-step" event times: the segments must split there
        solver_settings(method, rtol=1e-6, atol=1e-8, step=0.1),
    )
    tr = simulate_complete(model)
    # the breakpoints t1, t2, t2 + ramp are included together with points just either side of them
    t = np.unique(
        np.concatenate(
            [np.linspace(0.0, duration, 401), [t1 - 1e-9, t1, t1 + 1e-9, t2 - 1e-9, t2, t2 + 1e-9, t2 + ramp]]
        )
    )
    phi, omega = tr(t)
    omega_exact, phi_exact = _events_closed_form(t, J, M_d, omega0, t1, L1, t2, ramp, L2)
    # exact solution is piecewise polynomial of degree <= 3 in t and the rhs is polynomial in t: every RK
    # of order >= 3 reproduces it to round-off *only if* no step straddles a breakpoint (a straddling step
    # at rtol 1e-6 would give errors ~1e-6). 1e-10 = round-off over ~1e3 steps with margin.
    np.testing.assert_allclose(omega, omega_exact, rtol=0, atol=1e-10)
    np.testing.assert_allclose(phi, phi_exact, rtol=0, atol=1e-10)
    assert tr.stats.restarts >= 3  # one restart at each of t1, t2, t2 + ramp


# ---------------------------------------------------------------------------------------------
# 5-6: variable J, conservative systems

CRANK_SLIDER = {
    "type": "crank_slider",
    "crank": 0.08,
    "rod": 0.3,
    "offset": 0.02,
    "crank_mass": 1.5,
    "crank_cg": 0.03,
    "rod_mass": 1.2,
    "rod_cg": 0.11,
    "rod_inertia": 0.01,
    "slider_mass": 2.5,
}
FOUR_BAR = {
    "type": "four_bar",
    "crank": 0.05,
    "coupler": 0.2,
    "rocker": 0.15,
    "frame": 0.2,
    "frame_angle_deg": 10.0,
    "crank_mass": 0.5,
    "crank_cg": 0.02,
    "coupler_mass": 1.0,
    "coupler_cg": 0.08,
    "coupler_inertia": 0.004,
    "rocker_mass": 0.8,
    "rocker_cg": 0.06,
    "rocker_inertia": 0.002,
}


@pytest.mark.parametrize("method", ["DOP853", "Radau"])
def test_conservative_crank_slider_energy_and_revolution_time(method):
    omega0 = 20.0
    model = make_model(
        {"inertia": 0.02, "mechanism": CRANK_SLIDER},
        {"initial": {"phi": 0.0, "omega": omega0}, "duration": 1.0},
        solver_settings(method, rtol=1e-11, atol=1e-12),
    )
    tr = simulate_complete(model)
    t = np.linspace(0.0, 1.0, 1001)
    columns = model.columns(t, tr(t))
    E = columns["E_kinetic"]
    J0, dJ0 = model.inertia(0.0)
    E0 = 0.5 * J0 * omega0**2
    assert np.ptp(columns["J"]) > 0.1 * J0  # J really varies (the test is not trivial)
    # energy is conserved to the integration error: ~ a few rtol (1e-11) x E over the run
    np.testing.assert_allclose(E, E0, rtol=1e-8)
    # period of one revolution from the energy integral t = int dphi / omega, omega = sqrt(2 E / J(phi))
    T_quad, _ = integrate.quad(
        lambda p: math.sqrt(model.inertia(p)[0] / (2.0 * E0)), 0.0, 2.0 * math.pi, epsabs=1e-14, epsrel=1e-13, limit=200
    )
    assert T_quad < 1.0
    T_sim = optimize.brentq(lambda s: tr(s)[0] - 2.0 * math.pi, 0.0, 1.0, xtol=1e-15)
    # time error ~ rtol x T, quad to 1e-13: 1e-8 relative leaves margin
    assert T_sim == pytest.approx(T_quad, rel=1e-8)


def _crank_slider_potential(phi, m, gravity):
    """V = -sum m_k g . r_k for the crank_slider, positions from the geometry (not from the package)."""
    R, l, e = m["crank"], m["rod"], m["offset"]
    g = np.asarray(gravity)
    B = np.stack([R * np.cos(phi), R * np.sin(phi)])
    x = R * np.cos(phi) + np.sqrt(l**2 - (e - R * np.sin(phi)) ** 2)
    C = np.stack([x, np.full_like(x, e)])
    crank_cg = m["crank_cg"] / R * B
    rod_cg = B + m["rod_cg"] / l * (C - B)
    return -(m["crank_mass"] * g @ crank_cg + m["rod_mass"] * g @ rod_cg + m["slider_mass"] * g @ C)


def _four_bar_potential(phi, m, gravity):
    """V for the four-bar: C is the intersection of the circles |C - B| = b, |C - D| = c on the branch
    'open' = C to the right of the directed line D -> B (cross(B - D, C - D) < 0)."""
    a, b, c, d = m["crank"], m["coupler"], m["rocker"], m["frame"]
    th1 = math.radians(m["frame_angle_deg"])
    B = a * np.exp(1j * phi)
    D = d * np.exp(1j * th1)
    p = B - D
    f = np.abs(p)
    u = p / f
    along = (f**2 + c**2 - b**2) / (2 * f)  # from D along D->B
    across = np.sqrt(c**2 - along**2)
    C1 = D + u * (along + 1j * across)  # left of D->B
    C2 = D + u * (along - 1j * across)  # right of D->B
    C = C2
    assert np.all(np.imag(np.conj(p) * (C - D)) < 0)
    assert np.all(np.abs(np.abs(C1 - B) - b) < 1e-12)
    S2 = m["crank_cg"] / a * B
    S3 = B + m["coupler_cg"] * (C - B) / b
    S4 = D + m["rocker_cg"] * (C - D) / c
    g = complex(*gravity)
    dot = lambda r: (np.conj(g) * r).real  # noqa: E731  g . r
    return -(m["crank_mass"] * dot(S2) + m["coupler_mass"] * dot(S3) + m["rocker_mass"] * dot(S4))


@pytest.mark.parametrize(
    "mechanism,potential",
    [(CRANK_SLIDER, _crank_slider_potential), (FOUR_BAR, _four_bar_potential)],
    ids=["crank_slider", "four_bar"],
)
@pytest.mark.parametrize("gravity", [[0.0, -9.81], [4.0, -9.0]], ids=["down", "tilted"])
def test_gravity_kinetic_plus_potential_is_conserved(mechanism, potential, gravity):
    omega0 = 20.0
    model = make_model(
        {"inertia": 0.01, "gravity": gravity, "mechanism": mechanism},
        {"initial": {"phi": 0.3, "omega": omega0}, "duration": 1.5},
        {"method": "DOP853", "rtol": 1e-11, "atol": 1e-12},
    )
    tr = simulate_complete(model)
    t = np.linspace(0.0, 1.5, 1501)
    y = tr(t)
    columns = model.columns(t, y)
    assert np.all(y[1] > 0) and y[0, -1] > 4 * math.pi  # it turns over several times
    V = potential(y[0], mechanism, gravity)
    assert np.ptp(V) > 0.05 * columns["E_kinetic"][0]  # the weights matter (a sign error shows)
    total = columns["E_kinetic"] + V
    # conserved to the integration error (rtol 1e-11, ~10 turns): 1e-8 of the kinetic energy; a wrong sign
    # of the weight moment leaves an error ~ 2 ptp(V) > 0.1 E_kin
    np.testing.assert_allclose(total, total[0], rtol=0, atol=1e-8 * columns["E_kinetic"][0])


def test_slider_spring_kinetic_plus_elastic_is_conserved():
    k, x0, omega0 = 3000.0, 0.27, 15.0
    mechanism = {
        key: CRANK_SLIDER[key]
        for key in ("type", "crank", "rod", "offset", "rod_mass", "rod_cg", "rod_inertia", "slider_mass")
    }
    model = make_model(
        {
            "inertia": 0.05,
            "mechanism": mechanism,
            "loads": [{"type": "slider_spring", "stiffness": k, "free_position": x0}],
        },
        {"initial": {"omega": omega0}, "duration": 1.5},
        {"method": "DOP853", "rtol": 1e-11, "atol": 1e-12},
    )
    tr = simulate_complete(model)
    t = np.linspace(0.0, 1.5, 1501)
    y = tr(t)
    columns = model.columns(t, y)
    R, l, e = mechanism["crank"], mechanism["rod"], mechanism["offset"]
    x = R * np.cos(y[0]) + np.sqrt(l**2 - (e - R * np.sin(y[0])) ** 2)  # independent of the package
    np.testing.assert_allclose(columns["x_slider"], x, rtol=0, atol=1e-14)
    elastic = 0.5 * k * (x - x0) ** 2
    assert np.ptp(elastic) > 0.05 * columns["E_kinetic"][0]
    total = columns["E_kinetic"] + elastic
    # as above: integration error ~ rtol per turn; a sign error in the spring moment would be ~ ptp(elastic)
    np.testing.assert_allclose(total, total[0], rtol=0, atol=1e-8 * total[0])


# ---------------------------------------------------------------------------------------------
# 7: engine drive: work of the gas over a cycle = indicated work


def test_engine_cycle_work_equals_indicated_work():
    scene = load_scene("engine")
    data = scene.model_dump(exclude_none=True)
    drive, mech = data["machine"]["drive"], data["machine"]["mechanism"]
    area = math.pi * drive["bore"] ** 2 / 4
    R, l, e = mech["crank"], mech["rod"], mech["offset"]
    phi = np.linspace(0.0, 4 * math.pi, 720 * 200 + 1)  # 0.005 deg: table knots lie on the grid
    x = R * np.cos(phi) + np.sqrt(l**2 - (e - R * np.sin(phi)) ** 2)
    V = area * (x.max() - x)
    cycle = (np.degrees(phi) + drive["phase_deg"]) % drive["cycle_deg"]
    p = np.interp(cycle, drive["angle_deg"], drive["pressure"], period=drive["cycle_deg"])
    W_indicated = float(np.sum(0.5 * (p[1:] + p[:-1]) * np.diff(V)))
    stroke = math.sqrt((l + R) ** 2 - e**2) - math.sqrt((l - R) ** 2 - e**2)
    # the scene says "IMEP about 6.6 bar": a sanity check of the test's own integral (10 %)
    assert W_indicated / (area * stroke) == pytest.approx(6.6e5, rel=0.1)

    model = build_model(scene)
    assert model.dynamic_period() == pytest.approx(4 * math.pi, rel=1e-15)
    columns = model.columns(np.zeros_like(phi), np.vstack([phi, np.full_like(phi, 200.0)]))
    W_model = float(integrate.trapezoid(columns["M_drive"], phi))
    # both are trapezoid sums of the same integral on a 0.005-deg grid with the kinks on grid points:
    # O(h^2) ~ 1e-9 relative; 1e-6 catches any wrong factor or sign
    assert W_model == pytest.approx(W_indicated, rel=1e-6)

    data["machine"]["loads"] = []
    data["scenario"]["load_events"] = []
    drive_only = build_model(validate_scene(data))
    grid, dE = energy_swing(drive_only, 200.0)
    # energy_swing: midpoint rule with 7200 intervals (0.1 deg); the pressure table has kinks every 15 deg
    # that fall on the grid, so the error is O(h^2) ~ 1e-6 relative
    assert dE[-1] == pytest.approx(W_indicated, rel=1e-5)


# ---------------------------------------------------------------------------------------------
# 8: the lathe of source 000


@pytest.fixture(scope="module")
def lathe():
    model = build_model(load_scene("lathe"))
    return model, simulate(model)


def test_lathe_energy_swing_and_flywheel_formula(lathe):
    model, _ = lathe
    F_r, omega_m, delta, J_tt = 100.0, 15.0, 1.0 / 50.0, 2.0
    grid, dE = energy_swing(model, omega_m)
    # on-off moments with switches on the grid: the midpoint rule is exact up to round-off (~1e-13)
    assert dE.max() - dE.min() == pytest.approx(math.pi * F_r / 4.0, abs=1e-9)
    assert dE[-1] == pytest.approx(0.0, abs=1e-9)  # A_d = A_c over a turn
    J_fw = flywheel_for_constant_inertia(25.0 * math.pi, omega_m, delta, J_tt)
    assert J_fw == pytest.approx(model.scene.machine.flywheel.inertia, rel=1e-14)


def test_lathe_trajectory_extremes_are_exact(lathe):
    """The trajectory itself: omega = 15.15 at phi = 0 mod 2 pi and 14.85 at 270 deg (omega_m 15, delta 1/50)."""
    model, tr = lathe
    assert tr.status == "complete", tr.message
    turns = int(tr(tr.t_end)[0] // (2 * math.pi))
    assert turns >= 20
    for k in range(turns - 3, turns):
        for angle, expected in ((0.0, 15.15), (270.0, 14.85)):
            level = 2 * math.pi * k + math.radians(angle)
            t_at = optimize.brentq(lambda s: tr(s)[0] - level, 0.0, tr.t_end, xtol=1e-15)
            # DOP853 is exact between switches (constant moment, constant J), switches located to ~1e-15 s
            assert tr(t_at)[1] == pytest.approx(expected, abs=1e-10)


def test_lathe_simulated_speed_fluctuation(lathe):
    model, tr = lathe
    assert tr.status == "complete", tr.message
    steady = analyse_steady_state(model, tr)
    assert steady.steady is True, steady.note
    # the energy-swing formula is exact for constant J and omega-independent moments: omega_max = 15.15 at
    # phi = 0, omega_min = 14.85 at 270 deg; DOP853 at rtol 1e-10 is exact between switches (omega linear in t)
    assert steady.last.omega_m == pytest.approx(15.0, abs=1e-9)
    assert steady.last.delta == pytest.approx(1.0 / 50.0, abs=1e-9)


def _lathe_work(phi):
    """integral_0^phi (M_d + M_c) dphi for the lathe, in closed form (piecewise linear in phi)."""
    F_r, M_d = 100.0, 100.0 * 5.0 / 6.0
    turns, u = np.divmod(phi, 2 * math.pi)
    cut = np.radians([0.0, 270.0, 300.0, 330.0, 360.0])
    cutting_per_turn = F_r * (cut[1] - cut[0] + cut[3] - cut[2])
    cutting = F_r * (np.clip(u, cut[0], cut[1]) - cut[0]) + F_r * (np.clip(u, cut[2], cut[3]) - cut[2])
    return M_d * phi - turns * cutting_per_turn - cutting


def test_lathe_omega_of_phi_and_switches(lathe):
    model, tr = lathe
    J = model.inertia(0.0)[0]
    omega0 = model.scene.scenario.initial.omega
    t = np.linspace(0.0, tr.t_end, 20001)
    phi, omega = tr(t)
    exact = np.sqrt(omega0**2 + 2.0 / J * _lathe_work(phi))
    # piecewise-constant moment and constant J: omega linear in t between switches, reproduced exactly by
    # DOP853; switches located by Brent to 1e-15 s: only round-off remains
    np.testing.assert_allclose(omega, exact, rtol=0, atol=1e-10)
    phi_end = phi[-1]
    angles = np.radians([0.0, 270.0, 300.0, 330.0])
    crossed = sum(math.floor((phi_end - a) / (2 * math.pi)) - math.floor((0.0 - a) / (2 * math.pi)) for a in angles)
    assert crossed > 80  # ~24 turns in 10 s at 15 rad/s
    assert tr.stats.switches == crossed


# ---------------------------------------------------------------------------------------------
# 9: energy balance


def _compressor_balance(*overrides):
    model = build_model(load_scene("compressor", ["scenario.duration=1.0", *overrides]))
    return energy_balance(model, simulate_complete(model))


def test_compressor_energy_balance_tightens_with_rtol():
    coarse = _compressor_balance("solver.rtol=1e-6", "solver.atol=1e-8")
    fine = _compressor_balance()  # the scene's rtol 1e-9, atol 1e-11
    assert abs(fine.delta_kinetic) > 1000.0  # the machine did run up (~2 kJ)
    # the residual measures the integration error: it must shrink with the tolerance (at least 10x for 1000x
    # tighter rtol; observed ~3000x)
    assert abs(fine.relative_residual) < 0.1 * abs(coarse.relative_residual)


def test_compressor_energy_balance_at_tight_tolerance():
    # Gauss-Legendre (4 nodes) per solver step on the dense output: the residual is the integration error.
    # At the scene's rtol 1e-9 it is 4.7e-10 and at rtol 1e-11 2.0e-12, since the kinks of the slider_table force at
    # x = 0.20, 0.22, 0.24 m are located as breakpoints (before: 2.5e-8 and 1.8e-9); the bounds have a margin of 4-5x.
    assert abs(_compressor_balance().relative_residual) < 2e-9
    assert abs(_compressor_balance("solver.rtol=1e-11", "solver.atol=1e-13").relative_residual) < 1e-11


# ---------------------------------------------------------------------------------------------
# 10: steady-state detection


def test_steady_state_of_linear_motor_with_viscous_load():
    J, M0, w0, c = 0.5, 60.0, 150.0, 0.3
    omega_ss = M0 / (M0 / w0 + c)
    tau = J / (M0 / w0 + c)
    model = make_model(
        {
            "inertia": J,
            "drive": {"type": "linear_motor", "stall_torque": M0, "no_load_speed": w0},
            "loads": [{"type": "viscous", "coefficient": c}],
        },
        {"duration": 25 * tau},
        {"method": "DOP853", "rtol": 1e-10, "atol": 1e-10},
    )
    tr = simulate_complete(model)
    steady = analyse_steady_state(model, tr)
    assert steady.steady is True, steady.note
    # after 25 tau, exp(-25) ~ 1e-11: the last period's speeds equal omega_ss to the solver tolerance
    assert steady.last.omega_m == pytest.approx(omega_ss, rel=1e-7)
    assert steady.last.delta < 1e-7
    assert steady.t_steady is not None and steady.t_steady > 5 * tau  # not steady during the run-up


def test_accelerating_machine_is_not_steady():
    model = make_model(
        {"inertia": 1.0, "drive": {"type": "constant", "torque": 5.0}, "loads": [{"type": "constant", "torque": 2.0}]},
        {"initial": {"omega": 10.0}, "duration": 5.0},
    )
    tr = simulate_complete(model)
    steady = analyse_steady_state(model, tr)
    assert steady.steady is False
    assert steady.periods >= 2
    assert "still changes" in steady.note
