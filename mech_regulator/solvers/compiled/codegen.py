"""The code generator of the fast path: a scene's right-hand side and guards as the source of a small module that
numba compiles once and caches on disk.

From a MachineModel it writes `rhs(t, y, p, dydt)` and `guards(t, y, p, levels)` (compiled with the explicit
signatures of solvers/compiled/signatures.py) that call only the effects the scene has (each drive's, load's,
valve's and the servo's one definition compiled, effects/definition.py, the call written by its call_source as the
reference path's; the kernels of solvers/compiled/kernels.py for the rest) — a machine without a mechanism has no
kinematics call, an ungoverned one no governor — and the parameter vector p they read. Its pieces are in
solvers/compiled/source.py (p, the effects' calls, the module's text), the drive train's and joint friction's in
solvers/compiled/train_source.py, a governor's in its own module (governors/kind.py, GovernorKind.source). p is laid
out as

    p[0:SEGMENT_SLOTS]   the segment's inputs (set by the outer loop, solvers/compiled/run.py): external load
                         offset [N m] and slope [N m/s], held throttle [-], sleeve / servo / driven-part mode codes,
                         the switch window (lo, hi) [rad] the effects see phi clamped into and its edges for the
                         window's guards [rad], the clutch's mode code, the sign of the crank's speed at the
                         segment's start (joint friction's crank guard), the co-simulated throttle's slope [1/s],
                         curvature [1/s^2], start time [s], sensitivity to the crank's speed [s/rad] and stops
                         (low, high) [-] (LoadPiece.throttle_at);
    p[SEGMENT_SLOTS:...] the scene's numbers (SI), then its tables (each: offset and length among the numbers).

The source depends only on the scene's structure, never on its numbers: two scenes that differ only in values
share one module (a sweep compiles once). The module is written to the cache folder (env MECH_REGULATOR_CACHE,
default $XDG_CACHE_HOME/mech_regulator/compiled or ~/.cache/mech_regulator/compiled) under a hash of its source,
kernels.py's and effects/tables.py's source and the package and numba versions, imported with importlib (numba
caches the machine code in __pycache__ beside it), and kept in a process-wide dict.

With joint friction on a mechanism it also writes `reactions(t, y, p, squares)` (signatures.REACTIONS_SIGNATURE): the
|R_j|^2 = |R0_j + R1_j epsilon|^2 [N^2] of the journals with friction (time_domain._journals: not the guides), at the
rhs's own epsilon, which the integrators keep their steps' reach from (their branch points, docs/theory.md §6.5).

Guards are written in the order of MachineModel.guards(mode) (the governor's, then the clutch's and the driven
part's, then the joint friction's crank guard; then one N guard per guide with friction, time_domain._normal_guards),
+inf in the slots a mode does not use, then the switch window's two
guards phi - lo and hi - phi. The guards linear in the state (stops, sleeve at rest, slip ending, driven part at
rest, switch window) also get their rows [1, c0, c1..c_n] (level = c0 + sum c_i y_i) for the integrators' exact
location.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import inspect
import math
import sys
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numba
import numpy as np

import mech_regulator
from mech_regulator.cache import folder as cache_folder
from mech_regulator.cache import write as _write
from mech_regulator.effects import output_position_of
from mech_regulator.model import MachineModel
from mech_regulator.model.drivetrain import BACKWARD, CLUTCH_CODE, FORWARD, HELD, STUCK
from mech_regulator.model.machine import StateTable
from mech_regulator.solvers.compiled import kernels
from mech_regulator.solvers.compiled.events import NONLINEAR_ONTO, STEP_ONTO
from mech_regulator.solvers.compiled.source import (
    CLAMP_HI,
    CLAMP_LO,
    CLUTCH_MODE,
    DRIVEN_MODE,
    EXTERNAL_OFFSET,
    EXTERNAL_SLOPE,
    HELD_THROTTLE_EXPRESSION,
    NO_ANCHOR,
    NORMAL_SLOTS,
    PIECE_INDEX,
    SERVO_MODE,
    SLEEVE_MODE,
    WINDOW_HI,
    WINDOW_LO,
    GovernorWriter,
    Parameters,
    effect_call,
    effect_definition,
    held_position_call,
    module_source,
    present,
    reads_position,
    reduced_lines,
)
from mech_regulator.solvers.compiled.train_source import (
    clutch_lines,
    coupling_lines,
    crank_guard_lines,
    joint_friction_lines,
    kinetostatics_joints,
)
from mech_regulator.solvers.time_domain import _anchors, _break, _journals

DRIVEN_CODE = {FORWARD: 0.0, BACKWARD: 1.0, HELD: 2.0}

_LOADED: dict[str, object] = {}  # module hash -> imported module, for the whole process
_RECENT: dict[int, CompiledScene] = {}  # id(model) -> its CompiledScene, the last RECENT_MODELS models compiled
RECENT_MODELS = 64


@dataclass(frozen=True)
class CompiledScene:
    """A scene's compiled right-hand side and guards with its parameters.

    rhs, guards: the numba dispatchers (signatures.RHS_SIGNATURE, GUARDS_SIGNATURE), callable from Python;
    rhs_callback, guards_callback: the same functions compiled as C callbacks, what the integrators are given (a
    dispatcher argument costs numba some 50 us per call to turn into a function pointer); parameters: p with the
    segment slots zero; n_guards: slots of `guards` (mode guards, then two per model.state_tables entry from
    breakpoint_slot on: its value above the held piece's lower breakpoint and below its upper one, then the window's
    two if window_slot is not None); source and path of the generated module; table_slots: per state table the
    slot in p of its anchor (NaN: the table as it is), then its piece's lower and upper breakpoints in the guard's
    state (-inf, inf: none); mode_rows(mode) -> the linear rows of the mode's guards. Joint friction with a mechanism
    (docs/theory.md §6.5): friction_slot, the first of its slots in p (per guide with friction its normal sign s_N, 0:
    |N|, and its guard's start level; then the signs s_j of the kinetostatics' joints' relative rates, the presets' four
    or a linkage's all, 0: |k_j|), and normal_slot, the guard slot of the first guide's s_N N (a crank–slider's guide or
    a linkage's prismatic joints with friction, n_normals of them in joint_friction.guides' order, after the mode's
    guards; N itself while its s_N is 0, what hold_normal reads its sign from), or None; reactions_callback (a C
    callback, as rhs_callback) writes the |R_j|^2 of the n_journals journals with friction (guards_callback, never
    called, when n_journals is 0)."""

    model: MachineModel
    rhs: Callable[..., None]
    guards: Callable[..., None]
    rhs_callback: object
    guards_callback: object
    parameters: np.ndarray
    n_guards: int
    window_slot: int | None
    source: str
    path: Path
    breakpoint_slot: int | None = None
    table_slots: tuple[int, ...] = ()
    friction_slot: int | None = None
    normal_slot: int | None = None
    reactions_callback: object = None
    n_journals: int = 0
    n_normals: int = 0
    _mode_matrices: dict = field(default_factory=dict, repr=False, compare=False)  # (mode, sign of omega, window)
    # -> linear's rows before the breakpoints
    _mode_parameters: dict = field(default_factory=dict, repr=False, compare=False)  # (mode, window) -> p before the
    # piece and the tables (parameters_for)

    def parameters_for(
        self,
        piece,
        mode,
        window: tuple[float, float] | None,
        omega: float = 0.0,
        held: list[int] | None = None,
        y: np.ndarray | None = None,
    ) -> np.ndarray:
        """p for one segment: the external-load piece (offset [N m], slope [N m/s], held throttle), the mode's
        codes, the switch window (lo, hi) [rad] (effects see phi clamped to it less a margin of 1e-9 of its
        width, as MachineModel.rhs) and the sign of the crank's speed omega [rad/s] at the segment's start (which
        joint friction's crank guard watches, as MachineModel.guards(mode, y)); with held (per state table its piece,
        time_domain._held_pieces) and the start state y as the stepper steps it (phi the phase), the tables' anchors and
        their breakpoint guards' bounds (those of a table that turns with phi in the stepper's phi); with joint
        friction's corner angles and a window, the signs of the joints' relative rates at its middle (the guides' N
        signs: hold_normal)."""
        return self.parameters_with(self.piece_values(piece, omega), mode, window, held, y)

    def parameters_with(
        self,
        values,
        mode,
        window: tuple[float, float] | None,
        held: list[int] | None = None,
        y: np.ndarray | None = None,
    ) -> np.ndarray:
        """parameters_for with the values of p[PIECE_SLOTS] given (piece_values', or a row of the stepper's pieces:
        solvers/compiled/run.py)."""
        key = (mode, window)
        in_mode = self._mode_parameters.get(key)
        if in_mode is None:
            in_mode = self._mode_parameters[key] = self._parameters_in(mode, window)
        p = in_mode.copy()
        p[PIECE_INDEX] = values
        if held:
            anchors = _anchors(self.model.state_tables, held)
            for slot, anchor, (low, high) in zip(self.table_slots, anchors, self._held_bounds(held, y)):
                p[slot], p[slot + 1], p[slot + 2] = anchor, low, high
        return p

    def _parameters_in(self, mode, window: tuple[float, float] | None) -> np.ndarray:
        """The part of parameters_for's p that depends on the mode and the switch window (lo, hi) [rad] alone: the
        mode's codes, the clamp and the window, joint friction's signs of the relative rates."""
        p = self.parameters.copy()
        model = self.model
        if model.governor is not None and mode is not None:
            p[SLEEVE_MODE], p[SERVO_MODE] = model.governor.mode_codes((mode[0], mode[1]))
        if model.driven is not None:
            train = model.train_mode_of(mode)
            p[DRIVEN_MODE] = DRIVEN_CODE[train[-1]]
            if model.clutch is not None:
                p[CLUTCH_MODE] = CLUTCH_CODE[train[0]]
        if window is not None:
            margin = 1e-9 * (window[1] - window[0])
            p[CLAMP_LO], p[CLAMP_HI] = window[0] + margin, window[1] - margin
            p[WINDOW_LO], p[WINDOW_HI] = window
        if self.friction_slot is not None and window is not None:
            friction = present(model.joint_friction, "model's joint friction")
            if friction.corner_angles:  # |k_j| as s_j k_j
                first_rate = self.friction_slot + NORMAL_SLOTS * self.n_normals
                for index, sign in zip(friction.indices, friction.ratio_signs(0.5 * (window[0] + window[1]))):
                    p[first_rate + index] = sign
        return p

    @staticmethod
    def piece_values(piece, omega: float) -> tuple[float, ...]:
        """The values of p[PIECE_SLOTS] for an external-load piece (offset [N m], slope [N m/s], held throttle [-],
        the throttle's slope [1/s], curvature [1/s^2], start time [s], sensitivity to the crank's speed [s/rad] and
        stops (low, high) [-]; None: no load, full throttle) and the sign of the crank's speed omega [rad/s] at the
        segment's start."""
        if piece is None:
            return 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, sign_of(omega)
        return (
            piece.offset,
            piece.slope,
            piece.throttle,
            piece.throttle_slope,
            piece.throttle_curvature,
            piece.start,
            piece.throttle_per_speed,
            piece.throttle_low,
            piece.throttle_high,
            sign_of(omega),
        )

    def hold_normal(
        self, p: np.ndarray, t: float, y: np.ndarray, sides: tuple[float, ...], crossed: int | None
    ) -> tuple[float, ...]:
        """Set in p (parameters_for's, every s_N 0) the guides' normal signs s_N that the segment from (t [s], y, phi
        wrapped as the stepper's) holds and their guards' start levels, as time_domain._normal_guards: the sign of
        each guide's N at the start (read with every |N| as it is), but for guide number `crossed`, whose guard just
        crossed, its side in sides (already flipped); a guard's level starts at min(0, s_N N) there. Returns the
        signs, one per guide."""
        levels = np.zeros(self.n_guards)
        normal_slot = present(self.normal_slot, "compiled scene's normal slot")
        friction_slot = present(self.friction_slot, "compiled scene's friction slot")
        normals = slice(normal_slot, normal_slot + self.n_normals)
        signs = slice(friction_slot, friction_slot + NORMAL_SLOTS * self.n_normals, NORMAL_SLOTS)
        if crossed is None or self.n_normals > 1:  # a guide's guard reads N itself while its s_N is 0
            self.guards(t, y, p, levels)
        sides = tuple(
            sides[k] if k == crossed else 1.0 if level >= 0.0 else -1.0 for k, level in enumerate(levels[normals])
        )
        p[signs] = sides
        self.guards(t, y, p, levels)
        p[friction_slot + 1 : friction_slot + NORMAL_SLOTS * self.n_normals : NORMAL_SLOTS] = np.minimum(
            0.0, levels[normals]
        )
        return sides

    def _held_bounds(self, held: list[int], y: np.ndarray | None) -> list[tuple[float, float]]:
        """Per state table, the held piece's lower and upper breakpoints in the guard's state (the arm angle [rad] of a
        valve table's sleeve positions, the twist [rad], phi - twist [rad] for a driven part's table, phi the phase
        of the state y the stepper starts from, time_domain._held_pieces), moved to y (given with held) where it is
        just across one (as time_domain._breakpoint_guards); -inf, inf where the piece has none."""
        if not held:
            return []
        bounds = []
        start_state = present(y, "segment's start state")
        for (coefficients, table), i in zip(breakpoint_states(self.model), held):
            start = sum(c * start_state[index] for index, c in coefficients)
            bounds.append((min(_break(table, i - 1), start), max(_break(table, i), start)))
        return bounds

    def linear(
        self,
        mode,
        window: tuple[float, float] | None,
        omega: float = 0.0,
        held: list[int] | None = None,
        y: np.ndarray | None = None,
    ) -> np.ndarray:
        """The integrators' linear-guard matrix (n_guards rows of [flag, c0, c1..c_n]) for a mode, window and the
        crank's speed at the segment's start [rad/s]: flag 1 where the guard is c0 + sum c_i y_i, 0 where it is not
        linear (or unused); with held and the start state y, the breakpoint guards of the held pieces (STEP_ONTO)."""
        key = (mode, sign_of(omega), window)  # mode_rows reads omega's sign only
        rows = self._mode_matrices.get(key)
        n = len(self.model.state_names()) if rows is None else rows.shape[1] - 2
        if rows is None:
            rows = np.zeros((self.n_guards, n + 2))
            for slot, row in enumerate(mode_rows(self.model, mode, omega)):
                if row is not None:
                    rows[slot] = row
            if self.window_slot is not None and window is not None:
                rows[self.window_slot] = _row(n, 0, 1.0, -window[0])
                rows[self.window_slot + 1] = _row(n, 0, -1.0, window[1])
                rows[self.window_slot : self.window_slot + 2, 0] = STEP_ONTO  # a switch: the state by a step onto it
            if self.normal_slot is not None:  # a guide's N = 0: a nonlinear guard, also a step onto it
                rows[self.normal_slot : self.normal_slot + self.n_normals, 0] = NONLINEAR_ONTO
            self._mode_matrices[key] = rows
        matrix = rows.copy()  # the stepper writes the window's rows of its copy (integrators._kink_restart)
        if self.breakpoint_slot is not None and held is not None:  # a table's breakpoint: also a step onto it
            slot = self.breakpoint_slot
            bounds = self._held_bounds(held, y)
            for (coefficients, _), (low, high) in zip(breakpoint_states(self.model), bounds):
                if low > -math.inf:
                    matrix[slot] = _row(n, 0, 0.0, -low)
                    for index, c in coefficients:
                        matrix[slot, 2 + index] = c
                    matrix[slot, 0] = STEP_ONTO
                if high < math.inf:
                    matrix[slot + 1] = _row(n, 0, 0.0, high)
                    for index, c in coefficients:
                        matrix[slot + 1, 2 + index] = -c
                    matrix[slot + 1, 0] = STEP_ONTO
                slot += 2
        return matrix


def sign_of(value: float) -> float:
    """float(np.sign(value)) for a Python float (-1.0, 0.0, 1.0 or NaN), without numpy's call on a scalar."""
    return 1.0 if value > 0.0 else -1.0 if value < 0.0 else 0.0 if value == 0.0 else math.nan


def breakpoint_states(model: MachineModel) -> list[tuple[tuple[tuple[int, float], ...], StateTable]]:
    """Per model.state_tables entry, the (state index, coefficient) pairs of the combination of states its guards
    are linear in, and the table with its breakpoints there: the arm angle a_k = arccos(1 - z_k / (2 l)) [rad] of a
    valve table's sleeve breakpoints z_k (z rises with a), the twist [rad] of a coupling table's, phi - twist [rad]
    for a driven part's table (its knots)."""
    states = []
    for table in model.state_tables:
        if table.name == "valve table":  # only a governor with valve_breaks has one
            coefficients, breaks = present(model.governor, "governor").valve_table_state(table.breaks)
            states.append((coefficients, replace(table, breaks=breaks)))
        elif table.angular:
            states.append((((0, 1.0), (model.coupling_index, -1.0)), table))
        else:
            states.append((((model.coupling_index, 1.0),), table))
    return states


_ANNOUNCED: set[str | None] = set()  # the scenes whose new module compile_scene has announced in this process


def compile_scene(model: MachineModel) -> CompiledScene:
    """The compiled right-hand side and guards of a scene (generated, written to the cache and imported once per
    process; numba compiles only on the first start with an empty cache). A model compiled lately is answered
    from memory (a model is immutable; its entry holds it, so its id is not reused while there)."""
    recent = _RECENT.get(id(model))
    if recent is not None and recent.model is model:
        return recent
    (
        source,
        parameters,
        n_guards,
        window_slot,
        breakpoint_slot,
        table_slots,
        friction_slot,
        normal_slot,
        n_journals,
        n_normals,
    ) = generate(model)
    digest = hashlib.sha256(
        "\n".join([source, _kernels_source(), mech_regulator.__version__, numba.__version__]).encode()
    ).hexdigest()[:20]
    path = _module_path(digest)
    if digest not in _LOADED and (not path.exists() or path.read_text(encoding="utf-8") != source):
        if model.scene.name not in _ANNOUNCED:  # once per scene (its machine and its governor have a module each)
            _ANNOUNCED.add(model.scene.name)
            print(
                f"note: compiling the fast path's module of scene '{model.scene.name}' once (a few seconds; later "
                "runs load it at once)",
                file=sys.stderr,
                flush=True,
            )
        _write(path, source)
    module = load_scene_module(digest)
    compiled = CompiledScene(
        model,
        module.rhs,
        module.guards,
        module.rhs_callback,
        module.guards_callback,
        parameters,
        n_guards,
        window_slot,
        source,
        path,
        breakpoint_slot,
        table_slots,
        friction_slot,
        normal_slot,
        module.reactions_callback if n_journals else module.guards_callback,
        n_journals,
        n_normals,
    )
    if len(_RECENT) >= RECENT_MODELS:
        del _RECENT[next(iter(_RECENT))]
    _RECENT[id(model)] = compiled
    return compiled


def load_scene_module(digest: str):
    """The generated module scene_<digest>.py of the cache folder, imported once per process (numba loads its
    functions from its disk cache as it imports them, or compiles them) and kept in _LOADED. The command server
    (cli/server.py) also calls it, for the modules its last command loaded (loaded_scene_modules)."""
    module = _LOADED.get(digest)
    if module is None:
        spec = importlib.util.spec_from_file_location(f"mech_regulator_compiled_{digest}", _module_path(digest))
        if spec is None or spec.loader is None:
            raise ImportError(f"cannot import the fast path's generated module {_module_path(digest)}")
        module = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = module  # numba's cache finds the module's globals by its name
        spec.loader.exec_module(module)
        _LOADED[digest] = module
    return module


def loaded_scene_modules() -> list[str]:
    """The digests of the generated modules this process has imported (load_scene_module)."""
    return list(_LOADED)


def _module_path(digest: str) -> Path:
    return cache_folder() / f"scene_{digest}.py"


@functools.cache
def _kernels_source() -> str:
    """kernels.py's source and that of the tables' lookups it compiles (effects/tables.py), part of every module's
    cache name: numba's cache would not notice a changed kernel (a mechanism's generated functions are in the
    module's text itself)."""
    return inspect.getsource(kernels) + inspect.getsource(kernels.tables)


def _row(n_states: int, index: int, coefficient: float, constant: float) -> np.ndarray:
    """A linear guard's row [1, c0, c1..c_n] with one nonzero coefficient."""
    row = np.zeros(n_states + 2)
    row[0], row[1], row[2 + index] = 1.0, constant, coefficient
    return row


def _linear_row(n_states: int, coefficients: tuple[tuple[int, float], ...], constant: float) -> np.ndarray:
    """A linear guard's row [1, c0, c1..c_n] of its (state index, coefficient) pairs and its constant c0."""
    row = np.zeros(n_states + 2)
    row[0], row[1] = 1.0, constant
    for index, coefficient in coefficients:
        row[2 + index] = coefficient
    return row


def mode_rows(model: MachineModel, mode, omega: float = 0.0) -> list[np.ndarray | None]:
    """For each guard of model.guards(mode, y) with y's crank speed omega [rad/s], in its order, its linear row
    [1, c0, c1..c_n] or None (not linear in the state: among others joint friction's 'crank starts', -|omega|)."""
    crank = []
    if model.joint_friction is not None:  # 'crank stops': s omega with s the sign of omega at the segment's start
        crank = [None if omega == 0.0 else _row(len(model.state_names()), 1, sign_of(omega), 0.0)]
    if mode is None:
        return crank
    n = len(model.state_names())
    rows: list[np.ndarray | None] = []
    if model.governor is not None:
        rows += [
            None if linear is None else _linear_row(n, *linear)
            for linear in model.governor.linear_guards((mode[0], mode[1]))
        ]
    if model.driven is not None:
        train = model.train_mode_of(mode)
        index = model.driven_speed_index
        if model.clutch is not None and train[0] == STUCK:
            rows += [None, None]
        elif model.clutch is not None:  # the slip ends: s (omega - omega2)
            slip = _row(n, 1, CLUTCH_CODE[train[0]], 0.0)
            slip[2 + index] = -CLUTCH_CODE[train[0]]
            rows.append(slip)
        sign = {FORWARD: 1.0, BACKWARD: -1.0}.get(train[-1])
        rows += [None, None] if sign is None else [_row(n, index, sign, 0.0)]
    return rows + crank


def generate(
    model: MachineModel,
) -> tuple[str, np.ndarray, int, int | None, int | None, tuple[int, ...], int | None, int | None, int, int]:
    """(module source, parameters p, number of guard slots, slot of the switch window's first guard or None, slot of
    the first breakpoint guard or None, CompiledScene.table_slots, friction_slot, normal_slot, number of journals
    with friction that `reactions` writes, number of guides with friction) of a scene's model (see the
    module docstring). The model must pass run.fast_path_refusal."""
    machine = model.scene.machine
    p = Parameters()
    table_slots = tuple(p.slots(math.nan, -math.inf, math.inf) for _ in model.state_tables)  # anchor, low, high
    anchor_of = {table.name: f"p[{slot}]" for table, slot in zip(model.state_tables, table_slots)}  # kernels' anchor
    body: list[str] = ["phi = y[0]", "omega = y[1]"]
    if model.reduced is not None:  # the model's, not the scene's: a co-simulated governor has no mechanism
        gravity = machine.gravity if model.has_weight else None
        body += reduced_lines(machine.mechanism, gravity, p, "phi", ("J_links", "dJ", "total", "q", "dq"))
    else:
        body.append("J_links, dJ, total, q, dq = 0.0, 0.0, 0.0, 0.0, 0.0")
    body.append(f"J = {p.scalar(model.inertia_constant)} + J_links")
    coupled = model.driven is not None  # the external load on the driven part, not on the crank
    if not coupled:
        body.append(f"total -= p[{EXTERNAL_OFFSET}] + p[{EXTERNAL_SLOPE}] * t")
    governor = model.governor
    scaled, switched = [], []
    kinked = any(effect.kink_angles for effect in model.effects)
    anchor = "anchor" if kinked else "phi"
    friction = model.joint_friction
    friction_slot = normal_slot = None
    n_normals = len(friction.guides) if friction is not None else 0
    if friction is not None and friction.loads is not None:  # the guides' N signs and levels, the joints' rate signs
        friction_slot = p.slots(*[0.0] * (NORMAL_SLOTS * n_normals + len(kinetostatics_joints(machine.mechanism))))
    if kinked:  # between two kinks the tables continue along the segment that holds the window's middle (rhs);
        #         without a window (p's edges both 0) they are the tables themselves
        body.append(f"anchor = 0.5 * (p[{WINDOW_LO}] + p[{WINDOW_HI}]) if p[{WINDOW_HI}] > p[{WINDOW_LO}] else phi")
        in_position = [effect for effect in model.effects if reads_position(effect.definition)]
        kinks = sorted({angle for effect in in_position for angle in effect.kink_angles})
        if kinks:  # a slider table's piece: that of x on the anchor's interval between its breakpoint crossings
            body.append(f"q_anchor = {held_position_call(kinks, output_position_of(model.reduced), p, 'anchor')}")
        elif in_position:  # x never crosses its breakpoints
            body.append("q_anchor = q")
    for effect in model.effects:
        if effect.switch_angles:
            switched.append(effect_definition(effect))
        elif effect.role == "drive" and governor is not None:
            scaled.append(effect_definition(effect))
        elif effect.role == "drive":  # times the held throttle, 1 unless co-simulated: exact
            body.append(
                f"total += {HELD_THROTTLE_EXPRESSION} * "
                f"{effect_call(effect_definition(effect), p, 'phi', 'omega', 'q', 'dq', anchor)}"
            )
        else:
            body.append(f"total += {effect_call(effect_definition(effect), p, 'phi', 'omega', 'q', 'dq', anchor)}")
    if switched:
        body.append(f"clamped = min(max(phi, p[{CLAMP_LO}]), p[{CLAMP_HI}])")
        body += [f"total += {effect_call(definition, p, 'clamped', 'omega', 'q', 'dq')}" for definition in switched]
    governor_lines: list[str] = []
    guard_lines: list[str] = []
    n_mode_guards = 0
    if governor is not None:  # the governor's own part (GovernorKind.source), its throttle scaling the drives
        valve = getattr(model.scene.governor, "valve", None)  # a direct governor's entry has one
        part = governor.source(GovernorWriter(p, valve), anchor_of.get("valve table", NO_ANCHOR))
        governor_lines, guard_lines, n_mode_guards = part.rates, list(part.guards), part.n_guards
        body.append(f"share = {part.throttle}")
        body += [
            f"total += share * {effect_call(definition, p, 'phi', 'omega', 'q', 'dq', anchor)}" for definition in scaled
        ]
    body.append("net = total - 0.5 * dJ * omega * omega")
    body.append("dydt[0] = omega")
    journals, reaction_lines = [], []  # the journals' positions in the kinetostatics; `reactions`' body
    if model.coupling is not None:
        train_lines, train_guards = coupling_lines(model, p, anchor_of.get("coupling table", NO_ANCHOR), table_slots)
        body += train_lines
        guard_lines += train_guards
        n_mode_guards += 2
    elif model.clutch is not None:  # the crank's net moment again in guards, phi unclamped (MachineModel.crank_side)
        crank = [
            line.split(" = ")[0] + " = phi" if line.startswith(("clamped = ", "anchor = ")) else line
            for line in body
            if line != "dydt[0] = omega"
        ]
        train_lines, train_guards = clutch_lines(model, p, crank)
        body += train_lines
        guard_lines += train_guards
        n_mode_guards += 4
    else:
        body.append("dydt[1] = net / J")
    if friction is not None:
        share = "share" if governor is not None else HELD_THROTTLE_EXPRESSION
        body += joint_friction_lines(model, p, share, anchor, "q_anchor" if kinked else "q", friction_slot)
        guard_lines += crank_guard_lines()
        n_mode_guards += 1
        copy = [line.replace("dydt[", "rates[") for line in body]  # the body up to here: R0, R1 and the rhs's epsilon
        journals = [friction.indices[k] for k in _journals(model)]
        if journals:  # |R0_j + R1_j epsilon|^2 of each journal
            reaction_lines = (
                [f"rates = np.empty({len(model.state_names())})"]
                + copy
                + [f"squares[{k}] = abs(R0[{j}] + R1[{j}] * rates[1]) ** 2" for k, j in enumerate(journals)]
            )
        if friction.guides:  # per guide s_N N - its start level (N while s_N is 0), with the rhs's epsilon
            guard_lines += [f"rates = np.empty({len(model.state_names())})"] + copy
            normal_slot = n_mode_guards  # their own slots: the mode guards before them are fewer in some modes
            first_sign = present(friction_slot, "friction slot")  # guides' friction reads the kinetostatics' loads
            for k, position in enumerate(friction.guides):
                side, low = f"p[{first_sign + NORMAL_SLOTS * k}]", f"p[{first_sign + NORMAL_SLOTS * k + 1}]"
                normal = f"(R0[{friction.indices[position]}] + R1[{friction.indices[position]}] * rates[1]).imag"
                guard_lines.append(
                    f"levels[{normal_slot + k}] = {side} * {normal} - {low} if {side} != 0.0 else {normal}"
                )
            n_mode_guards += n_normals
    body += governor_lines
    n_guards = n_mode_guards
    breakpoint_slot = n_guards if table_slots else None
    for slot, (coefficients, _) in zip(table_slots, breakpoint_states(model)):  # -inf, inf bounds: +inf, inactive
        value = " + ".join(f"{c!r} * y[{index}]" for index, c in coefficients)
        guard_lines += [
            f"levels[{n_guards}] = {value} - p[{slot + 1}]",
            f"levels[{n_guards + 1}] = p[{slot + 2}] - ({value})",
        ]
        n_guards += 2
    window_slot = None
    if switched or kinked or (friction is not None and friction.corner_angles):
        window_slot = n_guards
        n_guards += 2
        guard_lines += [
            f"levels[{window_slot}] = y[0] - p[{WINDOW_LO}]",
            f"levels[{window_slot + 1}] = p[{WINDOW_HI}] - y[0]",
        ]
    source = module_source(body, guard_lines, n_guards, reaction_lines, p.functions, p.formulas)
    return (
        source,
        p.array(),
        n_guards,
        window_slot,
        breakpoint_slot,
        table_slots,
        friction_slot,
        normal_slot,
        len(journals),
        n_normals,
    )
