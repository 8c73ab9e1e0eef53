"""Each drive, load, valve and servo is defined once and both paths run that definition (docs/effects.md): for every
member of the scene's drive, load and valve unions (read from the pydantic unions, so a new member is walked without
editing this file) the reference path's closure and the fast path's compiled code, as the code generator writes it
into a scene's right-hand side, give the same numbers bit for bit on random states and random scene entries; so do
each table lookup (effects/tables.py), joint friction's Newton solve and the servo's formulas."""

from __future__ import annotations

import math
import typing
from typing import Annotated, Literal

import numpy as np
import pytest
from pydantic import Field

from mech_regulator.effects import build_drive, build_load, joint_friction, tables
from mech_regulator.effects.definition import DefinitionError, check_covered, definition_of, union_members
from mech_regulator.governors import servo as servo_motor
from mech_regulator.governors.valve import build_valve
from mech_regulator.scene import effect_keys, governor_keys, key_types
from mech_regulator.scene.loading import load_scene
from mech_regulator.solvers.compiled import kernels, source

STATES = 200
SEEDS = (1, 2, 3)  # random scene entries of each kind


def _sorted(rng, count: int, low: float, high: float) -> list[float]:
    """count strictly increasing random values in [low, high)."""
    return sorted({float(v) for v in np.round(rng.uniform(low, high, count), 3)})


def _table(rng, torque: str, period: float) -> dict:
    angles = _sorted(rng, int(rng.integers(2, 9)), 0.0, period)
    return {"angle_deg": angles, torque: list(rng.uniform(-50.0, 150.0, len(angles))), "period_deg": period}


def _intervals(rng) -> list[list[float]]:
    edges = _sorted(rng, 2 * int(rng.integers(1, 4)), 0.0, 360.0)
    return [edges[i : i + 2] for i in range(0, len(edges) - 1, 2)]


def _positions(rng) -> list[float]:
    return _sorted(rng, int(rng.integers(2, 7)), -0.2, 0.3)


# A random valid scene entry of each kind (its type given): a new member of a union needs one here.
EXAMPLES = {
    effect_keys.ConstantDrive: lambda rng, kind: {"torque": rng.uniform(-100.0, 100.0)},
    effect_keys.LinearMotor: lambda rng, kind: {
        "stall_torque": rng.uniform(1.0, 1e3),
        "no_load_speed": rng.uniform(1.0, 300.0),
    },
    effect_keys.TableDrive: lambda rng, kind: _table(rng, "torque", float(rng.choice([360.0, 720.0]))),
    effect_keys.Engine: lambda rng, kind: {
        "bore": rng.uniform(0.02, 0.2),
        "cycle_deg": 720.0,
        "firing_order": [1, 3, 4, 2],
        "phase_deg": rng.uniform(-360.0, 360.0),
        **{key: value for key, value in _table(rng, "pressure", 720.0).items() if key != "period_deg"},
    },
    effect_keys.ConstantLoad: lambda rng, kind: {"torque": rng.uniform(0.0, 100.0)},
    effect_keys.ViscousLoad: lambda rng, kind: {"coefficient": rng.uniform(0.0, 5.0)},
    effect_keys.FanLoad: lambda rng, kind: {"coefficient": rng.uniform(0.0, 1e-2)},
    effect_keys.TableLoad: lambda rng, kind: _table(rng, "torque", 360.0),
    effect_keys.CuttingLoad: lambda rng, kind: {"torque": rng.uniform(0.0, 100.0), "intervals_deg": _intervals(rng)},
    effect_keys.SliderConstant: lambda rng, kind: {"force": rng.uniform(-1e3, 1e3)},
    effect_keys.RockerConstant: lambda rng, kind: {"torque": rng.uniform(-1e2, 1e2)},
    effect_keys.OutputViscous: lambda rng, kind: {"coefficient": rng.uniform(0.0, 50.0)},
    effect_keys.OutputSpring: lambda rng, kind: {
        "stiffness": rng.uniform(0.0, 5e3),
        "free_position": rng.uniform(-0.1, 0.2),
    },
    effect_keys.SliderTable: lambda rng, kind: {
        "position": (x := _positions(rng)),
        "force": list(rng.uniform(-1e3, 1e3, len(x))),
    },
    governor_keys.LinearValve: lambda rng, kind: {
        "open_at": rng.uniform(0.0, 0.04),
        "closed_at": rng.uniform(0.05, 0.1),
    },
    governor_keys.TableValve: lambda rng, kind: {
        "sleeve": (z := _sorted(rng, int(rng.integers(2, 7)), 0.0, 0.1)),
        "throttle": list(rng.uniform(0.0, 1.0, len(z))),
    },
}


def _entries(union) -> list[tuple[type, str]]:
    """(class, type) of every member of a scene union and every value of its `type` literal."""
    return [
        (member, kind)
        for member in union_members(union)
        for kind in typing.get_args(member.model_fields["type"].annotation)
    ]


def _example(member: type, kind: str, seed: int):
    assert member in EXAMPLES, f"no example of {member.__name__}: add one to EXAMPLES"
    rng = np.random.default_rng(seed)
    return member.model_validate({"type": kind, **EXAMPLES[member](rng, kind)})


def _states(seed: int, outputs: int = 1) -> list[tuple]:
    """Random (t, phi, omega, anchor, q, dq) with signs and zeros; q and dq tuples with several outputs."""
    rng = np.random.default_rng(seed)
    states = []
    for i in range(STATES):
        omega = 0.0 if i % 17 == 0 else float(rng.uniform(-200.0, 300.0))
        phi = float(rng.uniform(-30.0, 60.0))
        q = tuple(float(v) for v in rng.uniform(-0.3, 0.4, outputs))
        dq = tuple(0.0 if i % 13 == 0 else float(v) for v in rng.uniform(-0.1, 0.1, outputs))
        anchor = phi + float(rng.uniform(-0.05, 0.05))
        states.append((float(rng.uniform(0.0, 10.0)), phi, omega, anchor, q, dq))
    return states


def _same(reference: float, fast: float) -> bool:
    """Equal bit for bit (NaN equal to NaN)."""
    return np.float64(reference).tobytes() == np.float64(fast).tobytes()


@pytest.mark.parametrize(
    ("member", "kind"),
    _entries(effect_keys.Drive) + _entries(effect_keys.Load),
    ids=lambda value: value if isinstance(value, str) else value.__name__,
)
def test_both_paths_give_each_drive_and_load_alike(member, kind):
    engine_mechanism = load_scene("engine_inline4").machine.mechanism
    mechanisms = [None, engine_mechanism] if member is effect_keys.Engine else [None]
    for seed, mechanism in ((seed, mechanism) for seed in SEEDS for mechanism in mechanisms):  # an engine on one
        spec = _example(member, kind, seed)  # cylinder and on four
        definition = definition_of(spec, mechanism)
        if member in union_members(effect_keys.Drive):
            effect = build_drive(spec, mechanism)
        else:
            effect = build_load(spec, 2.0 * math.pi)
        several = definition.outputs > 1
        functions = [(effect.moment, definition.moment, False)]
        if effect.output_force is not None:
            functions.append((effect.output_force, definition.output_force, False))
        if effect.segment_moment is not None and definition.table.kind != "clamped":  # a table in phi on a segment
            functions.append((effect.segment_moment, definition.moment, True))
        for reference, function, anchored in functions:
            fast, p = source.effect_kernel(definition, function, anchored)
            for t, phi, omega, anchor, q, dq in _states(seed, definition.outputs):
                outputs = [value for pair in zip(q, dq) for value in pair]
                expected = (
                    reference(anchor, t, phi, omega, q if several else q[0], dq if several else dq[0])
                    if anchored
                    else reference(t, phi, omega, q if several else q[0], dq if several else dq[0])
                )
                got = fast(t, phi, omega, anchor, q[0], p, *outputs)
                assert _same(expected, got), (spec, function.__name__, anchored, t, phi, omega, q, dq, expected, got)


@pytest.mark.parametrize(
    ("member", "kind"),
    _entries(governor_keys.Valve),
    ids=lambda value: value if isinstance(value, str) else value.__name__,
)
def test_both_paths_give_each_valve_alike(member, kind):
    spec = _example(member, kind, 3)
    throttle, _, breaks = build_valve(spec)
    definition = definition_of(spec)
    rng = np.random.default_rng(4)
    sleeve = list(rng.uniform(-0.02, 0.12, STATES)) + list(breaks)
    for anchored in (False, True):
        if anchored and definition.table is None:
            continue
        fast, p = source.valve_kernel(definition, anchored)
        for z in sleeve:
            anchor = z + float(rng.uniform(-0.01, 0.01))
            expected = throttle(z, anchor) if anchored else throttle(z)
            assert _same(expected, fast(z, anchor, p)), (spec, z, anchor)
            assert 0.0 <= throttle(z) <= 1.0


def _lookup_cases(rng) -> dict:
    """Per table lookup of effects/tables.py, a random table (its points, its n, the numbers after n) and random
    arguments before p (x [and anchor]): angles far from the table (negative, 1e7 rad), on its points, anchors NaN
    or near x."""
    period = float(rng.choice([2.0 * math.pi, 4.0 * math.pi]))
    angles = [float(v) for v in np.sort(rng.uniform(0.0, period, int(rng.integers(2, 9))))]
    knots = [float(v) for v in np.sort(rng.uniform(-0.2, 0.3, int(rng.integers(2, 9))))]
    edges = [float(v) for v in np.sort(rng.uniform(0.0, period, 2 * int(rng.integers(1, 4))))]
    start = float(rng.uniform(-1.0, 1.0))
    values = [float(v) for v in rng.uniform(-50.0, 150.0, 8)]
    xs = list(rng.uniform(-30.0, 60.0, STATES)) + angles + [1e7 + 0.1, -1e7 + 0.2, period, 0.0]
    positions = list(rng.uniform(-0.5, 0.6, STATES)) + knots

    def anchored(x: float, i: int) -> float:
        return math.nan if i % 3 == 0 else x if i % 3 == 1 else x + float(rng.uniform(-0.1, 0.1))

    return {
        tables.periodic_value: (
            [start + a for a in angles] + values[: len(angles)],
            len(angles),
            (period,),
            [(x, anchored(x, i)) for i, x in enumerate(xs) if i % 3],  # its anchor is never NaN
        ),
        tables.clamped_value: (
            knots + values[: len(knots)],
            len(knots),
            (),
            [(x, anchored(x, i)) for i, x in enumerate(positions)],
        ),
        tables.extrapolated_value: (
            knots + values[: len(knots)],
            len(knots),
            (),
            [(x, anchored(x, i)) for i, x in enumerate(positions)],
        ),
        tables.interval_value: (edges, len(edges), (period,), [(x,) for x in xs + edges]),
        tables.held_value: (
            angles + [period] + values[: len(angles) + 1],
            len(angles) + 1,
            (),
            [(x,) for x in xs + angles],
        ),
    }


@pytest.mark.parametrize("seed", SEEDS)
def test_both_paths_look_up_each_table_alike(seed):
    """Each table lookup of effects/tables.py (all its `*_value` functions): in Python over a list of the table's
    points (the reference path) and compiled over an array that holds the table after other numbers (the fast path's
    p) give the same numbers bit for bit, on random tables and at angles far from them."""
    cases = _lookup_cases(np.random.default_rng(seed))
    assert {lookup.__name__ for lookup in cases} == {name for name in vars(tables) if name.endswith("_value")}
    offset = 5
    for lookup, (points, n, numbers, arguments) in cases.items():
        fast = kernels.compiled(lookup.__module__, lookup.__name__)
        p = np.array([math.nan] * offset + points)
        for before in arguments:
            expected = lookup(*before, points, 0, n, *numbers)
            got = fast(*before, p, offset, n, *numbers)
            assert _same(expected, got), (lookup.__name__, before, points, expected, got)


def test_both_paths_give_the_servo_and_its_feedback_alike():
    rng = np.random.default_rng(5)
    for function in (servo_motor.servo_command, servo_motor.rigid_feedback, servo_motor.isodromic_rate):
        fast = kernels.compiled(function.__module__, function.__name__)
        for _ in range(STATES):
            arguments = [float(v) for v in rng.uniform(-0.05, 0.05, function.__code__.co_argcount)]
            if function is servo_motor.servo_command:  # gain, max speed (also unlimited), dead band
                arguments[1:] = [rng.uniform(1.0, 100.0), float(rng.choice([0.2, math.inf])), abs(arguments[3])]
            assert _same(function(*arguments), fast(*arguments)), (function.__name__, arguments)


def test_both_paths_solve_joint_friction_alike():
    """Joint friction's stick/slip Newton solve, one function: in Python over lists (the reference path) and compiled
    over tuples (the fast path's generated code) on random joints, at rest and moving, |k_j| and |N| or their held
    signs."""
    solve = joint_friction.friction_acceleration
    fast = kernels.compiled(solve.__module__, solve.__name__)
    rng = np.random.default_rng(6)
    for i in range(STATES):
        arms = [0.0 if k == 3 else float(v) for k, v in enumerate(rng.uniform(0.0, 0.02, 4))]  # one without friction
        ratios = [float(v) for v in rng.uniform(-1.5, 1.5, 4)]
        constant = [complex(*rng.uniform(-5e3, 5e3, 2)) for _ in range(4)]
        per_epsilon = [complex(*rng.uniform(-2.0, 2.0, 2)) for _ in range(4)]
        ratio_signs = [0.0] * 4 if i % 2 else [float(v) for v in rng.choice([-1.0, 1.0], 4)]
        normal_signs = [0.0, 0.0, 0.0, float(rng.choice([0.0, -1.0, 1.0]))]
        omega = 0.0 if i % 5 == 0 else float(rng.uniform(-50.0, 50.0))
        arguments = (omega, *(float(v) for v in (rng.uniform(-300.0, 300.0), rng.uniform(0.5, 5.0), rng.uniform(0, 5))))
        numbers = (joint_friction.NEWTON_TOLERANCE, joint_friction.NEWTON_ITERATIONS)
        expected = solve(*arguments, arms, ratios, constant, per_epsilon, True, *numbers, ratio_signs, normal_signs)
        got = fast(
            *arguments,
            tuple(arms),
            tuple(ratios),
            tuple(constant),
            tuple(per_epsilon),
            True,
            *numbers,
            tuple(ratio_signs),
            tuple(normal_signs),
        )
        assert _same(expected, got), (i, expected, got)
    collar_only = solve(3.0, 10.0, 2.0, 1.0, (), (), (), (), False, *numbers, (), ())
    assert collar_only == (10.0 - 1.0) / 2.0  # moving forward: (M - F) / J


def test_a_union_member_without_a_definition_fails_naming_it():
    class NewLoad(key_types.SceneModel):
        type: Literal["new"]

    union = Annotated[effect_keys.ViscousLoad | NewLoad, Field(discriminator="type")]
    with pytest.raises(DefinitionError, match="NewLoad"):
        check_covered(union)
    with pytest.raises(DefinitionError, match="NewLoad"):
        definition_of(NewLoad(type="new"))
