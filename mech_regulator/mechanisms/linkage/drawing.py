"""Drawing geometry of a linkage at a crank angle (pure numpy), in the outline format of mechanisms/drawing.py:
metres, y up, a dict of parts, each a polyline (n, 2) or a bundle of polylines (k, n, 2); `joints` is a set of
points.

Parts: `frame` (the polyline through the frame's points, fixed), `crank_path` (the circle of the crank's farthest
point, fixed), `crank` (its pivot to its farthest point: the last point is the crank pin), `links` (every other
moving link as the closed polygon through its points in the order given, padded by repeating its last point to the
longest; a cam's profile, turned with the crank, among them), `sliders` (a block on each prismatic joint's slider
point, along the guide, BLOCK_PER_CRANK crank lengths (a cam's largest radius, if longer) by half that; an empty
bundle without prismatic joints), `gears` (each gear's pitch circle with its radius to the link's x axis, so that
it shows the gear's turn; an empty bundle without gears) and `joints` (every lower pair's point; a cam pair's:
where the cam touches).
"""

from __future__ import annotations

import cmath
import math
from collections.abc import Callable

import numpy as np

from mech_regulator.mechanisms.linkage.cam import CamFollower, CamPair
from mech_regulator.mechanisms.linkage.gears import GearGroup
from mech_regulator.mechanisms.linkage.kinematics import make_solver
from mech_regulator.mechanisms.linkage.model import GEAR, PRISMATIC, Linkage
from mech_regulator.mechanisms.linkage.structure import Structure

MOVING_PARTS = ("crank", "links", "sliders", "gears", "joints")
GEAR_CIRCLE_POINTS = 73  # points of a pitch circle's polyline (after its radius)
BLOCK_PER_CRANK = 0.6  # slider block length along the guide, per crank length [-]
PROFILE_POINTS = 180  # points of a cam's profile as drawn
CIRCLE_POINTS = 73  # points of a drawn circle (72 segments)


def circle(centre: tuple[float, float], radius: float) -> np.ndarray:
    """Closed polyline of a circle [m], shape (CIRCLE_POINTS, 2)."""
    angles = np.linspace(0.0, 2.0 * math.pi, CIRCLE_POINTS)
    return np.column_stack([centre[0] + radius * np.cos(angles), centre[1] + radius * np.sin(angles)])


def crank_length(linkage: Linkage) -> float:
    """Distance from the crank's pivot to its farthest point [m]."""
    points = linkage.link(linkage.driving_crank()).points
    pivot = points[linkage.crank_pivot().name]
    return max(abs(p - pivot) for p in points.values())


def _xy(points: list[complex]) -> np.ndarray:
    return np.array([[p.real, p.imag] for p in points])


def link_polygon(linkage: Linkage, poses: dict, name: str) -> list[complex]:
    """The global points of a link in the order given, closed when it has three or more."""
    r, theta = poses[name][0], poses[name][1]
    points = [r + p * cmath.exp(1j * theta) for p in linkage.link(name).points.values()]
    return points + points[:1] if len(points) > 2 else points


def pitch_circles(linkage: Linkage, structure: Structure, poses: dict) -> list[tuple[str, complex, float, float]]:
    """(link, centre [m], pitch radius [m], the link's angle [rad]) of both gears of every gear mesh, at these
    poses (kinematics.solve)."""
    circles = []
    for group in structure.groups:
        if isinstance(group, GearGroup):
            for link, centre, rho in zip(group.mesh.links, group.mesh.gear_mesh().centres, group.pitch):
                r, theta = poses[link][0], poses[link][1]
                circles.append((link, r + linkage.link(link).points[centre] * cmath.exp(1j * theta), abs(rho), theta))
    return circles


def _gear_polyline(centre: complex, radius: float, theta: float) -> list[complex]:
    """The centre, then the pitch circle from the link's x axis round (its radius drawn, so the turn shows)."""
    angles = theta + np.linspace(0.0, 2.0 * np.pi, GEAR_CIRCLE_POINTS)
    return [centre] + list(centre + radius * np.exp(1j * angles))


def linkage_outliner(linkage: Linkage, structure: Structure) -> Callable[[float], dict[str, np.ndarray]]:
    """`outline_at(phi)`: the linkage's parts at crank angle phi [rad] (module docstring), with what does not depend
    on phi (the pose solver, the cams' profiles, the frame, the crank's radius) worked out once, here."""
    solve_at = make_solver(linkage, structure.groups)
    cams = {
        group.pair.name: CamPair(linkage, group, None, check=False)
        for group in structure.groups
        if isinstance(group, CamFollower)
    }
    profiles = {name: pair.profile(PROFILE_POINTS) for name, pair in cams.items()}
    frame_points = list(linkage.link(linkage.frame).points.values())
    crank_name = linkage.driving_crank()
    crank = linkage.link(crank_name)
    pivot_name = linkage.crank_pivot().name
    tip = max(crank.points.values(), key=lambda p: abs(p - crank.points[pivot_name]))
    pivot = linkage.link(linkage.frame).points[pivot_name]
    radius = max([crank_length(linkage)] + [float(np.max(np.abs(profile))) for profile in profiles.values()])
    half = 0.5 * BLOCK_PER_CRANK * radius

    def outline_at(phi: float) -> dict[str, np.ndarray]:
        poses = solve_at(phi, False)
        pose = poses[crank_name]
        others = [link_polygon(linkage, poses, name) for name in linkage.moving_links() if name != crank_name]
        others += [
            list(cams[name].centre + np.append(profile, profile[:1]) * cmath.exp(1j * phi))
            for name, profile in profiles.items()
        ]
        longest = max(len(points) for points in others)  # a linkage with W = 1 has at least one group
        blocks = []
        for joint in linkage.joints:
            if joint.kind == PRISMATIC:
                guide, slider = joint.links
                centre = poses[slider][0] + linkage.link(slider).points[joint.name] * cmath.exp(1j * poses[slider][1])
                along = cmath.exp(1j * (joint.direction + poses[guide][1]))
                corners = [centre + half * along * complex(x, 0.5 * y) for x, y in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
                blocks.append(_xy(corners + corners[:1]))
        joint_points = []
        for joint in linkage.joints:
            if joint.name in cams:  # a cam pair's point: where the cam touches
                joint_points.append(complex(cams[joint.name].contact_point(phi)[0]))
                continue
            if joint.kind == GEAR:
                continue
            link = joint.links[1]
            joint_points.append(poses[link][0] + linkage.link(link).points[joint.name] * cmath.exp(1j * poses[link][1]))
        return {
            "frame": _xy(frame_points),
            "crank_path": circle((pivot.real, pivot.imag), radius),
            "crank": _xy([pivot, pose[0] + tip * cmath.exp(1j * phi)]),
            "links": np.stack([_xy(points + points[-1:] * (longest - len(points))) for points in others]),
            "sliders": np.stack(blocks) if blocks else np.zeros((0, 5, 2)),
            "gears": np.array(
                [
                    _xy(_gear_polyline(centre, radius, theta))
                    for _, centre, radius, theta in pitch_circles(linkage, structure, poses)
                ]
            ).reshape((-1, GEAR_CIRCLE_POINTS + 1, 2)),
            "joints": _xy(joint_points),
        }

    return outline_at
