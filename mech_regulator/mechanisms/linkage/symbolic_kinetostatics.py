"""The generator of a linkage's kinetostatics (symbolic.joint_loads_source): flat_kinetostatics.joint_loads written out per kind of linkage on the poses symbolic_reduction places.

The kinetostatics joint friction reads (flat_kinetostatics.joint_loads: joint reactions R0 + R1 epsilon, the joints'
relative rates, the balancing moment) is written out the same way (`joint_loads_source`): from the same poses and their
derivatives, each moving link's d'Alembert terms for the two load cases (omega, epsilon = 0, Q, g) and (0, 1, 0, no
g); per dyad from the last inward its six multipliers from `A^T lambda = b` (A flat_derivatives.joint_rows' rows of its
three joints) by flat_derivatives.invert_dyad's block elimination written on A's entries, so that a joint's structural
zeros and ones drop out (the external joints' null vectors n_k and right inverses, the internal joint's 2 x 2 system
`(a_1 n_1 | a_2 n_2)^T lambda_I = (n_1 . b_1, n_2 . b_2)`, then `lambda_Ek = c_k . (b_k - a_k^T lambda_I)`), the
outer joints' reactions passed inward (a gear group: its link's 3 x 3 system by cofactors, _gear_reactions); the
crank's bearing and balancing moment last. A redundant link (statically
indeterminate) has none.
"""

from __future__ import annotations

import numpy as np

from mech_regulator.mechanisms.linkage import flat_kinetostatics, flat_program
from mech_regulator.mechanisms.linkage.symbolic_reduction import (
    Poses,
    Writer,
    add,
    cross,
    dot,
    function_source,
    mul,
    placed,
    scale,
    square,
    sub,
)

# ---------------------------------------------------------------------------------------------------------------
# The kinetostatics (flat_kinetostatics.kinetostatics and flat_kinetostatics.joint_reactions, written out per linkage)


def _joint_rows(poses: Poses, j: int):
    """flat_derivatives.joint_rows of the joint record at j as expressions: its two constraint rows by (x, y, theta) of
    its link a, then of its link b. Revolute, `r_a + q_a - r_b - q_b = 0` (q = p e): ((1, 0, -Im q_a), (-1, 0, Im q_b)),
    ((0, 1, Re q_a), (0, -1, -Re q_b)); prismatic (guide a, slider b), `Im(d conj w) = 0` (d = P_s - P_g, w = u e_a)
    and `theta_b - theta_a - alpha = 0`: ((Im w, -Re w, -Re((q_a + d) conj w)), (-Im w, Re w, Re(q_b conj w))),
    ((0, 0, -1), (0, 0, 1)); a gear mesh, rolling at the pitch point (u the unit vector from O_a to O_b, t = i u):
    ((t_x, t_y, rho_a + u . q_a), (-t_x, -t_y, -rho_b - u . q_b)), then a zero row."""
    w, sp = poses.w, poses.w.sp
    a, b = int(w.program[j + 1]), int(w.program[j + 2])
    qa, qb = mul(w.local(j, a), poses.turn[a]), mul(w.local(j, b), poses.turn[b])
    zero, one = sp.Integer(0), sp.Integer(1)
    if float(w.program[j]) == 0.0:
        return ((one, zero, -qa[1]), (-one, zero, qb[1])), ((zero, one, qa[0]), (zero, -one, -qb[0]))
    if float(w.program[j]) == flat_program.GEAR_MESH:
        line = sub(add(poses.origin[b], qb), add(poses.origin[a], qa))
        u = scale(line, 1 / sp.sqrt(square(line)))
        return (
            ((-u[1], u[0], w.number(j + 7) + dot(qa, u)), (u[1], -u[0], -w.number(j + 8) - dot(qb, u))),
            ((zero, zero, zero), (zero, zero, zero)),
        )
    direction = mul((w.number(j + 7), w.number(j + 8)), poses.turn[a])
    d = sub(add(poses.origin[b], qb), add(poses.origin[a], qa))
    return (
        (
            (direction[1], -direction[0], -dot(add(qa, d), direction)),
            (-direction[1], direction[0], dot(qb, direction)),
        ),
        ((zero, zero, -one), (zero, zero, one)),
    )


def _angular_rate(poses: Poses, link: int, crank: int):
    """theta' of a link: 0 for the frame, 1 for the crank, else Re(e) Im(e)' - Im(e) Re(e)' (e = e^{i theta})."""
    sp = poses.w.sp
    if link == 0:
        return sp.Integer(0)
    if link == crank:
        return sp.Integer(1)
    turn = poses.turn[link]
    return turn[0] * poses.w.rate_of(turn[1]) - turn[1] * poses.w.rate_of(turn[0])


def _dot3(u, v):
    return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]


def _cross3(u, v):
    return u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]


def _residuals(poses: Poses, program: np.ndarray, omega, force) -> dict:
    """flat_kinetostatics._inertia_residuals and flat_kinetostatics._output_load as expressions: per moving link, per
    load case, its three d'Alembert terms (x, y of r, theta): case 0 `m (S'' omega^2 - g)` and `I theta'' omega^2 + (S -
    r) x m (S'' omega^2 - g)`, less the output load Q (a moment on the output link; a force Q w on the output joint's
    slider at its point, -Q w on the guide); case 1 `m S'`, `I theta' + (S - r) x m S'`."""
    w = poses.w
    rate, crank = w.rate_of, int(program[2])
    gravity = w.number(5 + flat_program.JOINT_SIZE), w.number(6 + flat_program.JOINT_SIZE)
    square = omega * omega
    residual = {}
    for link in range(1, int(program[0])):
        record = flat_program.HEADER_SIZE + flat_program.LINK_SIZE * link
        mass, inertia = w.number(record), w.number(record + 3)
        to_centre = mul((w.number(record + 1), w.number(record + 2)), poses.turn[link])
        dS = tuple(rate(value) for value in add(poses.origin[link], to_centre))
        dtheta = _angular_rate(poses, link, crank)
        net = tuple(mass * (rate(dS[k]) * square - gravity[k]) for k in range(2))
        moving = tuple(mass * dS[k] for k in range(2))
        residual[link] = [
            [net[0], net[1], inertia * rate(dtheta) * square - cross(to_centre, net)],
            [moving[0], moving[1], inertia * dtheta - cross(to_centre, moving)],
        ]
    kind = int(program[3])
    if kind == 1:
        residual[int(program[4])][0][2] -= force
    elif kind == 2:
        j = 5
        guide, slider = int(program[j + 1]), int(program[j + 2])
        at = poses.point(j, slider)
        pull = scale(mul((w.number(j + 7), w.number(j + 8)), poses.turn[guide]), force)
        for link, sign in ((slider, 1), (guide, -1)):
            if link != 0:
                entries = residual[link][0]
                entries[0] -= sign * pull[0]
                entries[1] -= sign * pull[1]
                entries[2] += sign * cross(sub(at, poses.origin[link]), pull)
    return residual


def _assign_residual(w: Writer, residual: dict, links) -> None:
    """Assign the residual entries of these links (one batch), in place."""
    links = [link for link in links if link in residual]
    values = iter(w.assign([value for link in links for case in range(2) for value in residual[link][case]]))
    for link in links:
        residual[link] = [[next(values) for _ in range(3)] for _ in range(2)]


def _group_reactions(poses: Poses, program: np.ndarray, g: int, residual: dict) -> list:
    """The multipliers of the dyad at g for both load cases, [case][row] (joint k's rows 2 k, 2 k + 1: E1, internal,
    E2), from `A^T lambda = b` (b the residuals of L1 then L2) by flat_derivatives.invert_dyad's elimination: with the
    external joints' rows on their links (first_k, second_k), their null vectors n_k = first_k x second_k and right
    inverses c = (second x n, n x first) / |n|^2, the internal joint's rows a_1 (by L1), a_2 (by L2), the internal
    multipliers solve `M^T lambda_I = (n_1 . b_1, n_2 . b_2)`, M = (a_1 n_1 | a_2 n_2), and each external joint's are
    `c . (b_k - a_k^T lambda_I)`; then the reactions of the joints on the links it hangs on pass inward,
    `residual[link] -= (dC/dx_link)^T lambda`."""
    w = poses.w
    L1, L2 = int(program[g + 2]), int(program[g + 3])
    records = [g + 4 + flat_program.JOINT_SIZE * k for k in range(3)]
    rows = [_joint_rows(poses, j) for j in records]

    def by(joint, row, link):
        """The joint's row by `link`'s (x, y, theta)."""
        side = 0 if int(program[records[joint] + 1]) == link else 1
        return rows[joint][row][side]

    entries = [
        by(0, 0, L1),
        by(0, 1, L1),
        by(1, 0, L1),
        by(1, 1, L1),
        by(1, 0, L2),
        by(1, 1, L2),
        by(2, 0, L2),
        by(2, 1, L2),
    ]
    values = iter(w.assign([value for entry in entries for value in entry]))
    first1, second1, a1_first, a1_second, a2_first, a2_second, first2, second2 = [
        tuple(next(values) for _ in range(3)) for _ in entries
    ]
    n1, n2 = _cross3(first1, second1), _cross3(first2, second2)
    m11, m12, m21, m22 = _dot3(a1_first, n1), _dot3(a2_first, n2), _dot3(a1_second, n1), _dot3(a2_second, n2)
    inverse_determinant = 1 / (m11 * m22 - m12 * m21)
    scale1, scale2 = 1 / _dot3(n1, n1), 1 / _dot3(n2, n2)
    shared = w.assign(
        [
            *n1,
            *n2,
            m11,
            m12,
            m21,
            m22,
            inverse_determinant,
            scale1,
            scale2,
            *_cross3(second1, n1),
            *_cross3(n1, first1),
            *_cross3(second2, n2),
            *_cross3(n2, first2),
        ]
    )
    n1, n2, (m11, m12, m21, m22, inverse_determinant, scale1, scale2) = shared[0:3], shared[3:6], shared[6:13]
    c1, c2, d1, d2 = shared[13:16], shared[16:19], shared[19:22], shared[22:25]
    multipliers = []
    for case in range(2):
        b1, b2 = residual[L1][case], residual[L2][case]
        along1, along2 = _dot3(n1, b1), _dot3(n2, b2)
        internal = w.assign(
            [
                (m22 * along1 - m21 * along2) * inverse_determinant,
                (m11 * along2 - m12 * along1) * inverse_determinant,
            ]
        )
        r1 = [b1[k] - internal[0] * a1_first[k] - internal[1] * a1_second[k] for k in range(3)]
        r2 = [b2[k] - internal[0] * a2_first[k] - internal[1] * a2_second[k] for k in range(3)]
        multipliers.append(
            w.assign(
                [
                    _dot3(c1, r1) * scale1,
                    _dot3(c2, r1) * scale1,
                    internal[0],
                    internal[1],
                    _dot3(d1, r2) * scale2,
                    _dot3(d2, r2) * scale2,
                ]
            )
        )
    passed = set()
    for joint, j in enumerate(records):
        for side in range(2):
            link = int(program[j + 1 + side])
            if link in (0, L1, L2):
                continue
            passed.add(link)
            for case in range(2):
                for coordinate in range(3):
                    residual[link][case][coordinate] -= sum(
                        rows[joint][row][side][coordinate] * multipliers[case][2 * joint + row] for row in range(2)
                    )
    _assign_residual(w, residual, sorted(passed))
    return multipliers


def _gear_reactions(poses: Poses, program: np.ndarray, g: int, residual: dict) -> list:
    """The multipliers of the gear group at g for both load cases, [case][row] (its pivot's rows 0, 1, its mesh's
    2 and a zero 3, then zeros to the dyads' six), from its link's `A^T lambda = b` by
    flat_kinetostatics._solve_gear_reactions' cofactors; then the pivot's and the mesh's reactions on the links they
    join passed inward."""
    w, sp = poses.w, poses.w.sp
    link = int(program[g + 2])
    records = (g + 4, g + 4 + flat_program.JOINT_SIZE)
    rows = [_joint_rows(poses, j) for j in records]
    sides = [0 if int(program[j + 1]) == link else 1 for j in records]
    values = iter(
        w.assign([value for row in (rows[0][0][sides[0]], rows[0][1][sides[0]], rows[1][0][sides[1]]) for value in row])
    )
    a1, a2, a3 = [tuple(next(values) for _ in range(3)) for _ in range(3)]
    columns = (_cross3(a2, a3), _cross3(a3, a1), _cross3(a1, a2))
    (inverse_determinant,) = w.assign([1 / _dot3(a1, columns[0])])
    zero = sp.Integer(0)
    multipliers = [
        w.assign([_dot3(column, residual[link][case]) * inverse_determinant for column in columns]) + [zero, zero, zero]
        for case in range(2)
    ]
    passed = set()
    for joint, j in enumerate(records):
        side = 1 - sides[joint]
        on = int(program[j + 1 + side])
        if on == 0:
            continue
        passed.add(on)
        for case in range(2):
            for coordinate in range(3):
                residual[on][case][coordinate] -= sum(
                    rows[joint][row][side][coordinate] * multipliers[case][2 * joint + row] for row in range(2)
                )
    _assign_residual(w, residual, sorted(passed))
    return multipliers


def _float_code(sp, value) -> str:
    """An expression's code, a number written as a float literal (so that compiled tuples hold one type)."""
    return repr(float(value)) if value.is_number else sp.pycode(value)


def generate_joint_loads(program: np.ndarray, name: str) -> str:
    """The source of `def name(phi, omega, force, p, offset)` returning flat_kinetostatics.joint_loads' (R0, R1, ratios,
    M_b0, M_b1) of the linkage whose program is read from p at offset, the R's and ratios as tuples per joint in the
    linkage's order (the program's joint map): the poses (placed), the links' residuals (_residuals), each dyad's
    multipliers from the last inward (_group_reactions), the crank's bearing from its force equations and the
    balancing moment from its moment equation `M_b = residual_theta - (dC/dtheta_crank)^T lambda_pivot`, then
    flat_kinetostatics.joint_reactions' reactions and rates."""
    poses = placed(program)
    w, sp = poses.w, poses.w.sp
    omega, force = sp.symbols("omega force")
    n_links, n_groups, crank = int(program[0]), int(program[1]), int(program[2])
    residual = _residuals(poses, program, omega, force)
    _assign_residual(w, residual, range(1, n_links))
    groups_at = flat_program.HEADER_SIZE + flat_program.LINK_SIZE * n_links
    multipliers = {}
    for group in range(n_groups - 1, -1, -1):
        g = groups_at + flat_program.GROUP_SIZE * group
        if int(program[g]) == flat_program.REDUNDANT:
            raise ValueError("a linkage with a redundant link is statically indeterminate: no generated kinetostatics")
        if int(program[g]) == flat_program.CAM_FOLLOWER:
            raise ValueError(
                "a cam pair's contact is not in the kinetostatics by groups yet: no generated kinetostatics"
            )
        found = (_gear_reactions if int(program[g]) == flat_program.GEAR else _group_reactions)(
            poses, program, g, residual
        )
        for case in range(2):
            for row in range(6):
                multipliers[6 * group + row, case] = found[case][row]
    pivot = flat_kinetostatics.joint_map(program, 0) + 1
    rows = _joint_rows(poses, pivot)
    side = 0 if int(program[pivot + 1]) == crank else 1
    (x1, y1, t1), (x2, y2, t2) = rows[0][side], rows[1][side]
    inverse_determinant = 1 / (x1 * y2 - x2 * y1)
    slot = 6 * n_groups
    balancing = []
    for case in range(2):
        fx, fy, moment = residual[crank][case]
        first, second = w.assign([(fx * y2 - x2 * fy) * inverse_determinant, (x1 * fy - fx * y1) * inverse_determinant])
        multipliers[slot, case], multipliers[slot + 1, case] = first, second
        balancing.append(moment - t1 * first - t2 * second)
    at = flat_kinetostatics.joint_map(program, 0)
    reactions, ratios = [], []
    for joint in range(int(program[at])):
        entry = at + 1 + flat_program.JOINT_SIZE + 2 * joint
        j, slot = int(program[entry]), 2 * int(program[entry + 1])
        a, b = int(program[j + 1]), int(program[j + 2])
        if float(program[j]) in (0.0, flat_program.GEAR_MESH):  # a mesh's second multiplier is 0
            reactions.append([(multipliers[slot, case], multipliers[slot + 1, case]) for case in range(2)])
            ratios.append(_angular_rate(poses, a, crank) - _angular_rate(poses, b, crank))
        else:
            reactions.append([(sp.Integer(0), multipliers[slot, case]) for case in range(2)])
            P_s = poses.point(j, b)
            sliding = sub(
                sub(tuple(w.rate_of(value) for value in P_s), tuple(w.rate_of(value) for value in poses.origin[a])),
                scale((-(P_s[1] - poses.origin[a][1]), P_s[0] - poses.origin[a][0]), _angular_rate(poses, a, crank)),
            )
            ratios.append(dot(sliding, mul((w.number(j + 7), w.number(j + 8)), poses.turn[a])))
    values = iter(w.assign([part for joint in reactions for case in joint for part in case] + ratios + balancing))
    parts = [[(next(values), next(values)) for _ in range(2)] for _ in reactions]
    rates = [next(values) for _ in ratios]
    balancing = [next(values), next(values)]

    def complex_tuple(case):
        return (
            "("
            + "".join(
                f"complex({_float_code(sp, part[case][0])}, {_float_code(sp, part[case][1])}), " for part in parts
            )
            + ")"
        )

    returned = (
        f"{complex_tuple(0)}, {complex_tuple(1)}, ({''.join(_float_code(sp, v) + ', ' for v in rates)}), "
        f"{_float_code(sp, balancing[0])}, {_float_code(sp, balancing[1])}"
    )
    doc = (
        '"""Generated by mechanisms.linkage.symbolic: flat_kinetostatics.joint_loads (R0, R1 [N, N s^2/rad], ratios, M_b0 '
        "[N m], M_b1 [kg m^2]) at crank angle phi [rad], speed omega [rad/s], output force Q, the program at "
        'p[offset:]."""'
    )
    return function_source(w, name, "phi, omega, force, p, offset", doc, returned)
