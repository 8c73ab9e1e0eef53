"""The general linkage solver's kinetostatics by groups, in the subset of Python numba compiles: the multipliers
of every joint and the balancing moment for the two load cases of flat.py's module docstring, and the joint loads
joint friction reads (joint_loads; linkage/kinetostatics.py describes the method)."""

from __future__ import annotations

import math

import numpy as np

from mech_regulator.mechanisms.linkage.flat_derivatives import _cross3, _dot3, group_matrix, invert_dyad, joint_rows
from mech_regulator.mechanisms.linkage.flat_poses import solve_poses
from mech_regulator.mechanisms.linkage.flat_positions import _direction, _local, _origin, _point, _turn, motion
from mech_regulator.mechanisms.linkage.flat_program import (
    CAM_FOLLOWER,
    GEAR,
    GEAR_MESH,
    GROUP_SIZE,
    HEADER_SIZE,
    JOINT_SIZE,
    LINK_SIZE,
    POSE_SIZE,
    REDUNDANT,
    SCRATCH_SHAPE,
    SOLVED,
)

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
