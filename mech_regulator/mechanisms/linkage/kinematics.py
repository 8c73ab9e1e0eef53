"""Kinematics of a planar linkage group by group, and its reduction to the crank (physics.md section 1).

At crank angle phi the crank's pose is theta = phi with its pivot point on the frame's; the groups are then
placed and differentiated from the crank outward (groups.place, groups.differentiate). Every link's pose carries
[r, theta, r', theta', r'', theta''] (derivatives with respect to phi), so that a point p of a link moves as
`P = r + q`, `P' = r' + i theta' q`, `P'' = r'' + (i theta'' - theta'^2) q`, q = p e^{i theta}; at crank speed
omega and acceleration epsilon its velocity is P' omega and its acceleration P'' omega^2 + P' epsilon.
"""

from __future__ import annotations

import cmath
import math
from typing import Callable

from mech_regulator.mechanisms.linkage.groups import Pose, differentiate, place
from mech_regulator.mechanisms.linkage.model import Linkage, LinkageError
from mech_regulator.mechanisms.linkage.structure import Structure

Motion = tuple[complex, complex, complex]  # (P [m], dP/dphi [m/rad], d2P/dphi2 [m/rad^2])
ASSEMBLY_SAMPLES = 720  # crank angles over a turn at which a linkage is checked to assemble (every 0.5 deg)


def crank_pose(linkage: Linkage, phi: float) -> Pose:
    """The crank's pose at phi: theta = phi, r = A - p_A e^{i phi} (A: its pivot on the frame, p_A the pivot in
    the crank's coordinates), r' = -i p_A e^{i phi}, r'' = p_A e^{i phi}, theta' = 1, theta'' = 0."""
    pivot = linkage.crank_pivot().name
    pivot_on_crank = linkage.link(linkage.crank).points[pivot] * cmath.exp(1j * phi)
    return [linkage.link(linkage.frame).points[pivot] - pivot_on_crank, phi, -1j * pivot_on_crank, 1.0,
            pivot_on_crank, 0.0]


def solve(linkage: Linkage, structure: Structure, phi: float, derivatives: bool = True) -> dict[str, Pose]:
    """The poses of every link at crank angle phi [rad] (with derivatives unless `derivatives` is False); raises
    LinkageError naming the group that cannot assemble, or is at a dead point, and the angle."""
    poses = {linkage.frame: [0j, 0.0, 0j, 0.0, 0j, 0.0], linkage.crank: crank_pose(linkage, phi)}
    for group in structure.groups:
        place(linkage, group, poses, phi)
        if derivatives:
            differentiate(linkage, group, poses, phi)
    return poses


def motion(pose: Pose, point: complex) -> Motion:
    """(P, P', P'') of the point `point` (link coordinates [m]) of a link with this pose (module docstring)."""
    r, theta, dr, dtheta, ddr, ddtheta = pose
    q = point * cmath.exp(1j * theta)
    return r + q, dr + 1j * dtheta * q, ddr + complex(-dtheta * dtheta, ddtheta) * q


def output_coordinate(linkage: Linkage, poses: dict[str, Pose]) -> tuple[float, float]:
    """(q, dq/dphi) of the linkage's output: a prismatic joint's travel `q = Re((P_s - P_g) conj w)` [m] (its
    slider's point from the guide's point along the guide direction w), `q' = Re(d' conj w) + theta_g' Im(d conj w)`
    (the second term vanishes on the line); a link's angle theta [rad] and theta'; (0, 0) without an output."""
    if linkage.output_link is not None:
        pose = poses[linkage.output_link]
        return pose[1], pose[3]
    if linkage.output_joint is None:
        return 0.0, 0.0
    joint = linkage.joint(linkage.output_joint)
    guide, slider = joint.links
    P_g, dP_g, _ = motion(poses[guide], linkage.link(guide).points[joint.name])
    P_s, dP_s, _ = motion(poses[slider], linkage.link(slider).points[joint.name])
    w = cmath.exp(1j * (joint.direction + poses[guide][1]))
    d, dd = P_s - P_g, dP_s - dP_g
    return (d * w.conjugate()).real, (dd * w.conjugate()).real + poses[guide][3] * (d * w.conjugate()).imag


def make_reduced(linkage: Linkage, structure: Structure, gravity: tuple[float, float] | None
                 ) -> Callable[[float], tuple[float, float, float, float, float]]:
    """Build `reduced(phi) -> (J_links, dJ_links/dphi, M_weight, q, q')` for this linkage (the contract of
    mechanisms/__init__.py): over the moving links k (the crank included) with centres S_k and angles theta_k,
    `J_links = sum m_k |S_k'|^2 + I_k theta_k'^2`, `dJ/dphi = 2 sum (m_k Re(conj(S_k') S_k'') + I_k theta_k'
    theta_k'')`, `M_weight = sum m_k g . S_k'` (zero and not computed without gravity)."""
    links = [linkage.link(name) for name in linkage.moving_links()]
    gravity_c = complex(*gravity) if gravity is not None else 0j

    def reduced(phi: float) -> tuple[float, float, float, float, float]:
        poses = solve(linkage, structure, phi)
        J = dJ = weight = 0.0
        for link in links:
            pose = poses[link.name]
            _, dS, ddS = motion(pose, link.centre)
            J += link.mass * abs(dS) ** 2 + link.inertia * pose[3] * pose[3]
            dJ += 2.0 * (link.mass * (dS.conjugate() * ddS).real + link.inertia * pose[3] * pose[5])
            weight += link.mass * (gravity_c.conjugate() * dS).real
        return (J, dJ, weight) + output_coordinate(linkage, poses)

    return reduced


def moving_points(linkage: Linkage) -> list[tuple[str, str]]:
    """(point, link) of the points whose motion is reported: the revolute joints off the frame, the prismatic
    joints' slider points that no revolute joint of the slider already marks, then the points of interest."""
    found: dict[str, str] = {}
    for joint in sorted(linkage.joints, key=lambda j: j.kind != "revolute"):
        link = joint.links[1]
        if linkage.frame in joint.links and joint.kind == "revolute":
            continue
        local = linkage.link(link).points[joint.name]
        if joint.kind == "prismatic" and any(on == link and linkage.link(link).points[name] == local
                                             for name, on in found.items()):
            continue
        found.setdefault(joint.name, link)
    for point in linkage.points:
        found.setdefault(point, next(link.name for link in linkage.links
                                     if link.name != linkage.frame and point in link.points))
    return list(found.items())


def make_point_motions(linkage: Linkage, structure: Structure) -> Callable[[float], dict[str, Motion]]:
    """`motions(phi) -> {point: (P, P', P'')}` of the moving_points (complex numbers x + i y)."""
    points = [(name, link, linkage.link(link).points[name]) for name, link in moving_points(linkage)]

    def motions(phi: float) -> dict[str, Motion]:
        poses = solve(linkage, structure, phi)
        return {name: motion(poses[link], local) for name, link, local in points}

    return motions


def assembly_failures(linkage: Linkage, structure: Structure, samples: int = ASSEMBLY_SAMPLES) -> list[str]:
    """Where the linkage cannot be assembled or meets a dead point over a turn of the crank, checked at `samples`
    crank angles: one message per group naming the group, its spans [deg] and why it fails at the first angle;
    [] if none."""
    spans: dict[str, list[list[float]]] = {}
    first_reason: dict[str, str] = {}
    step = 360.0 / samples
    for k in range(samples):
        phi_deg = k * step
        try:
            solve(linkage, structure, math.radians(phi_deg))
        except LinkageError as error:
            what, reason = str(error).split(" at crank angle ", 1)
            first_reason.setdefault(what, reason)
            group_spans = spans.setdefault(what, [])
            if group_spans and abs(group_spans[-1][1] - (phi_deg - step)) < 1e-9:
                group_spans[-1][1] = phi_deg
            else:
                group_spans.append([phi_deg, phi_deg])
    for group_spans in spans.values():   # a span through 0 deg is one: 342 to 378 deg, not 0 to 18 and 342 to 359.5
        if len(group_spans) > 1 and group_spans[0][0] == 0.0 and abs(group_spans[-1][1] - (360.0 - step)) < 1e-9:
            group_spans[-1][1] = group_spans.pop(0)[1] + 360.0
    return [f"{what} fails for crank angles {', '.join(f'{lo:g} to {hi:g} deg' for lo, hi in group_spans)} "
            f"(checked every {step:g} deg; at {first_reason[what]})" for what, group_spans in spans.items()]
