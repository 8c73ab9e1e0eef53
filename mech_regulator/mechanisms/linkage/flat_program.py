"""The general linkage solver's program: the float64 vector a linkage is encoded into once (`encode`; its layout in
flat.py's module docstring), the sizes and codes of its records, and solve_poses' status codes."""

from __future__ import annotations

import math

import numpy as np

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
