"""The pieces of the fast path's generated module (solvers/compiled/codegen.py writes a scene's with them): the
parameter vector p and its segment slots, the calls of the effects' one definitions (effects/definition.py), the
valve's and a governor's formulas (GovernorWriter, governors/kind.py's SourceWriter), a mechanism's reduction, and the
module's text itself; one drive's, load's or valve's call compiled alone (effect_kernel, valve_kernel) for the check
that both paths agree."""

from __future__ import annotations

import functools
import hashlib
import inspect
import math
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TypeVar

import numba
import numpy as np

from mech_regulator import mechanisms
from mech_regulator.effects import Effect, held_positions
from mech_regulator.effects.definition import (
    CLAMPED,
    INTERVALS,
    PERIODIC,
    Definition,
    call_source,
    definition_of,
    summed_source,
)
from mech_regulator.mechanisms.linkage import flat_program, symbolic
from mech_regulator.scene import governor_keys
from mech_regulator.solvers.compiled import kernels

# Segment inputs: fixed slots at the start of p
EXTERNAL_OFFSET, EXTERNAL_SLOPE, HELD_THROTTLE, SLEEVE_MODE, SERVO_MODE, DRIVEN_MODE = range(6)
CLAMP_LO, CLAMP_HI, WINDOW_LO, WINDOW_HI, CLUTCH_MODE, CRANK_DIRECTION = range(6, 12)
THROTTLE_SLOPE, THROTTLE_CURVATURE, THROTTLE_START, THROTTLE_PER_SPEED, THROTTLE_LOW, THROTTLE_HIGH = range(12, 18)
SEGMENT_SLOTS = 18
# the slots a load piece and the crank's speed at its start set (CompiledScene.piece_values)
PIECE_SLOTS = (
    EXTERNAL_OFFSET,
    EXTERNAL_SLOPE,
    HELD_THROTTLE,
    THROTTLE_SLOPE,
    THROTTLE_CURVATURE,
    THROTTLE_START,
    THROTTLE_PER_SPEED,
    THROTTLE_LOW,
    THROTTLE_HIGH,
    CRANK_DIRECTION,
)
PIECE_INDEX = np.array(PIECE_SLOTS, dtype=np.int64)
# the throttle of a co-simulated machine: held, or the polynomial of LoadPiece.throttle_at
NORMAL_SLOTS = 2  # joint friction's slots in p from friction_slot, per guide with friction: its normal sign s_N and
#                  its guard's start level; then the signs s_j of the joints' relative rates
HELD_THROTTLE_EXPRESSION = (
    f"min(max(p[{HELD_THROTTLE}] + (t - p[{THROTTLE_START}]) * (p[{THROTTLE_SLOPE}] + "
    f"(t - p[{THROTTLE_START}]) * p[{THROTTLE_CURVATURE}]) + p[{THROTTLE_PER_SPEED}] * omega, p[{THROTTLE_LOW}]), "
    f"p[{THROTTLE_HIGH}])"
)
NO_ANCHOR = "math.nan"  # a table lookup's anchor that reads the table itself (effects/tables.py)

Part = TypeVar("Part")


def present(part: Part | None, name: str) -> Part:
    """An optional part (the model's governor, coupling, clutch or joint friction, a compiled scene's slot in p, a
    segment's start state) that the code reading it is only reached with: its callers generate or call that code only
    when it is there (run.fast_path_refusal, the model's builders, CompiledScene's docstring)."""
    if part is None:
        raise TypeError(f"the fast path's code generator read the {name}, which is not there")
    return part


class Parameters:
    """Builds p: scalars get a slot each; a table gets two slots (its offset and length), its columns appended
    after all scalars when done."""

    def __init__(self):
        self.values: list[float] = [0.0] * SEGMENT_SLOTS
        self.values[HELD_THROTTLE] = self.values[THROTTLE_HIGH] = 1.0
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


@dataclass(frozen=True)
class GovernorWriter:
    """The SourceWriter (governors/kind.py) a governor writes its part of the module with: p, and the scene
    governor's valve entry (governor_keys.Valve) if it has one."""

    p: Parameters
    valve: governor_keys.Valve | None
    sleeve_mode: str = f"p[{SLEEVE_MODE}]"
    servo_mode: str = f"p[{SERVO_MODE}]"

    def scalar(self, value: float) -> str:
        """p's new slot holding value, as source."""
        return self.p.scalar(value)

    def shared(self, *functions: Callable[..., float]) -> tuple[str, ...]:
        """shared_functions."""
        return shared_functions(functions, self.p)

    def formula_call(
        self, function: Callable[..., float], inputs: Mapping[str, str], numbers: Mapping[str, float]
    ) -> str:
        """formula_call."""
        return formula_call(self.p, function, inputs, numbers)

    def valve_call(self, z: str, anchor: str) -> str:
        """valve_call of the scene's valve."""
        return valve_call(definition_of(present(self.valve, "scene governor's valve")), self.p, z, anchor)


def effect_call(
    definition: Definition,
    p: Parameters,
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
    outputs (an engine's cylinders: output k >= 2's q and dq named as reduced_lines does). The call is written by
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


def formula_call(p: Parameters, function: Callable, inputs: Mapping[str, str], numbers: Mapping[str, float]) -> str:
    """The call of a formula function (a valve's, the servo's) as source, its numbers stored in p."""
    stored = {name: p.scalar(value) for name, value in numbers.items()}
    return call_source(function, p.formula(function), inputs, stored)


def valve_call(definition: Definition, p: Parameters, z: str, anchor: str = NO_ANCHOR) -> str:
    """The call of a valve's formula at the sleeve position z [m] as source, its table read on the piece that holds
    the anchor (anchor: 'p[slot]' of the valve table's anchor; NO_ANCHOR: z itself)."""
    inputs = {"z": z}
    if definition.table is not None:
        inputs["table"] = f"k.clamped_linear({z}, {anchor}, {p.table(definition.table.xs, definition.table.ys)})"
    return formula_call(p, definition.moment, inputs, definition.numbers)


def effect_kernel(definition: Definition, function: Callable | None = None, anchored: bool = False):
    """The fast path's code of one drive's or load's formula (definition.moment, or `function`: its output_force)
    alone, as generate writes it into a scene's rhs (effect_call), compiled: (f(t, phi, omega, anchor, q_anchor, p,
    q, dq[, q_2, dq_2, ...]) -> value, p), one q and dq per output of the mechanism; anchored: its table read on the
    piece that holds anchor [rad] (a periodic one) or the slider position q_anchor [m] (one in q). What the check
    that both paths agree compiles (test/test_effect_definitions.py)."""
    p = Parameters()
    call = effect_call(
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
    """The fast path's code of a valve's formula alone, as generate writes it (valve_call), compiled: (f(z, anchor,
    p) -> throttle [-], p); anchored: its table read on the piece that holds the sleeve position anchor [m]."""
    p = Parameters()
    return _kernel("z, anchor, p", valve_call(definition, p, "z", "anchor" if anchored else NO_ANCHOR), p)


def _kernel(arguments: str, call: str, p: Parameters):
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


def held_position_call(kinks, output_position, p: Parameters, anchor: str) -> str:
    """The kernel call (as source) of the slider position [m] that holds a slider table's piece on the interval
    between its kinks [rad] (sorted, in [0, 2 pi)) around the crank angle `anchor` (effects.held_positions of the
    mechanism's output_position, looked up by kernels.held_position)."""
    held = held_positions(tuple(kinks), output_position)
    return f"k.held_position({anchor}, {p.table(list(kinks) + [2.0 * math.pi], held)})"


def reduced_lines(mechanism, gravity, p: Parameters, angle: str, names: tuple[str, ...]) -> list[str]:
    """Source assigning a mechanism's reduced(phi) (mechanisms.build_reduced) at `angle` to the five `names` (J_links,
    dJ, weight, q, dq): the generated function of its linkage (mechanisms.linkage_of: a preset's or the scene's own;
    mechanisms/linkage/symbolic.py), the very source the reference path runs, added to the module (p.functions), on
    the linkage's program (flat_program.encode; gravity None: zero, no weight moment) stored as a table in p. Several outputs
    (a multi-cylinder engine's pistons): the first assigns q, dq, output k (k >= 2) q_k, dq_k (what the engine's gas
    moment reads)."""
    core, structure, outputs = mechanisms.linkage_of(mechanism)
    program = flat_program.encode(core, structure.groups, gravity)
    name, source = symbolic.reduced_source(program, symbolic.output_records(program, core, outputs))
    p.functions[name] = source
    call = f"{name}({angle}, {p.table(program).rsplit(', ', 1)[0]})"  # 'p, int(p[slot])': the program's offset
    if len(outputs) <= 1:
        return [f"{', '.join(names)} = {call}"]
    J, dJ, weight, q, dq = names
    rest = "".join(f", {q}_{k}, {dq}_{k}" for k in range(2, len(outputs) + 1))
    return [f"{J}, {dJ}, {weight}, {q}, {dq}{rest} = {call}"]


def shared_functions(functions, p: Parameters) -> tuple[str, ...]:
    """The names of functions the reference path runs (a governor's: a sensor's formulas, CentrifugalSensor.kernels;
    the PI law, governors/pi.py), their very source added to the module (p.functions) to be compiled."""
    for function in functions:
        p.functions[function.__name__] = inspect.getsource(function)
    return tuple(function.__name__ for function in functions)


def effect_definition(effect: Effect) -> Definition:
    """The definition an effect was built from (effects.Effect.definition), which the fast path compiles: every
    effect of a model that passes run.fast_path_refusal has one."""
    return present(effect.definition, f"definition of the effect '{effect.name}'")


def reads_position(definition: Definition | None) -> bool:
    """Whether a drive's or load's formula reads a table in the output position (a slider force table)."""
    return definition is not None and definition.table is not None and definition.table.kind == CLAMPED


_INLINED = ", inline='always'"


def module_source(
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
