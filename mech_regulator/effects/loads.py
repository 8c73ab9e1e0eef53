"""The loads (a scene's `machine.loads`, a driven part's and its branches'), each defined once for both paths
(effects/definition.py): its formula, a plain function numba compiles unchanged, its numbers and its table. A load
on the mechanism's output link also gives the force Q on it, whose reduced moment is Q dq/dphi (docs/theory.md
§2.2). Moments on the crank [N m]; a resisting one is negative."""

from __future__ import annotations

import math

from mech_regulator.effects.definition import CLAMPED, INTERVALS, PERIODIC, Definition, Table, define
from mech_regulator.scene import effect_keys


def constant_load(torque):
    """Constant load: M_c = -torque [N m]."""
    return -torque


def viscous_load(omega, c):
    """Viscous load: M_c = -c omega [N m]."""
    return -c * omega


def fan_load(omega, k):
    """Fan load: M_c = -k omega |omega| [N m]."""
    return -k * omega * abs(omega)


def table_load(table):
    """Table load: M_c = -M(phi), the periodic table read at phi [N m]."""
    return -table


def cutting_load(table, torque):
    """Cutting (on-off) load: M_c = -torque while phi lies in one of the cutting intervals (table 1.0), else 0 [N m]."""
    return -torque if table != 0.0 else 0.0


def output_constant(dq, value):
    """Constant force (slider, shuttle bar) [N] or moment (rocker) [N m] on the output link, reduced: M = Q dq/dphi."""
    return value * dq


def output_constant_force(value):
    """The constant force or moment itself, Q = value."""
    return value


def output_viscous(omega, dq, c):
    """Viscous force on the output link, reduced: M = -c (dq/dphi)^2 omega [N m]."""
    return -c * dq * dq * omega


def output_viscous_force(omega, dq, c):
    """The viscous force itself, Q = -c dq/dphi omega [N or N m]."""
    return -c * dq * omega


def output_spring_force(q, k, free):
    """The spring's force on the output link: Q = -k (q - q_free) [N or N m]."""
    return -k * (q - free)


def output_spring(q, dq, k, free):
    """Spring on the output link, reduced: M = -k (q - q_free) dq/dphi (output_spring_force reduced) [N m]."""
    return -k * (q - free) * dq


def slider_table(table, dq):
    """Slider force table, reduced: M = F(x) dx/dphi, F the clamped table read at the slider position x [N m]."""
    return table * dq


def slider_table_force(table):
    """The tabulated force itself, F(x) [N]."""
    return table


@define(effect_keys.ConstantLoad)
def _constant(load: effect_keys.ConstantLoad, mechanism=None) -> Definition:
    return Definition(
        "constant", "load", f"constant: M_c = -{load.torque:g} N m", constant_load, {"torque": load.torque}, dry=True
    )


@define(effect_keys.ViscousLoad)
def _viscous(load: effect_keys.ViscousLoad, mechanism=None) -> Definition:
    return Definition(
        "viscous",
        "load",
        f"viscous: M_c = -{load.coefficient:g} omega",
        viscous_load,
        {"c": load.coefficient},
        frozenset({"omega"}),
    )


@define(effect_keys.FanLoad)
def _fan(load: effect_keys.FanLoad, mechanism=None) -> Definition:
    return Definition(
        "fan",
        "load",
        f"fan: M_c = -{load.coefficient:g} omega |omega|",
        fan_load,
        {"k": load.coefficient},
        frozenset({"omega"}),
    )


@define(effect_keys.TableLoad)
def _table(load: effect_keys.TableLoad, mechanism=None) -> Definition:
    return Definition(
        "table",
        "load",
        f"table: M_c = -M(phi), {len(load.torque)} points over {load.period_deg:g} deg",
        table_load,
        depends_on=frozenset({"phi"}),
        table=Table(
            PERIODIC, tuple(math.radians(a) for a in load.angle_deg), tuple(load.torque), math.radians(load.period_deg)
        ),
    )


@define(effect_keys.CuttingLoad)
def _cutting(load: effect_keys.CuttingLoad, mechanism=None) -> Definition:
    """The intervals' edges from the first one's start, read at phi - start (mod the period)."""
    start = math.radians(load.intervals_deg[0][0])
    edges = tuple(math.radians(edge) - start for interval in load.intervals_deg for edge in interval)
    return Definition(
        "cutting",
        "load",
        f"cutting: M_c = -{load.torque:g} N m over {load.intervals_deg} deg",
        cutting_load,
        {"torque": load.torque},
        frozenset({"phi"}),
        Table(INTERVALS, edges, period=math.radians(load.period_deg), shifts=(-start,)),
    )


def _on(load) -> str:
    """The output link a load acts on, as `describe` names it."""
    return {"slider": "slider", "rocker": "rocker", "shuttle": "shuttle bar"}[load.type.split("_")[0]]


@define(effect_keys.SliderConstant, effect_keys.RockerConstant)
def _output_constant(load: effect_keys.SliderConstant | effect_keys.RockerConstant, mechanism=None) -> Definition:
    value = load.force if isinstance(load, effect_keys.SliderConstant) else load.torque
    return Definition(
        load.type,
        "load",
        f"constant on the {_on(load)}: M = {value:g} dq/dphi",
        output_constant,
        {"value": value},
        frozenset({"phi"}),
        output_force=output_constant_force,
        on_output=True,
    )


@define(effect_keys.OutputViscous)
def _output_viscous(load: effect_keys.OutputViscous, mechanism=None) -> Definition:
    return Definition(
        load.type,
        "load",
        f"viscous on the {_on(load)}: M = -{load.coefficient:g} (dq/dphi)^2 omega",
        output_viscous,
        {"c": load.coefficient},
        frozenset({"phi", "omega"}),
        output_force=output_viscous_force,
        on_output=True,
    )


@define(effect_keys.OutputSpring)
def _output_spring(load: effect_keys.OutputSpring, mechanism=None) -> Definition:
    return Definition(
        load.type,
        "load",
        f"spring on the {_on(load)}: M = -{load.stiffness:g} (q - {load.free_position:g}) dq/dphi",
        output_spring,
        {"k": load.stiffness, "free": load.free_position},
        frozenset({"phi"}),
        output_force=output_spring_force,
        on_output=True,
    )


@define(effect_keys.SliderTable)
def _slider_table(load: effect_keys.SliderTable, mechanism=None) -> Definition:
    return Definition(
        "slider_table",
        "load",
        f"slider force table F(x), {len(load.force)} points: M = F(x) dx/dphi",
        slider_table,
        depends_on=frozenset({"phi"}),
        table=Table(CLAMPED, tuple(load.position), tuple(load.force)),
        output_force=slider_table_force,
        on_output=True,
    )
