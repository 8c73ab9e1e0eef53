"""The general linkage solver, flat: a float64 program vector (`encode`) and plain functions over it in the subset
numba compiles (scalars, complex numbers, float arrays; no dicts or objects). It places the groups for the structure
checks, the kinematics tables, the point motions and the messages of a group that fails; what a machine integrates
(the reduction, the kinetostatics joint friction reads) runs as code generated per kind of linkage (symbolic.py),
which this solver's `reduced` and `joint_loads` check independently (the tests).

`reduced(phi, program, base)` gives the linkage's reduced quantities (J_links, dJ/dphi, M_weight, q, dq/dphi) of
mechanisms/__init__.py; `solve_poses` the links' poses and their phi-derivatives group by group, returning a status
(and the group and numbers that explain it) instead of raising, so the callers write the message (kinematics.py).
Each function is plain Python; `compiled(name)` gives its numba-compiled form (on first use: numba is imported only
then, so the package loads without it; the functions are registered with numba.extending.register_jitable so that
compiled code calls them compiled; numba's disk cache keeps them, compiled once per machine). Nothing below
`reduced` and `joint_loads` allocates: `solve_poses` and `kinetostatics` work in the arrays they are given, and
`reduced` and `joint_loads` allocate one workspace per call for them (`joint_loads` also its three results).

The equations (module docstring of groups.py, docs/theory.md §5.3): a link's pose is (r, theta), its point p at
`P = r + p e^{i theta}`; every pose carries POSE_SIZE floats [x, y, theta, x', y', theta', x'', y'', theta'',
cos theta, sin theta] (derivatives with respect to the crank angle phi; e^{i theta} kept so that it is computed once
per link). Per group: position in closed form (RRR, RRP, RPR, PRP, RPP, a redundant link), then `A u' = -K k'` and
`A u'' = -K k'' - gamma` from the joints' constraint rows (`joint_rows`, `joint_quadratic`), A inverted by
elimination in closed form (`invert_dyad`: each external joint's 2 x 3 rows, then a 2 x 2 system for the internal
joint; a redundant link's consistent 4 x 3 system by its pseudo-inverse (A^T A)^-1 A^T, the 3 x 3 by its
cofactors), refused as a dead point when A is exactly singular or |A|_max |A^-1|_max > DEAD_POINT_CONDITION.

Program layout (indices into the vector from `base`; link 0 is the frame, the moving links follow in the linkage's
order; a joint record is JOINT_SIZE floats [kind (0 revolute, 1 prismatic), link a, link b, p_a (x, y), p_b (x, y),
the guide's direction u (cos, sin), slider_angle], a and b as in model.Joint.links, p_a, p_b the joint's point in
each link [m]; a gear mesh's record (kind GEAR_MESH) [kind, a, b, the centres O_a, O_b in their links (x, y) [m],
the signed pitch radii rho_a, rho_b [m], the carrier link] (gears.py's module docstring)):
  header: number of links, number of groups, crank link, output kind (0 none, 1 link angle, 2 prismatic joint
  travel), output link, output joint record, gravity (gx, gy) [m/s^2], the output reference angle [rad] (a link
  output's angle is reported within pi of it, model.Linkage.output_reference), the crank pivot on the frame (x, y)
  [m] and on the crank (x, y) [m];
  per link LINK_SIZE floats: mass [kg], centre of mass (x, y) [m, own coordinates], inertia about it [kg m^2];
  per group GROUP_SIZE floats: kind code (KIND_CODES; REDUNDANT; GEAR; CAM_FOLLOWER), branch (+1 or -1; 0 an RRR
  group kept a parallelogram, groups.Dyad, its E1 record's u slots then holding B - P in B's known link [m]; a
  gear's phase_L [rad]), link L1, link L2 (-1 for a redundant link or a gear), then three joint records: E1,
  internal, E2 (a redundant link: its two joints, then zeros; a gear: its pivot, its mesh, then zeros; a cam
  follower (CAM_FOLLOWER, branch sigma, follower, roller or -1): its guide's record, its roller joint's (or zeros),
  then the cam record [CAM_CONTACT, cam, the touching link, the law's position relative to this record, the crank
  angle at the law's start [rad], the follower's travel d0 [m] (translating) or angle theta0 [rad] (oscillating) at
  s = 0, the spring's stiffness and preload, 0, 0]);
  the joint map (what the kinetostatics reports per joint): the number of the linkage's joints, the crank pivot's
  joint record, then per joint in the linkage's order (model.Linkage.joints) the position of its record from
  `base` and its multiplier slot (joint k of group number n: 3 n + k; the crank pivot: 3 n_groups; -1, -1 for a
  joint of none of the groups given, as while the structure is still being found);
  then each cam follower's law: its number of pieces and PIECE_SIZE floats per piece (law_at).

The kinetostatics by groups (source 001, chapter 3; linkage/kinetostatics.py describes it) is written here too:
`kinetostatics` gives the multipliers of every joint (a revolute joint's: the force on its first link from its
second, Fx, Fy [N]; a prismatic joint's: the normal force N on the slider along i w [N] and the couple on it [N m])
and the balancing moment for two load cases at once, (omega, epsilon = 0, Q, with gravity) and (0, 1, 0, without),
whose sum weighted (1, epsilon) is any state's (the reactions are linear in (omega^2, epsilon, g, Q));
`joint_loads` turns them into what joint friction reads (mechanisms.kinetostatics.JointLoads).
"""

from __future__ import annotations

import cmath
import functools
import math
import sys
import time

import numpy as np

from mech_regulator import cache

KIND_CODES = {"RRR": 0, "RRP": 1, "RPR": 2, "PRP": 3, "RPP": 4}
REDUNDANT = 5
GEAR = 6  # a gear group (gears.GearGroup): one link on its pivot, turned by its mesh
CAM_FOLLOWER = 7  # a cam follower group (linkage/cam.py), placed by its law (law_at)
GEAR_MESH = 2.0  # a gear mesh's joint record kind
CAM_CONTACT = 3.0  # a cam pair's joint record kind
PIECE_SIZE = 7  # a law piece: [start, length, code, a, b, c, d] (law_at)
JOINT_SIZE = 10
LINK_SIZE = 4
GROUP_SIZE = 4 + 3 * JOINT_SIZE
POSE_SIZE = 11
HEADER_SIZE = 5 + JOINT_SIZE + 7
OUTPUT_REFERENCE = 7 + JOINT_SIZE  # the header's output reference angle (module docstring)
SCRATCH_SHAPE = (14, 6)  # differentiate_group's A, A^-1, K k' and K k''
DEAD_POINT_CONDITION = 1e10  # condition of a group's equations beyond which its ratios count as infinite [-]
TWO_PI = 2.0 * math.pi

# solve_poses' status: what stopped the solution at a group (the numbers returned with it in brackets)
SOLVED = 0
RRR_APART = 1  # [distance of the external joints, |l1 - l2|, l1 + l2] [m]
RRP_GUIDE_FAR = 2  # [distance of the guide from E1, l1] [m]
RPR_PIVOTS_CLOSE = 3  # [the guide's offset |h|, the pivots' distance rho] [m]
GUIDES_PARALLEL = 4  # []
DEAD_POINT = 5  # []


# ---------------------------------------------------------------------------------------------------------------
# Encoding (plain Python: builds the program once per linkage)


def joint_record(linkage, joint, index: dict[str, int]) -> list[float]:
    """A joint's JOINT_SIZE floats (module docstring)."""
    a, b = joint.links
    pa, pb = linkage.link(a).points[joint.name], linkage.link(b).points[joint.name]
    return [
        0.0 if joint.kind == "revolute" else 1.0,
        float(index[a]),
        float(index[b]),
        pa.real,
        pa.imag,
        pb.real,
        pb.imag,
        math.cos(joint.direction),
        math.sin(joint.direction),
        joint.slider_angle,
    ]


def gear_record(linkage, group, index: dict[str, int]) -> list[float]:
    """A gear group's mesh record (module docstring)."""
    mesh = group.mesh
    a, b = mesh.links
    O_a, O_b = (linkage.link(link).points[centre] for link, centre in zip(mesh.links, mesh.gear.centres))
    return [
        GEAR_MESH,
        float(index[a]),
        float(index[b]),
        O_a.real,
        O_a.imag,
        O_b.real,
        O_b.imag,
        *group.pitch,
        float(index[group.carrier]),
    ]


def link_indices(linkage) -> dict[str, int]:
    """Each link's index in the program: the frame 0, the moving links 1, 2, ... in the linkage's order."""
    return {name: index for index, name in enumerate([linkage.frame] + linkage.moving_links())}


def encode(linkage, groups, gravity: tuple[float, float] | None) -> np.ndarray:
    """The program vector of a linkage (model.Linkage) solved by these groups (structure.Structure.groups, or the
    groups found so far), gravity (gx, gy) [m/s^2] or None (no weight moment); layout in the module docstring."""
    index = link_indices(linkage)
    pivot = linkage.crank_pivot()
    output_kind, output_link, output_joint = 0.0, 0.0, [0.0] * JOINT_SIZE
    if linkage.output_link is not None:
        output_kind, output_link = 1.0, float(index[linkage.output_link])
    elif linkage.output_joint is not None:
        output_kind, output_joint = 2.0, joint_record(linkage, linkage.joint(linkage.output_joint), index)
    gx, gy = gravity if gravity is not None else (0.0, 0.0)
    on_frame = linkage.link(linkage.frame).points[pivot.name]
    on_crank = linkage.link(linkage.crank).points[pivot.name]
    program = [
        float(len(index)),
        float(len(groups)),
        float(index[linkage.crank]),
        output_kind,
        output_link,
        *output_joint,
        gx,
        gy,
        linkage.output_reference,
        on_frame.real,
        on_frame.imag,
        on_crank.real,
        on_crank.imag,
    ]
    for name in index:
        link = linkage.link(name)
        program += [link.mass, link.centre.real, link.centre.imag, link.inertia]
    for group in groups:
        if group.kind == "cam follower":
            program += _cam_follower_records(linkage, group, index)
            continue
        if group.kind == "redundant link":
            joints = [joint_record(linkage, joint, index) for joint in group.joints] + [[0.0] * JOINT_SIZE]
            program += [float(REDUNDANT), 0.0, float(index[group.link]), -1.0]
        elif group.kind == "gear":
            joints = [joint_record(linkage, group.pivot, index), gear_record(linkage, group, index), [0.0] * JOINT_SIZE]
            program += [float(GEAR), group.phase, float(index[group.link]), -1.0]
        else:
            joints = [joint_record(linkage, joint, index) for joint in group.joints]
            branch = float(group.branch)
            if group.parallelogram is not None:  # B - P on B's known link, in the E1 record's unused u slots
                known = linkage.link(group.externals[0].other(group.links[0])).points
                side = known[group.externals[0].name] - known[group.parallelogram.name]
                joints[0][7:9], branch = [side.real, side.imag], 0.0
            program += [
                float(KIND_CODES[group.kind]),
                branch,
                float(index[group.links[0]]),
                float(index[group.links[1]]),
            ]
        program += [value for record in joints for value in record]
    found = {
        joint.name: (len(program) - GROUP_SIZE * (len(groups) - number) + 4 + JOINT_SIZE * k, 3 * number + k)
        for number, group in enumerate(groups)
        for k, joint in enumerate(group.joints)
    }
    program += [float(len(linkage.joints)), *joint_record(linkage, pivot, index)]
    found[pivot.name] = (len(program) - JOINT_SIZE, 3 * len(groups))
    for joint in linkage.joints:
        program += [float(value) for value in found.get(joint.name, (-1, -1))]
    for number, group in enumerate(groups):  # each cam follower's law, pointed to from its cam record
        if group.kind == "cam follower":
            record = HEADER_SIZE + LINK_SIZE * len(index) + GROUP_SIZE * number + 4 + 2 * JOINT_SIZE
            program[record + 3] = float(len(program) - record)
            pieces = group.pair.cam.law.pieces()
            program += [float(len(pieces))] + [value for piece in pieces for value in piece]
    return np.array(program, dtype=np.float64)


def _cam_follower_records(linkage, group, index: dict[str, int]) -> list[float]:
    """A cam follower group's GROUP_SIZE floats (module docstring); the law's position is filled in by encode."""
    spec = group.pair.cam
    sigma, zero = group.at_base
    roller = [0.0] * JOINT_SIZE if group.roller_joint is None else joint_record(linkage, group.roller_joint, index)
    cam = [
        CAM_CONTACT,
        float(index[group.pair.links[0]]),
        float(index[group.pair.links[1]]),
        0.0,
        spec.start,
        zero,
        spec.stiffness,
        spec.preload,
        0.0,
        0.0,
    ]
    return (
        [
            float(CAM_FOLLOWER),
            sigma,
            float(index[group.follower]),
            float(index[group.roller]) if group.roller is not None else -1.0,
        ]
        + joint_record(linkage, group.guide, index)
        + roller
        + cam
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


# ---------------------------------------------------------------------------------------------------------------
# Velocity and acceleration ratios


def joint_rows(program, j, poses):
    """The partial derivatives of the joint j's two constraint equations by its links' (x, y, theta), 12 floats:
    row r at [6 r : 6 r + 6] = (by link a's x, y, theta, by link b's x, y, theta).
    Revolute, `r_a + q_a - r_b - q_b = 0` (q = p e^{i theta}): its real and imaginary parts.
    Prismatic (guide a, slider b): the line `Im(d conj w) = 0`, d = P_s - P_g, w = u e^{i theta_g}, and the angle
    `theta_s - theta_g - alpha = 0`. Gear mesh (gears.py): rolling at the pitch point, `t . O_a' + rho_a theta_a' -
    t . O_b' - rho_b theta_b' = 0`, u = (O_b - O_a) / |O_b - O_a|, t = i u, O = r + q: by a (t_x, t_y, rho_a + u . q_a),
    by b (-t_x, -t_y, -rho_b - u . q_b); its second row zero (its multiplier: the tooth force along t on a [N])."""
    a, b = int(program[j + 1]), int(program[j + 2])
    qa = _local(program, j, a) * _turn(poses, a)
    qb = _local(program, j, b) * _turn(poses, b)
    if program[j] == 0.0:
        return (1.0, 0.0, -qa.imag, -1.0, 0.0, qb.imag, 0.0, 1.0, qa.real, 0.0, -1.0, -qb.real)
    if program[j] == GEAR_MESH:
        line = _origin(poses, b) + qb - _origin(poses, a) - qa
        u = line / abs(line)
        return (
            -u.imag,
            u.real,
            program[j + 7] + (qa * u.conjugate()).real,
            u.imag,
            -u.real,
            -program[j + 8] - (qb * u.conjugate()).real,
            0.0,
            0.0,
            0.0,
            0.0,
            0.0,
            0.0,
        )
    w = _direction(program, j) * _turn(poses, a)
    d = _origin(poses, b) + qb - _origin(poses, a) - qa
    return (
        w.imag,
        -w.real,
        -((qa + d) * w.conjugate()).real,
        -w.imag,
        w.real,
        (qb * w.conjugate()).real,
        0.0,
        0.0,
        -1.0,
        0.0,
        0.0,
        1.0,
    )


def joint_quadratic(program, j, poses):
    """The terms of the joint j's twice-differentiated constraints quadratic in the first derivatives (gamma).
    Revolute: `-theta_a'^2 q_a + theta_b'^2 q_b`. Prismatic line: `Im((theta_g'^2 q_g - theta_s'^2 q_s) conj w)
    - 2 theta_g' Re(d' conj w)`, d' = r_s' + i theta_s' q_s - r_g' - i theta_g' q_g (the term -theta_g'^2 Im(d conj w)
    vanishes on the line); the angle: 0."""
    a, b = int(program[j + 1]), int(program[j + 2])
    ka, kb = POSE_SIZE * a, POSE_SIZE * b
    dta, dtb = poses[ka + 5], poses[kb + 5]
    qa = _local(program, j, a) * _turn(poses, a)
    qb = _local(program, j, b) * _turn(poses, b)
    if program[j] == 0.0:
        gamma = -dta * dta * qa + dtb * dtb * qb
        return gamma.real, gamma.imag
    w = _direction(program, j) * _turn(poses, a)
    dd = complex(poses[kb + 3], poses[kb + 4]) + 1j * dtb * qb - complex(poses[ka + 3], poses[ka + 4]) - 1j * dta * qa
    line = ((dta * dta * qa - dtb * dtb * qb) * w.conjugate()).imag - 2.0 * dta * (dd * w.conjugate()).real
    return line, 0.0


def _enter(A, known, row, link, by_x, by_y, by_theta, L1, L2, poses):
    """Enter a constraint row's partial derivatives by `link`'s (x, y, theta) into the group's A (columns 0-2 for
    L1, 3-5 for L2) or, `link` being known, its terms into known[0, row] (K k') and known[1, row] (K k'')."""
    column = 0 if link == L1 else (3 if link == L2 else -1)
    if column >= 0:
        A[row, column], A[row, column + 1], A[row, column + 2] = by_x, by_y, by_theta
    else:
        k = POSE_SIZE * link
        known[0, row] += by_x * poses[k + 3] + by_y * poses[k + 4] + by_theta * poses[k + 5]
        known[1, row] += by_x * poses[k + 6] + by_y * poses[k + 7] + by_theta * poses[k + 8]


def group_matrix(program, g, poses, A, known):
    """Fill the group's A (its rows by its unknown links' (x, y, theta): 6 x 6, a redundant link's 4 x 3 in the top
    left of A) and the known links' terms of each row, K k' in known[0] and K k'' in known[1]; returns the number
    of rows. A dyad's rows: its external joint E1 (rows 0, 1, only L1's columns 0-2), its internal joint (rows 2,
    3), its external joint E2 (rows 4, 5, only L2's columns 3-5)."""
    L1, L2 = int(program[g + 2]), int(program[g + 3])
    n_joints = 2 if int(program[g]) == REDUNDANT else 3
    for row in range(2 * n_joints):
        for column in range(A.shape[1]):
            A[row, column] = 0.0
        known[0, row] = known[1, row] = 0.0
    for joint in range(n_joints):
        j = g + 4 + JOINT_SIZE * joint
        a, b = int(program[j + 1]), int(program[j + 2])
        rows = joint_rows(program, j, poses)
        _enter(A, known, 2 * joint, a, rows[0], rows[1], rows[2], L1, L2, poses)
        _enter(A, known, 2 * joint, b, rows[3], rows[4], rows[5], L1, L2, poses)
        _enter(A, known, 2 * joint + 1, a, rows[6], rows[7], rows[8], L1, L2, poses)
        _enter(A, known, 2 * joint + 1, b, rows[9], rows[10], rows[11], L1, L2, poses)
    return 2 * n_joints


def _row3(A, row, column):
    """The three entries A[row, column : column + 3] as a tuple."""
    return A[row, column], A[row, column + 1], A[row, column + 2]


def _dot3(u, v):
    """u . v of two 3-vectors."""
    return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]


def _cross3(u, v):
    """u x v of two 3-vectors."""
    return u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]


def _scaled3(u, factor):
    """factor u of a 3-vector."""
    return u[0] * factor, u[1] * factor, u[2] * factor


def _null_and_right_inverse(first, second):
    """For the 2 x 3 rows (first, second) of an external joint on its link (rank 2: a revolute joint's rows
    (1, 0, .), (0, 1, .), a prismatic's (w_y, -w_x, .), (0, 0, -+1)): their null vector n = first x second and the
    two columns of a right inverse, c1 = (second x n) / |n|^2, c2 = (n x first) / |n|^2 (first . c1 = second . c2 =
    1, first . c2 = second . c1 = 0)."""
    n = _cross3(first, second)
    scale = 1.0 / _dot3(n, n)
    return n, _scaled3(_cross3(second, n), scale), _scaled3(_cross3(n, first), scale)


def invert_dyad(A, inverse):
    """Fill `inverse` with the 6 x 6 A^-1 of a dyad (group_matrix's row blocks) by elimination: the external rows
    give each link's unknowns as u1 = P1 b_E1 + s1 n1, u2 = P2 b_E2 + s2 n2 (_null_and_right_inverse), the internal
    rows (a1 | a2) then the 2 x 2 system M (s1, s2) = b_I - a1 P1 b_E1 - a2 P2 b_E2, M = (a1 n1 | a2 n2), solved by
    Cramer's rule for each unit right-hand side b = e_column; False for an exactly singular M (then A is)."""
    n1, c1, c2 = _null_and_right_inverse(_row3(A, 0, 0), _row3(A, 1, 0))
    n2, d1, d2 = _null_and_right_inverse(_row3(A, 4, 3), _row3(A, 5, 3))
    a1_first, a1_second, a2_first, a2_second = _row3(A, 2, 0), _row3(A, 3, 0), _row3(A, 2, 3), _row3(A, 3, 3)
    m11, m12, m21, m22 = _dot3(a1_first, n1), _dot3(a2_first, n2), _dot3(a1_second, n1), _dot3(a2_second, n2)
    determinant = m11 * m22 - m12 * m21
    if determinant == 0.0:
        return False
    zero = (0.0, 0.0, 0.0)
    for column in range(6):
        p1 = c1 if column == 0 else (c2 if column == 1 else zero)
        p2 = d1 if column == 4 else (d2 if column == 5 else zero)
        t1 = (1.0 if column == 2 else 0.0) - _dot3(a1_first, p1) - _dot3(a2_first, p2)
        t2 = (1.0 if column == 3 else 0.0) - _dot3(a1_second, p1) - _dot3(a2_second, p2)
        s1 = (m22 * t1 - m12 * t2) / determinant
        s2 = (m11 * t2 - m21 * t1) / determinant
        for k in range(3):
            inverse[k, column] = p1[k] + s1 * n1[k]
            inverse[3 + k, column] = p2[k] + s2 * n2[k]
    return True


def _column_dot(A, first, second):
    """The sum over a redundant link's four rows of A[row, first] A[row, second]: an entry of A^T A."""
    return (
        A[0, first] * A[0, second]
        + A[1, first] * A[1, second]
        + A[2, first] * A[2, second]
        + A[3, first] * A[3, second]
    )


def pseudo_invert_redundant(A, inverse):
    """Fill inverse[0:3, 0:4] with the pseudo-inverse (A^T A)^-1 A^T of a redundant link's 4 x 3 A (exact on its
    consistent equations), the 3 x 3 N = A^T A inverted by its cofactors: the columns of N^-1 are (n2 x n3, n3 x n1,
    n1 x n2) / (n1 . (n2 x n3)), n_k the rows of N; False for an exactly singular N."""
    n1 = (_column_dot(A, 0, 0), _column_dot(A, 0, 1), _column_dot(A, 0, 2))
    n2 = (n1[1], _column_dot(A, 1, 1), _column_dot(A, 1, 2))
    n3 = (n1[2], n2[2], _column_dot(A, 2, 2))
    determinant = _dot3(n1, _cross3(n2, n3))
    if determinant == 0.0:
        return False
    columns = (_cross3(n2, n3), _cross3(n3, n1), _cross3(n1, n2))
    for r in range(3):
        for row in range(4):
            value = 0.0
            for c in range(3):
                value += columns[c][r] * A[row, c]
            inverse[r, row] = value / determinant
    return True


def _largest_magnitude(M, n_rows, n_columns):
    """max |M[row, column]| over the top left n_rows x n_columns of M."""
    largest = 0.0
    for row in range(n_rows):
        for column in range(n_columns):
            largest = max(largest, abs(M[row, column]))
    return largest


def _follow(program, j, poses, link, dtheta, ddtheta):
    """Set a link's theta' = dtheta and theta'' = ddtheta and its origin's derivatives from its point P of the
    revolute joint j on a known link: r' = P' - i theta' q, r'' = P'' - (i theta'' - theta'^2) q (q = p e^{i theta},
    p the joint's point in the link)."""
    k = POSE_SIZE * link
    known = _other(program, j, link)
    _, dP, ddP = motion(poses, known, _local(program, j, known))
    q = _local(program, j, link) * _turn(poses, link)
    dr, ddr = dP - 1j * dtheta * q, ddP - complex(-dtheta * dtheta, ddtheta) * q
    poses[k + 3], poses[k + 4], poses[k + 5] = dr.real, dr.imag, dtheta
    poses[k + 6], poses[k + 7], poses[k + 8] = ddr.real, ddr.imag, ddtheta


def differentiate_group(program, g, poses, scratch):
    """Set the first and second derivatives of the group's links' poses from `A u' = -K k'` and
    `A u'' = -K k'' - gamma` (module docstring), A and its inverse held in scratch (SCRATCH_SHAPE: A in rows 0-5,
    A^-1 in rows 6-11, K k' and K k'' in rows 12, 13); False at a dead point (A singular or its condition
    |A|_max |A^-1|_max beyond DEAD_POINT_CONDITION). A gear group's link: theta' and theta'' from its driver's and
    carrier's (_gear_angle), its origin from its pivot P's motion, r' = P' - i theta' q, r'' = P'' - (i theta'' -
    theta'^2) q (q = p e^{i theta}, p the pivot in the link); a parallelogram P B C D (an RRR group's branch 0):
    L1 turns with D's link and L2 with B's (C - B = D - P, C - D = B - P), each following its outer joint."""
    if int(program[g]) == CAM_FOLLOWER:  # its derivatives are its law's (_place_cam_follower)
        return True
    if int(program[g]) == GEAR:
        _follow(
            program,
            g + 4,
            poses,
            int(program[g + 2]),
            _gear_angle(program, g, poses, 5),
            _gear_angle(program, g, poses, 8),
        )
        return True
    if int(program[g]) == 0 and program[g + 1] == 0.0:  # a parallelogram: L1 turns with K2, L2 with K1
        L1, L2 = int(program[g + 2]), int(program[g + 3])
        K1, K2 = POSE_SIZE * _other(program, g + 4, L1), POSE_SIZE * _other(program, g + 4 + 2 * JOINT_SIZE, L2)
        _follow(program, g + 4, poses, L1, poses[K2 + 5], poses[K2 + 8])
        _follow(program, g + 4 + 2 * JOINT_SIZE, poses, L2, poses[K1 + 5], poses[K1 + 8])
        return True
    redundant = int(program[g]) == REDUNDANT
    n_unknown = 3 if redundant else 6
    n_rows = 4 if redundant else 6
    A, inverse, known = scratch[0:6], scratch[6:12], scratch[12:14]
    group_matrix(program, g, poses, A, known)
    if not (pseudo_invert_redundant(A, inverse) if redundant else invert_dyad(A, inverse)):
        return False
    if _largest_magnitude(inverse, n_unknown, n_rows) * _largest_magnitude(A, n_rows, n_unknown) > DEAD_POINT_CONDITION:
        return False
    links = (int(program[g + 2]), int(program[g + 3]))
    for order in range(1, 3):
        if order == 2:  # the first derivatives are known now: the right-hand side -(K k'' + gamma)
            for joint in range(n_rows // 2):
                line, other = joint_quadratic(program, g + 4 + JOINT_SIZE * joint, poses)
                known[1, 2 * joint] += line
                known[1, 2 * joint + 1] += other
        for unknown in range(n_unknown):
            value = 0.0
            for row in range(n_rows):
                value -= inverse[unknown, row] * known[order - 1, row]
            poses[POSE_SIZE * links[unknown // 3] + 3 * order + unknown % 3] = value
    return True


# ---------------------------------------------------------------------------------------------------------------
# The whole linkage


def solve_poses(phi, program, base, poses, scratch, derivatives):
    """Fill poses (POSE_SIZE per link, zeros for the frame) at crank angle phi [rad]: the crank's, theta = phi,
    r = A - p_A e^{i phi}, r' = -i p_A e^{i phi}, r'' = p_A e^{i phi}, theta' = 1, then each group's (with the
    derivatives if `derivatives`, worked out in `scratch`, an array of SCRATCH_SHAPE); returns (status, group number,
    three numbers) of the first group that fails (module docstring), (SOLVED, -1, 0, 0, 0) when all are solved."""
    for k in range(POSE_SIZE * int(program[base])):
        poses[k] = 0.0
    poses[9] = 1.0  # the frame's e^{i 0}
    crank = int(program[base + 2])
    pivot_frame = complex(program[base + HEADER_SIZE - 4], program[base + HEADER_SIZE - 3])
    turn = _unit(phi)
    pivot_crank = complex(program[base + HEADER_SIZE - 2], program[base + HEADER_SIZE - 1]) * turn
    k = POSE_SIZE * crank
    r, dr = pivot_frame - pivot_crank, -1j * pivot_crank
    _set_pose(poses, crank, r, phi, turn)
    poses[k + 3], poses[k + 4], poses[k + 5] = dr.real, dr.imag, 1.0
    poses[k + 6], poses[k + 7], poses[k + 8] = pivot_crank.real, pivot_crank.imag, 0.0
    g = base + HEADER_SIZE + LINK_SIZE * int(program[base])
    for group in range(int(program[base + 1])):
        status, first, second, third = place_group(program, g, poses)
        if status != SOLVED:
            return status, group, first, second, third
        if derivatives and not differentiate_group(program, g, poses, scratch):
            return DEAD_POINT, group, 0.0, 0.0, 0.0
        g += GROUP_SIZE
    return SOLVED, -1, 0.0, 0.0, 0.0


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


def near(angle, reference):
    """The angle [rad] plus the multiple of 2 pi that puts it within pi of `reference`:
    `angle - 2 pi floor((angle - reference) / (2 pi) + 1/2)`."""
    return angle - TWO_PI * math.floor((angle - reference) / TWO_PI + 0.5)


def reduced_from_poses(program, base, poses):
    """(J_links, dJ_links/dphi, M_weight, q, q') from solved poses: over the moving links k (the crank included)
    with centres S_k and angles theta_k, `J_links = sum m_k |S_k'|^2 + I_k theta_k'^2`, `dJ/dphi = 2 sum (m_k
    Re(conj(S_k') S_k'') + I_k theta_k' theta_k'')`, `M_weight = sum m_k g . S_k'` plus the cam followers' springs
    (cam_springs); the output q: a link's angle
    theta [rad] (within pi of the output reference angle, `near`) and theta', or a prismatic joint's travel `q = Re((P_s - P_g) conj w)` [m] (w the guide's direction),
    `q' = Re(d' conj w) + theta_g' Im(d conj w)`; (0, 0) without an output."""
    n_links = int(program[base])
    gravity = complex(program[base + 5 + JOINT_SIZE], program[base + 6 + JOINT_SIZE])
    J = dJ = weight = 0.0
    for link in range(1, n_links):
        record = base + HEADER_SIZE + LINK_SIZE * link
        mass, inertia = program[record], program[record + 3]
        _, dS, ddS = motion(poses, link, complex(program[record + 1], program[record + 2]))
        dtheta, ddtheta = poses[POSE_SIZE * link + 5], poses[POSE_SIZE * link + 8]
        J += mass * abs(dS) ** 2 + inertia * dtheta * dtheta
        dJ += 2.0 * (mass * (dS.conjugate() * ddS).real + inertia * dtheta * ddtheta)
        weight += mass * (gravity.conjugate() * dS).real
    weight += cam_springs(program, base, poses)
    output = program[base + 3]
    if output == 1.0:
        link = int(program[base + 4])
        return (
            J,
            dJ,
            weight,
            near(poses[POSE_SIZE * link + 2], program[base + OUTPUT_REFERENCE]),
            poses[POSE_SIZE * link + 5],
        )
    if output == 0.0:
        return J, dJ, weight, 0.0, 0.0
    j = base + 5
    guide, slider = int(program[j + 1]), int(program[j + 2])
    P_g, dP_g, _ = motion(poses, guide, _local(program, j, guide))
    P_s, dP_s, _ = motion(poses, slider, _local(program, j, slider))
    w = _direction(program, j) * _turn(poses, guide)
    d, dd = P_s - P_g, dP_s - dP_g
    return (
        J,
        dJ,
        weight,
        (d * w.conjugate()).real,
        (dd * w.conjugate()).real + poses[POSE_SIZE * guide + 5] * (d * w.conjugate()).imag,
    )


def reduced(phi, program, base):
    """The linkage's (J_links [kg m^2], dJ_links/dphi [kg m^2/rad], M_weight [N m], q, dq/dphi) at crank angle phi
    [rad] (reduced_from_poses), its program at `base` in `program`; NaNs where a group cannot assemble or is at a
    dead point (solve_poses tells which). Its one allocation per call holds the poses and the scratch."""
    n_poses = POSE_SIZE * int(program[base])
    workspace = np.empty(n_poses + SCRATCH_SHAPE[0] * SCRATCH_SHAPE[1])
    poses = workspace[:n_poses]
    if solve_poses(phi, program, base, poses, workspace[n_poses:].reshape(SCRATCH_SHAPE), True)[0] != SOLVED:
        return math.nan, math.nan, math.nan, math.nan, math.nan
    return reduced_from_poses(program, base, poses)


# ---------------------------------------------------------------------------------------------------------------
# Kinetostatics by groups (linkage/kinetostatics.py's module docstring)


def _planar_cross(u, v):
    """z component of the planar cross product u x v = Im(conj(u) v)."""
    return (u.conjugate() * v).imag


def joint_map(program, base):
    """The position in the program of the joint map (module docstring): its count of joints."""
    return base + HEADER_SIZE + LINK_SIZE * int(program[base]) + GROUP_SIZE * int(program[base + 1])


def _inertia_residuals(program, base, poses, omega, residual):
    """Fill residual[3 k : 3 k + 3, case] (k a link, zeros for the frame) with the d'Alembert terms of each moving
    link's equilibrium in its coordinates (x, y of its origin r, theta) for the two load cases: `m (a_S - g)`
    (x, y) and `I alpha + (S - r) x m (a_S - g)` (theta), with a_S = S'' omega^2, alpha = theta'' omega^2 and g
    (case 0, (omega, epsilon = 0)), a_S = S', alpha = theta' and no g (case 1, the rate with epsilon)."""
    n_links = int(program[base])
    gravity = complex(program[base + 5 + JOINT_SIZE], program[base + 6 + JOINT_SIZE])
    square = omega * omega
    for row in range(3):
        residual[row, 0] = residual[row, 1] = 0.0
    for link in range(1, n_links):
        record = base + HEADER_SIZE + LINK_SIZE * link
        mass, inertia = program[record], program[record + 3]
        centre = complex(program[record + 1], program[record + 2])
        _, dS, ddS = motion(poses, link, centre)
        to_centre = centre * _turn(poses, link)
        k = POSE_SIZE * link
        net = mass * (ddS * square - gravity)
        residual[3 * link, 0], residual[3 * link + 1, 0] = net.real, net.imag
        residual[3 * link + 2, 0] = inertia * poses[k + 8] * square + _planar_cross(to_centre, net)
        net = mass * dS
        residual[3 * link, 1], residual[3 * link + 1, 1] = net.real, net.imag
        residual[3 * link + 2, 1] = inertia * poses[k + 5] + _planar_cross(to_centre, net)


def _output_load(program, base, poses, force, residual):
    """Subtract load case 0's output load from the residuals: a moment Q [N m] on the output link, or a force
    Q w [N] on the output joint's slider at its point P_s and -Q w on the guide there (w the guide's direction; its
    power is Q q' omega); nothing without an output."""
    kind = program[base + 3]
    if force == 0.0 or kind == 0.0:
        return
    if kind == 1.0:
        residual[3 * int(program[base + 4]) + 2, 0] -= force
        return
    j = base + 5
    guide, slider = int(program[j + 1]), int(program[j + 2])
    at = _point(program, j, poses, slider)
    pull = force * _direction(program, j) * _turn(poses, guide)
    for side in range(2):
        link, sign = (slider, 1.0) if side == 0 else (guide, -1.0)
        if link != 0:
            residual[3 * link, 0] -= sign * pull.real
            residual[3 * link + 1, 0] -= sign * pull.imag
            residual[3 * link + 2, 0] -= sign * _planar_cross(at - _origin(poses, link), pull)


def _solve_group_reactions(program, g, group, poses, scratch, residual, multipliers):
    """The multipliers of the group at g (number `group`) for both load cases from `A^T lambda = residual` of its
    links (A the matrix of its kinematics, group_matrix; lambda = (A^-1)^T residual with invert_dyad's inverse),
    stored at multipliers[2 (3 group + k) + row, case] for its joint k's rows; then their reactions on the links
    it hangs on, `residual[link] -= (dC/dx_link)^T lambda` (joint_rows), passed inward. False where A is
    singular, or for a redundant link or a cam follower (statically indeterminate; the cam's contact force is
    linkage/cam.py's). A gear group: _solve_gear_reactions."""
    if int(program[g]) == REDUNDANT or int(program[g]) == CAM_FOLLOWER:
        return False
    if int(program[g]) == GEAR:
        return _solve_gear_reactions(program, g, group, poses, residual, multipliers)
    A, inverse, known = scratch[0:6], scratch[6:12], scratch[12:14]
    L1, L2 = int(program[g + 2]), int(program[g + 3])
    group_matrix(program, g, poses, A, known)
    if not invert_dyad(A, inverse):
        return False
    for case in range(2):
        for row in range(6):
            value = 0.0
            for unknown in range(6):
                link = L1 if unknown < 3 else L2
                value += inverse[unknown, row] * residual[3 * link + unknown % 3, case]
            multipliers[6 * group + row, case] = value
    for joint in range(3):
        j = g + 4 + JOINT_SIZE * joint
        rows = joint_rows(program, j, poses)
        for side in range(2):
            link = int(program[j + 1 + side])
            if link == 0 or link == L1 or link == L2:
                continue
            for row in range(2):
                for coordinate in range(3):
                    partial = rows[6 * row + 3 * side + coordinate]
                    for case in range(2):
                        residual[3 * link + coordinate, case] -= (
                            partial * multipliers[6 * group + 2 * joint + row, case]
                        )
    return True


def _solve_gear_reactions(program, g, group, poses, residual, multipliers):
    """The multipliers of the gear group at g (number `group`): its link's three equations `A^T lambda = residual`,
    A's rows its pivot's two and its mesh's one by the link's (x, y, theta), A^T inverted by its cofactors (the
    columns of A^-T are (a2 x a3, a3 x a1, a1 x a2) / (a1 . (a2 x a3)), a_k A's rows); stored at the pivot's slot
    3 group and the mesh's 3 group + 1 (its second row 0), then passed inward to the pivot's known link and to the
    driver (joint_rows). False where A is singular."""
    link = int(program[g + 2])
    records = (g + 4, g + 4 + JOINT_SIZE)
    rows = (joint_rows(program, records[0], poses), joint_rows(program, records[1], poses))
    sides = (0 if int(program[records[0] + 1]) == link else 3, 0 if int(program[records[1] + 1]) == link else 3)
    a1 = (rows[0][sides[0]], rows[0][sides[0] + 1], rows[0][sides[0] + 2])
    a2 = (rows[0][6 + sides[0]], rows[0][7 + sides[0]], rows[0][8 + sides[0]])
    a3 = (rows[1][sides[1]], rows[1][sides[1] + 1], rows[1][sides[1] + 2])
    determinant = _dot3(a1, _cross3(a2, a3))
    if determinant == 0.0:
        return False
    columns = (_cross3(a2, a3), _cross3(a3, a1), _cross3(a1, a2))
    for case in range(2):
        b = (residual[3 * link, case], residual[3 * link + 1, case], residual[3 * link + 2, case])
        multipliers[6 * group, case] = _dot3(columns[0], b) / determinant
        multipliers[6 * group + 1, case] = _dot3(columns[1], b) / determinant
        multipliers[6 * group + 2, case] = _dot3(columns[2], b) / determinant
        multipliers[6 * group + 3, case] = 0.0
    for joint in range(2):
        other = 3 - sides[joint]
        on = int(program[records[joint] + 1 + other // 3])
        if on == 0:
            continue
        for row in range(2):
            for coordinate in range(3):
                partial = rows[joint][6 * row + other + coordinate]
                for case in range(2):
                    residual[3 * on + coordinate, case] -= partial * multipliers[6 * group + 2 * joint + row, case]
    return True


def kinetostatics(phi, omega, force, program, base, poses, scratch, residual, multipliers):
    """The kinetostatics by groups at crank angle phi [rad], crank speed omega [rad/s] and output force Q [N or
    N m] (linkage/kinetostatics.py): solves the poses (solve_poses, in poses and scratch), the links' d'Alembert
    residuals (residual, 3 n_links x 2) with the output load, each group's multipliers from the farthest inward
    (_solve_group_reactions), then the crank's: its pivot's reaction from the crank's force equations and the
    balancing moment M_b from its moment equation, `M_b = residual_theta - (dC/dtheta_crank)^T lambda_pivot`.
    Fills multipliers (2 (3 n_groups + 1) x 2: joint slot s at rows 2 s, 2 s + 1, the pivot's slot 3 n_groups;
    columns the load cases (omega, epsilon = 0, Q, with gravity) and (0, 1, 0, without)); returns (solved,
    M_b of case 0 [N m], of case 1 [kg m^2]), (False, NaN, NaN) where a group cannot assemble, is at a dead point
    or is a redundant link."""
    if solve_poses(phi, program, base, poses, scratch, True)[0] != SOLVED:
        return False, math.nan, math.nan
    _inertia_residuals(program, base, poses, omega, residual)
    _output_load(program, base, poses, force, residual)
    n_groups = int(program[base + 1])
    groups_at = base + HEADER_SIZE + LINK_SIZE * int(program[base])
    for group in range(n_groups - 1, -1, -1):
        if not _solve_group_reactions(
            program, groups_at + GROUP_SIZE * group, group, poses, scratch, residual, multipliers
        ):
            return False, math.nan, math.nan
    crank = int(program[base + 2])
    pivot = joint_map(program, base) + 1
    rows = joint_rows(program, pivot, poses)
    side = 0 if int(program[pivot + 1]) == crank else 3
    x1, y1, t1 = rows[side], rows[side + 1], rows[side + 2]  # the pivot's first row by the crank's (x, y, theta)
    x2, y2, t2 = rows[6 + side], rows[7 + side], rows[8 + side]  # its second
    determinant = x1 * y2 - x2 * y1
    slot = 6 * n_groups
    balancing = 0.0
    for case in range(2):
        fx, fy = residual[3 * crank, case], residual[3 * crank + 1, case]
        first = (fx * y2 - x2 * fy) / determinant
        second = (x1 * fy - fx * y1) / determinant
        multipliers[slot, case], multipliers[slot + 1, case] = first, second
        if case == 0:
            balancing = residual[3 * crank + 2, 0] - t1 * first - t2 * second
    return True, balancing, residual[3 * crank + 2, 1] - t1 * multipliers[slot, 1] - t2 * multipliers[slot + 1, 1]


def joint_reactions(program, base, poses, multipliers, reactions, ratios):
    """From kinetostatics' poses and multipliers, per joint in the linkage's order (the joint map): reactions[0, j]
    = R0 and reactions[1, j] = R1 (R = R0 + R1 epsilon, complex Fx + i Fy [N] and [N s^2/rad]: a revolute joint's
    force on its first link from its second; a prismatic joint's normal force on the slider as i N, in the guide's
    own frame) and ratios[j], a revolute joint's relative angular speed over omega theta_a' - theta_b' [-], a
    prismatic joint's sliding speed over omega `Re((P_s' - r_g' - i theta_g' (P_s - r_g)) conj w)` [m/rad]
    (w the guide's direction e^{i theta_g} u); a gear mesh's tooth force along t on its link a as a real R [N]
    (joint_rows) and ratio theta_a' - theta_b' [-]."""
    at = joint_map(program, base)
    for joint in range(int(program[at])):
        entry = at + 1 + JOINT_SIZE + 2 * joint
        j, slot = base + int(program[entry]), 2 * int(program[entry + 1])
        a, b = int(program[j + 1]), int(program[j + 2])
        ka = POSE_SIZE * a
        if program[j] == 0.0 or program[j] == GEAR_MESH:  # a mesh's second multiplier is 0
            reactions[0, joint] = complex(multipliers[slot, 0], multipliers[slot + 1, 0])
            reactions[1, joint] = complex(multipliers[slot, 1], multipliers[slot + 1, 1])
            ratios[joint] = poses[ka + 5] - poses[POSE_SIZE * b + 5]
        else:
            reactions[0, joint] = complex(0.0, multipliers[slot, 0])
            reactions[1, joint] = complex(0.0, multipliers[slot, 1])
            P_s, dP_s, _ = motion(poses, b, _local(program, j, b))
            sliding = dP_s - complex(poses[ka + 3], poses[ka + 4]) - 1j * poses[ka + 5] * (P_s - _origin(poses, a))
            ratios[joint] = (sliding * (_direction(program, j) * _turn(poses, a)).conjugate()).real


def workspace_sizes(program, base):
    """(poses, residual rows, multiplier rows) of kinetostatics' arrays for the program at base: POSE_SIZE
    n_links, 3 n_links, 2 (3 n_groups + 1)."""
    n_links = int(program[base])
    return POSE_SIZE * n_links, 3 * n_links, 2 * (3 * int(program[base + 1]) + 1)


def joint_loads(phi, omega, force, program, base):
    """What joint friction reads of the linkage at crank angle phi [rad], speed omega [rad/s] and output force Q
    (mechanisms.kinetostatics.JointLoads): (R0, R1, ratios, M_b0 [N m], M_b1 [kg m^2]), R0 and R1 complex arrays
    and ratios per joint in the linkage's order (joint_reactions), the balancing moment M_b = M_b0 + M_b1 epsilon;
    NaNs where a group fails (kinetostatics). Its allocations per call: one workspace and the three results."""
    n_poses, n_residual, n_multipliers = workspace_sizes(program, base)
    scratch_size = SCRATCH_SHAPE[0] * SCRATCH_SHAPE[1]
    workspace = np.empty(n_poses + scratch_size + 2 * (n_residual + n_multipliers))
    poses = workspace[:n_poses]
    scratch = workspace[n_poses : n_poses + scratch_size].reshape(SCRATCH_SHAPE)
    start = n_poses + scratch_size
    residual = workspace[start : start + 2 * n_residual].reshape((n_residual, 2))
    multipliers = workspace[start + 2 * n_residual :].reshape((n_multipliers, 2))
    n_joints = int(program[joint_map(program, base)])
    reactions = np.empty((2, n_joints), dtype=np.complex128)
    ratios = np.empty(n_joints)
    solved, constant, per_epsilon = kinetostatics(
        phi, omega, force, program, base, poses, scratch, residual, multipliers
    )
    if solved:
        joint_reactions(program, base, poses, multipliers, reactions, ratios)
    else:
        reactions[:, :] = math.nan
        ratios[:] = math.nan
    return reactions[0], reactions[1], ratios, constant, per_epsilon


@functools.cache
def _registered() -> None:
    """Register every function of the solver with numba (once), so that compiled code calls them compiled: all but
    `reduced` and `joint_loads` (which allocate their workspace) without numba's runtime (`_nrt=False`: they
    allocate nothing, and so spend no time counting references to the arrays they are passed)."""
    from numba.extending import register_jitable

    register_jitable(reduced)
    register_jitable(joint_loads)
    for function in (
        law_at,
        _place_cam_follower,
        cam_springs,
        _local,
        _other,
        _unit,
        _direction,
        _origin,
        _turn,
        _point,
        _set_pose,
        _pin,
        _swing,
        _angle_across,
        _origin_line,
        _lines_cross,
        _lines_meet,
        gear_ratio,
        _gear_angle,
        place_group,
        joint_rows,
        joint_quadratic,
        _solve_gear_reactions,
        _follow,
        _enter,
        group_matrix,
        _row3,
        _dot3,
        _cross3,
        _scaled3,
        _null_and_right_inverse,
        invert_dyad,
        _column_dot,
        pseudo_invert_redundant,
        _largest_magnitude,
        differentiate_group,
        solve_poses,
        motion,
        near,
        reduced_from_poses,
        _planar_cross,
        joint_map,
        _inertia_residuals,
        _output_load,
        _solve_group_reactions,
        kinetostatics,
        joint_reactions,
        workspace_sizes,
    ):
        register_jitable(_nrt=False)(function)


# What the reference path calls compiled, with the argument types of its calls (kinematics.py, kinetostatics.py);
# `reduced` and `joint_loads` are not among them: a machine runs the code generated from its groups (symbolic.py),
# and the general solver's reduction and joint loads are kept as the independent check of that code
# (kinematics.make_reduced, the tests)
COMPILED_FUNCTIONS = {
    "solve_poses": "(float64, float64[::1], int64, float64[::1], float64[:, ::1], boolean)",
    "kinetostatics": "(float64, float64, float64, float64[::1], int64, float64[::1], float64[:, ::1], "
    "float64[:, ::1], float64[:, ::1])",
}


@functools.cache
def compiled(name: str):
    """The numba-compiled form of this module's function `name` (COMPILED_FUNCTIONS), the same source the
    reference path and the fast path's generated right-hand sides run (numba imported here, on first use; numba
    compiles it at its first call, or loads it from its disk cache)."""
    from numba import njit

    _registered()
    return njit(cache=True)(globals()[name])


def compiled_announced(name: str):
    """compiled(name), saying on stderr when its first call will compile it (5-15 s, once per machine: nothing in
    numba's disk cache for this source yet), for the callers that call it next (kinematics.py); the plain function
    within cache.run_uncompiled."""
    if cache.uncompiled():
        return globals()[name]
    from numba.core.caching import FunctionCache

    function = compiled(name)
    if not function.signatures and not FunctionCache(function.py_func)._cache_file._load_index():
        print(
            f"note: compiling the linkage solver's {name} once (about 5-15 s; later runs load it at once)",
            file=sys.stderr,
            flush=True,
        )
    return function


def compile_all(report) -> None:
    """Compile (or load from numba's disk cache) every function of COMPILED_FUNCTIONS for the argument types of
    the reference path's calls, reporting a line after each (`mech-regulator compile`)."""
    for name, signature in COMPILED_FUNCTIONS.items():
        started = time.perf_counter()
        compiled_announced(name).compile(signature)
        report(f"  the linkage solver's {name} ready in {time.perf_counter() - started:.1f} s")
