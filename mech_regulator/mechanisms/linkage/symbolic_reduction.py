"""The generator of a linkage's reduced(phi) (symbolic.reduced_source): its groups' poses in closed form and their phi-derivatives, written as straight-line code (docs/theory.md §5.3).

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
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from mech_regulator.mechanisms.linkage import flat_positions, flat_program


def literal(value: float):
    """The literal a number is written as (0, 1 or -1), or None: read from p."""
    return int(value) if value in (0.0, 1.0, -1.0) else None


# ---------------------------------------------------------------------------------------------------------------
# Generation (sympy is imported only here: a cached source needs none)


class Writer:
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
        exact = literal(self.program[i])
        if exact is not None:
            return self.sp.Integer(exact)
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


def add(u, v):
    """u + v of two complex quantities, (re, im) pairs."""
    return u[0] + v[0], u[1] + v[1]


def sub(u, v):
    """u - v."""
    return u[0] - v[0], u[1] - v[1]


def mul(u, v):
    """u v."""
    return u[0] * v[0] - u[1] * v[1], u[0] * v[1] + u[1] * v[0]


def conj(u):
    """conj(u)."""
    return u[0], -u[1]


def scale(u, factor):
    """u factor (factor real)."""
    return u[0] * factor, u[1] * factor


def square(u):
    """|u|^2."""
    return u[0] * u[0] + u[1] * u[1]


def cross(u, v):
    """Im(u conj v)."""
    return u[1] * v[0] - u[0] * v[1]


def dot(u, v):
    """Re(u conj v)."""
    return u[0] * v[0] + u[1] * v[1]


class Poses:
    """The links' poses as expressions: origin r and turn e = e^{i theta} per link index; `angle` the angle theta of
    the links whose angle is phi's (the frame, the crank, gears)."""

    def __init__(self, writer: Writer):
        self.w = writer
        zero, one = writer.sp.Integer(0), writer.sp.Integer(1)
        self.origin = {0: (zero, zero)}
        self.turn = {0: (one, zero)}
        self.cams: list = []  # (s, s', cam record) of each cam follower group (_place_cam_follower)
        self.angle = {0: zero}

    def point(self, j: int, link: int):
        """Global position of the joint j's point on `link`: r + p e."""
        return add(self.origin[link], mul(self.w.local(j, link), self.turn[link]))

    def set(self, link: int, origin, turn) -> None:
        """Store a link's pose, assigned with its derivatives."""
        values = self.w.jets([origin[0], origin[1], turn[0], turn[1]])
        self.origin[link], self.turn[link] = (values[0], values[1]), (values[2], values[3])

    def pin(self, j: int, link: int, at, turn) -> None:
        """The pose of `link` with turn e and its point of joint j at `at`: r = at - p e."""
        self.set(link, sub(at, mul(self.w.local(j, link), turn)), turn)

    def swing(self, pivot: int, tip: int, link: int, P, T) -> None:
        """The pose of `link` whose point of joint `pivot` is at P and of joint `tip` at T:
        e = (T - P) conj(d) / |d|^2, d = p_tip - p_pivot."""
        d = sub(self.w.local(tip, link), self.w.local(pivot, link))
        turn = scale(mul(sub(T, P), conj(d)), 1 / square(d))
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
        return mul(known_turn, rotation)

    def line(self, j: int, unknown: int, turn):
        """(c, w): the line c + s w on which the origin of `unknown` lies, its turn being `turn`, joined by the
        prismatic joint j to a known link (flat_positions._origin_line)."""
        guide, slider = int(self.w.program[j + 1]), int(self.w.program[j + 2])
        u = (self.w.number(j + 7), self.w.number(j + 8))
        if unknown == slider:
            return sub(self.point(j, guide), mul(self.w.local(j, slider), turn)), mul(u, self.turn[guide])
        return sub(self.point(j, slider), mul(self.w.local(j, guide), turn)), mul(u, turn)


def _meet(c1, w1, c2, w2):
    """The intersection of the lines c1 + s w1 and c2 + t w2."""
    return add(c1, scale(w1, cross(sub(c2, c1), w2) / cross(w1, w2)))


def _place(poses: Poses, program: np.ndarray, g: int) -> None:
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
        l1_square = square(sub(w.local(Ji, L1), w.local(E1, L1)))
        if (
            kind == 0 and sigma == 0
        ):  # the parallelogram P B C D: C = D + (B - P), B - P on K1 (flat_positions.place_group)
            D = poses.point(E2, K2)
            C = tuple(w.jets(list(add(D, mul((w.number(E1 + 7), w.number(E1 + 8)), poses.turn[K1])))))
            poses.swing(E2, Ji, L2, D, C)
        elif kind == 0:
            D = poses.point(E2, K2)
            l2_square = square(sub(w.local(Ji, L2), w.local(E2, L2)))
            v = tuple(w.jets(list(sub(D, B))))
            (f_square,) = w.jets([square(v)])
            (along,) = w.jets([(l1_square - l2_square + f_square) / (2 * f_square)])
            (height,) = w.jets([sigma * w.root(l1_square / f_square - along * along)])
            C = add(B, (along * v[0] - height * v[1], along * v[1] + height * v[0]))
            C = tuple(w.jets(list(C)))
            poses.swing(E2, Ji, L2, D, C)
        else:
            turn2 = poses.across_turn(E2, K2, poses.turn[K2])
            c, direction = poses.line(E2, L2, turn2)
            m = tuple(w.jets(list(sub(add(c, mul(w.local(Ji, L2), turn2)), B))))
            (along,) = w.jets([dot(m, direction)])
            (root,) = w.jets([sigma * w.root(along * along - square(m) + l1_square)])
            C = add(add(m, B), scale(direction, root - along))
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
        offset = cross(
            add(
                sub(w.local(pivot_g, guide), w.local(Ji, guide)),
                mul(sub(w.local(Ji, slider), w.local(pivot_s, slider)), rotation),
            ),
            u,
        )
        span = tuple(w.jets(list(sub(Ps, Pg))))
        (rho_square,) = w.jets([square(span)])
        (root,) = w.jets([sigma * w.root(rho_square - offset * offset)])
        turn_g = scale(mul(mul(span, conj(u)), (root, offset)), 1 / rho_square)
        poses.pin(pivot_g, guide, Pg, turn_g)
        poses.pin(pivot_s, slider, Ps, mul(poses.turn[guide], rotation))
        return
    turn2 = poses.across_turn(E2, K2, poses.turn[K2])
    if kind == 3:  # PRP
        turn1 = poses.across_turn(E1, K1, poses.turn[K1])
        c1, w1 = poses.line(E1, L1, turn1)
        c2, w2 = poses.line(E2, L2, turn2)
        C = _meet(add(c1, mul(w.local(Ji, L1), turn1)), w1, add(c2, mul(w.local(Ji, L2), turn2)), w2)
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


def _place_cam_follower(poses: Poses, program: np.ndarray, g: int) -> None:
    """Place the cam follower group at g (flat_positions._place_cam_follower's formulas): its law's s, s', s'' assigned
    by flat_positions.law_at (nested in the generated function, function_source) as symbols whose rates are one
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
        origin = sub(add(poses.point(guide, 0), scale(u, w.number(cam + 5) + s)), mul(w.local(guide, follower), turn))
        poses.set(follower, origin, turn)
    else:
        theta = w.number(cam + 5) + sigma * s
        poses.pin(guide, follower, poses.point(guide, 0), (sp.cos(theta), sp.sin(theta)))
    if roller >= 0:
        poses.pin(pin, roller, poses.point(pin, follower), poses.turn[follower])
    poses.cams.append((s, ds, cam))


def placed(program: np.ndarray) -> Poses:
    """Every link's pose of the program (base 0) as expressions with their phi-derivatives: the crank's
    `r = A - p_A e^{i phi}`, e = (cos phi, sin phi), then each group's closed form (_place) in turn."""
    poses = Poses(Writer(program))
    writer, crank = poses.w, int(program[2])
    pivot_frame = writer.number(flat_program.HEADER_SIZE - 4), writer.number(flat_program.HEADER_SIZE - 3)
    pivot_crank = writer.number(flat_program.HEADER_SIZE - 2), writer.number(flat_program.HEADER_SIZE - 1)
    poses.origin[crank] = sub(pivot_frame, mul(pivot_crank, writer.crank_turn))
    poses.turn[crank] = writer.crank_turn
    poses.angle[crank] = writer.phi
    g = flat_program.HEADER_SIZE + flat_program.LINK_SIZE * int(program[0])
    for _ in range(int(program[1])):
        _place(poses, program, g)
        g += flat_program.GROUP_SIZE
    return poses


def generate_reduced(program: np.ndarray, outputs: Sequence[int], name: str) -> str:
    """The source of `def name(phi, p, offset)` returning (J_links, dJ/dphi, M_weight, q_1, q_1', ...) of the
    linkage whose program (flat_program.encode, base 0) is read from p at offset; `outputs`: the record positions of the
    prismatic joints whose travels are the q's (none: the program's own output, flat_poses.reduced_from_poses)."""
    poses = placed(program)
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
        centre = add(poses.origin[link], mul(local_centre, turn))
        dS = (rate(centre[0]), rate(centre[1]))
        weight += mass * dot(dS, gravity)
        if link == crank:  # turning about its pivot at theta' = 1: a constant m |c - p_A|^2 + I, no dJ
            J += mass * square(sub(local_centre, pivot_crank)) + inertia
            continue
        ddS = (rate(dS[0]), rate(dS[1]))
        dtheta = turn[0] * rate(turn[1]) - turn[1] * rate(turn[0])
        ddtheta = turn[0] * rate(rate(turn[1])) - turn[1] * rate(rate(turn[0]))
        J += mass * square(dS) + inertia * dtheta * dtheta
        dJ += 2 * (mass * dot(dS, ddS) + inertia * dtheta * ddtheta)
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
        direction = mul((writer.number(j + 7), writer.number(j + 8)), poses.turn[guide])
        q = dot(sub(poses.point(j, slider), poses.point(j, guide)), direction)
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
    return function_source(
        writer,
        name,
        "phi, p, offset",
        doc,
        ", ".join(sp.pycode(value) if not value.is_Symbol else str(value) for value in final),
    )


def function_source(writer: Writer, name: str, arguments: str, doc: str, returned: str) -> str:
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
