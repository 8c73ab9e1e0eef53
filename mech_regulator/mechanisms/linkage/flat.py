"""The general linkage solver, flat: a float64 program vector (`encode`) and plain functions over it in the subset
numba compiles (scalars, complex numbers, float arrays; no dicts or objects). It places the groups for the structure
checks, the kinematics tables, the point motions and the messages of a group that fails; what a machine integrates
(the reduction, the kinetostatics joint friction reads) runs as code generated per kind of linkage (symbolic.py),
which this solver's `reduced` and `joint_loads` check independently (the tests).

The solver is six modules: flat_program.py (the program's layout, `encode`, the status codes), flat_positions.py
(each kind of group placed in closed form), flat_derivatives.py (the groups' velocity and acceleration ratios),
flat_poses.py (`solve_poses`, `reduced`), flat_kinetostatics.py (`kinetostatics`, `joint_loads`), and this one: the
layout below, and the registration and compilation of them all with numba.

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

import functools
import sys
import time

from mech_regulator import cache, numba_cache
from mech_regulator.mechanisms.linkage.flat_derivatives import (
    _column_dot,
    _cross3,
    _dot3,
    _enter,
    _follow,
    _largest_magnitude,
    _null_and_right_inverse,
    _row3,
    _scaled3,
    differentiate_group,
    group_matrix,
    invert_dyad,
    joint_quadratic,
    joint_rows,
    pseudo_invert_redundant,
)
from mech_regulator.mechanisms.linkage.flat_kinetostatics import (
    _inertia_residuals,
    _output_load,
    _planar_cross,
    _solve_gear_reactions,
    _solve_group_reactions,
    joint_loads,
    joint_map,
    joint_reactions,
    kinetostatics,
    workspace_sizes,
)
from mech_regulator.mechanisms.linkage.flat_poses import near, reduced, reduced_from_poses, solve_poses
from mech_regulator.mechanisms.linkage.flat_positions import (
    _angle_across,
    _direction,
    _gear_angle,
    _lines_cross,
    _lines_meet,
    _local,
    _origin,
    _origin_line,
    _other,
    _pin,
    _place_cam_follower,
    _point,
    _set_pose,
    _swing,
    _turn,
    _unit,
    cam_springs,
    gear_ratio,
    law_at,
    motion,
    place_group,
)


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
    """The numba-compiled form of the solver's function `name` (COMPILED_FUNCTIONS), the same source the
    reference path and the fast path's generated right-hand sides run (numba imported here, on first use; numba
    compiles it at its first call, or loads it from its disk cache)."""
    from numba import njit

    numba_cache.install()  # keyed on the package's source: every flat_*.py module the function calls
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
