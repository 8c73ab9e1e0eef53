"""Limits on what a scene may ask for, so that every input ends within seconds with a result or a clear message
(docs/scenes.md, section "Limits", says each one and why).

Scene files travel (students share them, a ROS launch passes one in): a file may be hostile or just extreme. The
limits fall in three groups:

- reading: the size of a scene file, the nesting depth of its YAML and the size of its YAML once aliases are
  expanded (loading.py's loader enforces them while it composes the document, before anything is built);
- numbers: the magnitude of any number, and the work a run would take (steps, output samples) worked out from the
  scene before it runs (run_refusals; the reduced inertia J(phi) is scanned over a turn when the model is built);
- the run itself: a speed beyond MAX_SPEED (or a non-finite state) ends the run at once as failed, keeping what was
  computed, and so does a run that has taken MAX_STEPS steps (solvers/time_domain.py, energy_method.py, cosim.py).

This module imports only the standard library (the command line names output files with output_stem before it
loads anything heavy).
"""

from __future__ import annotations

import math
import re
from typing import Any

# Reading a scene file
MAX_SCENE_BYTES = 1_000_000  # a scene file's size [bytes]: the bundled ones are 1-3 kB; the YAML reader takes ~3 s/MB
MAX_YAML_DEPTH = 40  # nesting of mappings and lists: the deepest key of the format is 9 levels down
MAX_YAML_NODES = 200_000  # values (nodes) of a YAML document with its aliases expanded (an alias counts as the
# whole node it repeats): more than a file of MAX_SCENE_BYTES holds without aliases; an alias bomb stops at once
MAX_YAML_CHARACTERS = 2_000_000  # characters of the scalars of a YAML document with its aliases expanded
MAX_BASE_CHAIN = 16  # scenes in a chain of `base:`

# Numbers of a scene
MAX_MAGNITUDE = 1e15  # any number's magnitude, in its key's unit (SI): beyond every physical quantity of a machine
# (a pressure of 1e9 Pa, a stiffness of 1e10 N m/rad), and small enough that products of a few never overflow
MAX_DURATION = 1e7  # scenario.duration [s] (115 days), as `mech-regulator run --duration`
MAX_STEPS = 10_000_000  # steps of one run (RK4 or the energy method worked out before the run; any method, and the
# exchanges of a co-simulation, counted while it runs): ~10 s on the fast path, minutes on the reference path
LONG_RUN = 100.0  # [s]: an adaptive method's run longer than this is probed before it starts (solvers.simulate)
PROBE_DURATION = 1.0  # [s] of the run's start the probe steps; its steps, at its rate, over the duration are the
# estimate of the run's steps (the probe costs at most a hundredth of the run)
MAX_SAMPLES = 20_000_000  # output samples of a run, duration x solver.sample_rate: rows of the CSV (~4 GB), a few GB
# of memory while they are written
MAX_SPEED = 1e6  # [rad/s] (about 10 million rpm): a crank or driven speed beyond it is a blow-up; the run stops there
MIN_INERTIA_FRACTION = 1e-9  # the reduced inertia J(phi) must stay above this fraction of its largest value
MIN_INERTIA = 1e-12  # [kg m^2] the smallest reduced inertia (a watch's balance wheel has ~1e-9): moments up to
# MAX_MAGNITUDE divided by it stay far from overflow, also squared and in a Jacobian's differences

# Output names
MAX_NAME_LENGTH = 80  # characters of an output file's stem made from a scene's name
_UNSAFE = re.compile(r"[^A-Za-z0-9_.-]+")


def output_stem(name: str | None, default: str = "scene") -> str:
    """A file-name stem made from a scene's name: only letters, digits, '_', '.' and '-' (every other run of
    characters, separators and control characters included, becomes one '_'), no leading '.', '_' or '-', no '..',
    at most MAX_NAME_LENGTH characters; `default` when nothing is left. It can never name another folder."""
    stem = _UNSAFE.sub("_", str(name) if name is not None else "")
    stem = re.sub(r"\.{2,}", ".", stem).lstrip("._-")[:MAX_NAME_LENGTH].rstrip(".")
    return stem if stem.strip("_-") else default


def shown(value: Any, limit: int = 300) -> str:
    """A value as a message shows it: its repr, cut to `limit` characters; a large value (a huge integer or string,
    a long or deep list, an alias bomb) is abbreviated without being written out whole first."""
    if _small(value):
        text = repr(value)
    else:
        import reprlib

        short = reprlib.Repr()
        short.maxstring = short.maxother = short.maxlong = 60
        short.maxlist = short.maxtuple = short.maxdict = short.maxset = 8
        short.maxlevel = 3
        text = short.repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _small(value: Any, budget: int = 200) -> bool:
    """Whether a value has at most `budget` parts (containers, items, 40-character pieces of text and digits)."""
    pending = [value]
    while pending:
        node = pending.pop()
        budget -= 1
        if isinstance(node, dict):
            pending += list(node.keys())[:budget] + list(node.values())[:budget]
        elif isinstance(node, (list, tuple, set)):
            pending += list(node)[: budget + 1]
        elif isinstance(node, str):
            budget -= len(node) // 40
        elif isinstance(node, int) and not isinstance(node, bool):
            budget -= node.bit_length() // 128
        if budget < 0:
            return False
    return True


def number_refusals(data: Any, path: str = "") -> list[str]:
    """One line per number in a scene's (unvalidated) data whose magnitude exceeds MAX_MAGNITUDE: its dotted key,
    its value and the limit. Checked before the schema's validation, whose checks multiply numbers."""
    problems: list[str] = []
    pending = [(path, data)]
    while pending:
        key, node = pending.pop()
        if isinstance(node, dict):
            pending += [(f"{key}.{child}" if key else str(child), value) for child, value in reversed(node.items())]
        elif isinstance(node, list):
            pending += [
                (f"{key}.{index}" if key else str(index), value) for index, value in reversed(list(enumerate(node)))
            ]
        elif (
            isinstance(node, int) and not isinstance(node, bool) or isinstance(node, float) and math.isfinite(node)
        ) and abs(node) > MAX_MAGNITUDE:  # (NaN and infinities: the schema says "a finite number")
            problems.append(
                f"{key or '(top level)'} = {shown(node)}: beyond the limit on any number of a scene, "
                f"|value| <= {MAX_MAGNITUDE:g} (in the key's SI unit)"
            )
    return problems


def run_refusals(scene) -> list[str]:
    """One line per setting of a validated scene that would make its run impossible (too long, too many steps or
    output samples, a speed beyond MAX_SPEED from the start): the key, its value, the work it means and what is
    allowed."""
    problems = []
    scenario, solver = scene.scenario, scene.solver
    duration = scenario.duration
    if duration > MAX_DURATION:
        problems.append(f"scenario.duration = {duration:g} s: longer than the limit of {MAX_DURATION:g} s (115 days)")
        return problems
    initial = scenario.initial
    for key, value in (("omega", initial.omega), ("omega_driven", initial.omega_driven)):
        if value is not None and abs(value) > MAX_SPEED:
            problems.append(
                f"scenario.initial.{key} = {value:g} rad/s: beyond the limit of {MAX_SPEED:g} rad/s on "
                "any speed (about 10 million rpm)"
            )
    if solver.method == "RK4":
        steps = duration / solver.step
        if steps > MAX_STEPS:
            problems.append(
                f"solver.step = {solver.step:g} s would take {steps:.3g} steps for {duration:g} s; "
                f"expected at most {MAX_STEPS:g} steps: solver.step >= {duration / MAX_STEPS:.3g} s"
            )
    elif solver.method == "energy":
        dphi = math.radians(solver.phi_step_deg)
        per_turn = 2.0 * math.pi / dphi
        turned = abs(initial.omega) * duration
        if per_turn > MAX_STEPS:
            problems.append(
                f"solver.phi_step_deg = {solver.phi_step_deg:g} deg would take {per_turn:.3g} steps per "
                f"turn; expected at most {MAX_STEPS:g} steps: solver.phi_step_deg >= "
                f"{360.0 / MAX_STEPS:.3g} deg"
            )
        elif turned / dphi > MAX_STEPS:
            problems.append(
                f"solver.phi_step_deg = {solver.phi_step_deg:g} deg would take {turned / dphi:.3g} steps "
                f"for {duration:g} s at the initial speed {initial.omega:g} rad/s; expected at most "
                f"{MAX_STEPS:g} steps: solver.phi_step_deg >= {math.degrees(turned / MAX_STEPS):.3g} deg"
            )
    elif solver.max_step is not None and duration / solver.max_step > MAX_STEPS:
        problems.append(
            f"solver.max_step = {solver.max_step:g} s would take at least {duration / solver.max_step:.3g} "
            f"steps for {duration:g} s; expected at most {MAX_STEPS:g} steps: solver.max_step >= "
            f"{duration / MAX_STEPS:.3g} s (or none)"
        )
    samples = duration * solver.sample_rate
    if samples > MAX_SAMPLES:
        problems.append(
            f"solver.sample_rate = {solver.sample_rate:g} Hz gives {samples:.3g} output samples over "
            f"{duration:g} s; expected at most {MAX_SAMPLES:g}: solver.sample_rate <= "
            f"{MAX_SAMPLES / duration:.3g} Hz"
        )
    return problems


def exchange_refusal(option: str, exchange_step: float, duration: float) -> str | None:
    """Why a co-simulation's exchange step [s] over `duration` [s] would take too many exchanges (None if not)."""
    exchanges = duration / exchange_step
    if exchanges > MAX_STEPS:
        return (
            f"{option} {exchange_step:g} s would take {exchanges:.3g} exchanges for {duration:g} s; expected at "
            f"most {MAX_STEPS:g}: an exchange step >= {duration / MAX_STEPS:.3g} s"
        )
    return None


def speed_beyond_limit(names: tuple[str, ...], y) -> tuple[str, float] | None:
    """(name, value) of the first speed in the state y (the entries named omega or omega_driven in `names`, as
    MachineModel.state_names) that is not finite or beyond MAX_SPEED, else None."""
    for name, value in zip(names, y):
        if name in ("omega", "omega_driven") and not abs(value) <= MAX_SPEED:
            return name, float(value)
    return None
