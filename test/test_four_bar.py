"""Tests of mech_regulator.mechanisms.four_bar against the loop-closure equation, an independent
circle-intersection construction, the closed forms of source 004 (velocities and the I, K, G, M
acceleration formulas), finite differences and energy (potential) consistency.

Loop: a e^{i th2} + b e^{i th3} = d e^{i th1} + c e^{i th4}, th2 = phi, A at the origin, D = d e^{i th1}.
Branches: 'open' puts C to the right of the directed line D->B, 'crossed' to the left.

Tolerance conventions: EPS = double unit round-off.  A central difference with step h has
truncation error h^2/6 |f'''| and rounding error ~ EPS |f| / h.  For the crank-rockers below
(lengths O(1), |th'''| <= ~50) with h = 1e-5 both are ~1e-10 or less, so 1e-8 leaves a margin of
~100 while a wrong term would be O(0.1..1).
"""

from __future__ import annotations

import cmath
import math

import numpy as np
import pytest
from support import preset_reduced

from mech_regulator.mechanisms.four_bar import (
    BRANCH_SIGN,
    FourBarGeometry,
    link_angles,
    unassemblable_crank_ranges,
)

EPS = np.finfo(float).eps
H = 1e-5
TWO_PI = 2.0 * math.pi

# (a, b, c, d, th1): Grashof crank-rockers (crank a shortest), including frame angles other than 0 and SI scale
CRANK_ROCKERS = [
    pytest.param(1.0, 3.0, 2.5, 3.5, 0.0, id="cr_th1=0"),
    pytest.param(1.0, 2.6, 2.2, 3.0, 0.7, id="cr_th1=0.7"),
    pytest.param(0.8, 3.2, 2.0, 3.0, -2.5, id="cr_th1=-2.5"),
    pytest.param(0.05, 0.12, 0.09, 0.13, 1.9, id="cr_metres_th1=1.9"),
]
BRANCHES = [pytest.param(name, id=name) for name in ("open", "crossed")]
ANGLES = np.linspace(0.0, TWO_PI, 73)[:-1] + 0.0171


def wrap(x):
    """Angle difference reduced to [-pi, pi]."""
    return math.remainder(x, TWO_PI)


def is_grashof_crank(a, b, c, d):
    lengths = sorted([a, b, c, d])
    return lengths[0] == a and lengths[0] + lengths[3] <= lengths[1] + lengths[2]


def circle_intersection(phi, a, b, c, d, th1, branch):
    """Independent position: C is at distance b from B and c from D, on the requested side of D->B.
    Returns (B, C, D) as complex numbers, or None when the circles do not meet."""
    B = a * cmath.exp(1j * phi)
    D = d * cmath.exp(1j * th1)
    p = B - D
    f = abs(p)
    u = p / f
    x0 = (c * c - b * b + f * f) / (2.0 * f)  # projection of C - D on the direction D->B
    h2 = c * c - x0 * x0
    if h2 < 0.0:
        return None
    side = -1.0 if branch == "open" else 1.0  # right of D->B is -i u
    C = D + (x0 + side * 1j * math.sqrt(h2)) * u
    return B, C, D


def cross(u, v):
    """z-component of u x v for complex numbers as plane vectors."""
    return (u.conjugate() * v).imag


def angles(phi, geo, branch):
    a, b, c, d, th1 = geo
    return link_angles(phi, a, b, c, d, th1, BRANCH_SIGN[branch])


def source_accelerations(phi, th3, th4, w3, w4, a, b, c, w2=1.0, al2=0.0):
    """Source 004 eqs (14)-(16): al3 = (I K - G M)/(G L - H K), al4 = (I L - H M)/(G L - H K)."""
    G, Hh, K, L = c * math.sin(th4), b * math.sin(th3), c * math.cos(th4), b * math.cos(th3)
    I = a * al2 * math.sin(phi) + a * w2**2 * math.cos(phi) + b * w3**2 * math.cos(th3) - c * w4**2 * math.cos(th4)
    M = a * al2 * math.cos(phi) - a * w2**2 * math.sin(phi) - b * w3**2 * math.sin(th3) + c * w4**2 * math.sin(th4)
    den = G * L - Hh * K
    return (I * K - G * M) / den, (I * L - Hh * M) / den


# ----------------------------------------------------------------------------- positions and branches


def test_branch_sign_constants():
    assert BRANCH_SIGN == {"open": -1.0, "crossed": 1.0}


@pytest.mark.parametrize("branch", BRANCHES)
@pytest.mark.parametrize("a, b, c, d, th1", CRANK_ROCKERS)
def test_positions_close_the_loop_on_the_right_branch(a, b, c, d, th1, branch):
    assert is_grashof_crank(a, b, c, d)
    scale = a + b + c + d
    for phi in ANGLES:
        th3, _, _, th4, _, _ = link_angles(phi, a, b, c, d, th1, BRANCH_SIGN[branch])
        residual = a * cmath.exp(1j * phi) + b * cmath.exp(1j * th3) - d * cmath.exp(1j * th1) - c * cmath.exp(1j * th4)
        # a few O(scale) operations: rounding ~ 10 EPS scale ~ 2e-15 scale
        assert abs(residual) <= 1e-14 * scale
        B, C, D = circle_intersection(phi, a, b, c, d, th1, branch)
        C_pkg = D + c * cmath.exp(1j * th4)
        assert abs(C_pkg - B) == pytest.approx(b, abs=1e-14 * scale)
        assert abs(C_pkg - D) == pytest.approx(c, abs=1e-14 * scale)
        # same point as the independent construction (acos near +-1 amplifies rounding by 1/|sin gamma|; these
        # linkages keep the transmission angle well away from 0 and pi -> ~1e-15 scale observed, 1e-13 allowed)
        assert abs(C_pkg - C) <= 1e-13 * scale
        # open: C right of D->B (negative cross product), crossed: left
        side = cross(B - D, C_pkg - D)
        assert side < 0 if branch == "open" else side > 0
        assert abs(wrap(th3 - cmath.phase(C - B))) <= 1e-12
        assert abs(wrap(th4 - cmath.phase(C - D))) <= 1e-12


@pytest.mark.parametrize("a, b, c, d, th1", CRANK_ROCKERS)
def test_branches_are_mirror_images_about_DB(a, b, c, d, th1):
    """Reflection about the line D-B (direction psi = arg(B - D)) maps an angle th to 2 psi - th."""
    for phi in ANGLES:
        o = link_angles(phi, a, b, c, d, th1, BRANCH_SIGN["open"])
        x = link_angles(phi, a, b, c, d, th1, BRANCH_SIGN["crossed"])
        psi = cmath.phase(a * cmath.exp(1j * phi) - d * cmath.exp(1j * th1))
        assert abs(wrap(o[3] + x[3] - 2 * psi)) <= 1e-13
        assert abs(wrap(o[0] + x[0] - 2 * psi)) <= 1e-13
        # the two branches are distinct away from toggles
        assert abs(wrap(o[3] - x[3])) > 0.1


# ----------------------------------------------------------------------------- velocities and accelerations


def _fd(f, phi, h):
    """Central difference of an angle-valued function (difference wrapped to (-pi, pi])."""
    return wrap(f(phi + h) - f(phi - h)) / (2.0 * h)


def _fd5(f, phi, h):
    """Five-point central difference (error h^4/30 |f^(5)|); differences to f(phi) wrapped for angles."""
    f0 = f(phi)
    df = [wrap(f(phi + k * h) - f0) for k in (-2, -1, 1, 2)]
    return (df[0] - 8.0 * df[1] + 8.0 * df[2] - df[3]) / (12.0 * h)


@pytest.mark.parametrize("branch", BRANCHES)
@pytest.mark.parametrize("a, b, c, d, th1", CRANK_ROCKERS)
def test_velocity_ratios(a, b, c, d, th1, branch):
    s = BRANCH_SIGN[branch]
    for phi in ANGLES:
        th3, dth3, _, th4, dth4, _ = link_angles(phi, a, b, c, d, th1, s)
        # source 004 (13), evaluated here from the returned angles
        w3 = a * math.sin(th4 - phi) / (b * math.sin(th3 - th4))
        w4 = a * math.sin(phi - th3) / (c * math.sin(th4 - th3))
        assert dth3 == pytest.approx(w3, rel=1e-12, abs=1e-14)
        assert dth4 == pytest.approx(w4, rel=1e-12, abs=1e-14)
        # the velocity loop closes: i a e^{i phi} + i b th3' e^{i th3} - i c th4' e^{i th4} = 0
        vloop = a * cmath.exp(1j * phi) + b * dth3 * cmath.exp(1j * th3) - c * dth4 * cmath.exp(1j * th4)
        assert abs(vloop) <= 1e-13 * (a + b + c)
        # finite differences of the independent circle-intersection positions (h = 1e-5, see header)
        fd3 = _fd(
            lambda p: cmath.phase((lambda B, C, D: C - B)(*circle_intersection(p, a, b, c, d, th1, branch))), phi, H
        )
        fd4 = _fd(
            lambda p: cmath.phase((lambda B, C, D: C - D)(*circle_intersection(p, a, b, c, d, th1, branch))), phi, H
        )
        assert dth3 == pytest.approx(fd3, abs=1e-8)
        assert dth4 == pytest.approx(fd4, abs=1e-8)


@pytest.mark.parametrize("branch", BRANCHES)
@pytest.mark.parametrize("a, b, c, d, th1", CRANK_ROCKERS)
def test_accelerations(a, b, c, d, th1, branch):
    s = BRANCH_SIGN[branch]
    for phi in ANGLES:
        th3, dth3, ddth3, th4, dth4, ddth4 = link_angles(phi, a, b, c, d, th1, s)
        fd3 = (link_angles(phi + H, a, b, c, d, th1, s)[1] - link_angles(phi - H, a, b, c, d, th1, s)[1]) / (2 * H)
        fd4 = (link_angles(phi + H, a, b, c, d, th1, s)[4] - link_angles(phi - H, a, b, c, d, th1, s)[4]) / (2 * H)
        assert ddth3 == pytest.approx(fd3, abs=1e-8)
        assert ddth4 == pytest.approx(fd4, abs=1e-8)
        # source 004 (14)-(16) with omega2 = 1, alpha2 = 0 (Cramer's rule on the same 2x2 system)
        al3, al4 = source_accelerations(phi, th3, th4, dth3, dth4, a, b, c)
        assert ddth3 == pytest.approx(al3, rel=1e-11, abs=1e-12)
        assert ddth4 == pytest.approx(al4, rel=1e-11, abs=1e-12)


def test_source_numbers_crank_point():
    """Seed 004: a = 100 mm, omega = 10 rad/s constant -> |v_A| = 1000 mm/s and |a_A| = 1e4 mm/s^2; and the
    coupler point velocity v_B = v_A + b w3 i e^{i th3} equals the rocker tip velocity c w4 i e^{i th4}."""
    a, b, c, d, th1, w = 100.0, 300.0, 250.0, 350.0, 0.2, 10.0
    for phi in ANGLES:
        th3, dth3, ddth3, th4, dth4, ddth4 = link_angles(phi, a, b, c, d, th1, BRANCH_SIGN["open"])
        vA = 1j * a * w * cmath.exp(1j * phi)
        assert abs(vA) == pytest.approx(1000.0, rel=1e-15)
        aA = -a * w * w * cmath.exp(1j * phi)
        assert abs(aA) == pytest.approx(1e4, rel=1e-15)
        vC = vA + 1j * b * dth3 * w * cmath.exp(1j * th3)
        assert abs(vC - 1j * c * dth4 * w * cmath.exp(1j * th4)) <= 1e-12 * 1000.0
        aC = aA + b * w * w * (1j * ddth3 - dth3**2) * cmath.exp(1j * th3)
        assert abs(aC - c * w * w * (1j * ddth4 - dth4**2) * cmath.exp(1j * th4)) <= 1e-12 * 1e4


# ----------------------------------------------------------------------------- branch continuity


@pytest.mark.parametrize("branch", BRANCHES)
@pytest.mark.parametrize("a, b, c, d, th1", CRANK_ROCKERS)
def test_branch_never_flips_over_a_full_turn(a, b, c, d, th1, branch):
    s = BRANCH_SIGN[branch]
    n = 3600
    phis = np.linspace(0.0, TWO_PI, n + 1)
    dphi = phis[1] - phis[0]
    rows = np.array([link_angles(p, a, b, c, d, th1, s) for p in phis])
    th3, dth3, ddth3, th4, dth4, ddth4 = rows.T
    # Taylor: |th(phi + dphi) - th(phi) - th'(phi) dphi| <= max|th''| dphi^2 / 2; factor 1.5 because max|th''| is
    # itself only sampled on the grid.  A branch jump would be O(1) rad, ~1e4 times this bound.
    for th, dth, ddth in ((th4, dth4, ddth4), (th3, dth3, ddth3)):
        steps = np.array([wrap(x) for x in np.diff(th)])
        bound = 1.5 * np.abs(ddth).max() * dphi**2 / 2
        assert np.all(np.abs(steps - dth[:-1] * dphi) <= bound + 1e-13)
        # the rocker and the coupler oscillate: no net rotation over a crank turn
        assert abs(steps.sum()) <= 1e-9
    # the side of C relative to D->B never changes
    B = a * np.exp(1j * phis)
    D = d * cmath.exp(1j * th1)
    C = D + c * np.exp(1j * th4)
    side = ((B - D).conj() * (C - D)).imag
    assert np.all(side < 0) if branch == "open" else np.all(side > 0)
    # and the rocker oscillates through a finite angle (it is a rocker, not a second crank)
    swing = np.ptp(np.unwrap(th4))
    assert 0.0 < swing < math.pi


@pytest.mark.parametrize("branch", BRANCHES)
@pytest.mark.parametrize("th1", [0.0, 0.3, -2.0])
def test_near_toggle_velocities_finite_and_consistent(th1, branch):
    """a + d = 4 = b + c - 5e-4: at phi = th1 + pi coupler and rocker are almost aligned (transmission angle
    ~2 deg), but the velocity ratios stay finite because sin(th4 - th2) -> 0 with sin(th3 - th4)."""
    a, b, c, d = 1.0, 2.5, 1.5005, 3.0
    s = BRANCH_SIGN[branch]
    assert is_grashof_crank(a, b, c, d)
    assert unassemblable_crank_ranges(a, b, c, d, th1) == []
    phis = th1 + math.pi + np.linspace(-0.2, 0.2, 401)
    sin_min = 1.0
    for phi in phis:
        th3, dth3, ddth3, th4, dth4, ddth4 = link_angles(phi, a, b, c, d, th1, s)
        sin_min = min(sin_min, abs(math.sin(th3 - th4)))
        assert all(math.isfinite(v) for v in (dth3, dth4, ddth3, ddth4))
        # 1/sin(th3 - th4) reaches ~30 here; an uncancelled singularity would give |th'| >> 1
        assert abs(dth3) < 1.0 and abs(dth4) < 1.0
        # Near the toggle the returned th' carry ~1e-13 rounding error (acos near 1 and sin(th3 - th4) ~ 0.03
        # amplify EPS ~30-fold), so a 3-point difference is noise-limited for small steps (~1e-7 at h = 1e-6)
        # and truncation-limited for large ones (th'''' ~ 1e4: ~1.5e-7 at h = 1e-5).  The 5-point stencil with
        # h = 1e-4 has truncation h^4/30 |f^(5)| plus noise ~1.5e-13/h; observed <= 1e-10 for the velocities
        # and <= 2e-9 for the accelerations over this sweep -> tolerances 1e-9 and 2e-8.
        h = 1e-4
        fd3 = _fd5(lambda p: link_angles(p, a, b, c, d, th1, s)[0], phi, h)
        fd4 = _fd5(lambda p: link_angles(p, a, b, c, d, th1, s)[3], phi, h)
        assert dth3 == pytest.approx(fd3, abs=1e-9)
        assert dth4 == pytest.approx(fd4, abs=1e-9)
        fdd3 = _fd5(lambda p: link_angles(p, a, b, c, d, th1, s)[1], phi, h)
        fdd4 = _fd5(lambda p: link_angles(p, a, b, c, d, th1, s)[4], phi, h)
        assert ddth3 == pytest.approx(fdd3, abs=2e-8)
        assert ddth4 == pytest.approx(fdd4, abs=2e-8)
    # the sweep really passes close to the toggle
    assert sin_min < 0.05


# ----------------------------------------------------------------------------- assemblability


@pytest.mark.parametrize(
    "a, b, c, d, th1", CRANK_ROCKERS + [pytest.param(1.0, 2.5, 1.5005, 3.0, 0.3, id="near_toggle")]
)
def test_grashof_crank_turns_fully(a, b, c, d, th1):
    assert unassemblable_crank_ranges(a, b, c, d, th1) == []
    for branch in ("open", "crossed"):
        for phi in np.linspace(0.0, TWO_PI, 721):
            link_angles(phi, a, b, c, d, th1, BRANCH_SIGN[branch])  # must not raise


def _in_ranges(phi, ranges):
    return any((phi - lo) % TWO_PI <= hi - lo for lo, hi in ranges)


def _distance_to_ends(phi, ranges):
    return min(abs(wrap(phi - end)) for r in ranges for end in r)


UNASSEMBLABLE = [
    # non-Grashof (s + l > p + q), crank blocked by the far toggle |B - D| = b + c
    pytest.param(3.0, 2.0, 2.5, 2.0, 0.0, 1, id="nongrashof_far_th1=0"),
    pytest.param(3.0, 2.0, 2.5, 2.0, 2.8, 1, id="nongrashof_far_th1=2.8"),
    # non-Grashof, crank blocked by the near toggle |B - D| = |b - c|
    pytest.param(2.0, 3.5, 1.2, 2.2, 1.1, 1, id="nongrashof_near_th1=1.1"),
    # Grashof but the crank is not the shortest link: two blocked intervals
    pytest.param(2.0, 3.0, 0.6, 2.2, -0.4, 2, id="rocker_input_two_ranges"),
]


@pytest.mark.parametrize("a, b, c, d, th1, n_ranges", UNASSEMBLABLE)
def test_unassemblable_ranges_are_exactly_where_link_angles_fails(a, b, c, d, th1, n_ranges):
    ranges = unassemblable_crank_ranges(a, b, c, d, th1)
    assert len(ranges) == n_ranges
    # interval ends are toggle positions: |B - D| = b + c or |b - c| (rounding of acos near a
    # non-degenerate root ~ EPS / |sin| -> well below 1e-12)
    for lo, hi in ranges:
        assert 0.0 < hi - lo < TWO_PI
        for end in (lo, hi):
            f = abs(a * cmath.exp(1j * end) - d * cmath.exp(1j * th1))
            assert min(abs(f - (b + c)), abs(f - abs(b - c))) <= 1e-12 * (a + d)
    # on a grid (skipping 1e-9 rad around the ends, where rounding decides), ValueError iff inside a range
    n_inside = 0
    for phi in th1 + np.linspace(-math.pi, math.pi, 1441)[:-1] + 1e-4:
        if _distance_to_ends(phi, ranges) < 1e-9:
            continue
        inside = _in_ranges(phi, ranges)
        n_inside += inside
        for branch in ("open", "crossed"):
            if inside:
                with pytest.raises(ValueError):
                    link_angles(phi, a, b, c, d, th1, BRANCH_SIGN[branch])
            else:
                th3, _, _, th4, _, _ = link_angles(phi, a, b, c, d, th1, BRANCH_SIGN[branch])
                assert circle_intersection(phi, a, b, c, d, th1, branch) is not None
                assert math.isfinite(th3) and math.isfinite(th4)
    assert 0 < n_inside < 1440
    # just inside / just outside each end (1e-7 rad: |B - D| moves by ~1e-7 a d |sin| >> rounding)
    for lo, hi in ranges:
        for end, into in ((lo, +1), (hi, -1)):
            with pytest.raises(ValueError):
                link_angles(end + into * 1e-7, a, b, c, d, th1, -1.0)
            link_angles(end - into * 1e-7, a, b, c, d, th1, -1.0)


def test_never_assemblable():
    """Frame longer than the other three together: no crank angle closes the loop."""
    a, b, c, d, th1 = 1.0, 1.0, 1.0, 5.0, 0.5
    ranges = unassemblable_crank_ranges(a, b, c, d, th1)
    assert len(ranges) == 1 and ranges[0][1] - ranges[0][0] == pytest.approx(TWO_PI, rel=1e-15)
    for phi in np.linspace(0.0, TWO_PI, 37):
        with pytest.raises(ValueError):
            link_angles(phi, a, b, c, d, th1, -1.0)


def test_crank_pin_on_rocker_pivot_raises_value_error():
    """a = d and phi = th1 put B on D; with b != c the loop cannot close (0 < |b - c|), the range function
    says so, and link_angles should raise ValueError like everywhere else in that range."""
    a, b, c, d, th1 = 1.0, 2.0, 1.5, 1.0, 0.3
    assert _in_ranges(th1, unassemblable_crank_ranges(a, b, c, d, th1))
    with pytest.raises(ValueError):
        link_angles(th1, a, b, c, d, th1, -1.0)


# ----------------------------------------------------------------------------- reduced inertia and weight


def _geometry(a, b, c, d, th1, branch, **over):
    g = dict(
        crank=a,
        coupler=b,
        rocker=c,
        frame=d,
        frame_angle=th1,
        branch_sign=BRANCH_SIGN[branch],
        crank_mass=2.0,
        crank_cg=-0.25 * a,
        coupler_mass=1.5,
        coupler_cg=0.4 * b,
        coupler_inertia=0.3 * b * b,
        rocker_mass=1.2,
        rocker_cg=0.6 * c,
        rocker_inertia=0.1 * c * c,
    )
    g.update(over)
    return FourBarGeometry(**g)


def _points(phi, g, branch):
    """Independent positions (circle intersection): crank, coupler and rocker centres; th3, th4."""
    B, C, D = circle_intersection(phi, g.crank, g.coupler, g.rocker, g.frame, g.frame_angle, branch)
    S2 = g.crank_cg * cmath.exp(1j * phi)
    S3 = B + (g.coupler_cg / g.coupler) * (C - B)
    S4 = D + (g.rocker_cg / g.rocker) * (C - D)
    return S2, S3, S4, cmath.phase(C - B), cmath.phase(C - D)


def _J_independent(phi, g, branch):
    p, m = _points(phi + H, g, branch), _points(phi - H, g, branch)
    dS3, dS4 = (p[1] - m[1]) / (2 * H), (p[2] - m[2]) / (2 * H)
    dth3, dth4 = wrap(p[3] - m[3]) / (2 * H), wrap(p[4] - m[4]) / (2 * H)
    return (
        g.coupler_mass * abs(dS3) ** 2
        + g.coupler_inertia * dth3**2
        + g.rocker_mass * abs(dS4) ** 2
        + g.rocker_inertia * dth4**2
    )


def _potential(phi, g, branch, gravity):
    """V = -sum m g . r_S."""
    S2, S3, S4, _, _ = _points(phi, g, branch)
    gc = complex(*gravity)
    dot = lambda z: (gc.conjugate() * z).real  # noqa: E731
    return -(g.crank_mass * dot(S2) + g.coupler_mass * dot(S3) + g.rocker_mass * dot(S4))


@pytest.mark.parametrize("gravity", [(0.0, -9.81), (2.0, -9.0)], ids=["vertical", "tilted"])
@pytest.mark.parametrize("branch", BRANCHES)
@pytest.mark.parametrize("a, b, c, d, th1", CRANK_ROCKERS)
def test_make_reduced_inertia_and_weight(a, b, c, d, th1, branch, gravity):
    g = _geometry(a, b, c, d, th1, branch)
    reduced = preset_reduced(g, gravity)
    L = a + b + c + d
    J_scale = (g.coupler_mass + g.rocker_mass) * L**2 + g.coupler_inertia + g.rocker_inertia
    M_scale = (g.crank_mass + g.coupler_mass + g.rocker_mass) * math.hypot(*gravity) * L
    for phi in ANGLES[::2]:
        J, dJ, Mw, th4, dth4 = reduced(phi)
        # FD velocity ratios (h = 1e-5) are accurate to ~1e-11 relative for these smooth positions, so J, the FD
        # of J and the FD of V are within ~1e-11 of their scales (observed <= 7e-12): tolerance 1e-10 x scale
        assert J == pytest.approx(_J_independent(phi, g, branch), abs=1e-10 * J_scale)
        assert J > 0
        assert dJ == pytest.approx((reduced(phi + H)[0] - reduced(phi - H)[0]) / (2 * H), abs=1e-10 * J_scale)
        dV = (_potential(phi + H, g, branch, gravity) - _potential(phi - H, g, branch, gravity)) / (2 * H)
        assert Mw == pytest.approx(-dV, abs=1e-10 * M_scale)
        # output coordinate: the rocker angle and its ratio
        assert abs(wrap(th4 - _points(phi, g, branch)[4])) <= 1e-12
        assert dth4 == pytest.approx(link_angles(phi, a, b, c, d, th1, BRANCH_SIGN[branch])[4], rel=1e-15)


@pytest.mark.parametrize("gravity", [None, (0.0, 0.0)])
def test_make_reduced_without_gravity(gravity):
    g = _geometry(1.0, 2.6, 2.2, 3.0, 0.7, "crossed")
    with_g = preset_reduced(g, (0.0, -9.81))
    without = preset_reduced(g, gravity)
    for phi in ANGLES:
        J, dJ, Mw, th4, dth4 = without(phi)
        assert Mw == 0.0
        assert (J, dJ, th4, dth4) == tuple(v for i, v in enumerate(with_g(phi)) if i != 2)
    assert max(abs(with_g(p)[2]) for p in ANGLES) > 1.0


def test_make_reduced_weight_is_conservative_over_a_turn():
    """The weights' work over a full crank turn is zero (periodic trapezoid rule: spectrally accurate)."""
    g = _geometry(0.8, 3.2, 2.0, 3.0, -2.5, "open")
    reduced = preset_reduced(g, (1.5, -9.81))
    phis = np.linspace(0.0, TWO_PI, 721)
    M = np.array([reduced(p)[2] for p in phis])
    assert abs(np.trapezoid(M, phis)) <= 1e-10 * np.abs(M).max() * TWO_PI
    assert np.abs(M).max() > 1.0
