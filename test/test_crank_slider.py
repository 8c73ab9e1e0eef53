"""Tests of mech_regulator.mechanisms.crank_slider against independent closed forms (source 002),
finite differences and energy (potential) consistency.

Geometry under test: crank pin B = R (cos phi, sin phi), slider on y = e at
x = R cos phi + sqrt(l^2 - (e - R sin phi)^2).  Source 002 measures the piston displacement
x_src = sqrt((l + R)^2 - a^2) - (R cos alpha + l cos beta), l sin beta = R sin alpha - a, from the
outer dead centre, with alpha = phi and a = e; hence x_src = sqrt((l+R)^2 - e^2) - x(phi),
v_src = -x' omega and j_src = -x'' omega^2 at constant omega.

Tolerance conventions: EPS is the double-precision unit round-off.  A central difference with
step h has truncation error h^2/6 |f'''| and rounding error ~ EPS |f| / h; with h = 1e-5 and the
lengths used here (<= 0.6 m, derivatives of the same order) both are ~1e-11, so tolerances of
1e-9 x (length scale) leave a margin of ~100 while still catching any wrong term (which would be
of order R, i.e. 1e-2 .. 1e-1).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from support import preset_reduced

from mech_regulator.mechanisms.crank_slider import (
    CrankSliderGeometry,
    dead_centres,
    slider_kinematics,
    stroke,
)

EPS = np.finfo(float).eps
H = 1e-5  # finite-difference step [rad]

# (R, l, e): central, positive and negative offset, short rod / large lambda, large offset
GEOMETRIES = [
    pytest.param(0.1, 0.4, 0.0, id="central"),
    pytest.param(0.1, 0.5, 0.03, id="offset+"),
    pytest.param(0.1, 0.5, -0.03, id="offset-"),
    pytest.param(0.05, 0.2, 0.02, id="offset+_lambda0.25"),
    pytest.param(0.1, 0.3, -0.12, id="short_rod_big_offset-"),
]
# small-lambda geometries only: the source's approximations are expansions in lambda
APPROX_GEOMETRIES = GEOMETRIES[:4]
OFFSET_APPROX_GEOMETRIES = GEOMETRIES[1:4]

ANGLES = np.linspace(-math.pi, math.pi, 37)[:-1] + 0.0123  # avoid landing exactly on symmetric points
GRID = np.linspace(0.0, 2.0 * math.pi, 2881)  # 0.125 deg


# ----------------------------------------------------------------------------- independent references


def x_src_exact(alpha, R, l, a):
    """Source 002 (1-11): displacement from the outer dead centre, l sin beta = R sin alpha - a."""
    sin_beta = (R * math.sin(alpha) - a) / l
    return math.sqrt((l + R) ** 2 - a * a) - (R * math.cos(alpha) + l * math.sqrt(1.0 - sin_beta**2))


def x_src_approx(alpha, R, lam, k, signs=(1, 1, 1)):
    """Source (1-3)/(1-13); `signs` flips the sign of individual correction terms (for the
    'the bound is tight enough to catch a sign error' checks)."""
    s1, s2, s3 = signs
    return R * (s1 * (1 - math.cos(alpha)) + s2 * lam / 4 * (1 - math.cos(2 * alpha)) - s3 * lam * k * math.sin(alpha))


def v_src_approx(alpha, R, w, lam, k, signs=(1, 1, 1)):
    """Source (1-4)/(1-14)."""
    s1, s2, s3 = signs
    return R * w * (s1 * math.sin(alpha) + s2 * lam / 2 * math.sin(2 * alpha) - s3 * lam * k * math.cos(alpha))


def j_src_approx(alpha, R, w, lam, k, k_sign=+1.0, signs=(1, 1)):
    """d v_src/dt of (1-14): R w^2 (cos a + lambda cos 2a + k_sign * lambda k sin a).
    k_sign = +1 is the correct derivative; k_sign = -1 is what source 002 prints as (1-15)."""
    s1, s2 = signs
    return R * w * w * (s1 * math.cos(alpha) + s2 * lam * math.cos(2 * alpha) + k_sign * lam * k * math.sin(alpha))


def _T(u):
    """T(u) = 1 - sqrt(1-u) - u/2 >= 0 (remainder of the first-order expansion of sqrt(1-u))."""
    return 1.0 - math.sqrt(1.0 - u) - 0.5 * u


def _T1(u):
    """T'(u) = (1/sqrt(1-u) - 1)/2, >= 0 and increasing on [0, 1)."""
    return 0.5 * (1.0 / math.sqrt(1.0 - u) - 1.0)


def _T2(u):
    """T''(u) = (1-u)^(-3/2)/4, > 0 and increasing on [0, 1)."""
    return 0.25 * (1.0 - u) ** -1.5


def approximation_bounds(R, l, e, w=1.0):
    """Rigorous bounds of (exact - approximate) for x, v, j of source 002's formulas.

    Writing u = lambda^2 (sin a - k)^2 and W = e^2/(l + R)^2, the exact displacement is
    x_src = (l + R) sqrt(1 - W) - R cos a - l sqrt(1 - u), and expanding both square roots to first
    order gives exactly
        x_src - x_approx = R lambda^2 k^2 / (2 (1 + lambda)) + l T(u) - (l + R) T(W),
    with T >= 0 (T(u) ~ u^2/8: the neglected order is R lambda^3 and R lambda k^2 * lambda).
    Differentiating (only u depends on a): v error = w l T'(u) u', j error = w^2 l (T''(u) u'^2 + T'(u) u''),
    |u'| <= 2 lambda^2 (1 + |k|), |u''| <= 2 lambda^2 (2 + |k|), u <= u_max = lambda^2 (1 + |k|)^2.
    """
    lam, k = R / l, e / R
    u_max = lam**2 * (1 + abs(k)) ** 2
    W = e * e / (l + R) ** 2
    bx = R * lam**2 * k**2 / (2 * (1 + lam)) + l * _T(u_max) + (l + R) * _T(W)
    du = 2 * lam**2 * (1 + abs(k))
    ddu = 2 * lam**2 * (2 + abs(k))
    bv = w * l * _T1(u_max) * du
    bj = w * w * l * (_T2(u_max) * du * du + _T1(u_max) * ddu)
    return bx, bv, bj


def slider_x(phi, R, l, e):
    """Independent slider position (the brief's geometry)."""
    return R * math.cos(phi) + math.sqrt(l * l - (e - R * math.sin(phi)) ** 2)


def rod_angle(phi, R, l, e):
    return math.atan2(e - R * math.sin(phi), slider_x(phi, R, l, e) - R * math.cos(phi))


def central_diff(f, phi, h=H):
    return (f(phi + h) - f(phi - h)) / (2.0 * h)


# ----------------------------------------------------------------------------- exact position


@pytest.mark.parametrize("R, l, e", GEOMETRIES)
def test_position_matches_source_exact_formula(R, l, e):
    """x_src (source 002, measured from the outer dead centre) = sqrt((l+R)^2 - e^2) - x(phi)."""
    S1 = math.sqrt((l + R) ** 2 - e * e)
    for phi in ANGLES:
        x = slider_kinematics(phi, R, l, e)[0]
        # both sides are a handful of O(l) operations: rounding <= ~10 EPS (l + R) ~ 2e-15 m
        assert x_src_exact(phi, R, l, e) == pytest.approx(S1 - x, abs=1e-12 * (l + R))
        # and the slider lies on the rod circle about the pin: |C - B| = l
        assert math.hypot(x - R * math.cos(phi), e - R * math.sin(phi)) == pytest.approx(l, abs=1e-12 * l)


# ----------------------------------------------------------------------------- approximate formulas


@pytest.mark.parametrize("R, l, e", APPROX_GEOMETRIES)
def test_source_approximations_within_neglected_order(R, l, e):
    """Source (1-3)/(1-4)/(1-5) (central) and (1-13)/(1-14)/(corrected 1-15) (offset) agree with the
    exact kinematics within the rigorous bound of the neglected terms, and that bound is tight enough
    that flipping the sign of any single term of the approximation violates it somewhere."""
    w = 7.0  # rad/s; the checks scale exactly with w, w^2
    lam, k = R / l, e / R
    bx, bv, bj = approximation_bounds(R, l, e, w)
    # the bound itself is of the neglected order: O(R lambda^3 (1+|k|)^4 + R lambda^2 k^2)
    assert bx <= R * (lam**3 * (1 + abs(k)) ** 4 / 8 * 1.2 + lam**2 * k**2) + 1e-15
    S1 = math.sqrt((l + R) ** 2 - e * e)
    flipped_x = {s: 0.0 for s in [(-1, 1, 1), (1, -1, 1), (1, 1, -1)]}
    flipped_v = {s: 0.0 for s in flipped_x}
    flipped_j = {s: 0.0 for s in [(-1, 1), (1, -1)]}
    flipped_j_k = 0.0
    for alpha in GRID[::4]:
        x, dx, ddx = slider_kinematics(alpha, R, l, e)[:3]
        xs, vs, js = S1 - x, -dx * w, -ddx * w * w
        # tiny additive slack for rounding of O(R) quantities
        assert abs(xs - x_src_approx(alpha, R, lam, k)) <= bx + 1e-14
        assert abs(vs - v_src_approx(alpha, R, w, lam, k)) <= bv + 1e-13 * w
        assert abs(js - j_src_approx(alpha, R, w, lam, k)) <= bj + 1e-12 * w * w
        for s in flipped_x:
            flipped_x[s] = max(flipped_x[s], abs(xs - x_src_approx(alpha, R, lam, k, s)))
            flipped_v[s] = max(flipped_v[s], abs(vs - v_src_approx(alpha, R, w, lam, k, s)))
        for s in flipped_j:
            flipped_j[s] = max(flipped_j[s], abs(js - j_src_approx(alpha, R, w, lam, k, signs=s)))
        flipped_j_k = max(flipped_j_k, abs(js - j_src_approx(alpha, R, w, lam, k, k_sign=-1.0)))
    # every wrong sign is detected (a term multiplied by k only exists with an offset)
    for s, err in flipped_x.items():
        if s[2] == -1 and k == 0:
            continue
        assert err > bx, f"x: sign flip {s} not detected"
        assert flipped_v[s] > bv, f"v: sign flip {s} not detected"
    for s, err in flipped_j.items():
        assert err > bj, f"j: sign flip {s} not detected"
    if k != 0:
        assert flipped_j_k > bj


@pytest.mark.parametrize("R, l, e", OFFSET_APPROX_GEOMETRIES)
def test_offset_acceleration_sign_slip_in_source(R, l, e):
    """Source 002 prints j ~ R w^2 (cos a + lambda cos 2a - lambda k sin a); the derivative of its own
    v gives + lambda k sin a.  The corrected form is within the approximation bound of the exact
    acceleration; the printed one is off by ~2 lambda k R w^2 at a = 90 deg."""
    w = 10.0
    lam, k = R / l, e / R
    _, _, bj = approximation_bounds(R, l, e, w)
    alpha = math.pi / 2
    j_exact = -slider_kinematics(alpha, R, l, e)[2] * w * w
    corrected = j_src_approx(alpha, R, w, lam, k, k_sign=+1.0)
    printed = j_src_approx(alpha, R, w, lam, k, k_sign=-1.0)
    assert abs(j_exact - corrected) <= bj
    assert abs(j_exact - printed) > bj
    # the printed error is 2 lambda k R w^2 up to the approximation error of the corrected formula
    assert printed - j_exact == pytest.approx(-2 * lam * k * R * w * w, abs=bj)
    # and the corrected form is the derivative of the source's v (1-14): central difference in time
    dt = 1e-6
    dv = (v_src_approx(alpha + w * dt, R, w, lam, k) - v_src_approx(alpha - w * dt, R, w, lam, k)) / (2 * dt)
    # truncation (w dt)^2/6 * R w^3 ~ 2e-10, rounding EPS R w / dt ~ 2e-10
    assert dv == pytest.approx(corrected, abs=1e-8 * R * w * w)


@pytest.mark.parametrize("R, l", [(0.1, 0.45), (0.05, 0.3), (0.12, 0.36)])  # lambda = 0.22, 0.17, 0.33
def test_extreme_accelerations_central(R, l):
    """j(0) = R w^2 (1 + lambda), j(pi) = -R w^2 (1 - lambda): for the approximate formula, and for the
    exact central crank-slider too (x'' = -R - R^2 cos 2phi / l + O(sin^2 phi) is exact at 0 and pi)."""
    w = 3.0
    lam = R / l
    assert j_src_approx(0.0, R, w, lam, 0.0) == pytest.approx(R * w * w * (1 + lam), rel=1e-14)
    assert j_src_approx(math.pi, R, w, lam, 0.0) == pytest.approx(-R * w * w * (1 - lam), rel=1e-14)
    j0 = -slider_kinematics(0.0, R, l, 0.0)[2] * w * w
    jpi = -slider_kinematics(math.pi, R, l, 0.0)[2] * w * w
    # exact identity; sin(pi) = 1.2e-16 perturbs it by O(EPS^2), rounding ~ few EPS
    assert j0 == pytest.approx(R * w * w * (1 + lam), rel=1e-13)
    assert jpi == pytest.approx(-R * w * w * (1 - lam), rel=1e-13)
    # these are the extremes of the exact acceleration when lambda <= 1/4 (source 1-6); for lambda > 1/4
    # the minimum is lower, at cos a = -1/(4 lambda), ~ -R w^2 (lambda + 1/(8 lambda)) (approximate)
    js = np.array([-slider_kinematics(p, R, l, 0.0)[2] for p in GRID]) * w * w
    assert js.max() == pytest.approx(j0, abs=1e-12)
    if lam < 0.25:
        assert js.min() == pytest.approx(jpi, abs=1e-12)
    else:
        _, _, bj = approximation_bounds(R, l, 0.0, w)
        assert js.min() < jpi - 1e-6
        assert js.min() == pytest.approx(
            -R * w * w * (lam + 1 / (8 * lam)), abs=bj + 1e-5
        )  # + grid error max|j''| dphi^2/8 ~ 2e-6


# ----------------------------------------------------------------------------- dead centres and stroke


@pytest.mark.parametrize("R, l, e", GEOMETRIES)
def test_dead_centres_and_stroke(R, l, e):
    outer, inner = dead_centres(R, l, e)
    # source 002 (1-8)/(1-9) in this geometry: sin a1 = lambda k/(1 + lambda), a2 - pi: sin = lambda k/(1 - lambda)
    lam, k = R / l, e / R
    assert math.sin(outer) == pytest.approx(lam * k / (1 + lam), abs=1e-15)
    assert math.sin(inner - math.pi) == pytest.approx(lam * k / (1 - lam), abs=1e-15)
    x_out, dx_out = slider_kinematics(outer, R, l, e)[:2]
    x_in, dx_in = slider_kinematics(inner, R, l, e)[:2]
    # exact stationarity; x' is a sum of O(R) terms -> rounding ~ 10 EPS R
    assert abs(dx_out) <= 1e-13 * R
    assert abs(dx_in) <= 1e-13 * R
    # crank and rod collinear: |C| = l + R at the outer, l - R at the inner dead centre
    assert math.hypot(x_out, e) == pytest.approx(l + R, abs=1e-13)
    assert math.hypot(x_in, e) == pytest.approx(l - R, abs=1e-13)
    # extremes over a fine grid: the grid cannot beat the true extremum (up to rounding), and misses it by at
    # most max|x''| dphi^2 / 8 (quadratic around a stationary point)
    xs = np.array([slider_kinematics(p, R, l, e)[0] for p in GRID])
    ddx_max = max(abs(slider_kinematics(p, R, l, e)[2]) for p in GRID[::8])
    grid_err = 1.5 * ddx_max * (GRID[1] - GRID[0]) ** 2 / 8
    assert xs.max() <= x_out + 1e-14
    assert xs.max() >= x_out - grid_err
    assert xs.min() >= x_in - 1e-14
    assert xs.min() <= x_in + grid_err
    # the maximum is attained near `outer` and the minimum near `inner` (not at some other stationary point)
    dphi = GRID[1] - GRID[0]
    assert abs(math.remainder(GRID[xs.argmax()] - outer, 2 * math.pi)) <= dphi
    assert abs(math.remainder(GRID[xs.argmin()] - inner, 2 * math.pi)) <= dphi
    S = stroke(R, l, e)
    assert S == pytest.approx(x_out - x_in, abs=1e-13)
    assert S == pytest.approx(xs.max() - xs.min(), abs=2 * grid_err + 1e-14)
    # source 1-10 in dimensionless form: S = R [sqrt((1/lambda + 1)^2 - k^2) - sqrt((1/lambda - 1)^2 - k^2)]
    S_src = R * (math.sqrt((1 / lam + 1) ** 2 - k * k) - math.sqrt((1 / lam - 1) ** 2 - k * k))
    assert S == pytest.approx(S_src, rel=1e-13)
    if e == 0:
        assert S == pytest.approx(2 * R, rel=1e-14)
    else:
        assert S > 2 * R  # an offset lengthens the stroke


# ----------------------------------------------------------------------------- derivatives


@pytest.mark.parametrize("R, l, e", GEOMETRIES)
def test_derivatives_against_finite_differences(R, l, e):
    scale = l + R
    for phi in list(ANGLES) + list(dead_centres(R, l, e)):
        x, dx, ddx, th, dth, ddth = slider_kinematics(phi, R, l, e)
        assert x == pytest.approx(slider_x(phi, R, l, e), abs=1e-14 * scale)
        assert th == pytest.approx(rod_angle(phi, R, l, e), abs=1e-14)
        # first derivatives from the independent positions (h = 1e-5: error ~1e-11 x scale, see header)
        assert dx == pytest.approx(central_diff(lambda p: slider_x(p, R, l, e), phi), abs=1e-9 * scale)
        assert dth == pytest.approx(central_diff(lambda p: rod_angle(p, R, l, e), phi), abs=1e-9)
        # second derivatives from the (now verified) first derivatives
        assert ddx == pytest.approx(central_diff(lambda p: slider_kinematics(p, R, l, e)[1], phi), abs=1e-9 * scale)
        assert ddth == pytest.approx(central_diff(lambda p: slider_kinematics(p, R, l, e)[4], phi), abs=1e-9)
        # and a direct second difference of x (h = 1e-3: truncation h^2/12 |x''''| ~ 1e-7 x scale,
        # rounding 4 EPS |x| / h^2 ~ 1e-9)
        h2 = 1e-3
        fd2 = (slider_x(phi + h2, R, l, e) - 2 * x + slider_x(phi - h2, R, l, e)) / h2**2
        assert ddx == pytest.approx(fd2, abs=1e-6 * scale)


# ----------------------------------------------------------------------------- reduced inertia and weight


def _geometry(R, l, e, **over):
    g = dict(
        crank=R,
        rod=l,
        offset=e,
        crank_mass=2.0,
        crank_cg=-0.3 * R,
        rod_mass=1.5,
        rod_cg=0.35 * l,
        rod_inertia=0.02,
        slider_mass=0.8,
    )
    g.update(over)
    return CrankSliderGeometry(**g)


def _points(phi, g):
    """Independent positions: crank centre S1, rod centre S2, slider C; rod angle."""
    B = np.array([g.crank * math.cos(phi), g.crank * math.sin(phi)])
    C = np.array([slider_x(phi, g.crank, g.rod, g.offset), g.offset])
    rho = g.rod_cg / g.rod
    S2 = B + rho * (C - B)
    S1 = g.crank_cg * np.array([math.cos(phi), math.sin(phi)])
    theta = math.atan2(C[1] - B[1], C[0] - B[0])
    return S1, S2, C, theta


def _J_independent(phi, g):
    """sum m |dS/dphi|^2 + J_S (dtheta/dphi)^2 with velocity ratios from central differences."""
    _, S2p, Cp, thp = _points(phi + H, g)
    _, S2m, Cm, thm = _points(phi - H, g)
    dS2 = (S2p - S2m) / (2 * H)
    dC = (Cp - Cm) / (2 * H)
    dth = (thp - thm) / (2 * H)
    return g.rod_mass * dS2 @ dS2 + g.rod_inertia * dth**2 + g.slider_mass * dC @ dC


def _potential(phi, g, gravity):
    """V = -sum m g . r_S (crank, rod, slider)."""
    S1, S2, C, _ = _points(phi, g)
    gv = np.array(gravity)
    return -(g.crank_mass * gv @ S1 + g.rod_mass * gv @ S2 + g.slider_mass * gv @ C)


@pytest.mark.parametrize("R, l, e", GEOMETRIES)
@pytest.mark.parametrize("gravity", [(0.0, -9.81), (3.0, -8.5)], ids=["vertical", "tilted"])
def test_make_reduced_inertia_and_weight(R, l, e, gravity):
    g = _geometry(R, l, e)
    reduced = preset_reduced(g, gravity)
    J_scale = g.rod_mass * (l + R) ** 2 + g.rod_inertia + g.slider_mass * R**2  # dominant size of J
    M_scale = (g.crank_mass + g.rod_mass + g.slider_mass) * math.hypot(*gravity) * (l + R)
    for phi in ANGLES:
        J, dJ, Mw, x, dx = reduced(phi)
        # velocity ratios by central differences are accurate to ~1e-11 m/rad, so J to ~1e-11 J_scale
        assert J == pytest.approx(_J_independent(phi, g), abs=1e-9 * J_scale)
        assert J > 0
        # dJ/dphi against a central difference of the package's J (same error budget as the header)
        assert dJ == pytest.approx(central_diff(lambda p: reduced(p)[0], phi), abs=1e-9 * J_scale)
        # weight moment = -dV/dphi (the weights are conservative forces); V = O(M_scale), FD error ~1e-11 M_scale
        dV = central_diff(lambda p: _potential(p, g, gravity), phi)
        assert Mw == pytest.approx(-dV, abs=1e-9 * M_scale)
        assert x == pytest.approx(slider_x(phi, R, l, e), abs=1e-14 * (l + R))
        assert dx == pytest.approx(central_diff(lambda p: slider_x(p, R, l, e), phi), abs=1e-9 * (l + R))


def test_make_reduced_weight_integrates_to_zero_over_a_turn():
    """Weights are conservative: the work of M_weight over a full turn is zero (trapezoid rule on a periodic
    smooth integrand is spectrally accurate), while the work over half a turn equals -(V(pi) - V(0))."""
    g = _geometry(0.1, 0.35, 0.04)
    gravity = (1.0, -9.81)
    reduced = preset_reduced(g, gravity)
    phis = np.linspace(0.0, 2 * math.pi, 721)
    M = np.array([reduced(p)[2] for p in phis])
    work = np.trapezoid(M, phis)
    assert abs(work) <= 1e-12 * np.abs(M).max() * 2 * math.pi
    half = phis <= math.pi + 1e-12
    work_half = np.trapezoid(M[half], phis[half])
    # trapezoid error on a non-periodic interval: (b - a) h^2 / 12 max|M''|, M'' = O(M) here -> ~1e-5 relative
    assert work_half == pytest.approx(
        -(_potential(math.pi, g, gravity) - _potential(0.0, g, gravity)), abs=1e-4 * np.abs(M).max()
    )


@pytest.mark.parametrize("gravity", [None, (0.0, 0.0)])
def test_make_reduced_without_gravity(gravity):
    g = _geometry(0.1, 0.45, -0.02)
    with_g = preset_reduced(g, (0.0, -9.81))
    without = preset_reduced(g, gravity)
    for phi in ANGLES:
        J, dJ, Mw, x, dx = without(phi)
        assert Mw == 0.0
        # the inertia part does not depend on gravity
        assert (J, dJ, x, dx) == tuple(v for i, v in enumerate(with_g(phi)) if i != 2)
    # and the weight is really there when gravity is given (so the zero above means something)
    assert max(abs(with_g(p)[2]) for p in ANGLES) > 0.1


def test_make_reduced_massless_links():
    """Only the slider has mass: J = m x'^2 exactly, and only the crank has mass: no inertia, weight
    moment of a point mass on a circle (M = m g . r' = m r_cg (-gx sin phi + gy cos phi))."""
    R, l, e = 0.08, 0.3, 0.01
    slider_only = preset_reduced(_geometry(R, l, e, crank_mass=0.0, rod_mass=0.0, rod_inertia=0.0), None)
    crank_only = preset_reduced(
        _geometry(R, l, e, rod_mass=0.0, rod_inertia=0.0, slider_mass=0.0, crank_mass=3.0, crank_cg=0.05), (0.5, -9.81)
    )
    for phi in ANGLES:
        dx = slider_kinematics(phi, R, l, e)[1]
        assert slider_only(phi)[0] == pytest.approx(0.8 * dx * dx, rel=1e-14, abs=1e-300)
        J, dJ, Mw, _, _ = crank_only(phi)
        assert J == 0.0 and dJ == 0.0
        assert Mw == pytest.approx(3.0 * 0.05 * (-0.5 * math.sin(phi) - 9.81 * math.cos(phi)), abs=1e-14)
