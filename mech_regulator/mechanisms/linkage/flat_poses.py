"""The general linkage solver's kinematics, in the subset of Python numba compiles: the links' poses and their
phi-derivatives group by group (solve_poses, returning a status instead of raising) and the linkage's
 reduced quantities J_links, dJ/dphi, M_weight, q, dq/dphi (reduced; flat.py describes the program)."""

from __future__ import annotations

import math

import numpy as np

from mech_regulator.mechanisms.linkage.flat_derivatives import differentiate_group
from mech_regulator.mechanisms.linkage.flat_positions import (
    _direction,
    _local,
    _set_pose,
    _turn,
    _unit,
    cam_springs,
    motion,
    place_group,
)
from mech_regulator.mechanisms.linkage.flat_program import (
    DEAD_POINT,
    GROUP_SIZE,
    HEADER_SIZE,
    JOINT_SIZE,
    LINK_SIZE,
    OUTPUT_REFERENCE,
    POSE_SIZE,
    SCRATCH_SHAPE,
    SOLVED,
    TWO_PI,
)

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
