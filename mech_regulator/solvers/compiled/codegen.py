"""The code generator of the fast path: a scene's right-hand side and guards as the source of a small module that
numba compiles once and caches on disk.

From a MachineModel it writes `rhs(t, y, p, dydt)` and `guards(t, y, p, levels)` (compiled with the explicit
signatures of solvers/compiled/signatures.py) that call only the effects the scene has (each drive's, load's,
valve's and the servo's one definition compiled, effects/definition.py, the call written by its call_source as the
reference path's; the kernels of solvers/compiled/kernels.py for the rest) — a machine without a mechanism has no
kinematics call, an ungoverned one no governor — and the parameter vector p they read, laid out as

    p[0:SEGMENT_SLOTS]   the segment's inputs (set by the outer loop, solvers/compiled/run.py): external load
                         offset [N m] and slope [N m/s], held throttle [-], sleeve / servo / driven-part mode codes,
                         the switch window (lo, hi) [rad] the effects see phi clamped into and its edges for the
                         window's guards [rad], the clutch's mode code, the sign of the crank's speed at the
                         segment's start (joint friction's crank guard), the co-simulated throttle's slope [1/s],
                         curvature [1/s^2] and start time [s] (LoadPiece.throttle_at);
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
from mech_regulator import mechanisms
from mech_regulator.cache import folder as cache_folder
from mech_regulator.cache import write as _write
from mech_regulator.effects import held_positions, joint_friction, output_position_of
from mech_regulator.effects.definition import (
    CLAMPED,
    INTERVALS,
    PERIODIC,
    Definition,
    call_source,
    definition_of,
    summed_source,
)
from mech_regulator.governors import pi
from mech_regulator.governors import servo as servo_motor
from mech_regulator.mechanisms.linkage import flat, symbolic
from mech_regulator.model import MachineModel
from mech_regulator.model.drivetrain import BACKWARD, CLUTCH_CODE, FORWARD, HELD, STUCK, DrivenModel
from mech_regulator.model.machine import StateTable
from mech_regulator.scene import schema
from mech_regulator.solvers.compiled import kernels
from mech_regulator.solvers.compiled.integrators import NONLINEAR_ONTO, STEP_ONTO
from mech_regulator.solvers.time_domain import _anchors, _break, _journals

# Segment inputs: fixed slots at the start of p
EXTERNAL_OFFSET, EXTERNAL_SLOPE, HELD_THROTTLE, SLEEVE_MODE, SERVO_MODE, DRIVEN_MODE = range(6)
CLAMP_LO, CLAMP_HI, WINDOW_LO, WINDOW_HI, CLUTCH_MODE, CRANK_DIRECTION = range(6, 12)
THROTTLE_SLOPE, THROTTLE_CURVATURE, THROTTLE_START = range(12, 15)
SEGMENT_SLOTS = 15
# the slots a load piece and the crank's speed at its start set (CompiledScene.piece_values)
PIECE_SLOTS = (
    EXTERNAL_OFFSET,
    EXTERNAL_SLOPE,
    HELD_THROTTLE,
    THROTTLE_SLOPE,
    THROTTLE_CURVATURE,
    THROTTLE_START,
    CRANK_DIRECTION,
)
PIECE_INDEX = np.array(PIECE_SLOTS, dtype=np.int64)
# the throttle of a co-simulated machine: held, or the polynomial of LoadPiece.throttle_at
NORMAL_SLOTS = 2  # joint friction's slots in p from friction_slot, per guide with friction: its normal sign s_N and
#                  its guard's start level; then the signs s_j of the joints' relative rates
HELD_THROTTLE_EXPRESSION = (
    f"min(max(p[{HELD_THROTTLE}] + (t - p[{THROTTLE_START}]) * (p[{THROTTLE_SLOPE}] + "
    f"(t - p[{THROTTLE_START}]) * p[{THROTTLE_CURVATURE}]), 0.0), 1.0)"
)

SLEEVE_CODE = {"": 0.0, "free": 0.0, "up": 1.0, "down": 2.0, "stuck": 3.0, "low": 4.0, "high": 5.0}
SERVO_CODE = {"": 0.0, "free": 0.0, "low": 1.0, "high": 2.0}
DRIVEN_CODE = {FORWARD: 0.0, BACKWARD: 1.0, HELD: 2.0}
ARM, ARM_RATE, SERVO, SHIFT = 2, 3, 4, 5
NO_ANCHOR = "math.nan"  # a table lookup's anchor that reads the table itself (effects/tables.py)

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
    rhs: object
    guards: object
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
        p = self.parameters.copy()
        p[PIECE_INDEX] = self.piece_values(piece, omega)
        model = self.model
        if model.governor is not None and mode is not None:
            p[SLEEVE_MODE], p[SERVO_MODE] = SLEEVE_CODE[mode[0]], SERVO_CODE[mode[1]]
        if model.driven is not None:
            train = model.train_mode_of(mode)
            p[DRIVEN_MODE] = DRIVEN_CODE[train[-1]]
            if model.clutch is not None:
                p[CLUTCH_MODE] = CLUTCH_CODE[train[0]]
        if window is not None:
            margin = 1e-9 * (window[1] - window[0])
            p[CLAMP_LO], p[CLAMP_HI] = window[0] + margin, window[1] - margin
            p[WINDOW_LO], p[WINDOW_HI] = window
        friction = model.joint_friction
        if self.friction_slot is not None and window is not None and friction.corner_angles:  # |k_j| as s_j k_j
            first_rate = self.friction_slot + NORMAL_SLOTS * self.n_normals
            for index, sign in zip(friction.indices, friction.ratio_signs(0.5 * (window[0] + window[1]))):
                p[first_rate + index] = sign
        if held is not None:
            anchors = _anchors(self.model.state_tables, held)
            for slot, anchor, (low, high) in zip(self.table_slots, anchors, self._held_bounds(held, y)):
                p[slot], p[slot + 1], p[slot + 2] = anchor, low, high
        return p

    @staticmethod
    def piece_values(piece, omega: float) -> tuple[float, ...]:
        """The values of p[PIECE_SLOTS] for an external-load piece (offset [N m], slope [N m/s], held throttle [-],
        the throttle's slope [1/s], curvature [1/s^2] and start time [s]; None: no load, full throttle) and the sign
        of the crank's speed omega [rad/s] at the segment's start."""
        if piece is None:
            return 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, sign_of(omega)
        return (
            piece.offset,
            piece.slope,
            piece.throttle,
            piece.throttle_slope,
            piece.throttle_curvature,
            piece.start,
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
        normals = slice(self.normal_slot, self.normal_slot + self.n_normals)
        signs = slice(self.friction_slot, self.friction_slot + NORMAL_SLOTS * self.n_normals, NORMAL_SLOTS)
        if crossed is None or self.n_normals > 1:  # a guide's guard reads N itself while its s_N is 0
            self.guards(t, y, p, levels)
        sides = tuple(
            sides[k] if k == crossed else 1.0 if level >= 0.0 else -1.0 for k, level in enumerate(levels[normals])
        )
        p[signs] = sides
        self.guards(t, y, p, levels)
        p[self.friction_slot + 1 : self.friction_slot + NORMAL_SLOTS * self.n_normals : NORMAL_SLOTS] = np.minimum(
            0.0, levels[normals]
        )
        return sides

    def _held_bounds(self, held: list[int], y: np.ndarray) -> list[tuple[float, float]]:
        """Per state table, the held piece's lower and upper breakpoints in the guard's state (the arm angle [rad] of a
        valve table's sleeve positions, the twist [rad], phi - twist [rad] for a driven part's table, phi the phase
        of the state y the stepper starts from, time_domain._held_pieces), moved to y where it is just across one (as
        time_domain._breakpoint_guards); -inf, inf where the piece has none."""
        bounds = []
        for (coefficients, table), i in zip(breakpoint_states(self.model), held):
            start = sum(c * y[index] for index, c in coefficients)
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
        n = len(self.model.state_names())
        key = (mode, sign_of(omega), window)  # mode_rows reads omega's sign only
        rows = self._mode_matrices.get(key)
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
        if table.name == "valve table":
            states.append(
                (((ARM, 1.0),), replace(table, breaks=tuple(model.governor.sensor.arm_angle(z) for z in table.breaks)))
            )
        elif table.angular:
            states.append((((0, 1.0), (model.coupling_index, -1.0)), table))
        else:
            states.append((((model.coupling_index, 1.0),), table))
    return states


_ANNOUNCED: set[str] = set()  # the scenes whose new module compile_scene has announced in this process


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
    governor = model.governor
    if governor is not None and governor.kind != "pi":
        low, high = governor.sensor.stop_angles()
        hit_low, hit_high = _row(n, ARM, 1.0, -low), _row(n, ARM, -1.0, high)
        rows += {
            "free": [hit_low, hit_high],
            "up": [_row(n, ARM_RATE, 1.0, 0.0), hit_high],
            "down": [_row(n, ARM_RATE, -1.0, 0.0), hit_low],
            "stuck": [None, None],
            "low": [None],
            "high": [None],
        }[mode[0]]
        if governor.kind == "indirect":
            s_low, s_high = governor.travel
            rows += [_row(n, SERVO, 1.0, -s_low), _row(n, SERVO, -1.0, s_high)] if mode[1] == "free" else [None]
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


class _Parameters:
    """Builds p: scalars get a slot each; a table gets two slots (its offset and length), its columns appended
    after all scalars when done."""

    def __init__(self):
        self.values: list[float] = [0.0] * SEGMENT_SLOTS
        self.values[HELD_THROTTLE] = 1.0
        self.tables: list[tuple[int, list[float]]] = []
        self.functions: dict[str, str] = {}  # name -> source of the generated functions the module calls
        self.formulas: dict[str, Callable] = {}  # name in the module -> a definition's formula the module calls

    def scalar(self, value: float) -> str:
        return f"p[{self.slot(value)}]"

    def formula(self, function: Callable) -> str:
        """The name the module calls a definition's formula function by (kernels.compiled), noted in formulas."""
        name = f"{function.__module__.rsplit('.', 1)[-1]}_{function.__name__}"
        self.formulas[name] = function
        return name

    def slot(self, value: float) -> int:
        """A new scalar slot holding value; its index in p."""
        self.values.append(float(value))
        return len(self.values) - 1

    def slots(self, *values: float) -> int:
        """Consecutive new scalar slots holding values; the index in p of the first."""
        first = len(self.values)
        self.values += [float(value) for value in values]
        return first

    def table(self, *columns) -> str:
        """'p, offset, n' for the kernels: the columns (equal lengths) stored one after the other."""
        offset_slot = len(self.values)
        self.values += [0.0, float(len(columns[0]))]
        self.tables.append((offset_slot, [float(v) for column in columns for v in column]))
        return f"p, int(p[{offset_slot}]), int(p[{offset_slot + 1}])"

    def array(self) -> np.ndarray:
        values = list(self.values)
        for offset_slot, data in self.tables:
            values[offset_slot] = float(len(values))
            values += data
        return np.array(values, dtype=float)


def _effect_call(
    definition: Definition,
    p: _Parameters,
    phi: str,
    omega: str,
    q: str,
    dq: str,
    anchor: str | None = None,
    held: str | None = None,
    function: Callable | None = None,
) -> str:
    """The call of a drive's or load's formula (definition.moment, or `function`: its output_force) as source, its
    numbers and table stored in p: a periodic table in phi read on the segment that holds `anchor` (default phi: the
    table itself), a clamped table in the output position on the piece that holds the slider position `held` [m]
    (default: q at the anchor phi, else generate's q_anchor), an interval table at phi; summed over the mechanism's
    outputs (an engine's cylinders: output k >= 2's q and dq named as _reduced_lines does). The call is written by
    definition.summed_source, as the reference path's."""
    function = function or definition.moment
    numbers = {name: p.scalar(value) for name, value in definition.numbers.items()}
    spec = definition.table
    anchor = anchor or phi
    read = None
    if spec is not None:
        columns = p.table(spec.xs, spec.ys) if spec.ys else p.table(spec.xs)
        period = p.scalar(spec.period) if spec.kind != CLAMPED else ""
        shifts = [f" + {p.scalar(shift)}" for shift in spec.shifts] if spec.shifts is not None else None
        held = held or (q if anchor == phi else f"{q}_anchor")  # x on the anchor's interval (generate's q_anchor)

        def read(i: int, position: str) -> str:
            shift = shifts[i] if shifts is not None else ""
            if spec.kind == PERIODIC:
                return f"k.periodic_linear({phi}{shift}, {anchor}{shift}, {columns}, {period})"
            if spec.kind == INTERVALS:
                return f"k.inside_intervals({phi}{shift}, {columns}, {period})"
            return f"k.clamped_linear({position}, {held}, {columns})"

    def inputs(i: int) -> dict[str, str]:
        position, ratio = (q, dq) if i == 0 else (f"{q}_{i + 1}", f"{dq}_{i + 1}")
        given = {"t": "t", "phi": phi, "omega": omega, "q": position, "dq": ratio}
        if read is not None:
            given["table"] = read(i, position)
        return given

    return summed_source(definition, function, p.formula(function), inputs, numbers)


def _formula_call(p: _Parameters, function: Callable, inputs: dict[str, str], numbers: dict[str, float]) -> str:
    """The call of a formula function (a valve's, the servo's) as source, its numbers stored in p."""
    stored = {name: p.scalar(value) for name, value in numbers.items()}
    return call_source(function, p.formula(function), inputs, stored)


def _valve_call(definition: Definition, p: _Parameters, z: str, anchor: str = NO_ANCHOR) -> str:
    """The call of a valve's formula at the sleeve position z [m] as source, its table read on the piece that holds
    the anchor (anchor: 'p[slot]' of the valve table's anchor; NO_ANCHOR: z itself)."""
    inputs = {"z": z}
    if definition.table is not None:
        inputs["table"] = f"k.clamped_linear({z}, {anchor}, {p.table(definition.table.xs, definition.table.ys)})"
    return _formula_call(p, definition.moment, inputs, definition.numbers)


def effect_kernel(definition: Definition, function: Callable | None = None, anchored: bool = False):
    """The fast path's code of one drive's or load's formula (definition.moment, or `function`: its output_force)
    alone, as generate writes it into a scene's rhs (_effect_call), compiled: (f(t, phi, omega, anchor, q_anchor, p,
    q, dq[, q_2, dq_2, ...]) -> value, p), one q and dq per output of the mechanism; anchored: its table read on the
    piece that holds anchor [rad] (a periodic one) or the slider position q_anchor [m] (one in q). What the check
    that both paths agree compiles (test/test_effect_definitions.py)."""
    p = _Parameters()
    call = _effect_call(
        definition,
        p,
        "phi",
        "omega",
        "q",
        "dq",
        "anchor" if anchored else None,
        "q_anchor" if anchored else None,
        function,
    )
    outputs = "".join(f", q_{k}, dq_{k}" for k in range(2, definition.outputs + 1))
    return _kernel(f"t, phi, omega, anchor, q_anchor, p, q, dq{outputs}", call, p)


def valve_kernel(definition: Definition, anchored: bool = False):
    """The fast path's code of a valve's formula alone, as generate writes it (_valve_call), compiled: (f(z, anchor,
    p) -> throttle [-], p); anchored: its table read on the piece that holds the sleeve position anchor [m]."""
    p = _Parameters()
    return _kernel("z, anchor, p", _valve_call(definition, p, "z", "anchor" if anchored else NO_ANCHOR), p)


def _kernel(arguments: str, call: str, p: _Parameters):
    """(The function `kernel(arguments): return call` compiled by numba over the kernels and p's formulas, p's
    array); compiled once per process for each source (the source depends only on the entry's structure)."""
    formulas = tuple((name, function.__module__, function.__name__) for name, function in p.formulas.items())
    return _compiled_kernel(f"def kernel({arguments}):\n    return {call}\n", formulas), p.array()


@functools.cache
def _compiled_kernel(source: str, formulas: tuple[tuple[str, str, str], ...]):
    """The function `kernel` of source compiled by numba, math, the kernels and the formulas (name, module, function
    name) in its globals, as in a generated module."""
    namespace = {"math": math, "k": kernels} | {
        name: kernels.compiled(module, function) for name, module, function in formulas
    }
    exec(source, namespace)
    return numba.njit(namespace["kernel"])


def _held_position_call(kinks, output_position, p: _Parameters, anchor: str) -> str:
    """The kernel call (as source) of the slider position [m] that holds a slider table's piece on the interval
    between its kinks [rad] (sorted, in [0, 2 pi)) around the crank angle `anchor` (effects.held_positions of the
    mechanism's output_position, looked up by kernels.held_position)."""
    held = held_positions(tuple(kinks), output_position)
    return f"k.held_position({anchor}, {p.table(list(kinks) + [2.0 * math.pi], held)})"


def _reduced_lines(mechanism, gravity, p: _Parameters, angle: str, names: tuple[str, ...]) -> list[str]:
    """Source assigning a mechanism's reduced(phi) (mechanisms.build_reduced) at `angle` to the five `names` (J_links,
    dJ, weight, q, dq): the generated function of its linkage (mechanisms.linkage_of: a preset's or the scene's own;
    mechanisms/linkage/symbolic.py), the very source the reference path runs, added to the module (p.functions), on
    the linkage's program (flat.encode; gravity None: zero, no weight moment) stored as a table in p. Several outputs
    (a multi-cylinder engine's pistons): the first assigns q, dq, output k (k >= 2) q_k, dq_k (what the engine's gas
    moment reads)."""
    core, structure, outputs = mechanisms.linkage_of(mechanism)
    program = flat.encode(core, structure.groups, gravity)
    name, source = symbolic.reduced_source(program, symbolic.output_records(program, core, outputs))
    p.functions[name] = source
    call = f"{name}({angle}, {p.table(program).rsplit(', ', 1)[0]})"  # 'p, int(p[slot])': the program's offset
    if len(outputs) <= 1:
        return [f"{', '.join(names)} = {call}"]
    J, dJ, weight, q, dq = names
    rest = "".join(f", {q}_{k}, {dq}_{k}" for k in range(2, len(outputs) + 1))
    return [f"{J}, {dJ}, {weight}, {q}, {dq}{rest} = {call}"]


def _shared_functions(functions, p: _Parameters) -> tuple[str, ...]:
    """The names of functions the reference path runs (a sensor's formulas, CentrifugalSensor.kernels; the PI law,
    governors/pi.py), their very source added to the module (p.functions) to be compiled."""
    for function in functions:
        p.functions[function.__name__] = inspect.getsource(function)
    return tuple(function.__name__ for function in functions)


def generate(
    model: MachineModel,
) -> tuple[str, np.ndarray, int, int | None, int | None, tuple[int, ...], int | None, int | None, int, int]:
    """(module source, parameters p, number of guard slots, slot of the switch window's first guard or None, slot of
    the first breakpoint guard or None, CompiledScene.table_slots, friction_slot, normal_slot, number of journals
    with friction that `reactions` writes, number of guides with friction) of a scene's model (see the
    module docstring). The model must pass run.fast_path_refusal."""
    machine = model.scene.machine
    p = _Parameters()
    table_slots = tuple(p.slots(math.nan, -math.inf, math.inf) for _ in model.state_tables)  # anchor, low, high
    anchor_of = {table.name: f"p[{slot}]" for table, slot in zip(model.state_tables, table_slots)}  # kernels' anchor
    body: list[str] = ["phi = y[0]", "omega = y[1]"]
    if model.reduced is not None:  # the model's, not the scene's: a co-simulated governor has no mechanism
        gravity = machine.gravity if model.has_weight else None
        body += _reduced_lines(machine.mechanism, gravity, p, "phi", ("J_links", "dJ", "total", "q", "dq"))
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
        friction_slot = p.slots(*[0.0] * (NORMAL_SLOTS * n_normals + len(_kinetostatics_joints(machine.mechanism))))
    if kinked:  # between two kinks the tables continue along the segment that holds the window's middle (rhs);
        #         without a window (p's edges both 0) they are the tables themselves
        body.append(f"anchor = 0.5 * (p[{WINDOW_LO}] + p[{WINDOW_HI}]) if p[{WINDOW_HI}] > p[{WINDOW_LO}] else phi")
        in_position = [effect for effect in model.effects if _reads_position(effect.definition)]
        kinks = sorted({angle for effect in in_position for angle in effect.kink_angles})
        if kinks:  # a slider table's piece: that of x on the anchor's interval between its breakpoint crossings
            body.append(f"q_anchor = {_held_position_call(kinks, output_position_of(model.reduced), p, 'anchor')}")
        elif in_position:  # x never crosses its breakpoints
            body.append("q_anchor = q")
    for effect in model.effects:
        if effect.switch_angles:
            switched.append(effect.definition)
        elif effect.role == "drive" and governor is not None:
            scaled.append(effect.definition)
        elif effect.role == "drive":  # times the held throttle, 1 unless co-simulated: exact
            body.append(
                f"total += {HELD_THROTTLE_EXPRESSION} * "
                f"{_effect_call(effect.definition, p, 'phi', 'omega', 'q', 'dq', anchor)}"
            )
        else:
            body.append(f"total += {_effect_call(effect.definition, p, 'phi', 'omega', 'q', 'dq', anchor)}")
    if switched:
        body.append(f"clamped = min(max(phi, p[{CLAMP_LO}]), p[{CLAMP_HI}])")
        body += [f"total += {_effect_call(definition, p, 'clamped', 'omega', 'q', 'dq')}" for definition in switched]
    governor_lines, guard_lines, opening = [], [], []
    if governor is not None and governor.kind == "pi":
        throttle_name, rate_name = _shared_functions((pi.pi_throttle, pi.pi_integral_rate), p)
        law = f"y[{pi.INTEGRAL}], omega, " + ", ".join(p.scalar(value) for value in governor.law())
        throttle = f"{throttle_name}({law})"
        governor_lines.append(f"dydt[{pi.INTEGRAL}] = {rate_name}({law})")
    elif governor is not None:
        sensor = governor.sensor
        sleeve_kernel, lift_kernel, acceleration_kernel = _shared_functions(sensor.kernels(), p)
        sensor_args = ", ".join(p.scalar(value) for value in sensor.kernel_parameters())
        kinetic, static = p.scalar(sensor.kinetic_friction), p.scalar(sensor.static_friction)
        low, high = (p.scalar(v) for v in sensor.stop_angles())
        z = f"{sleeve_kernel}(y[{ARM}], {sensor_args})"
        if governor.kind == "direct":
            throttle = _valve_call(
                definition_of(model.scene.governor.valve), p, z, anchor_of.get("valve table", NO_ANCHOR)
            )
        else:
            throttle = f"y[{SERVO}]"
            opening = [f"opening = {z} - {p.scalar(governor.pilot_neutral)}"]
            if governor.feedback == "rigid":
                feedback = _formula_call(
                    p,
                    servo_motor.rigid_feedback,
                    {"servo": f"y[{SERVO}]"},
                    {"gain": governor.feedback_gain, "reference": governor.feedback_reference},
                )
                opening.append(f"opening += {feedback}")
            elif governor.feedback == "isodromic":
                opening.append(f"opening += y[{SHIFT}]")
            command = _formula_call(
                p,
                servo_motor.servo_command,
                {"opening": "opening"},
                {"gain": governor.servo_gain, "max_speed": governor.servo_max_speed, "dead_band": governor.dead_band},
            )
        lift = f"{lift_kernel}(y[{ARM}], omega, {sensor_args})"
        governor_lines += [
            f"sleeve_mode = p[{SLEEVE_MODE}]",
            "if sleeve_mode <= 2.0:",
            f"    friction = 0.0 if sleeve_mode == 0.0 else ({kinetic} if sleeve_mode == 1.0 else -{kinetic})",
            f"    dydt[{ARM}] = y[{ARM_RATE}]",
            f"    dydt[{ARM_RATE}] = {acceleration_kernel}(y[{ARM}], y[{ARM_RATE}], omega, friction, {sensor_args})",
            "else:",
            f"    dydt[{ARM}] = 0.0",
            f"    dydt[{ARM_RATE}] = 0.0",
        ]
        guard_lines += [
            f"sleeve_mode = p[{SLEEVE_MODE}]",
            "if sleeve_mode == 0.0:",
            f"    levels[0] = y[{ARM}] - {low}",
            f"    levels[1] = {high} - y[{ARM}]",
            "    g = 2",
            "elif sleeve_mode == 1.0:",
            f"    levels[0] = y[{ARM_RATE}]",
            f"    levels[1] = {high} - y[{ARM}]",
            "    g = 2",
            "elif sleeve_mode == 2.0:",
            f"    levels[0] = -y[{ARM_RATE}]",
            f"    levels[1] = y[{ARM}] - {low}",
            "    g = 2",
            "elif sleeve_mode == 3.0:",
            f"    force = {lift}",
            f"    levels[0] = {static} - force",
            f"    levels[1] = {static} + force",
            "    g = 2",
            "elif sleeve_mode == 4.0:",
            f"    levels[0] = {static} - {lift}",
            "    g = 1",
            "else:",
            f"    levels[0] = {static} + {lift}",
            "    g = 1",
        ]
        if governor.kind == "indirect":
            s_low, s_high = (p.scalar(v) for v in governor.travel)
            governor_lines += opening + [
                f"servo_rate = {command} if p[{SERVO_MODE}] == 0.0 else 0.0",
                f"dydt[{SERVO}] = servo_rate",
            ]
            if governor.feedback == "isodromic":
                rate = _formula_call(
                    p,
                    servo_motor.isodromic_rate,
                    {"servo_rate": "servo_rate", "shift": f"y[{SHIFT}]"},
                    {"gain": governor.feedback_gain, "time_constant": governor.feedback_time_constant},
                )
                governor_lines.append(f"dydt[{SHIFT}] = {rate}")
            guard_lines += (
                [
                    f"if p[{SERVO_MODE}] == 0.0:",
                    f"    levels[g] = y[{SERVO}] - {s_low}",
                    f"    levels[g + 1] = {s_high} - y[{SERVO}]",
                    "    g += 2",
                    "else:",
                ]
                + [f"    {line}" for line in opening]
                + [
                    f"    command = {command}",
                    f"    levels[g] = -command if p[{SERVO_MODE}] == 1.0 else command",
                    "    g += 1",
                ]
            )
    if governor is not None:
        body.append(f"share = {throttle}")
        body += [
            f"total += share * {_effect_call(definition, p, 'phi', 'omega', 'q', 'dq', anchor)}"
            for definition in scaled
        ]
    body.append("net = total - 0.5 * dJ * omega * omega")
    body.append("dydt[0] = omega")
    n_mode_guards = 0
    journals, reaction_lines = [], []  # the journals' positions in the kinetostatics; `reactions`' body
    if governor is not None and governor.kind != "pi":
        n_mode_guards = 2 + (2 if governor.kind == "indirect" else 0)
    if model.coupling is not None:
        train_lines, train_guards = _coupling_lines(model, p, anchor_of.get("coupling table", NO_ANCHOR), table_slots)
        body += train_lines
        guard_lines += train_guards
        n_mode_guards += 2
    elif model.clutch is not None:  # the crank's net moment again in guards, phi unclamped (MachineModel.crank_side)
        crank = [
            line.split(" = ")[0] + " = phi" if line.startswith(("clamped = ", "anchor = ")) else line
            for line in body
            if line != "dydt[0] = omega"
        ]
        train_lines, train_guards = _clutch_lines(model, p, crank)
        body += train_lines
        guard_lines += train_guards
        n_mode_guards += 4
    else:
        body.append("dydt[1] = net / J")
    if model.joint_friction is not None:
        share = "share" if governor is not None else HELD_THROTTLE_EXPRESSION
        body += _joint_friction_lines(model, p, share, anchor, "q_anchor" if kinked else "q", friction_slot)
        guard_lines += _crank_guard_lines()
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
            for k, position in enumerate(friction.guides):
                side, low = f"p[{friction_slot + NORMAL_SLOTS * k}]", f"p[{friction_slot + NORMAL_SLOTS * k + 1}]"
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
    source = _module(body, guard_lines, n_guards, reaction_lines, p.functions, p.formulas)
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


def _joint_friction_lines(
    model: MachineModel, p: _Parameters, share: str, anchor: str, held: str, friction_slot: int | None
) -> list[str]:
    """Source that turns the crank's frictionless dydt[1] = epsilon_0 into the root of J epsilon = J epsilon_0 -
    sign(omega) F(epsilon) (MachineModel.rhs, effects.joint_friction): the force Q on the output link (the effects'
    output forces, the drive's times the throttle `share`), the joint reactions R0 + R1 epsilon of the mechanism's
    kinetostatics at (phi, omega, Q) and the Newton solve; a thrust collar alone needs no kinetostatics. anchor,
    held: the crank angle and slider position the tables in the output forces are read on (_effect_call);
    friction_slot: CompiledScene's (the guides' normal signs and the joints' rate signs between two corners)."""
    friction = model.joint_friction
    collar, tolerance = p.scalar(friction.collar), p.scalar(joint_friction.NEWTON_TOLERANCE)
    iterations = f"int({p.scalar(joint_friction.NEWTON_ITERATIONS)})"
    solve = p.formula(joint_friction.friction_acceleration)  # the reference path's own Newton solve, compiled
    if friction.loads is None:
        return [
            f"dydt[1] = {solve}(omega, J * dydt[1], J, {collar}, (0.0, 0.0, 0.0, 0.0), "
            f"(0.0, 0.0, 0.0, 0.0), (0j, 0j, 0j, 0j), (0j, 0j, 0j, 0j), False, {tolerance}, {iterations}, "
            "(0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0))"
        ]
    lines = ["force = 0.0"]
    scaled = []
    for effect in model.effects:
        if effect.output_force is None:
            continue
        definition = effect.definition
        call = _effect_call(definition, p, "phi", "omega", "q", "dq", anchor, held, definition.output_force)
        if effect.role == "drive":
            scaled.append(f"force += {share} * {call}")
        else:
            lines.append(f"force += {call}")
    lines += scaled
    machine = model.scene.machine
    joints = _kinetostatics_joints(machine.mechanism)
    core, structure, _ = mechanisms.linkage_of(machine.mechanism)  # its generated kinetostatics, with gravity
    program = flat.encode(core, structure.groups, machine.gravity)
    name, source = symbolic.joint_loads_source(program)
    p.functions[name] = source
    lines.append(f"R0, R1, ratios, _, _ = {name}(phi, omega, force, {p.table(program).rsplit(', ', 1)[0]})")
    arms = [0.0] * len(joints)  # a joint without friction: arm 0, its terms exact zeros
    for index, arm_length in zip(friction.indices, friction.arms):
        arms[index] = arm_length
    normals = ["0.0"] * len(joints)  # a guide's |N| read as s_N N (its p slot), every other joint's |R|
    for k, position in enumerate(friction.guides):
        normals[friction.indices[position]] = f"p[{friction_slot + NORMAL_SLOTS * k}]"
    first_rate = friction_slot + NORMAL_SLOTS * len(friction.guides)
    signs = "".join(f"p[{first_rate + j}], " for j in range(len(joints)))
    lines.append(
        f"dydt[1] = {solve}(omega, J * dydt[1], J, {collar}, "
        f"({''.join(p.scalar(v) + ', ' for v in arms)}), ratios, R0, R1, True, {tolerance}, {iterations}, "
        f"({signs}), ({''.join(sign + ', ' for sign in normals)}))"
    )
    return lines


def _kinetostatics_joints(mechanism) -> tuple[str, ...]:
    """The joints a mechanism's kinetostatics reports, in its order (mechanisms.build_kinetostatics): its linkage's."""
    return tuple(joint.name for joint in mechanisms.linkage_of(mechanism)[0].joints)


def _crank_guard_lines() -> list[str]:
    """Source of the joint friction's crank guard (MachineModel.guards), after the mode's: with s the sign of the
    crank's speed at the segment's start (p's CRANK_DIRECTION), 'crank stops', s omega, or, starting at rest (s = 0),
    'crank starts', -|omega| (omega leaves 0: the solver restarts to watch for the next stop)."""
    return [
        f"direction = p[{CRANK_DIRECTION}]",
        "levels[g] = direction * omega if direction != 0.0 else -abs(omega)",
        "g += 1",
    ]


def _coupling_lines(
    model: MachineModel, p: _Parameters, anchor: str, table_slots: tuple[int, ...]
) -> tuple[list[str], list[str]]:
    """Source of the coupling and the driven part behind it (MachineModel._train, drive_train_at): the crank's
    dydt[1] = (net - M_m) / J, d twist/dt = omega - omega2 and domega2/dt in the driven part's mode; and its guards
    (at rest: the holding margins R -+ push; turning: s omega2); anchor: 'p[slot]' of a coupling table's anchor, or
    NO_ANCHOR; table_slots: generate's (a driven part's table loads' anchors)."""
    coupling = model.coupling
    spec = model.scene.machine.coupling
    twist_index, speed_index = model.coupling_index, model.driven_speed_index
    if coupling.table is None:
        elastic = f"{p.scalar(coupling.stiffness)} * twist"
    else:
        elastic = f"k.extrapolated_linear(twist, {anchor}, {p.table(coupling.table[0], coupling.table[1])})"
    driven = spec.driven
    state = [
        f"twist = y[{twist_index}]",
        f"omega2 = y[{speed_index}]",
        f"passed = {elastic} + {p.scalar(coupling.damping)} * (omega - omega2)",
    ]
    dynamics = ["phi2 = y[0] - twist"]
    if driven.mechanism is not None:
        dynamics += _reduced_lines(
            driven.mechanism, model.scene.machine.gravity, p, "phi2", ("I_links", "dI", "weight2", "q2", "dq2")
        )
    else:
        dynamics.append("I_links, dI, weight2, q2, dq2 = 0.0, 0.0, 0.0, 0.0, 0.0")
    dynamics += [f"I2 = {p.scalar(coupling.driven.inertia)} + I_links", "smooth = 0.0"]
    located = {table.name: f"p[{slot}]" for table, slot in zip(model.state_tables, table_slots)}
    names = [f"driven part's {effect.name}" for effect in model.driven.effects[: len(driven.loads)]]
    anchors = {index: located[name] for index, name in enumerate(names) if name in located}
    dynamics += _driven_smooth_lines(driven, p, "phi2", "omega2", "q2", "dq2", anchors, model.driven)
    resistance = f"{p.scalar(coupling.driven.resistance)} + (p[{EXTERNAL_OFFSET}] + p[{EXTERNAL_SLOPE}] * t)"
    rhs = (
        state
        + [
            "dydt[1] = (net - passed) / J",
            f"dydt[{twist_index}] = omega - omega2",
            f"if p[{DRIVEN_MODE}] == 2.0:",
            f"    dydt[{speed_index}] = 0.0",
            "else:",
        ]
        + [f"    {line}" for line in dynamics]
        + [
            f"    direction = 1.0 if p[{DRIVEN_MODE}] == 0.0 else -1.0",
            f"    dydt[{speed_index}] = k.driven_acceleration(direction, passed, weight2, smooth, dI, omega2, I2, "
            f"{resistance})",
        ]
    )
    guards = (
        [f"if p[{DRIVEN_MODE}] == 2.0:"]
        + [f"    {line}" for line in state + dynamics]
        + [
            f"    levels[g] = k.driven_margin(passed, weight2, smooth, dI, omega2, {resistance}, -1.0)",
            f"    levels[g + 1] = k.driven_margin(passed, weight2, smooth, dI, omega2, {resistance}, 1.0)",
            "    g += 2",
            f"elif p[{DRIVEN_MODE}] == 0.0:",
            f"    levels[g] = y[{speed_index}]",
            "    g += 1",
            "else:",
            f"    levels[g] = -y[{speed_index}]",
            "    g += 1",
        ]
    )
    return rhs, guards


def _driven_smooth_lines(
    driven: schema.DrivenPart,
    p: _Parameters,
    phi: str,
    omega: str,
    q: str,
    dq: str,
    anchors: dict[int, str] | None = None,
    model: DrivenModel | None = None,
) -> list[str]:
    """Source adding a driven part's non-Coulomb moments to `smooth` (DrivenModel.smooth_moment): its own loads,
    then each branch's reduced to the main shaft, M_n(omega / i_1n) / i_1n (drivetrain._reduced); constant loads
    are Coulomb resistances, in R. anchors: per index of an own load that is a located table, the slot p[k] of its
    anchor phi2 [rad] (NaN: the table as it is); a slider table's is read on the piece of x held on the interval
    between its kinks around the anchor (`{q}_anchor<index>`, from model's effect and mechanism)."""
    anchors = anchors or {}
    lines = []
    for index, load in enumerate(driven.loads):
        slot = anchors.get(index)
        definition = definition_of(load)
        if definition.dry:
            continue
        if slot is None:
            lines.append(f"smooth += {_effect_call(definition, p, phi, omega, q, dq)}")
        elif _reads_position(definition):
            held = f"{q}_anchor{index}"
            position = _held_position_call(model.effects[index].kink_angles, output_position_of(model.reduced), p, slot)
            lines += [
                f"{held} = {position} if {slot} == {slot} else {q}",
                f"smooth += {_effect_call(definition, p, phi, omega, q, dq, held=held)}",
            ]
        else:
            anchor = f"({slot} if {slot} == {slot} else {phi})"  # NaN: the table as it is
            lines.append(f"smooth += {_effect_call(definition, p, phi, omega, q, dq, anchor=anchor)}")
    for branch in driven.branches:
        ratio = p.scalar(branch.ratio)
        definitions = [definition_of(load) for load in branch.loads]
        lines += [
            f"smooth += {_effect_call(definition, p, phi, f'({omega} / {ratio})', q, dq)} / {ratio}"
            for definition in definitions
            if not definition.dry
        ]
    return lines


def _reads_position(definition: Definition | None) -> bool:
    """Whether a drive's or load's formula reads a table in the output position (a slider force table)."""
    return definition is not None and definition.table is not None and definition.table.kind == CLAMPED


def _clutch_lines(model: MachineModel, p: _Parameters, crank: list[str]) -> tuple[list[str], list[str]]:
    """Source of the friction clutch and the driven part behind it (MachineModel._train, drivetrain.ClutchModel) in
    the train mode of p (CLUTCH_MODE, DRIVEN_MODE): dydt[1] and domega2/dt of clutch_forces, the driven part read at
    omega2 = omega while stuck. Stuck, domega2/dt is the crank's (the reference freezes omega2 and sets it to omega
    in its outputs, MachineModel.constraint; equal starting values and equal rates keep them equal bit for bit here).
    Guards, in drivetrain.train_guards' order: stuck, static_torque -+ T (crank: the crank's net moment F1, phi
    unclamped); slipping, s (omega - omega2); then the driven part's margins R -+ push at rest or s omega2 turning."""
    clutch = model.clutch
    index = model.driven_speed_index
    omega2 = f"omega2 = y[1] if p[{CLUTCH_MODE}] == 0.0 else y[{index}]"
    driven = ["smooth = 0.0"] + _driven_smooth_lines(
        model.scene.machine.clutch.driven, p, "0.0", "omega2", "0.0", "0.0"
    )
    resistance = f"resistance = {p.scalar(clutch.driven.resistance)} + (p[{EXTERNAL_OFFSET}] + p[{EXTERNAL_SLOPE}] * t)"
    forces = (
        f"epsilon, epsilon2, torque, push = k.clutch_forces(p[{CLUTCH_MODE}], p[{DRIVEN_MODE}], net, J, smooth, "
        f"resistance, {p.scalar(clutch.driven.inertia)}, {p.scalar(clutch.kinetic_torque)})"
    )
    rhs = [omega2] + driven + [resistance, forces, "dydt[1] = epsilon", f"dydt[{index}] = epsilon2"]
    static = p.scalar(clutch.static_torque)
    guards = (
        crank
        + rhs[:-2]
        + [
            f"if p[{CLUTCH_MODE}] == 0.0:",
            f"    levels[g] = {static} - torque",
            f"    levels[g + 1] = {static} + torque",
            "    g += 2",
            "else:",
            f"    levels[g] = p[{CLUTCH_MODE}] * (omega - y[{index}])",
            "    g += 1",
            f"if p[{DRIVEN_MODE}] == 2.0:",
            "    levels[g] = resistance - push",
            "    levels[g + 1] = resistance + push",
            "    g += 2",
            f"elif p[{DRIVEN_MODE}] == 0.0:",
            f"    levels[g] = y[{index}]",
            "    g += 1",
            "else:",
            f"    levels[g] = -y[{index}]",
            "    g += 1",
        ]
    )
    return rhs, guards


_INLINED = ", inline='always'"


def _module(
    rhs_body: list[str],
    guard_body: list[str],
    n_guards: int,
    reaction_body: list[str],
    functions: dict[str, str],
    formulas: dict[str, Callable],
) -> str:
    """The generated module's source (`reactions` only with a reaction_body), the definitions' `formulas` (name in
    the module -> function, compiled by kernels.compiled; with a hash of each one's module source, so that a changed
    formula makes a new module) and the generated `functions` (name -> source) compiled before the right-hand side
    that calls them, with numpy's error model (a division by zero gives
    an infinity or NaN, which the callers read, instead of an exception and a test per division); the reduction
    inlined into its callers (numba's IR inlining: `crank_slider_bench` 13 % slower as a call than with the hand kernel
    it replaced, 4-5 % inlined), the kinetostatics not (inlined it doubled the friction scenes' compile time)."""
    indent = "\n    "
    guards = [f"for i in range({n_guards}):", "    levels[i] = math.inf", "omega = y[1]", "g = 0"] + guard_body
    signatures = f"GUARDS_SIGNATURE, {'REACTIONS_SIGNATURE, ' if reaction_body else ''}RHS_SIGNATURE"
    reactions = (
        "\n\n@njit(REACTIONS_SIGNATURE, cache=True)\n"
        f"def reactions(t, y, p, squares):{indent}{indent.join(reaction_body)}\n\n\n"
        "reactions_callback = cfunc(REACTIONS_SIGNATURE, cache=True)(reactions.py_func)\n"
        if reaction_body
        else ""
    )
    compiled = "".join(
        f"{name} = k.compiled({function.__module__!r}, {function.__name__!r})  # source "
        f"{_module_source_hash(function.__module__)}\n"
        for name, function in sorted(formulas.items())
    )
    return (
        '"""Generated by mech_regulator.solvers.compiled.codegen: a scene\'s right-hand side and guards (do not edit;\n'
        'the parameters are in p)."""\n\n'
        "import math\n\n"
        "import numpy as np\n"
        "from numba import cfunc, njit\n\n"
        "from mech_regulator.solvers.compiled import kernels as k\n"
        f"from mech_regulator.solvers.compiled.signatures import {signatures}\n\n"
        + (f"{compiled}\n" if compiled else "")
        + "\n"
        + "".join(
            f"@njit(cache=True, error_model='numpy'{_INLINED if name.startswith(symbolic.FUNCTION_NAME) else ''})"
            f"\n{source}\n\n"
            for name, source in functions.items()
        )
        + "@njit(RHS_SIGNATURE, cache=True)\n"
        f"def rhs(t, y, p, dydt):{indent}{indent.join(rhs_body)}\n\n\n"
        "@njit(GUARDS_SIGNATURE, cache=True)\n"
        f"def guards(t, y, p, levels):{indent}{indent.join(guards)}\n\n\n"
        "rhs_callback = cfunc(RHS_SIGNATURE, cache=True)(rhs.py_func)\n"
        "guards_callback = cfunc(GUARDS_SIGNATURE, cache=True)(guards.py_func)\n" + reactions
    )


@functools.cache
def _module_source_hash(module: str) -> str:
    """A short hash of a module's source (a definitions' module, written into the generated module)."""
    return hashlib.sha256(inspect.getsource(sys.modules[module]).encode()).hexdigest()[:16]
