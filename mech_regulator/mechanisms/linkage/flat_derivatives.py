"""The general linkage solver's velocity and acceleration ratios, in the subset of Python numba compiles: a group's
joint constraint rows, `A u' = -K k'` and `A u'' = -K k'' - gamma`, A inverted in closed form (a dyad's block
elimination, a redundant link's pseudo-inverse) and refused as a dead point beyond DEAD_POINT_CONDITION
(docs/theory.md §5.3; flat.py describes the program and the poses)."""

from __future__ import annotations

from mech_regulator.mechanisms.linkage.flat_positions import (
    _direction,
    _gear_angle,
    _local,
    _origin,
    _other,
    _turn,
    motion,
)
from mech_regulator.mechanisms.linkage.flat_program import (
    CAM_FOLLOWER,
    DEAD_POINT_CONDITION,
    GEAR,
    GEAR_MESH,
    JOINT_SIZE,
    POSE_SIZE,
    REDUNDANT,
)

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
