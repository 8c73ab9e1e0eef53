"""Kinetostatics of a planar linkage by groups (source 001, chapter 3): the joint reactions from the farthest group
inward and the balancing moment on the crank.

Every class-II group is statically determinate (3 n = 2 p5: six equilibrium equations, six reaction unknowns).
With d'Alembert's inertia forces each link is in equilibrium; written for a link's coordinates (x, y of its origin r,
theta) its equations are

    m a_S = F,    I alpha + (S - r) x m a_S = M_r,

F the forces on it and M_r their moment about r (gravity m g at S, an output load, the joints' reactions). The
reactions of a joint are the multipliers lambda of its constraint equations (flat.joint_rows): a joint contributes
`(dC/dx_link)^T lambda` to each of its links, so a group's links give `A^T lambda = (inertia - applied - reactions of
the groups farther out)`, A the matrix of its kinematics (flat.group_matrix). A revolute joint's lambda is the
force on its first link from its second [N] (its second link gets -lambda); a prismatic joint's are the normal
force N on the slider along i w (w the guide's direction) [N] and the couple on the slider [N m] (the guide gets
the opposite). Solving the groups from the last one to the first, each passes its outer joints' reactions inward;
the crank's equilibrium then gives its bearing's reaction and the balancing moment M_b, which equals the reduced
form `J epsilon + 1/2 J' omega^2 - M_weight - Q q'` (J of kinematics.make_reduced, the crank included) — a
built-in check of both. The right-hand sides are linear in (omega^2, epsilon, g, Q), so several load cases share one
position solution and one factorisation per group; joint friction reads two of them, the reactions at epsilon = 0
and their rate with epsilon (make_joint_loads, in the form of mechanisms.kinetostatics.JointLoads).
"""

from __future__ import annotations

import cmath
from typing import Callable, NamedTuple

import numpy as np

from mech_regulator.mechanisms.kinetostatics import JointLoads, Kinetostatics
from mech_regulator.mechanisms.linkage.groups import RedundantLink, _rows
from mech_regulator.mechanisms.linkage.kinematics import make_solver, motion
from mech_regulator.mechanisms.linkage.model import PRISMATIC, Linkage, LinkageError
from mech_regulator.mechanisms.linkage.structure import Structure


class LinkageLoads(NamedTuple):
    """Joint reactions by joint name: revolute, the force on its first link from its second, Fx + i Fy [N];
    prismatic, (N [N] along i w on the slider, couple on the slider [N m]); and the balancing moment M_b on the
    crank [N m]."""

    reactions: dict[str, complex | tuple[float, float]]
    balancing: float


def _cross(u: complex, v: complex) -> float:
    """z component of the planar cross product u x v."""
    return (u.conjugate() * v).imag


def _solver(linkage: Linkage, structure: Structure, gravity: tuple[float, float] | None
            ) -> Callable[[float, list[tuple[float, float, float, bool]]], tuple[dict, dict[str, np.ndarray],
                                                                                 np.ndarray]]:
    """Build `reactions(phi, cases) -> (poses, multipliers, balancing)` for several load cases at one crank angle,
    each case (omega, epsilon, Q, weighs): the poses of kinematics.make_solver, each joint's multipliers (module
    docstring) as an array [2, cases] and the balancing moments M_b [N m] of the cases; `weighs` False leaves out
    gravity (the reactions are linear in (omega^2, epsilon, g, Q): a case (0, 1, 0, False) gives their rate with
    epsilon)."""
    if any(isinstance(group, RedundantLink) for group in structure.groups):
        raise LinkageError("a linkage with a redundant link is statically indeterminate: its joint reactions do not "
                           "follow from equilibrium alone")
    gravity_c = complex(*gravity) if gravity is not None else 0j
    moving = [linkage.link(name) for name in linkage.moving_links()]
    pivot = linkage.crank_pivot()
    solve_at = make_solver(linkage, structure.groups)

    def reactions(phi: float, cases: list[tuple[float, float, float, bool]]):
        poses = solve_at(phi)
        count = len(cases)
        # residual[k][:, case] = inertia - applied, generalised over (x, y, theta about the origin r)
        residual = {}
        for link in moving:
            pose = poses[link.name]
            _, dS, ddS = motion(pose, link.centre)
            to_centre = link.centre * cmath.exp(1j * pose[1])
            columns = np.empty((3, count))
            for case, (omega, epsilon, _, weighs) in enumerate(cases):
                net = link.mass * (ddS * omega * omega + dS * epsilon - (gravity_c if weighs else 0j))
                alpha = pose[5] * omega * omega + pose[3] * epsilon
                columns[:, case] = net.real, net.imag, link.inertia * alpha + _cross(to_centre, net)
            residual[link.name] = columns
        for case, (_, _, output_force, _) in enumerate(cases):
            _apply_output(linkage, poses, output_force, residual, case)
        multipliers: dict[str, np.ndarray] = {}
        for group in reversed(structure.groups):
            rows = [(joint, partials) for joint in group.joints for partials in _rows(linkage, poses, joint)]
            columns = {link: 3 * index for index, link in enumerate(group.links)}
            A = np.zeros((6, 6))
            for row, (_, partials) in enumerate(rows):
                for link, column in columns.items():
                    if link in partials:
                        A[row, column:column + 3] = partials[link]
            values = np.linalg.solve(A.T, np.concatenate([residual[link] for link in group.links]))
            for (joint, partials), value in zip(rows, values):
                for link, partial in partials.items():
                    if link not in columns and link in residual:
                        residual[link] = residual[link] - np.outer(partial, value)
            for index, joint in enumerate(group.joints):
                multipliers[joint.name] = values[2 * index:2 * index + 2]
        (first, second) = [partials[linkage.crank] for partials in _rows(linkage, poses, pivot)]
        forces = np.linalg.solve(np.array([[first[0], second[0]], [first[1], second[1]]]), residual[linkage.crank][:2])
        multipliers[pivot.name] = forces
        balancing = residual[linkage.crank][2] - first[2] * forces[0] - second[2] * forces[1]
        return poses, multipliers, balancing

    return reactions


def make_kinetostatics(linkage: Linkage, structure: Structure, gravity: tuple[float, float] | None
                       ) -> Callable[[float, float, float, float], LinkageLoads]:
    """Build `loads(phi, omega, epsilon, Q) -> LinkageLoads` (module docstring), Q the generalised force on the
    output (a force along the output joint's guide on its slider [N], or a moment on the output link [N m])."""
    reactions = _solver(linkage, structure, gravity)

    def loads(phi: float, omega: float, epsilon: float, output_force: float = 0.0) -> LinkageLoads:
        _, multipliers, balancing = reactions(phi, [(omega, epsilon, output_force, True)])
        return LinkageLoads({joint.name: _reaction(joint, multipliers[joint.name][:, 0]) for joint in linkage.joints},
                            float(balancing[0]))

    return loads


def make_joint_loads(linkage: Linkage, structure: Structure, gravity: tuple[float, float] | None
                     ) -> tuple[Kinetostatics, tuple[str, ...]]:
    """The linkage's kinetostatics in the form joint friction reads (mechanisms.kinetostatics.JointLoads) and its
    joint names (the linkage's order): `loads(phi, omega, Q)` gives every joint's reaction affine in epsilon,
    `R = R0 + R1 epsilon` (R0 at (omega, epsilon = 0, Q) with gravity, R1 at (0, 1, 0) without: the reactions are
    linear in (omega^2, epsilon, g, Q)): a revolute joint's, the force on its first link from its second, Fx + i Fy
    [N]; a prismatic joint's, the normal force on the slider in the guide's own frame, i N [N] (as a crank–slider's
    guide: N along i w, w the guide's direction; its couple, which joint friction does not read, is left out), so
    |R| = |N| and Im R = N, whose sign changes joint friction locates; the balancing moment (M_b0 [N m], M_b1
    [kg m^2]); and the ratios (module kinetostatics.JointLoads): a revolute joint's relative angular speed
    theta_a' - theta_b' [-], a prismatic joint's sliding speed over omega,
    `Re((P_s' - r_g' - i theta_g' (P_s - r_g)) conj w)` [m/rad]."""
    reactions = _solver(linkage, structure, gravity)
    joints = linkage.joints

    def loads(phi: float, omega: float, output_force: float) -> JointLoads:
        poses, multipliers, balancing = reactions(phi, [(omega, 0.0, output_force, True), (0.0, 1.0, 0.0, False)])
        forces, ratios = [], []
        for joint in joints:
            first, second = multipliers[joint.name]
            a, b = joint.links
            if joint.kind == PRISMATIC:
                P_s, dP_s, _ = motion(poses[b], linkage.link(b).points[joint.name])
                r_g, theta_g, dr_g, dtheta_g = poses[a][:4]
                w = cmath.exp(1j * (joint.direction + theta_g))
                forces.append((first[0] * 1j, first[1] * 1j))
                ratios.append(((dP_s - dr_g - 1j * dtheta_g * (P_s - r_g)) * w.conjugate()).real)
            else:
                forces.append((complex(first[0], second[0]), complex(first[1], second[1])))
                ratios.append(poses[a][3] - poses[b][3])
        constant, per_epsilon = zip(*forces)
        return JointLoads(constant, per_epsilon, (float(balancing[0]), float(balancing[1])), tuple(ratios))

    return loads, tuple(joint.name for joint in joints)


def _reaction(joint, multipliers) -> complex | tuple[float, float]:
    """A joint's reaction from its two multipliers (module docstring)."""
    if joint.kind == PRISMATIC:
        return float(multipliers[0]), float(multipliers[1])
    return complex(multipliers[0], multipliers[1])


def _apply_output(linkage: Linkage, poses: dict, output_force: float, residual: dict, case: int) -> None:
    """Subtract the output load of load case `case` from the residuals: a moment Q on the output link, or a force
    Q w on the output joint's slider at its point P_s and -Q w on the guide there (its power is Q q' omega)."""
    if output_force == 0.0:
        return
    if linkage.output_link is not None:
        residual[linkage.output_link][2, case] -= output_force
        return
    joint = linkage.joint(linkage.output_joint)
    guide, slider = joint.links
    P_s = motion(poses[slider], linkage.link(slider).points[joint.name])[0]
    force = output_force * cmath.exp(1j * (joint.direction + poses[guide][1]))
    for link, sign in ((slider, 1.0), (guide, -1.0)):
        if link in residual:
            arm = P_s - poses[link][0]
            residual[link][:, case] -= sign * np.array([force.real, force.imag, _cross(arm, force)])
