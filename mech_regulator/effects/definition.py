"""One definition of each kind of drive, load and valve, run by both paths (docs/effects.md).

A kind's formula is a plain Python function of floats, written once in the kind's module (effects/drives.py,
effects/loads.py, governors/valve.py), that numba compiles unchanged: no closures, no Python objects, no calls but
`math`'s, `abs`, `min` and `max`; arithmetic and conditional expressions. Its arguments are named: the inputs the
caller provides (an effect's t [s], phi [rad], omega [rad/s], q and dq (the mechanism's output coordinate and
dq/dphi) and `table`, the value of the kind's table; a valve's sleeve position z [m] and `table`), then the kind's
numbers (SI, read from the scene entry). The reference path binds the numbers into a closure (reference_closure),
the fast path's code generator (solvers/compiled/codegen.py) writes a call of the compiled function with the
numbers read from its parameter vector; both write the call with `call_source`, so the arithmetic is the same and
the outputs agree bit for bit.

A kind is registered for its scene classes with `define`; `definition_of(spec)` finds it, and `check_covered` fails
at import when a member of a scene union has none (effects/__init__.py and governors/valve.py call it once their
kinds are registered).
"""

from __future__ import annotations

import inspect
import math
import typing
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

PERIODIC, CLAMPED, INTERVALS = "periodic", "clamped", "intervals"


class DefinitionError(TypeError):
    """A scene entry without a definition, or a definition whose formula reads an argument nobody gives."""


@dataclass(frozen=True)
class Table:
    """The table a formula reads as its `table` argument.

    kind: PERIODIC, linear between the points and periodic in phi (effects.tables.periodic_linear), read at
    phi + shift; CLAMPED, linear between the points and held beyond them (tables.clamped_linear), read at the
    output position q (a drive's or load's) or at the sleeve position z (a valve's); INTERVALS, 1.0 while
    (phi + shift) mod period lies in one of the intervals [xs[2k], xs[2k+1]) and 0.0 outside (the xs from 0, ascending).
    xs, ys: the points (xs in rad for PERIODIC and INTERVALS); period [rad]; shifts: per output of the mechanism (an
    engine's cylinders) the shift of phi [rad] its table is read at, the formula summed over them; None: phi itself,
    one output.
    """

    kind: str
    xs: tuple[float, ...]
    ys: tuple[float, ...] = ()
    period: float = math.nan
    shifts: tuple[float, ...] | None = None


@dataclass(frozen=True)
class Definition:
    """A scene entry's drive, load or valve, as both paths run it.

    name: the column name of its moment in outputs; role: 'drive', 'load' or 'valve'; formula: what it computes, for
    `describe`; moment: the formula (module docstring; a valve's throttle [-], else the moment on the crank [N m]);
    numbers: its numbers by argument name [SI]; depends_on: which of 't', 'phi', 'omega' the moment reads;
    table: the table it reads, or None; output_force: for an effect on the mechanism's output link, the generalised
    force Q on it (slider force along +x [N], rocker moment [N m]) whose reduced moment is Q dq, a function as
    `moment`, else None; on_output: it acts on the output link (periodic with the mechanism); dry: a constant
    resisting moment, what a driven part counts among its Coulomb resistances.
    """

    name: str
    role: str
    formula: str
    moment: Callable[..., float]
    numbers: Mapping[str, float] = field(default_factory=dict)
    depends_on: frozenset[str] = frozenset()
    table: Table | None = None
    output_force: Callable[..., float] | None = None
    on_output: bool = False
    dry: bool = False

    @property
    def outputs(self) -> int:
        """How many outputs of the mechanism its formula is summed over (an engine's cylinders)."""
        return len(self.table.shifts) if self.table is not None and self.table.shifts is not None else 1


_DEFINITIONS: dict[type, Callable[..., Definition]] = {}


def define(*kinds: type) -> Callable:
    """Register the decorated `definition(spec, mechanism) -> Definition` for the scene classes `kinds`."""

    def register(build: Callable[..., Definition]) -> Callable[..., Definition]:
        for kind in kinds:
            _DEFINITIONS[kind] = build
        return build

    return register


def definition_of(spec, mechanism=None) -> Definition:
    """The definition of a scene's drive, load or valve entry (an engine reads the mechanism's cylinders)."""
    build = _DEFINITIONS.get(type(spec))
    if build is None:
        raise DefinitionError(
            f"no definition for the scene entry {type(spec).__name__} (type '{spec.type}'); each "
            "drive, load and valve kind registers one with effects.definition.define "
            "(docs/effects.md)"
        )
    return build(spec, mechanism)


def union_members(union) -> tuple[type, ...]:
    """The scene classes of a scene union (effect_keys.Drive, effect_keys.Load, governor_keys.Valve, ...): the
    members of its Union, each unwrapped from its Annotated."""
    members = typing.get_args(union)[0] if typing.get_origin(union) is typing.Annotated else union
    return tuple(
        typing.get_args(member)[0] if typing.get_origin(member) is typing.Annotated else member
        for member in typing.get_args(members)
    )


def check_covered(*unions) -> None:
    """Raise DefinitionError naming the members of the scene unions that no definition is registered for."""
    missing = [kind.__name__ for union in unions for kind in union_members(union) if kind not in _DEFINITIONS]
    if missing:
        raise DefinitionError(
            f"no definition for the scene entries {', '.join(missing)}; each drive, load and valve "
            "kind registers one with effects.definition.define (docs/effects.md)"
        )


def call_source(
    function: Callable[..., float], name: str, inputs: Mapping[str, str], numbers: Mapping[str, str]
) -> str:
    """The source `name(arguments)` of a call of a formula function: each argument, by its name, the expression
    inputs[name] or numbers[name]; the one way both paths write it."""
    arguments = []
    for argument in inspect.signature(function).parameters:
        expression = inputs.get(argument, numbers.get(argument))
        if expression is None:
            raise DefinitionError(
                f"{function.__module__}.{function.__name__} reads '{argument}', which is neither "
                f"an input ({', '.join(inputs)}) nor one of its numbers ({', '.join(numbers)})"
            )
        arguments.append(expression)
    return f"{name}({', '.join(arguments)})"


def summed_source(
    definition: Definition,
    function: Callable[..., float],
    name: str,
    inputs: Callable[[int], Mapping[str, str]],
    numbers: Mapping[str, str],
) -> str:
    """call_source of a formula function once per output of the mechanism (inputs(i): output i's input expressions),
    summed left to right in parentheses when there are several."""
    terms = [call_source(function, name, inputs(i), numbers) for i in range(definition.outputs)]
    return terms[0] if len(terms) == 1 else "(" + " + ".join(terms) + ")"


def reference_closure(
    definition: Definition,
    function: Callable[..., float],
    arguments: str,
    inputs: Callable[[int], Mapping[str, str]],
    namespace: dict,
) -> Callable[..., float]:
    """The reference path's closure `lambda arguments: ...` of a formula function, its numbers bound, the call
    written by summed_source (as the fast path's) from the input expressions inputs(i) over the names in namespace
    (the closures the inputs call: a table, ...)."""
    namespace = dict(namespace, formula=function)
    numbers = {}
    for index, (argument, value) in enumerate(definition.numbers.items()):
        numbers[argument], namespace[f"number{index}"] = f"number{index}", value
    call = summed_source(definition, function, "formula", inputs, numbers)
    return eval(f"lambda {arguments}: {call}", namespace)


def reference_function(
    definition: Definition,
    function: Callable[..., float],
    table: Callable[..., float] | None,
    anchored: bool,
    held: Callable[[float], float] | None = None,
) -> Callable[..., float]:
    """The reference path's closure of a drive's or load's formula function: `(t, phi, omega, q, dq) -> value`, or
    with anchored `(anchor, t, phi, omega, q, dq)`, the table read on the piece that holds the anchor [rad] (a periodic
    table: the segment of phi = anchor; a clamped one in q: the piece of x = held(anchor) [m]). With several outputs q
    and dq are tuples, one entry per output. table: the kind's table as a Python closure (y(x, anchor=None)), None
    without one."""
    spec = definition.table
    shifts = () if spec is None or spec.shifts is None else spec.shifts
    several = definition.outputs > 1

    def inputs(i: int) -> dict[str, str]:
        given = {
            "t": "t",
            "phi": "phi",
            "omega": "omega",
            "q": f"q[{i}]" if several else "q",
            "dq": f"dq[{i}]" if several else "dq",
        }
        if spec is not None and spec.kind == CLAMPED:
            given["table"] = f"table({given['q']}, held(anchor))" if anchored else f"table({given['q']})"
        elif spec is not None:
            shift = f" + shift{i}" if shifts else ""
            given["table"] = f"table(phi{shift}, anchor{shift})" if anchored else f"table(phi{shift})"
        return given

    namespace = {"table": table, "held": held} | {f"shift{index}": shift for index, shift in enumerate(shifts)}
    arguments = "anchor, t, phi, omega, q, dq" if anchored else "t, phi, omega, q, dq"
    return reference_closure(definition, function, arguments, inputs, namespace)
