"""Engines (docs/theory.md §4, source 002): piston kinematics, multi-cylinder crankshafts, torque curves and their
harmonics, and the `mech-regulator engine` command.

References are written here independently of the package: the slider position from the loop closure, time
derivatives by central differences, the indicator work integrated over the piston displacement, the classic
first-order inertia torque `m R^2 w^2 (lambda/4 sin phi - 1/2 sin 2phi - 3 lambda/4 sin 3phi)`, and the
potential energy of the links of every cylinder in the plane.
"""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest
from support import model_of, preset_reduced, run_cli, scene, simulate_complete

from mech_regulator.analysis.engine import harmonics, torque_curves
from mech_regulator.mechanisms.checks import refuse_unbuildable
from mech_regulator.mechanisms.crank_slider import CrankSliderGeometry, dead_centres, stroke
from mech_regulator.mechanisms.engine import (
    firing_delays,
    mean_piston_speed,
    piston_motion,
    source_approximation,
    source_dead_centre_angles,
    source_from_exact,
)
from mech_regulator.scene import SceneError, load_scene, validate_scene

TURN = np.arange(720) * (2.0 * math.pi / 720)  # 0.5 deg over one turn


def slider_x(phi, R, l, e):
    """Independent piston position: loop closure of the crank (pin R e^{i phi}) and the rod to the line y = e."""
    return R * math.cos(phi) + math.sqrt(l * l - (e - R * math.sin(phi)) ** 2)


def approximation_errors(R, l, e, omega):
    """Largest |exact - source 002's approximation| of x, v, j over a turn (in the source's convention)."""
    exact = np.array([source_from_exact(piston_motion(p, omega, R, l, e), R, l, e) for p in TURN])
    approximate = np.array([source_approximation(p, omega, R, l, e) for p in TURN])
    return np.abs(exact - approximate).max(axis=0)


# ----------------------------------------------------------------------------------------------
# 1. Piston kinematics


@pytest.mark.parametrize("R, l, e", [(0.04, 0.14, 0.0), (0.05, 0.2, 0.012), (0.05, 0.2, -0.02)])
def test_exact_velocity_and_acceleration_are_time_derivatives_of_x(R, l, e):
    """v and a of piston_motion against central differences in time of the independent x along
    phi(t) = phi0 + omega t + epsilon t^2 / 2 (so the x' epsilon term of a is checked too)."""
    omega, epsilon, h = 200.0, 3.0e4, 1e-6
    for phi0 in (0.3, 1.9, 4.0):

        def x(t, phi0=phi0):
            return slider_x(phi0 + omega * t + 0.5 * epsilon * t * t, R, l, e)

        motion = piston_motion(phi0, omega, R, l, e, epsilon)
        assert motion.x == pytest.approx(x(0.0), abs=1e-15)
        # truncation h^2/6 |x'''| ~ 1e-12 R w^3 h^2 ~ 1e-7 m/s; rounding EPS l / h ~ 3e-11 m/s
        assert motion.v == pytest.approx((x(h) - x(-h)) / (2 * h), abs=1e-6)
        # second difference: rounding 4 EPS l / h^2 ~ 1e-4 m/s^2 against a ~ R w^2 = 2e3 m/s^2
        assert motion.a == pytest.approx((x(h) - 2 * x(0.0) + x(-h)) / h**2, abs=2e-3 * R * omega**2)
    # epsilon really enters (the check above could not tell a missing x' epsilon otherwise)
    assert piston_motion(1.0, omega, R, l, e, epsilon).a != piston_motion(1.0, omega, R, l, e).a


def test_source_approximation_error_shrinks_like_lambda_cubed_central_and_squared_offset():
    """Source 002's formulas are first order in lambda: the neglected terms of x, v, j are O(lambda^3) for a
    central engine; with an offset at fixed k, x also neglects R lambda^2 k^2 / 2 (the constant of the top dead
    centre), so its error is O(lambda^2), while v and j stay O(lambda^3). Halving lambda divides the error by 8
    (or 4): the measured orders are log2 of the ratios."""
    R, omega = 0.05, 10.0
    for k, expected_orders in ((0.0, (3, 3, 3)), (0.3, (2, 3, 3))):
        errors = [approximation_errors(R, R / lam, k * R, omega) for lam in (0.05, 0.025)]
        orders = np.log2(errors[0] / errors[1])
        # measured: 3.005 3.006 3.008 (central); 2.34 3.01 3.01 (offset: R lambda^2 k^2/2 + O(lambda^3))
        assert orders == pytest.approx(expected_orders, abs=0.4)
        # and the size: central x error ~ R lambda^3 / 8 (the next term of the expansion)
        if k == 0.0:
            assert errors[0][0] == pytest.approx(R * 0.05**3 / 8, rel=0.02)


def test_offset_acceleration_sign_corrected():
    """The source prints j ~ R w^2 (cos a + lambda cos 2a - lambda k sin a); the time derivative of its own v
    (1-14) has + lambda k sin a. Ours is the time derivative of the approximate v, and it is closer to the exact
    acceleration than the printed form by about 2 lambda k R w^2."""
    R, l, e, omega = 0.05, 0.25, 0.02, 150.0
    lam, k = R / l, e / R
    h = 1e-7
    for alpha in (0.4, math.pi / 2, 2.5, 4.4):
        j = source_approximation(alpha, omega, R, l, e).a
        dv = (
            source_approximation(alpha + omega * h, omega, R, l, e).v
            - source_approximation(alpha - omega * h, omega, R, l, e).v
        ) / (2 * h)
        assert j == pytest.approx(dv, abs=1e-6 * R * omega**2)
    alpha = math.pi / 2
    exact = source_from_exact(piston_motion(alpha, omega, R, l, e), R, l, e).a
    ours = source_approximation(alpha, omega, R, l, e).a
    printed = ours - 2 * lam * k * R * omega**2 * math.sin(alpha)
    assert abs(ours - exact) < 0.2 * abs(printed - exact)
    assert abs(printed - exact) == pytest.approx(2 * lam * k * R * omega**2, rel=0.2)


@pytest.mark.parametrize("R, l, e", [(0.04, 0.14, 0.0), (0.05, 0.2, 0.03), (0.05, 0.2, -0.03)])
def test_dead_centres_stroke_and_mean_piston_speed(R, l, e):
    """Source's alpha1, alpha2 map to our dead centres phi = alpha1, pi + alpha2; there the piston stands still
    and x is extreme; stroke = x_max - x_min; mean |v| over a turn = S n / 30."""
    alpha1, alpha2 = source_dead_centre_angles(R, l, e)
    top, bottom = dead_centres(R, l, e)
    assert top == pytest.approx(alpha1, abs=1e-15)
    assert bottom == pytest.approx(math.pi + alpha2, abs=1e-15)
    omega = 100.0
    assert abs(piston_motion(top, omega, R, l, e).v) < 1e-12
    assert abs(piston_motion(bottom, omega, R, l, e).v) < 1e-12
    fine = np.linspace(0.0, 2 * math.pi, 20001)
    xs = np.array([slider_x(p, R, l, e) for p in fine])
    # a grid misses a quadratic extremum by at most |x''| dphi^2 / 8 ~ 0.05 * 1e-7 m
    assert xs.max() == pytest.approx(slider_x(top, R, l, e), abs=1e-8)
    assert xs.min() == pytest.approx(slider_x(bottom, R, l, e), abs=1e-8)
    assert stroke(R, l, e) == pytest.approx(xs.max() - xs.min(), abs=2e-8)
    assert source_from_exact(piston_motion(top, omega, R, l, e), R, l, e).x == pytest.approx(0.0, abs=1e-15)
    speeds = np.array([abs(piston_motion(p, omega, R, l, e).v) for p in fine[:-1]])
    n = omega * 30 / math.pi
    assert mean_piston_speed(stroke(R, l, e), omega) == pytest.approx(stroke(R, l, e) * n / 30, rel=1e-15)
    # |v| has kinks at the dead centres: the rectangle rule errs by O(dphi^2) there
    assert speeds.mean() == pytest.approx(mean_piston_speed(stroke(R, l, e), omega), rel=1e-6)


def test_acceleration_at_dead_centres_central():
    """j(0) = R w^2 (1 + lambda), j(pi) = -R w^2 (1 - lambda) hold exactly for the central crank–slider."""
    R, l, omega = 0.04, 0.14, 277.5
    lam = R / l
    top = source_from_exact(piston_motion(0.0, omega, R, l, 0.0), R, l, 0.0)
    bottom = source_from_exact(piston_motion(math.pi, omega, R, l, 0.0), R, l, 0.0)
    assert top.a == pytest.approx(R * omega**2 * (1 + lam), rel=1e-13)
    assert bottom.a == pytest.approx(-R * omega**2 * (1 - lam), rel=1e-13)


# ----------------------------------------------------------------------------------------------
# 2. Multi-cylinder engines

ENGINE = load_scene("engine").model_dump(exclude_none=True)
INLINE4 = load_scene("engine_inline4").model_dump(exclude_none=True)


def v_twin(firing_deg):
    """A 90 deg V-twin on one throw (cylinder 2's axis at 90 deg), with gravity, offset and every mass."""
    data = scene(ENGINE, machine__gravity=[1.5, -9.81])
    data["machine"]["mechanism"].update(
        offset=0.006,
        crank_mass=1.2,
        crank_cg=0.01,
        cylinders=[{"throw_deg": 0.0}, {"throw_deg": 0.0, "bank_deg": 90.0}],
    )
    data["machine"]["drive"]["firing_deg"] = firing_deg
    data["machine"]["drive"]["phase_deg"] = 30.0
    data["scenario"]["load_events"] = []
    return data


def single_cylinder_moment(data, shift_deg):
    """The engine moment of the single-cylinder scene with the cycle shifted: M(phi) of phase_deg + shift_deg."""
    single = scene(data)
    single["machine"]["mechanism"].pop("cylinders")
    single["machine"]["drive"].pop("firing_order", None)
    single["machine"]["drive"].pop("firing_deg", None)
    single["machine"]["drive"]["phase_deg"] += shift_deg
    model = model_of(single)
    return lambda phi: model.effects[0].moment(0.0, phi, 0.0, *model.reduced(phi)[3:])


def test_firing_order_gives_the_classic_delays():
    assert firing_delays([0, 180, 180, 0], [0] * 4, 720.0, [1, 3, 4, 2]) == [0.0, 540.0, 180.0, 360.0]
    assert firing_delays([0, 180, 180, 0], [0] * 4, 720.0, [1, 2, 4, 3]) == [0.0, 180.0, 540.0, 360.0]
    assert firing_delays([0, 120, 240], [0] * 3, 360.0, [1, 3, 2]) == [0.0, 240.0, 120.0]  # two-stroke triple
    with pytest.raises(ValueError, match="firing_order 1-2-3-4 does not fit the crankshaft: cylinder 4"):
        firing_delays([0, 180, 180, 0], [0] * 4, 720.0, [1, 2, 3, 4])
    with pytest.raises(ValueError, match=r"firing_deg\[1\] = 90 deg does not fit .* 270 or 630"):
        firing_delays([0, 90], [0, 0], 720.0, firing_deg=[0, 90])


@pytest.mark.parametrize("data", [pytest.param(INLINE4, id="inline4"), pytest.param(v_twin([0.0, 450.0]), id="V-twin")])
def test_multi_cylinder_is_the_sum_of_phase_shifted_single_cylinders(data):
    """J, J' and the weight moment are the sums of the single cylinder's at phi_i = phi + throw_i - bank_i (the
    weight with gravity turned into the cylinder's frame); the gas moment is the sum of the single-cylinder
    moments at phi_i with the cycle delayed by the firing delay d_i: M_i(phi) = M_1(phi_i) of phase - d_i - shift_i."""
    model = model_of(data)
    mechanism, drive = data["machine"]["mechanism"], data["machine"]["drive"]
    fields = {k: mechanism.get(k, 0.0) for k in CrankSliderGeometry._fields}
    gravity = data["machine"].get("gravity")
    throws = [c.get("throw_deg", 0.0) for c in mechanism["cylinders"]]
    banks = [c.get("bank_deg", 0.0) for c in mechanism["cylinders"]]
    delays = firing_delays(throws, banks, drive["cycle_deg"], drive.get("firing_order"), drive.get("firing_deg"))
    singles = []
    for throw, bank, delay in zip(throws, banks, delays):
        b = math.radians(bank)
        turned = (
            None
            if gravity is None
            else (
                gravity[0] * math.cos(b) + gravity[1] * math.sin(b),
                -gravity[0] * math.sin(b) + gravity[1] * math.cos(b),
            )
        )
        shift = throw - bank
        singles.append(
            (
                math.radians(shift),
                preset_reduced(CrankSliderGeometry(**fields), turned),
                single_cylinder_moment(data, -delay - shift),
            )
        )
    drive_effect = model.effects[0]
    for phi in np.linspace(0.0, 4 * math.pi, 97) + 0.011:
        J, dJ, weight, xs, dxs = model.reduced(phi)
        parts = [reduced(phi + shift) for shift, reduced, _ in singles]
        assert J == pytest.approx(sum(p[0] for p in parts), rel=1e-14)
        assert dJ == pytest.approx(sum(p[1] for p in parts), rel=1e-12, abs=1e-15)
        assert weight == pytest.approx(sum(p[2] for p in parts), rel=1e-12, abs=1e-14)
        assert xs == pytest.approx(tuple(p[3] for p in parts), rel=1e-14)
        gas = drive_effect.moment(0.0, phi, 0.0, xs, dxs)
        expected = sum(moment(phi + shift) for shift, _, moment in singles)
        assert gas == pytest.approx(expected, rel=1e-12, abs=1e-9)


def test_v_twin_weight_is_minus_the_slope_of_the_potential():
    """The weight moment of a V-twin (banks 0 and 90 deg) is -dV/dphi, V = -sum m g . r of cranks, rods and
    pistons placed in the plane independently (each cylinder's points rotated by its bank): catches a wrong turn
    of gravity into a cylinder's frame."""
    data = v_twin([0.0, 450.0])
    mechanism = data["machine"]["mechanism"]
    model = model_of(data)
    R, l, e = mechanism["crank"], mechanism["rod"], mechanism["offset"]
    g = np.array(data["machine"]["gravity"])

    def potential(phi):
        total = 0.0
        for bank in (0.0, math.pi / 2):
            turn = np.array([[math.cos(bank), -math.sin(bank)], [math.sin(bank), math.cos(bank)]])
            local = phi - bank  # the pin's angle from this cylinder's axis
            pin = np.array([R * math.cos(local), R * math.sin(local)])
            piston = np.array([slider_x(local, R, l, e), e])
            rod_centre = pin + mechanism["rod_cg"] / l * (piston - pin)
            crank_centre = mechanism["crank_cg"] / R * pin
            for mass, point in (
                (mechanism["crank_mass"], crank_centre),
                (mechanism["rod_mass"], rod_centre),
                (mechanism["slider_mass"], piston),
            ):
                total -= mass * g @ (turn @ point)
        return total

    h = 1e-5
    for phi in np.linspace(0.0, 2 * math.pi, 25):
        slope = (potential(phi + h) - potential(phi - h)) / (2 * h)
        assert model.reduced(phi)[2] == pytest.approx(-slope, abs=1e-7)
    assert max(abs(model.reduced(p)[2]) for p in np.linspace(0, 6, 13)) > 0.1  # the weight is really there


def test_scene_errors_name_the_key_and_what_is_expected():
    bad = [
        (scene(INLINE4, machine__drive__firing_order=[1, 2, 3, 4]), "firing_order 1-2-3-4 does not fit"),
        (scene(INLINE4, machine__drive__firing_order=[2, 1, 3, 4]), "starting with 1"),
        (scene(INLINE4, machine__drive__firing_order=None), "give drive.firing_order"),
        (
            scene(INLINE4, machine__loads=[{"type": "slider_viscous", "coefficient": 1.0}]),
            "acts on the slider, but the crank–slider has 4 cylinders",
        ),
        (scene(ENGINE, machine__drive__firing_order=[1]), "need several cylinders"),
        (scene(INLINE4, machine__drive__firing_deg=[0, 540, 180, 360]), "either firing_order or firing_deg"),
    ]
    bad_first = scene(INLINE4)
    bad_first["machine"]["mechanism"]["cylinders"][0] = {"throw_deg": 90.0}
    bad.append((bad_first, "cylinder 1 is the reference"))
    for data, message in bad:  # read, then built: the firing is the mechanisms' check (mechanisms/checks.py)
        with pytest.raises(SceneError, match=message):
            refuse_unbuildable(validate_scene(data))


def test_inline4_simulates_with_one_column_per_piston():
    data = scene(INLINE4, scenario__duration=0.02)
    model = model_of(data)
    trajectory = simulate_complete(model)
    times = trajectory.samples(2000.0)
    columns = model.columns(times, trajectory(times))
    assert {"x_slider", "v_slider", "x_slider_4", "v_slider_4"} <= set(columns)
    phi = columns["phi"]
    np.testing.assert_allclose(columns["x_slider_2"], [slider_x(p + math.pi, 0.04, 0.14, 0.0) for p in phi], atol=1e-14)
    np.testing.assert_allclose(columns["x_slider_4"], columns["x_slider"], atol=0.0)


# ----------------------------------------------------------------------------------------------
# 3. Torque curves and harmonics


def indicated_work(data, cylinders=1):
    """Loop integral of p dV over one cycle, V = A (x_top - x), from the table integrated over the piston
    displacement on a 0.005 deg grid (the table's knots lie on it, so the trapezoid rule is exact up to the
    curvature of V between knots)."""
    drive, mech = data["machine"]["drive"], data["machine"]["mechanism"]
    area = math.pi * drive["bore"] ** 2 / 4
    R, l, e = mech["crank"], mech["rod"], mech.get("offset", 0.0)
    cycle = drive["cycle_deg"]
    phi = np.radians(np.linspace(0.0, cycle, int(cycle) * 200 + 1))
    x = R * np.cos(phi) + np.sqrt(l**2 - (e - R * np.sin(phi)) ** 2)
    p = np.interp(
        (np.degrees(phi) + drive.get("phase_deg", 0.0)) % cycle, drive["angle_deg"], drive["pressure"], period=cycle
    )
    return cylinders * float(np.sum(0.5 * (p[1:] + p[:-1]) * np.diff(-area * x)))


OFFSET_ENGINE = scene(ENGINE)
OFFSET_ENGINE["machine"]["mechanism"]["offset"] = 0.012


@pytest.mark.parametrize(
    "data, cylinders", [(ENGINE, 1), (INLINE4, 4), (OFFSET_ENGINE, 1)], ids=["single", "inline4", "offset"]
)
def test_mean_gas_torque_is_indicated_work_over_cycle_angle(data, cylinders):
    curves = torque_curves(model_of(data), 250.0)
    work = indicated_work(data, cylinders)
    if data is not OFFSET_ENGINE:  # the scene says "IMEP about 6.6 bar"
        assert work / (cylinders * math.pi * 0.08**2 / 4 * 0.08) == pytest.approx(6.6e5, rel=0.05)
    # rectangle rule on a periodic curve with kinks at the table's knots: O(dphi^2) ~ 1e-5 relative
    assert np.mean(curves.gas_total) == pytest.approx(work / math.radians(720.0), rel=1e-4)
    assert abs(np.mean(curves.inertia)) < 1e-12 * np.abs(curves.inertia).max()  # J is periodic: no mean


def test_two_stroke_mean_gas_torque():
    data = scene(ENGINE, machine__drive__cycle_deg=360.0, machine__drive__phase_deg=180.0)
    drive = data["machine"]["drive"]
    drive["angle_deg"] = [a / 2 for a in drive["angle_deg"]]
    curves = torque_curves(model_of(data), 250.0)
    assert curves.phi[-1] < 2 * math.pi
    assert np.mean(curves.gas_total) == pytest.approx(indicated_work(data) / (2 * math.pi), rel=1e-4)


def test_one_cylinder_listed_gives_the_torque_curves_of_the_plain_engine():
    """`cylinders: [one]` is the plain single-cylinder engine (its reduced mechanism has one slider, dq a float)."""
    listed = scene(ENGINE, machine__mechanism__cylinders=[{"throw_deg": 0.0, "bank_deg": 0.0}])
    plain, one = torque_curves(model_of(ENGINE), 250.0), torque_curves(model_of(listed), 250.0)
    assert one.gas.shape == plain.gas.shape == (1, plain.phi.size)
    np.testing.assert_allclose(one.gas, plain.gas, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(one.inertia, plain.inertia, rtol=1e-12, atol=1e-9)


def test_fourier_series_reproduces_the_curves():
    curves = torque_curves(model_of(INLINE4), 300.0)
    for values in (curves.gas[0], curves.total):
        fourier = harmonics(values, curves.cycle)
        np.testing.assert_allclose(fourier(curves.phi), values, rtol=0, atol=1e-10 * np.abs(values).max())
    # between the samples a smooth curve is reproduced too (it is band-limited to round-off): the inertia moment
    # of one cylinder -1/2 J'(phi) omega^2 at the midpoints, from the package's J' (independently tested)
    single = torque_curves(model_of(ENGINE), 300.0)
    fourier = harmonics(single.inertia, single.cycle)
    model = model_of(ENGINE)
    middles = single.phi[:200] + 0.5 * (single.phi[1] - single.phi[0])
    expected = [-0.5 * model.reduced(p)[1] * 300.0**2 for p in middles]
    np.testing.assert_allclose(fourier(middles), expected, rtol=0, atol=1e-9 * np.abs(single.inertia).max())


def test_inline4_harmonics_cancel_except_even_orders():
    """Even firing of four identical cylinders (four-stroke, 180 deg apart): the gas moments add in orders 2, 4,
    6, ... and cancel in all others (0.5, 1, 1.5, ...); order 2 is four times one cylinder's. The inertia moment
    has no first (nor any odd) order, while one cylinder's has."""
    four = torque_curves(model_of(INLINE4), 300.0)
    one = torque_curves(model_of(ENGINE), 300.0)
    gas4, gas1 = harmonics(four.gas_total, four.cycle), harmonics(one.gas_total, one.cycle)
    scale = gas4.amplitudes.max()
    even = np.isclose(gas4.orders % 2.0, 0.0)
    assert np.all(gas4.amplitudes[~even] < 1e-11 * scale)
    assert np.all(gas1.amplitudes[:4] > 0.1 * gas1.amplitudes.max())  # orders 0.5..2 of one cylinder are all there
    order2 = np.flatnonzero(np.isclose(gas4.orders, 2.0))[0]
    assert gas4.amplitudes[order2] == pytest.approx(4 * gas1.amplitudes[order2], rel=1e-12)
    assert gas4.phases[order2] == pytest.approx(gas1.phases[order2], abs=1e-10)
    assert gas4.orders[np.argmax(gas4.amplitudes)] == 2.0
    inertia4, inertia1 = harmonics(four.inertia, four.cycle), harmonics(one.inertia, one.cycle)
    first = np.flatnonzero(np.isclose(inertia4.orders, 1.0))[0]
    odd = np.isclose(inertia4.orders % 2.0, 1.0)
    assert inertia1.amplitudes[first] > 1.0
    assert np.all(inertia4.amplitudes[odd] < 1e-12 * inertia4.amplitudes.max())
    assert np.all(inertia4.amplitudes[~np.isclose(inertia4.orders % 1.0, 0.0)] < 1e-12 * inertia4.amplitudes.max())


@pytest.mark.parametrize("lam", [0.2, 0.1])
def test_inertia_torque_harmonics_of_a_piston_match_the_classic_first_order_form(lam):
    """Piston of mass m alone: -1/2 J' w^2 = m R^2 w^2 (lambda/4 sin phi - 1/2 sin 2phi - 3 lambda/4 sin 3phi)
    + O(lambda^2), i.e. amplitudes lambda/4, 1/2, 3 lambda/4 (m R^2 w^2) at phases -90, +90, +90 deg."""
    R, m, omega = 0.05, 2.0, 100.0
    data = scene(ENGINE)
    data["machine"]["mechanism"] = {"type": "crank_slider", "crank": R, "rod": R / lam, "slider_mass": m}
    fourier = harmonics(torque_curves(model_of(data), omega).inertia, 4 * math.pi)
    unit = m * R**2 * omega**2
    for order, amplitude, phase in ((1.0, lam / 4, -90.0), (2.0, 0.5, 90.0), (3.0, 3 * lam / 4, 90.0)):
        k = np.flatnonzero(np.isclose(fourier.orders, order))[0]
        # neglected: O(lambda^3) here (measured 5e-4, 5e-5, 2.3e-3 at lambda 0.2); a wrong factor is O(lambda)
        assert fourier.amplitudes[k] / unit == pytest.approx(amplitude, abs=0.1 * lam**2)
        assert math.degrees(fourier.phases[k]) == pytest.approx(phase, abs=1e-6)


# ----------------------------------------------------------------------------------------------
# 4. The command


def test_engine_command_end_to_end(tmp_path, capsys):
    csv_path, png_path = tmp_path / "curves.csv", tmp_path / "engine.png"
    code, out, err = run_cli(
        capsys, "engine", "engine_inline4", "--omega", "300", "--json", "--out", str(csv_path), "--plot", str(png_path)
    )
    assert code == 0, err
    report = json.loads(out)
    assert report["cylinders"]["firing_order"] == [1, 3, 4, 2]
    assert report["geometry"]["stroke"] == pytest.approx(0.08, rel=1e-14)
    assert report["piston"]["j_top"] == pytest.approx(0.04 * 300**2 * (1 + 0.04 / 0.14), rel=1e-13)
    work = indicated_work(INLINE4, 4)
    assert report["torque"]["mean_gas"] == pytest.approx(work / (4 * math.pi), rel=1e-4)
    assert report["torque"]["indicated_power"] == pytest.approx(300 * work / (4 * math.pi), rel=1e-4)
    assert report["torque"]["gas_harmonics"][0]["order"] == 2.0
    with csv_path.open() as handle:
        rows = list(csv.reader(handle))
    assert rows[0] == [
        "phi_deg",
        "x",
        "v",
        "a",
        "M_gas_1",
        "M_gas_2",
        "M_gas_3",
        "M_gas_4",
        "M_gas",
        "M_inertia",
        "M_total",
    ]
    assert len(rows) == 1 + 720 * 4
    assert png_path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    code, out, err = run_cli(capsys, "engine", "engine")
    assert code == 0, err
    assert "firing order 1," not in out and "cylinders: 1 (four-stroke)" in out
    assert "mean indicated moment" in out and "largest harmonics" in out


@pytest.mark.parametrize(
    "argv, message",
    [
        (
            ["engine", "lathe"],
            "scene 'lathe' is not an engine: expected mechanism.type crank_slider and drive.type engine",
        ),
        (["engine", "engine", "--omega", "-5"], "--omega = -5 rad/s: expected a crank speed > 0"),
        (["engine", "engine", "--set", "scenario.initial.omega=0"], "scenario.initial.omega = 0 rad/s: expected"),
        (
            ["engine", "engine", "--plot", "/nonexistent/folder/e.png"],
            "the folder '/nonexistent/folder' does not exist",
        ),
        (
            ["engine", "engine_inline4", "--set", "machine.drive.firing_order=[1,2,3,4]"],
            "firing_order 1-2-3-4 does not fit the crankshaft",
        ),
    ],
)
def test_engine_command_bad_input(capsys, argv, message):
    code, out, err = run_cli(capsys, *argv)
    assert code == 2
    assert message in err
    assert out == ""
