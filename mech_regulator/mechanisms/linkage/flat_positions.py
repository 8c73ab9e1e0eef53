"""The general linkage solver's positions, in the subset of Python numba compiles: each kind of group placed in
closed form from its known joints (RRR, RRP, RPR, PRP, RPP, a redundant link, a gear on its pivot, a cam follower by
its law, law_at), with the link-pose helpers they share (docs/theory.md §5.3; flat.py describes the program and the
poses)."""

from __future__ import annotations

import cmath
import math

from mech_regulator.mechanisms.linkage.flat_program import (
    CAM_FOLLOWER,
    GEAR,
    GROUP_SIZE,
    GUIDES_PARALLEL,
    HEADER_SIZE,
    JOINT_SIZE,
    LINK_SIZE,
    POSE_SIZE,
    REDUNDANT,
    RPR_PIVOTS_CLOSE,
    RRP_GUIDE_FAR,
    RRR_APART,
    SOLVED,
    TWO_PI,
)

# ---------------------------------------------------------------------------------------------------------------
# A cam follower's law (mechanisms/cam_laws.py describes the laws; this is their one implementation)


def law_at(theta, program, at):
    """(s, s', s'') of the law at `at` in the program [n, then n pieces of 7 floats: start [rad], length [rad], code,
    a, b, c, d] at cam angle theta [rad] (taken within [0, 2 pi)): in the piece that holds theta, t = theta - start,
    x = t / length in [0, 1], code 0 a dwell s = a; 1 uniform, 2 harmonic, 3 cycloidal, 4 polynomial_345:
    s = a + b f(x), s' = b f'(x) / length, s'' = b f''(x) / length^2 (cam_laws.py's f); 5 a cubic (a table's
    spline) s = a + b t + c t^2 + d t^3. Self-contained (math only): the generated code nests this very source."""
    two_pi = 2.0 * math.pi
    x = theta - two_pi * math.floor(theta / two_pi)
    low, high = 0, int(program[at]) - 1
    while low < high:  # the last piece starting at or before x
        middle = (low + high + 1) // 2
        if program[at + 1 + 7 * middle] <= x:
            low = middle
        else:
            high = middle - 1
    k = at + 1 + 7 * low
    t, length, code, a, b = x - program[k], program[k + 1], program[k + 2], program[k + 3], program[k + 4]
    if code == 0.0:
        return a, 0.0, 0.0
    if code == 5.0:
        c, d = program[k + 5], program[k + 6]
        return a + t * (b + t * (c + t * d)), b + t * (2.0 * c + 3.0 * d * t), 2.0 * c + 6.0 * d * t
    u = min(max(t / length, 0.0), 1.0)
    if code == 1.0:
        f, df, ddf = u, 1.0, 0.0
    elif code == 2.0:
        f = 0.5 * (1.0 - math.cos(math.pi * u))
        df, ddf = 0.5 * math.pi * math.sin(math.pi * u), 0.5 * math.pi * math.pi * math.cos(math.pi * u)
    elif code == 3.0:
        f = u - math.sin(two_pi * u) / two_pi
        df, ddf = 1.0 - math.cos(two_pi * u), two_pi * math.sin(two_pi * u)
    else:
        f = u * u * u * (10.0 - 15.0 * u + 6.0 * u * u)
        df, ddf = 30.0 * u * u * (1.0 - u) * (1.0 - u), 60.0 * u * (1.0 - u) * (1.0 - 2.0 * u)
    return a + b * f, b * df / length, b * ddf / (length * length)


def _place_cam_follower(program, g, poses):
    """Set the poses, with their phi-derivatives, of the cam follower group at g (and its roller's, turning with
    it) from its law at the cam's angle: translating, theta = alpha, r = G + (d0 + s) u - p e^{i alpha}
    (r' = s' u, r'' = s'' u); oscillating, theta = theta0 + sigma s, r = Q - p e^{i theta} (Q, p its pivot on the
    frame and on itself); the roller pinned at the follower's point of their joint (linkage/cam.py)."""
    sigma, follower, roller = program[g + 1], int(program[g + 2]), int(program[g + 3])
    guide, pin, cam = g + 4, g + 4 + JOINT_SIZE, g + 4 + 2 * JOINT_SIZE
    phi = poses[POSE_SIZE * int(program[cam + 1]) + 2]
    s, ds, dds = law_at(phi - program[cam + 4], program, cam + int(program[cam + 3]))
    k = POSE_SIZE * follower
    if program[guide] != 0.0:  # translating
        theta = program[guide + 9]
        turn = _unit(theta)
        u = _direction(program, guide)
        r = _point(program, guide, poses, 0) + (program[cam + 5] + s) * u - _local(program, guide, follower) * turn
        _set_pose(poses, follower, r, theta, turn)
        poses[k + 3], poses[k + 4], poses[k + 5] = (ds * u).real, (ds * u).imag, 0.0
        poses[k + 6], poses[k + 7], poses[k + 8] = (dds * u).real, (dds * u).imag, 0.0
    else:
        theta = program[cam + 5] + sigma * s
        turn = _unit(theta)
        q = _local(program, guide, follower) * turn
        dtheta, ddtheta = sigma * ds, sigma * dds
        _set_pose(poses, follower, _point(program, guide, poses, 0) - q, theta, turn)
        dr, ddr = -1j * dtheta * q, -complex(-dtheta * dtheta, ddtheta) * q
        poses[k + 3], poses[k + 4], poses[k + 5] = dr.real, dr.imag, dtheta
        poses[k + 6], poses[k + 7], poses[k + 8] = ddr.real, ddr.imag, ddtheta
    if roller >= 0:
        P, dP, ddP = motion(poses, follower, _local(program, pin, follower))
        q = _local(program, pin, roller) * turn
        dtheta, ddtheta = poses[k + 5], poses[k + 8]
        _set_pose(poses, roller, P - q, theta, turn)
        dr, ddr = dP - 1j * dtheta * q, ddP - complex(-dtheta * dtheta, ddtheta) * q
        m = POSE_SIZE * roller
        poses[m + 3], poses[m + 4], poses[m + 5] = dr.real, dr.imag, dtheta
        poses[m + 6], poses[m + 7], poses[m + 8] = ddr.real, ddr.imag, ddtheta


def cam_springs(program, base, poses):
    """The reduced moment [N m] of the cam followers' springs at the crank angle of the poses: the sum of
    -(F0 + k s) s' over the cam follower groups (linkage/cam.py)."""
    moment = 0.0
    g = base + HEADER_SIZE + LINK_SIZE * int(program[base])
    for _ in range(int(program[base + 1])):
        if int(program[g]) == CAM_FOLLOWER:
            cam = g + 4 + 2 * JOINT_SIZE
            phi = poses[POSE_SIZE * int(program[cam + 1]) + 2]
            s, ds, _ = law_at(phi - program[cam + 4], program, cam + int(program[cam + 3]))
            moment -= (program[cam + 7] + program[cam + 6] * s) * ds
        g += GROUP_SIZE
    return moment


# ---------------------------------------------------------------------------------------------------------------
# Points and poses


def _local(program, j, link):
    """The point of the joint record at j in the coordinates of `link` (one of its two links) [m]."""
    if int(program[j + 1]) == link:
        return complex(program[j + 3], program[j + 4])
    return complex(program[j + 5], program[j + 6])


def _other(program, j, link):
    """The link the joint record at j joins to `link`."""
    a = int(program[j + 1])
    return int(program[j + 2]) if a == link else a


def _unit(angle):
    """e^{i angle} = cos(angle) + i sin(angle)."""
    return complex(math.cos(angle), math.sin(angle))


def _direction(program, j):
    """The unit direction u of the prismatic joint j's guide line, in the guide's coordinates."""
    return complex(program[j + 7], program[j + 8])


def _origin(poses, link):
    """The position r [m] of a link's coordinate origin."""
    return complex(poses[POSE_SIZE * link], poses[POSE_SIZE * link + 1])


def _turn(poses, link):
    """e^{i theta} of a link, kept with its pose."""
    return complex(poses[POSE_SIZE * link + 9], poses[POSE_SIZE * link + 10])


def _point(program, j, poses, link):
    """Global position [m] of the joint j's point on `link`: r + p e^{i theta}."""
    return _origin(poses, link) + _local(program, j, link) * _turn(poses, link)


def _set_pose(poses, link, r, theta, turn):
    """Store a link's position: origin r [m], angle theta [rad] and turn = e^{i theta}."""
    k = POSE_SIZE * link
    poses[k], poses[k + 1], poses[k + 2], poses[k + 9], poses[k + 10] = r.real, r.imag, theta, turn.real, turn.imag


def _pin(program, j, poses, link, at, theta):
    """Set the pose of `link` with angle theta (taken in [-pi, pi]) and its point of joint j at `at`:
    r = at - p e^{i theta}."""
    theta = theta - TWO_PI * math.floor(theta / TWO_PI + 0.5)
    turn = _unit(theta)
    _set_pose(poses, link, at - _local(program, j, link) * turn, theta, turn)


def _swing(program, pivot, tip, poses, link, P, T):
    """Set the pose of `link` whose point of joint `pivot` is at P and of joint `tip` at T (|T - P| its own)."""
    theta = cmath.phase(T - P) - cmath.phase(_local(program, tip, link) - _local(program, pivot, link))
    _pin(program, pivot, poses, link, P, theta)


def _angle_across(program, j, known, theta_known):
    """The angle [rad] of the link the prismatic joint j joins to `known`: theta_slider = theta_guide + alpha."""
    if int(program[j + 1]) == known:
        return theta_known + program[j + 9]
    return theta_known - program[j + 9]


def _origin_line(program, j, poses, unknown, turn):
    """(c, w): the line c + s w (w unit) on which the origin r of `unknown` lies, that link having the angle
    theta (turn = e^{i theta}) and being joined by the prismatic joint j to a known link.
    Slider unknown: its point must lie on the guide line G + t w -> r = G - p_s e^{i theta} + t w.
    Guide unknown: the slider's point S = r + (p_g + t u) e^{i theta} -> r = S - p_g e^{i theta} - t w."""
    guide, slider = int(program[j + 1]), int(program[j + 2])
    u = _direction(program, j)
    if unknown == slider:
        w = u * _turn(poses, guide)
        return _point(program, j, poses, guide) - _local(program, j, slider) * turn, w
    return _point(program, j, poses, slider) - _local(program, j, guide) * turn, u * turn


def _lines_cross(w1, w2):
    """Im(w1 conj w2): zero for parallel lines."""
    return (w1 * w2.conjugate()).imag


def _lines_meet(c1, w1, c2, w2):
    """Intersection of the lines c1 + s w1 and c2 + t w2: `s = Im((c2 - c1) conj w2) / Im(w1 conj w2)`."""
    return c1 + w1 * ((c2 - c1) * w2.conjugate()).imag / _lines_cross(w1, w2)


# ---------------------------------------------------------------------------------------------------------------
# Position of a group in closed form (groups.py's module docstring)


def place_group(program, g, poses):
    """Set the positions of the links of the group at g, the links it joins being known; returns (status, three
    numbers explaining it) (module docstring: SOLVED, RRR_APART, ...)."""
    kind, sigma = int(program[g]), program[g + 1]
    L1, L2 = int(program[g + 2]), int(program[g + 3])
    E1, Ji, E2 = g + 4, g + 4 + JOINT_SIZE, g + 4 + 2 * JOINT_SIZE
    if kind == CAM_FOLLOWER:  # placed with its derivatives (differentiate_group leaves it)
        _place_cam_follower(program, g, poses)
        return SOLVED, 0.0, 0.0, 0.0
    if kind == REDUNDANT:
        _swing(
            program,
            E1,
            Ji,
            poses,
            L1,
            _point(program, E1, poses, _other(program, E1, L1)),
            _point(program, Ji, poses, _other(program, Ji, L1)),
        )
        return SOLVED, 0.0, 0.0, 0.0
    if kind == GEAR:  # theta_L = theta_c + k (theta_G - theta_c) + phase_L, L's pivot on its known link
        theta = _gear_angle(program, g, poses, 2)
        turn = _unit(theta)
        _set_pose(
            poses, L1, _point(program, E1, poses, _other(program, E1, L1)) - _local(program, E1, L1) * turn, theta, turn
        )
        return SOLVED, 0.0, 0.0, 0.0
    K1, K2 = _other(program, E1, L1), _other(program, E2, L2)
    if kind == 0 or kind == 1:  # RRR, RRP
        B = _point(program, E1, poses, K1)
        l1 = abs(_local(program, Ji, L1) - _local(program, E1, L1))
        if kind == 0 and sigma == 0.0:  # the parallelogram P B C D: C = D + (B - P)
            D = _point(program, E2, poses, K2)
            C = D + complex(program[E1 + 7], program[E1 + 8]) * _turn(poses, K1)
            _swing(program, E2, Ji, poses, L2, D, C)
        elif kind == 0:
            D = _point(program, E2, poses, K2)
            l2 = abs(_local(program, Ji, L2) - _local(program, E2, L2))
            v = D - B
            f = abs(v)
            cos_B = (l1 * l1 + f * f - l2 * l2) / (2.0 * l1 * f) if f > 0.0 else math.inf
            if not -1.0 <= cos_B <= 1.0:
                return RRR_APART, f, abs(l1 - l2), l1 + l2
            C = B + l1 * _unit(cmath.phase(v) + sigma * math.acos(cos_B))
            _swing(program, E2, Ji, poses, L2, D, C)
        else:
            theta2 = _angle_across(program, E2, K2, poses[POSE_SIZE * K2 + 2])
            turn2 = _unit(theta2)
            c, w = _origin_line(program, E2, poses, L2, turn2)
            m = c + _local(program, Ji, L2) * turn2 - B
            along = (m * w.conjugate()).real
            discriminant = along * along - abs(m) ** 2 + l1 * l1
            if discriminant < 0.0:
                return RRP_GUIDE_FAR, math.sqrt(abs(m) ** 2 - along * along), l1, 0.0
            C = m + B + w * (-along + sigma * math.sqrt(discriminant))
            _pin(program, Ji, poses, L2, C, theta2)
        _swing(program, E1, Ji, poses, L1, B, C)
        return SOLVED, 0.0, 0.0, 0.0
    if kind == 2:  # RPR
        guide, slider = int(program[Ji + 1]), int(program[Ji + 2])
        pivot_g, pivot_s = (E1, E2) if guide == L1 else (E2, E1)
        Pg = _point(program, pivot_g, poses, _other(program, pivot_g, guide))
        Ps = _point(program, pivot_s, poses, _other(program, pivot_s, slider))
        u = _direction(program, Ji)
        alpha = program[Ji + 9]
        # The line's offset from the pivots, in the guide's coordinates: h = Im((p_g[pivot] - p_g[J]
        # + (p_s[J] - p_s[pivot]) e^{i alpha}) conj u).
        h = (
            (
                _local(program, pivot_g, guide)
                - _local(program, Ji, guide)
                + (_local(program, Ji, slider) - _local(program, pivot_s, slider)) * _unit(alpha)
            )
            * u.conjugate()
        ).imag
        rho = abs(Ps - Pg)
        if rho < abs(h) or rho == 0.0:
            return RPR_PIVOTS_CLOSE, abs(h), rho, 0.0
        a = math.asin(-h / rho)
        theta_g = cmath.phase(Ps - Pg) - cmath.phase(u) - (a if sigma > 0 else math.pi - a)
        _pin(program, pivot_g, poses, guide, Pg, theta_g)
        _pin(program, pivot_s, poses, slider, Ps, theta_g + alpha)
        return SOLVED, 0.0, 0.0, 0.0
    theta2 = _angle_across(program, E2, K2, poses[POSE_SIZE * K2 + 2])
    turn2 = _unit(theta2)
    if kind == 3:  # PRP
        theta1 = _angle_across(program, E1, K1, poses[POSE_SIZE * K1 + 2])
        turn1 = _unit(theta1)
        c1, w1 = _origin_line(program, E1, poses, L1, turn1)
        c2, w2 = _origin_line(program, E2, poses, L2, turn2)
        if abs(_lines_cross(w1, w2)) < 1e-12:
            return GUIDES_PARALLEL, 0.0, 0.0, 0.0
        C = _lines_meet(c1 + _local(program, Ji, L1) * turn1, w1, c2 + _local(program, Ji, L2) * turn2, w2)
        _pin(program, Ji, poses, L1, C, theta1)
        _pin(program, Ji, poses, L2, C, theta2)
        return SOLVED, 0.0, 0.0, 0.0
    # RPP: L1 pinned at B with the angle its prismatic internal joint gives it from L2's.
    theta1 = _angle_across(program, Ji, L2, theta2)
    _pin(program, E1, poses, L1, _point(program, E1, poses, K1), theta1)
    c1, w1 = _origin_line(program, Ji, poses, L2, turn2)
    c2, w2 = _origin_line(program, E2, poses, L2, turn2)
    if abs(_lines_cross(w1, w2)) < 1e-12:
        return GUIDES_PARALLEL, 0.0, 0.0, 0.0
    _set_pose(poses, L2, _lines_meet(c1, w1, c2, w2), theta2, turn2)
    return SOLVED, 0.0, 0.0, 0.0


def gear_ratio(program, g):
    """k = rho_G / rho_L of the gear group at g: (theta_L - theta_c)' over (theta_G - theta_c)'."""
    mesh = g + 4 + JOINT_SIZE
    if int(program[mesh + 2]) == int(program[g + 2]):
        return program[mesh + 7] / program[mesh + 8]
    return program[mesh + 8] / program[mesh + 7]


def _gear_angle(program, g, poses, slot):
    """The gear group's link angle (slot 2), or its first or second phi-derivative (slots 5, 8), from its driver's
    and carrier's: `theta_L = theta_c + k (theta_G - theta_c) + phase_L` (the phase in the angle only)."""
    mesh = g + 4 + JOINT_SIZE
    carrier = POSE_SIZE * int(program[mesh + 9]) + slot
    driver = POSE_SIZE * _other(program, mesh, int(program[g + 2])) + slot
    value = poses[carrier] + gear_ratio(program, g) * (poses[driver] - poses[carrier])
    return value + program[g + 1] if slot == 2 else value


def motion(poses, link, point):
    """(P, P', P'') of the point `point` (link coordinates [m]) of a link: P = r + q, P' = r' + i theta' q,
    P'' = r'' + (i theta'' - theta'^2) q, q = point e^{i theta}."""
    k = POSE_SIZE * link
    q = point * _turn(poses, link)
    return (
        complex(poses[k], poses[k + 1]) + q,
        complex(poses[k + 3], poses[k + 4]) + 1j * poses[k + 5] * q,
        complex(poses[k + 6], poses[k + 7]) + complex(-poses[k + 5] * poses[k + 5], poses[k + 8]) * q,
    )
