"""A linkage's reduced(phi) as straight-line code, generated from its groups' closed forms (docs/theory.md §5.3).

The general solver (flat.py) places each group by its closed form and differentiates it through the group's 6 x 6
constraint system; that costs some 0.45 us per call on a crank–slider whose hand-written formula costs 0.025 us.
This module writes, once per kind of linkage, the function a designer would write by hand: each group's position
in closed form without angles (a link's pose is its origin r and its turn e^{i theta} = (cos theta, sin theta),
both algebraic in the known poses: no sine, cosine or arctangent but the crank's), and its first and second
derivatives with respect to phi by the chain rule, symbolically (sympy), common subexpressions shared (sympy.cse).
The fast path compiles the source into a scene's module and the reference path compiles the very same source
(reference_function), so both give the same numbers; flat.py stays the solver of everything else (structure, kinematics, the
messages of a group that cannot assemble) and the tests hold the two to 1e-12.

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

The closed forms per group (groups.py's module docstring; sigma the group's branch):
- RRR: with v = D - B, f^2 = |v|^2, `C = B + a v + sigma h i v`, a = (l1^2 - l2^2 + f^2) / (2 f^2),
  h = sqrt(l1^2 / f^2 - a^2) (the acos form's C = B + l1 e^{i (arg v + sigma acos ...)} without its angles);
- RRP: C on the line c + s w of L2's known angle, `C = m + B + w (-Re(m conj w) + sigma sqrt(Re(m conj w)^2 - |m|^2
  + l1^2))`, m = c + p_C e^{i theta2} - B;
- RPR: the guide's turn `e^{i theta_g} = (Ps - Pg) conj(u) (sigma sqrt(rho^2 - h^2) + i h) / rho^2` (rho = |Ps - Pg|,
  h the line's offset from the pivots), the slider's e^{i theta_g} e^{i alpha};
- PRP, RPP: intersections of two known lines, `c1 + w1 Im((c2 - c1) conj w2) / Im(w1 conj w2)`;
- a link through two known points P, T (a dyad's links, a redundant link): `e^{i theta} = (T - P) conj(d) / |d|^2`,
  d its own vector between the two points, r = P - p e^{i theta};
- a gear (gears.py): its angle `theta_L = theta_c + k (theta_G - theta_c) + phase_L` from the angles of its driver
  and carrier, which are phi's (linear in phi: the frame, the crank, gears), `e^{i theta_L} = (cos theta_L, sin
  theta_L)` and r = P - p e^{i theta_L} from its pivot P;
- a cam follower (linkage/cam.py): its law's s, s', s'' from flat_positions.law_at, whose source the function nests (the
  law's pieces are read from p at run time), then its pose in s (flat_positions._place_cam_follower's formulas); its
  spring's -(F0 + k s) s' joins M_weight.
Then, over the moving links k with centres S_k = r_k + c_k e^{i theta_k} and theta' = Re(e) Im(e)' - Im(e) Re(e)'
(e = e^{i theta}): `J = sum m_k |S_k'|^2 + I_k theta_k'^2`, `dJ/dphi = 2 sum (m_k S_k'.S_k'' + I_k theta_k'
theta_k'')` (the crank's term the constant m |c - p_A|^2 + I, p_A its pivot, written so: it is exactly zero for a
preset's crank, whose inertia is in machine.inertia), `M_weight = sum m_k g.S_k'` and the outputs: a prismatic joint's travel `q = Re((P_s - P_g) conj w)` or
a link's angle atan2(Im e, Re e) (within pi of the output reference, flat_poses.near), with q'
(flat_poses.reduced_from_poses).

The numbers are read from the linkage's program (flat_program.encode) in p at `offset`, so the source depends only on
the linkage's structure and on which of its numbers are exactly 0, 1 or -1 (written as literals, so that a joint at a
link's origin or a guide along x costs nothing): two linkages of one kind share one source, kept in the cache folder
(mech_regulator.cache) under a hash of that key, so sympy runs once per kind of linkage and machine.
"""

from __future__ import annotations

import functools
import hashlib
import math
import sys
from collections.abc import Callable, Sequence

import numpy as np

from mech_regulator import cache
from mech_regulator.mechanisms.linkage import (
    flat,
    flat_derivatives,
    flat_kinetostatics,
    flat_poses,
    flat_positions,
    flat_program,
)
from mech_regulator.mechanisms.linkage.model import Linkage, LinkageError
from mech_regulator.mechanisms.linkage.structure import Structure

FUNCTION_NAME = "linkage_reduced"
JOINT_LOADS_NAME = "linkage_joint_loads"


# ---------------------------------------------------------------------------------------------------------------
# The key: the program's structural entries exactly, its numbers as 0, 1, -1 or 'x'


def _structural_positions(program: np.ndarray) -> set[int]:
    """The positions in a program (flat_program.encode's layout, base 0) of its counts, codes, link indices, branches
    and joint-map entries (everything that is not a length, angle, mass or gravity)."""
    n_links, n_groups = int(program[0]), int(program[1])
    positions = {0, 1, 2, 3, 4}

    def joint(j):
        positions.update((j, j + 1, j + 2))
        if program[j] == flat_program.GEAR_MESH:
            positions.add(j + 9)  # the carrier link

    joint(5)
    g = flat_program.HEADER_SIZE + flat_program.LINK_SIZE * n_links
    for _ in range(n_groups):
        positions.update(range(g, g + 4))
        for k in range(3):
            joint(g + 4 + flat_program.JOINT_SIZE * k)
        if int(program[g]) == flat_program.CAM_FOLLOWER:  # where its law is (a cam law's pieces are read at run time)
            positions.add(g + 4 + 2 * flat_program.JOINT_SIZE + 3)
        g += flat_program.GROUP_SIZE
    positions.add(g)
    joint(g + 1)
    positions.update(range(g + 1 + flat_program.JOINT_SIZE, g + 1 + flat_program.JOINT_SIZE + 2 * int(program[g])))
    return positions


def _literal(value: float):
    """The literal a number is written as (0, 1 or -1), or None: read from p."""
    return int(value) if value in (0.0, 1.0, -1.0) else None


@functools.cache
def _generator_source_hash() -> str:
    """The hash of this module's and the general solver's source (flat.py and its flat_*.py modules; program_key)."""
    import inspect

    modules = (
        sys.modules[__name__],
        flat,
        flat_program,
        flat_positions,
        flat_derivatives,
        flat_poses,
        flat_kinetostatics,
    )
    return hashlib.sha256("".join(inspect.getsource(module) for module in modules).encode()).hexdigest()


def program_key(program: np.ndarray, outputs: Sequence[int]) -> str:
    """The hash of what the generated source depends on: the structural entries of the program, the literal
    pattern of its numbers, the output joints' record positions and the generator's own source (this module's and
    flat.py's, whose layout it reads: a changed generator never meets an old cached source)."""
    structural = _structural_positions(program)
    pattern = [repr(float(v)) if i in structural else repr(_literal(v)) for i, v in enumerate(program)]
    text = f"{_generator_source_hash()}|{'|'.join(pattern)}|{tuple(outputs)}"
    return hashlib.sha256(text.encode()).hexdigest()[:20]


# ---------------------------------------------------------------------------------------------------------------
# Generation (sympy is imported only here: a cached source needs none)


class _Writer:
    """Builds the expressions group by group and writes them as assignments. Complex quantities are (re, im) pairs
    of sympy expressions. Every symbol that stands for a function of phi has its derivative with respect to phi in
    `rate` (a symbol, an expression or zero); `rate_of(expr)` is the chain rule `sum d expr/d s rate(s)`."""

    def __init__(self, program: np.ndarray):
        import sympy

        self.sp = sympy
        self.program = program
        self.read: dict[int, object] = {}
        self.rate: dict[object, object] = {}
        self.lines: list[str] = []
        self.count = 0
        self.laws = False  # a cam follower's law is evaluated: the function nests flat_positions.law_at
        cos_phi, sin_phi, phi = sympy.symbols("cos_phi sin_phi phi")
        self.rate[cos_phi], self.rate[sin_phi], self.rate[phi] = -sin_phi, cos_phi, sympy.Integer(1)
        self.crank_turn = (cos_phi, sin_phi)
        self.phi = phi

    # numbers and points of the program
    def number(self, i: int):
        """The program's number at i: a literal, or the symbol of p[offset + i]."""
        literal = _literal(self.program[i])
        if literal is not None:
            return self.sp.Integer(literal)
        if i not in self.read:
            self.read[i] = self.sp.Symbol(f"n{i}")
        return self.read[i]

    def local(self, j: int, link: int):
        """The point of the joint record at j in the coordinates of `link` (flat_positions._local)."""
        k = 3 if int(self.program[j + 1]) == link else 5
        return self.number(j + k), self.number(j + k + 1)

    def other(self, j: int, link: int) -> int:
        a = int(self.program[j + 1])
        return int(self.program[j + 2]) if a == link else a

    # the chain rule and assignments
    def rate_of(self, expr):
        """d expr / d phi by the chain rule over the symbols with a known rate."""
        total = self.sp.Integer(0)
        for symbol in expr.free_symbols:
            rate = self.rate.get(symbol)
            if rate is None:
                continue
            if rate == "unknown":
                raise RuntimeError(f"the third derivative of {symbol} was asked for")
            total += expr.diff(symbol) * rate
        return total

    def assign(self, exprs: list) -> list:
        """Write `exprs` as assignments (common subexpressions shared) and return the symbols that stand for them
        (numbers and plain symbols stay themselves)."""
        sp = self.sp
        targets, wanted = [], []
        for expr in exprs:
            if expr.is_number or expr.is_Symbol:
                targets.append(expr)
            else:
                self.count += 1
                symbol = sp.Symbol(f"v{self.count}")
                targets.append(symbol)
                wanted.append((symbol, expr))
        if wanted:
            common, reduced = sp.cse(
                [expr for _, expr in wanted], symbols=sp.numbered_symbols(f"t{self.count}_"), order="none"
            )
            self.lines += [f"{name} = {sp.pycode(value)}" for name, value in common]
            self.lines += [f"{symbol} = {sp.pycode(value)}" for (symbol, _), value in zip(wanted, reduced)]
        return targets

    def jets(self, exprs: list) -> list:
        """Assign `exprs` with their first and second derivatives (one batch, so they share subexpressions); each
        symbol's rate is its derivative's symbol (the second derivatives' rates are never needed: no third
        derivative is asked for)."""
        firsts = [self.rate_of(expr) for expr in exprs]
        seconds = [self.rate_of(expr) for expr in firsts]
        symbols = self.assign(list(exprs) + firsts + seconds)
        n = len(exprs)
        self._chain(symbols[:n], symbols[n : 2 * n], symbols[2 * n :])
        return symbols[:n]

    def _chain(self, values, firsts, seconds) -> None:
        """Record rate(value) = first and rate(first) = second for the symbols just assigned."""
        for value, first, second in zip(values, firsts, seconds):
            if value.is_Symbol and value not in self.rate:
                self.rate[value] = first
            if first.is_Symbol and first not in self.rate:
                self.rate[first] = second
            if second.is_Symbol and second not in self.rate:
                self.rate[second] = "unknown"

    def root(self, expr):
        """sqrt(expr) with its derivatives written through the root itself, s' = a' / (2 s), s'' = (a'' - 2 s'^2)
        / (2 s) (a = expr), so that the code has one square root and no fractional power."""
        sp = self.sp
        (argument,) = self.jets([expr])
        rate = self.rate_of(argument)
        curvature = self.rate_of(rate)
        (value,) = self.assign([sp.sqrt(argument)])
        (half_inverse,) = self.assign([1 / (2 * value)])
        (first,) = self.assign([rate * half_inverse])
        (second,) = self.assign([(curvature - 2 * first * first) * half_inverse])
        self._chain([value], [first], [second])
        return value


def _add(u, v):
    return u[0] + v[0], u[1] + v[1]


def _sub(u, v):
    return u[0] - v[0], u[1] - v[1]


def _mul(u, v):
    return u[0] * v[0] - u[1] * v[1], u[0] * v[1] + u[1] * v[0]


def _conj(u):
    return u[0], -u[1]


def _scale(u, factor):
    return u[0] * factor, u[1] * factor


def _square(u):
    return u[0] * u[0] + u[1] * u[1]


def _cross(u, v):
    """Im(u conj v)."""
    return u[1] * v[0] - u[0] * v[1]


def _dot(u, v):
    """Re(u conj v)."""
    return u[0] * v[0] + u[1] * v[1]


class _Poses:
    """The links' poses as expressions: origin r and turn e = e^{i theta} per link index; `angle` the angle theta of
    the links whose angle is phi's (the frame, the crank, gears)."""

    def __init__(self, writer: _Writer):
        self.w = writer
        zero, one = writer.sp.Integer(0), writer.sp.Integer(1)
        self.origin = {0: (zero, zero)}
        self.turn = {0: (one, zero)}
        self.cams: list = []  # (s, s', cam record) of each cam follower group (_place_cam_follower)
        self.angle = {0: zero}

    def point(self, j: int, link: int):
        """Global position of the joint j's point on `link`: r + p e."""
        return _add(self.origin[link], _mul(self.w.local(j, link), self.turn[link]))

    def set(self, link: int, origin, turn) -> None:
        """Store a link's pose, assigned with its derivatives."""
        values = self.w.jets([origin[0], origin[1], turn[0], turn[1]])
        self.origin[link], self.turn[link] = (values[0], values[1]), (values[2], values[3])

    def pin(self, j: int, link: int, at, turn) -> None:
        """The pose of `link` with turn e and its point of joint j at `at`: r = at - p e."""
        self.set(link, _sub(at, _mul(self.w.local(j, link), turn)), turn)

    def swing(self, pivot: int, tip: int, link: int, P, T) -> None:
        """The pose of `link` whose point of joint `pivot` is at P and of joint `tip` at T:
        e = (T - P) conj(d) / |d|^2, d = p_tip - p_pivot."""
        d = _sub(self.w.local(tip, link), self.w.local(pivot, link))
        turn = _scale(_mul(_sub(T, P), _conj(d)), 1 / _square(d))
        self.pin(pivot, link, P, turn)

    def across_turn(self, j: int, known: int, known_turn):
        """e^{i theta} of the link the prismatic joint j joins to the link `known` of turn known_turn:
        theta_slider = theta_guide + alpha."""
        value = float(self.w.program[j + 9])
        if value == 0.0:
            return known_turn
        sp = self.w.sp
        alpha = self.w.number(j + 9)
        rotation = (sp.cos(alpha), sp.sin(alpha) if int(self.w.program[j + 1]) == known else -sp.sin(alpha))
        return _mul(known_turn, rotation)

    def line(self, j: int, unknown: int, turn):
        """(c, w): the line c + s w on which the origin of `unknown` lies, its turn being `turn`, joined by the
        prismatic joint j to a known link (flat_positions._origin_line)."""
        guide, slider = int(self.w.program[j + 1]), int(self.w.program[j + 2])
        u = (self.w.number(j + 7), self.w.number(j + 8))
        if unknown == slider:
            return _sub(self.point(j, guide), _mul(self.w.local(j, slider), turn)), _mul(u, self.turn[guide])
        return _sub(self.point(j, slider), _mul(self.w.local(j, guide), turn)), _mul(u, turn)


def _meet(c1, w1, c2, w2):
    """The intersection of the lines c1 + s w1 and c2 + t w2."""
    return _add(c1, _scale(w1, _cross(_sub(c2, c1), w2) / _cross(w1, w2)))


def _place(poses: _Poses, program: np.ndarray, g: int) -> None:
    """Place the group at g (flat_positions.place_group's closed forms, written without angles)."""
    w, sp = poses.w, poses.w.sp
    kind, sigma = int(program[g]), int(program[g + 1])
    L1, L2 = int(program[g + 2]), int(program[g + 3])
    E1, Ji, E2 = g + 4, g + 4 + flat_program.JOINT_SIZE, g + 4 + 2 * flat_program.JOINT_SIZE
    if kind == flat_program.CAM_FOLLOWER:
        _place_cam_follower(poses, program, g)
        return
    if kind == flat_program.REDUNDANT:
        poses.swing(E1, Ji, L1, poses.point(E1, w.other(E1, L1)), poses.point(Ji, w.other(Ji, L1)))
        return
    if (
        kind == flat_program.GEAR
    ):  # flat_positions.place_group's gear: theta_L = theta_c + k (theta_G - theta_c) + phase_L
        rho_a, rho_b = w.number(Ji + 7), w.number(Ji + 8)
        ratio = rho_a / rho_b if int(program[Ji + 2]) == L1 else rho_b / rho_a
        carrier = poses.angle[int(program[Ji + 9])]
        (angle,) = w.jets([carrier + ratio * (poses.angle[w.other(Ji, L1)] - carrier) + w.number(g + 1)])
        poses.angle[L1] = angle
        poses.pin(E1, L1, poses.point(E1, w.other(E1, L1)), (sp.cos(angle), sp.sin(angle)))
        return
    K1, K2 = w.other(E1, L1), w.other(E2, L2)
    if kind in (0, 1):  # RRR, RRP
        B = poses.point(E1, K1)
        l1_square = _square(_sub(w.local(Ji, L1), w.local(E1, L1)))
        if (
            kind == 0 and sigma == 0
        ):  # the parallelogram P B C D: C = D + (B - P), B - P on K1 (flat_positions.place_group)
            D = poses.point(E2, K2)
            C = tuple(w.jets(list(_add(D, _mul((w.number(E1 + 7), w.number(E1 + 8)), poses.turn[K1])))))
            poses.swing(E2, Ji, L2, D, C)
        elif kind == 0:
            D = poses.point(E2, K2)
            l2_square = _square(_sub(w.local(Ji, L2), w.local(E2, L2)))
            v = tuple(w.jets(list(_sub(D, B))))
            (f_square,) = w.jets([_square(v)])
            (along,) = w.jets([(l1_square - l2_square + f_square) / (2 * f_square)])
            (height,) = w.jets([sigma * w.root(l1_square / f_square - along * along)])
            C = _add(B, (along * v[0] - height * v[1], along * v[1] + height * v[0]))
            C = tuple(w.jets(list(C)))
            poses.swing(E2, Ji, L2, D, C)
        else:
            turn2 = poses.across_turn(E2, K2, poses.turn[K2])
            c, direction = poses.line(E2, L2, turn2)
            m = tuple(w.jets(list(_sub(_add(c, _mul(w.local(Ji, L2), turn2)), B))))
            (along,) = w.jets([_dot(m, direction)])
            (root,) = w.jets([sigma * w.root(along * along - _square(m) + l1_square)])
            C = _add(_add(m, B), _scale(direction, root - along))
            C = tuple(w.jets(list(C)))
            poses.pin(Ji, L2, C, turn2)
        poses.swing(E1, Ji, L1, B, C)
        return
    if kind == 2:  # RPR
        guide, slider = int(program[Ji + 1]), int(program[Ji + 2])
        pivot_g, pivot_s = (E1, E2) if guide == L1 else (E2, E1)
        Pg = poses.point(pivot_g, w.other(pivot_g, guide))
        Ps = poses.point(pivot_s, w.other(pivot_s, slider))
        u = (w.number(Ji + 7), w.number(Ji + 8))
        alpha = float(program[Ji + 9])
        rotation = (
            (sp.Integer(1), sp.Integer(0)) if alpha == 0.0 else (sp.cos(w.number(Ji + 9)), sp.sin(w.number(Ji + 9)))
        )
        offset = _cross(
            _add(
                _sub(w.local(pivot_g, guide), w.local(Ji, guide)),
                _mul(_sub(w.local(Ji, slider), w.local(pivot_s, slider)), rotation),
            ),
            u,
        )
        span = tuple(w.jets(list(_sub(Ps, Pg))))
        (rho_square,) = w.jets([_square(span)])
        (root,) = w.jets([sigma * w.root(rho_square - offset * offset)])
        turn_g = _scale(_mul(_mul(span, _conj(u)), (root, offset)), 1 / rho_square)
        poses.pin(pivot_g, guide, Pg, turn_g)
        poses.pin(pivot_s, slider, Ps, _mul(poses.turn[guide], rotation))
        return
    turn2 = poses.across_turn(E2, K2, poses.turn[K2])
    if kind == 3:  # PRP
        turn1 = poses.across_turn(E1, K1, poses.turn[K1])
        c1, w1 = poses.line(E1, L1, turn1)
        c2, w2 = poses.line(E2, L2, turn2)
        C = _meet(_add(c1, _mul(w.local(Ji, L1), turn1)), w1, _add(c2, _mul(w.local(Ji, L2), turn2)), w2)
        C = tuple(w.jets(list(C)))
        poses.pin(Ji, L1, C, turn1)
        poses.pin(Ji, L2, C, turn2)
        return
    # RPP: L1 pinned at B with the angle its prismatic internal joint gives it from L2's
    turn1 = poses.across_turn(Ji, L2, turn2)
    poses.pin(E1, L1, poses.point(E1, K1), turn1)
    c1, w1 = poses.line(Ji, L2, turn2)
    c2, w2 = poses.line(E2, L2, turn2)
    poses.set(L2, _meet(c1, w1, c2, w2), turn2)


def _place_cam_follower(poses: _Poses, program: np.ndarray, g: int) -> None:
    """Place the cam follower group at g (flat_positions._place_cam_follower's formulas): its law's s, s', s'' assigned
    by flat_positions.law_at (nested in the generated function, _function_source) as symbols whose rates are one
    another, then the follower's pose (translating: turn e^{i alpha}, r = G + (d0 + s) u - p e^{i alpha}; oscillating:
    turn e^{i (theta0 + sigma s)}, pinned at its pivot) and its roller's, pinned at their joint with the follower's
    turn; (s, s', the cam record's position) kept in poses.cams for the springs."""
    w, sp = poses.w, poses.w.sp
    sigma, follower, roller = int(program[g + 1]), int(program[g + 2]), int(program[g + 3])
    guide, pin, cam = g + 4, g + 4 + flat_program.JOINT_SIZE, g + 4 + 2 * flat_program.JOINT_SIZE
    w.count += 1
    s, ds, dds = sp.symbols(f"s{w.count} ds{w.count} dds{w.count}")
    w.lines.append(
        f"{s}, {ds}, {dds} = law_at(phi - {sp.pycode(w.number(cam + 4))}, p, int(at) + {cam + int(program[cam + 3])})"
    )
    w.rate[s], w.rate[ds], w.rate[dds] = ds, dds, "unknown"
    w.laws = True
    if float(program[guide]) != 0.0:  # translating
        turn = poses.across_turn(guide, 0, poses.turn[0])
        u = (w.number(guide + 7), w.number(guide + 8))
        origin = _sub(
            _add(poses.point(guide, 0), _scale(u, w.number(cam + 5) + s)), _mul(w.local(guide, follower), turn)
        )
        poses.set(follower, origin, turn)
    else:
        theta = w.number(cam + 5) + sigma * s
        poses.pin(guide, follower, poses.point(guide, 0), (sp.cos(theta), sp.sin(theta)))
    if roller >= 0:
        poses.pin(pin, roller, poses.point(pin, follower), poses.turn[follower])
    poses.cams.append((s, ds, cam))


def _placed(program: np.ndarray) -> _Poses:
    """Every link's pose of the program (base 0) as expressions with their phi-derivatives: the crank's
    `r = A - p_A e^{i phi}`, e = (cos phi, sin phi), then each group's closed form (_place) in turn."""
    poses = _Poses(_Writer(program))
    writer, crank = poses.w, int(program[2])
    pivot_frame = writer.number(flat_program.HEADER_SIZE - 4), writer.number(flat_program.HEADER_SIZE - 3)
    pivot_crank = writer.number(flat_program.HEADER_SIZE - 2), writer.number(flat_program.HEADER_SIZE - 1)
    poses.origin[crank] = _sub(pivot_frame, _mul(pivot_crank, writer.crank_turn))
    poses.turn[crank] = writer.crank_turn
    poses.angle[crank] = writer.phi
    g = flat_program.HEADER_SIZE + flat_program.LINK_SIZE * int(program[0])
    for _ in range(int(program[1])):
        _place(poses, program, g)
        g += flat_program.GROUP_SIZE
    return poses


def _generate(program: np.ndarray, outputs: Sequence[int], name: str) -> str:
    """The source of `def name(phi, p, offset)` returning (J_links, dJ/dphi, M_weight, q_1, q_1', ...) of the
    linkage whose program (flat_program.encode, base 0) is read from p at offset; `outputs`: the record positions of the
    prismatic joints whose travels are the q's (none: the program's own output, flat_poses.reduced_from_poses)."""
    poses = _placed(program)
    writer = poses.w
    sp = writer.sp
    n_links, crank = int(program[0]), int(program[2])
    pivot_crank = writer.number(flat_program.HEADER_SIZE - 2), writer.number(flat_program.HEADER_SIZE - 1)
    gravity = writer.number(5 + flat_program.JOINT_SIZE), writer.number(6 + flat_program.JOINT_SIZE)
    J = dJ = weight = sp.Integer(0)
    rate = writer.rate_of
    for link in range(1, n_links):
        record = flat_program.HEADER_SIZE + flat_program.LINK_SIZE * link
        mass, inertia = writer.number(record), writer.number(record + 3)
        turn = poses.turn[link]
        local_centre = (writer.number(record + 1), writer.number(record + 2))
        centre = _add(poses.origin[link], _mul(local_centre, turn))
        dS = (rate(centre[0]), rate(centre[1]))
        weight += mass * _dot(dS, gravity)
        if link == crank:  # turning about its pivot at theta' = 1: a constant m |c - p_A|^2 + I, no dJ
            J += mass * _square(_sub(local_centre, pivot_crank)) + inertia
            continue
        ddS = (rate(dS[0]), rate(dS[1]))
        dtheta = turn[0] * rate(turn[1]) - turn[1] * rate(turn[0])
        ddtheta = turn[0] * rate(rate(turn[1])) - turn[1] * rate(rate(turn[0]))
        J += mass * _square(dS) + inertia * dtheta * dtheta
        dJ += 2 * (mass * _dot(dS, ddS) + inertia * dtheta * ddtheta)
    for s, ds, cam in poses.cams:  # the cam followers' springs, -(F0 + k s) s' (flat_positions.cam_springs)
        weight -= (writer.number(cam + 7) + writer.number(cam + 6) * s) * ds
    results = [J, dJ, weight]
    kind = int(program[3])
    if outputs:
        records = list(outputs)
    elif kind == 2:
        records = [5]
    else:
        records = []
    for j in records:
        guide, slider = int(program[j + 1]), int(program[j + 2])
        direction = _mul((writer.number(j + 7), writer.number(j + 8)), poses.turn[guide])
        q = _dot(_sub(poses.point(j, slider), poses.point(j, guide)), direction)
        results += [q, rate(q)]
    if not records and kind == 1:
        turn = poses.turn[int(program[4])]
        (angle,) = writer.assign([sp.atan2(turn[1], turn[0])])
        reference = writer.number(flat_program.OUTPUT_REFERENCE)
        results += [
            angle - 2 * sp.pi * sp.floor((angle - reference) / (2 * sp.pi) + sp.Rational(1, 2)),
            turn[0] * rate(turn[1]) - turn[1] * rate(turn[0]),
        ]
    elif not records:
        results += [sp.Integer(0), sp.Integer(0)]
    final = writer.assign(results)
    doc = (
        '"""Generated by mechanisms.linkage.symbolic: (J_links [kg m^2], dJ/dphi [kg m^2/rad], M_weight [N m], '
        'then q, dq/dphi per output) at crank angle phi [rad], the program at p[offset:]."""'
    )
    return _function_source(
        writer,
        name,
        "phi, p, offset",
        doc,
        ", ".join(sp.pycode(value) if not value.is_Symbol else str(value) for value in final),
    )


def _function_source(writer: _Writer, name: str, arguments: str, doc: str, returned: str) -> str:
    """The source of `def name(arguments)` with the docstring doc: the program's numbers the writer read, then its
    lines, then `return returned`."""
    # an unsigned offset: compiled, p[at + i] then needs no check for a negative index (some 2 ns a read)
    reads = [f"{symbol} = p[at + {i}]" for i, symbol in sorted(writer.read.items())]
    body = ["at = np.uint64(offset)", "cos_phi = math.cos(phi)", "sin_phi = math.sin(phi)"] + reads + writer.lines
    if writer.laws:  # flat_positions.law_at's own source, nested (numba compiles an inner function called in place)
        import inspect

        body = inspect.getsource(flat_positions.law_at).rstrip().split("\n") + body
    body.append(f"return {returned}")
    return f"def {name}({arguments}):\n    {doc}\n    " + "\n    ".join(body) + "\n"


# ---------------------------------------------------------------------------------------------------------------
# The kinetostatics (flat_kinetostatics.kinetostatics and flat_kinetostatics.joint_reactions, written out per linkage)


def _joint_rows(poses: _Poses, j: int):
    """flat_derivatives.joint_rows of the joint record at j as expressions: its two constraint rows by (x, y, theta) of
    its link a, then of its link b. Revolute, `r_a + q_a - r_b - q_b = 0` (q = p e): ((1, 0, -Im q_a), (-1, 0, Im q_b)),
    ((0, 1, Re q_a), (0, -1, -Re q_b)); prismatic (guide a, slider b), `Im(d conj w) = 0` (d = P_s - P_g, w = u e_a)
    and `theta_b - theta_a - alpha = 0`: ((Im w, -Re w, -Re((q_a + d) conj w)), (-Im w, Re w, Re(q_b conj w))),
    ((0, 0, -1), (0, 0, 1)); a gear mesh, rolling at the pitch point (u the unit vector from O_a to O_b, t = i u):
    ((t_x, t_y, rho_a + u . q_a), (-t_x, -t_y, -rho_b - u . q_b)), then a zero row."""
    w, sp = poses.w, poses.w.sp
    a, b = int(w.program[j + 1]), int(w.program[j + 2])
    qa, qb = _mul(w.local(j, a), poses.turn[a]), _mul(w.local(j, b), poses.turn[b])
    zero, one = sp.Integer(0), sp.Integer(1)
    if float(w.program[j]) == 0.0:
        return ((one, zero, -qa[1]), (-one, zero, qb[1])), ((zero, one, qa[0]), (zero, -one, -qb[0]))
    if float(w.program[j]) == flat_program.GEAR_MESH:
        line = _sub(_add(poses.origin[b], qb), _add(poses.origin[a], qa))
        u = _scale(line, 1 / sp.sqrt(_square(line)))
        return (
            ((-u[1], u[0], w.number(j + 7) + _dot(qa, u)), (u[1], -u[0], -w.number(j + 8) - _dot(qb, u))),
            ((zero, zero, zero), (zero, zero, zero)),
        )
    direction = _mul((w.number(j + 7), w.number(j + 8)), poses.turn[a])
    d = _sub(_add(poses.origin[b], qb), _add(poses.origin[a], qa))
    return (
        (
            (direction[1], -direction[0], -_dot(_add(qa, d), direction)),
            (-direction[1], direction[0], _dot(qb, direction)),
        ),
        ((zero, zero, -one), (zero, zero, one)),
    )


def _angular_rate(poses: _Poses, link: int, crank: int):
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


def _residuals(poses: _Poses, program: np.ndarray, omega, force) -> dict:
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
        to_centre = _mul((w.number(record + 1), w.number(record + 2)), poses.turn[link])
        dS = tuple(rate(value) for value in _add(poses.origin[link], to_centre))
        dtheta = _angular_rate(poses, link, crank)
        net = tuple(mass * (rate(dS[k]) * square - gravity[k]) for k in range(2))
        moving = tuple(mass * dS[k] for k in range(2))
        residual[link] = [
            [net[0], net[1], inertia * rate(dtheta) * square - _cross(to_centre, net)],
            [moving[0], moving[1], inertia * dtheta - _cross(to_centre, moving)],
        ]
    kind = int(program[3])
    if kind == 1:
        residual[int(program[4])][0][2] -= force
    elif kind == 2:
        j = 5
        guide, slider = int(program[j + 1]), int(program[j + 2])
        at = poses.point(j, slider)
        pull = _scale(_mul((w.number(j + 7), w.number(j + 8)), poses.turn[guide]), force)
        for link, sign in ((slider, 1), (guide, -1)):
            if link != 0:
                entries = residual[link][0]
                entries[0] -= sign * pull[0]
                entries[1] -= sign * pull[1]
                entries[2] += sign * _cross(_sub(at, poses.origin[link]), pull)
    return residual


def _assign_residual(w: _Writer, residual: dict, links) -> None:
    """Assign the residual entries of these links (one batch), in place."""
    links = [link for link in links if link in residual]
    values = iter(w.assign([value for link in links for case in range(2) for value in residual[link][case]]))
    for link in links:
        residual[link] = [[next(values) for _ in range(3)] for _ in range(2)]


def _group_reactions(poses: _Poses, program: np.ndarray, g: int, residual: dict) -> list:
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


def _gear_reactions(poses: _Poses, program: np.ndarray, g: int, residual: dict) -> list:
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


def _generate_joint_loads(program: np.ndarray, name: str) -> str:
    """The source of `def name(phi, omega, force, p, offset)` returning flat_kinetostatics.joint_loads' (R0, R1, ratios,
    M_b0, M_b1) of the linkage whose program is read from p at offset, the R's and ratios as tuples per joint in the
    linkage's order (the program's joint map): the poses (_placed), the links' residuals (_residuals), each dyad's
    multipliers from the last inward (_group_reactions), the crank's bearing from its force equations and the
    balancing moment from its moment equation `M_b = residual_theta - (dC/dtheta_crank)^T lambda_pivot`, then
    flat_kinetostatics.joint_reactions' reactions and rates."""
    poses = _placed(program)
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
            sliding = _sub(
                _sub(tuple(w.rate_of(value) for value in P_s), tuple(w.rate_of(value) for value in poses.origin[a])),
                _scale((-(P_s[1] - poses.origin[a][1]), P_s[0] - poses.origin[a][0]), _angular_rate(poses, a, crank)),
            )
            ratios.append(_dot(sliding, _mul((w.number(j + 7), w.number(j + 8)), poses.turn[a])))
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
    return _function_source(w, name, "phi, omega, force, p, offset", doc, returned)


# a cached file is a module: this header, then the function (what the fast path adds to a scene's module)
MODULE_HEADER = '"""Generated by mech_regulator.mechanisms.linkage.symbolic (do not edit)."""\n\nimport math\n\nimport numpy as np\n\n\n'


@functools.cache
def _source_by_key(file_name: str) -> str | None:
    """The function's source in the cache folder's module of this name (None: not generated yet on this machine)."""
    path = cache.folder() / file_name
    if not path.exists():
        return None
    text = path.read_text(encoding="utf-8")
    return text[len(MODULE_HEADER) :] if text.startswith(MODULE_HEADER) else None


def _cached_source(file_name: str, generate: Callable[[], str]) -> str:
    """The source kept in the cache folder under file_name (a module: MODULE_HEADER and the function), generated now
    (sympy) and kept if not there yet."""
    source = _source_by_key(file_name)
    if source is None:
        source = generate()
        cache.write(cache.folder() / file_name, MODULE_HEADER + source)
        _source_by_key.cache_clear()
    return source


def reduced_source(program: np.ndarray, outputs: Sequence[int] = ()) -> tuple[str, str]:
    """(function name, source) of the generated reduced function of a linkage program (flat_program.encode, base 0) with
    these output joint records (prismatic joints' record positions; empty: the program's output), from the cache
    folder if generated before, else generated now (sympy) and cached."""
    key = program_key(program, outputs)
    name = f"{FUNCTION_NAME}_{key}"
    return name, _cached_source(_file_name(name), lambda: _generate(program, outputs, name))


def joint_loads_source(program: np.ndarray) -> tuple[str, str]:
    """(function name, source) of the generated kinetostatics of a linkage program (flat_program.encode, base 0) without
    a redundant link: `name(phi, omega, force, p, offset) -> (R0, R1, ratios, M_b0, M_b1)`,
    flat_kinetostatics.joint_loads' numbers with R0, R1 and ratios as tuples per joint in the linkage's order; from the
    cache folder if generated before, else generated now (sympy) and cached."""
    key = program_key(program, ())
    name = f"{JOINT_LOADS_NAME}_{key}"
    return name, _cached_source(_file_name(name), lambda: _generate_joint_loads(program, name))


def _file_name(name: str) -> str:
    """The cache folder's module of a generated function."""
    return f"{name}.py"


def reference_function(name: str) -> Callable:
    """_reference_function(name) on the process's path: compiled, or plain within cache.run_uncompiled."""
    return _reference_function(name, cache.uncompiled())


@functools.cache
def _reference_function(name: str, plain: bool) -> Callable:
    """The generated function `name` (reduced_source or joint_loads_source made it: its module is in the cache
    folder) compiled by numba for the reference path, as the fast path compiles the same source into a scene's
    module: numba's disk cache beside the module keeps it, so it compiles once per kind of linkage and machine (said
    on stderr before it does, a second or a few; `plain`: the function as plain Python, not compiled). Plain Python
    ran it 3 to 8 times slower than the general solver compiled, which the reference path called before."""
    import importlib.util

    path = cache.folder() / _file_name(name)
    spec = importlib.util.spec_from_file_location(f"mech_regulator_generated_{name}", path)
    assert spec is not None and spec.loader is not None, f"{path}: a .py file has a source loader"
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # numba's cache finds the module's globals by its name
    spec.loader.exec_module(module)
    if plain:
        return getattr(module, name)
    from numba import njit
    from numba.core.caching import FunctionCache

    function = njit(cache=True, error_model="numpy")(getattr(module, name))  # as codegen compiles it
    if not FunctionCache(function.py_func)._cache_file._load_index():
        what = "joint reactions" if name.startswith(JOINT_LOADS_NAME) else "reduced inertia"
        print(
            f"note: compiling the linkage's generated {what} code once (a few seconds; later runs load it at once)",
            file=sys.stderr,
            flush=True,
        )
    return function


def output_records(program: np.ndarray, linkage: Linkage, joints: Sequence[str]) -> list[int]:
    """The record positions (in the program's joint map) of the named joints, for `reduced_source`'s outputs."""
    first = flat_kinetostatics.joint_map(program, 0) + 1 + flat_program.JOINT_SIZE
    index = {joint.name: k for k, joint in enumerate(linkage.joints)}
    return [int(program[first + 2 * index[name]]) for name in joints]


def make_reduced(
    linkage: Linkage, structure: Structure, gravity: tuple[float, float] | None, outputs: Sequence[str] = ()
) -> Callable[[float], tuple[float, ...]]:
    """`reduced(phi) -> (J_links, dJ/dphi, M_weight, q, dq/dphi)` of a linkage by its generated code
    (reference_function: compiled, the source the fast path compiles; with `outputs`, prismatic joints' names: q,
    dq/dphi of each in turn); where a group cannot assemble or is at a dead point (the code gives NaN or an infinity:
    a square root of a negative number, a division by zero), the LinkageError of the general solver
    (kinematics.make_solver) naming the group and why. Within cache.run_uncompiled it is the general solver's
    plain flat_poses.reduced instead when there are no `outputs` (no sympy: the same numbers to rounding, the tests
    compare them), else the generated code as plain Python."""
    from mech_regulator.mechanisms.linkage.kinematics import make_solver

    if cache.uncompiled() and not outputs:
        from mech_regulator.mechanisms.linkage.kinematics import make_reduced as general_reduced

        return general_reduced(linkage, structure, gravity)
    program = flat_program.encode(linkage, structure.groups, gravity)
    name, _ = reduced_source(program, output_records(program, linkage, outputs))
    function = reference_function(name)

    def reduced(phi: float) -> tuple[float, ...]:
        values = function(phi, program, 0)
        if not math.isfinite(sum(values)):  # a NaN or an infinity among them (one test, not one per value)
            make_solver(linkage, structure.groups)(phi)  # raises the group's LinkageError
            raise LinkageError(
                f"the linkage's reduced quantities are not finite at crank angle {math.degrees(phi):.3f} deg"
            )
        return values

    return reduced
