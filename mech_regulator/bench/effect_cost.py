"""What each effect costs: the same machine measured as effects are added one at a time.

"Simulate only the effects a scene calls for" is a claim about cost, so it is measured: a chain of
scenes, each the previous one plus one effect (constant J -> mechanism J(phi) -> engine torque ->
governor -> sleeve friction -> stops reached -> elastic coupling -> joint friction), each run through the same scenario
(the engine_direct machine under 6 N m, the load thrown off at 0.5 s) with the same solver (DOP853,
rtol 1e-8). For each: the CPU time of one right-hand-side evaluation (timed alone, at the states of
the run), the evaluations, steps and mode changes per simulated second, and the CPU time per simulated
second of the whole run (solver, guards and events included). Numbers to print, never to assert.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from mech_regulator.bench.accuracy import timed
from mech_regulator.model import MachineModel, build_model
from mech_regulator.scene import load_scene
from mech_regulator.solvers import Trajectory, simulate

BASE_SCENE = "engine_direct"
SCENARIO = (
    "scenario.duration=1.5",
    "scenario.load_events=[{time: 0.5, torque: 0.0}]",
    "solver.method=DOP853",
    "solver.rtol=1e-8",
    "solver.atol=1e-10",
)
UNGOVERNED = ("governor=null", "scenario.initial={omega: 224.17}")
CONSTANT_DRIVE = "machine.drive={type: constant, torque: 11.5}"  # about the engine's mean moment at this load [N m]
FRICTION = ("governor.friction=2.0", "governor.static_friction=3.0")
STOPS = (
    "governor.stroke=[0.02, 0.034]",
    "governor.valve.closed_at=0.034",
)  # the rejection drives the sleeve up to 0.034 m
COUPLING = (
    "machine.loads=[{type: viscous, coefficient: 0.02}]",
    "machine.coupling={stiffness: 5000.0, damping: 2.0, driven: {inertia: 0.1, loads: [{type: fan, "
    "coefficient: 1.5e-4}]}}",
)
# lubricated journals of an 80 mm bore engine: main bearing 50 mm, crank pin 40 mm, wrist pin 22 mm; piston on its liner
JOINT_FRICTION = (
    "machine.joint_friction={coefficient: 0.02, guide: 0.02, joints: {crank_bearing: {radius: 0.025, "
    "fit: run_in}, crank_pin: {radius: 0.02, fit: run_in}, wrist_pin: {radius: 0.011, fit: run_in}}}",
)


@dataclass(frozen=True)
class EffectStep:
    """One link of the chain: a label, the effect it adds and the changes to BASE_SCENE that make it."""

    label: str
    adds: str
    overrides: tuple[str, ...]


EFFECT_CHAIN = (
    EffectStep(
        "constant J",
        "J0 + flywheel, constant drive, viscous and fan loads, external load",
        UNGOVERNED + ("machine.mechanism=null", "machine.inertia=0.23", CONSTANT_DRIVE),
    ),
    EffectStep(
        "+ mechanism J(phi)",
        "crank-slider kinematics per evaluation: J(phi), dJ/dphi, the J' omega^2 / 2 term",
        UNGOVERNED + (CONSTANT_DRIVE,),
    ),
    EffectStep("+ engine torque", "indicator-diagram table p(phi) times dx/dphi", UNGOVERNED),
    EffectStep("+ governor", "direct Porter governor: 2 more states, throttle(z), stop guards", ()),
    EffectStep("+ sleeve friction", "Coulomb friction, static > kinetic: stick/slip modes and their guards", FRICTION),
    EffectStep(
        "+ stops reached", "a shorter stroke: the sleeve lands on its stop after the rejection", FRICTION + STOPS
    ),
    EffectStep(
        "+ elastic coupling", "the generator as a second mass on a coupling: 2 more states", FRICTION + STOPS + COUPLING
    ),
    EffectStep(
        "+ joint friction",
        "kinetostatics of the crank-slider per evaluation, friction in 3 journals and the "
        "guide, epsilon from the implicit equation (Newton)",
        FRICTION + STOPS + COUPLING + JOINT_FRICTION,
    ),
)


@dataclass(frozen=True)
class EffectCost:
    """The measured cost of one link of the chain: rhs_us, CPU time of one right-hand-side evaluation [us];
    rhs_per_s, steps_per_s, events_per_s: per simulated second; cpu_per_s: CPU time of the run per
    simulated second [s/s] (median of the repeats); status of the run."""

    label: str
    adds: str
    states: int
    rhs_us: float
    rhs_per_s: float
    steps_per_s: float
    events_per_s: float
    cpu_per_s: float
    status: str


def step_model(step: EffectStep) -> MachineModel:
    """The machine of one link of the chain."""
    return build_model(load_scene(BASE_SCENE, list(SCENARIO + step.overrides)))


def rhs_microseconds(model: MachineModel, trajectory: Trajectory, samples: int = 2000, rounds: int = 5) -> float:
    """CPU time of one evaluation of the model's right-hand side [us], timed alone at `samples` states of
    the run in the governor's initial mode (best of `rounds`: the least disturbed)."""
    times = np.linspace(trajectory.t_start, trajectory.t_end, samples)
    states = list(trajectory(times).T)
    rhs = model.rhs(model.piece_at(0.0), None, model.initial_mode(states[0]))
    best = np.inf
    for _ in range(rounds):
        start = time.process_time()
        for t, y in zip(times, states):
            rhs(t, y)
        best = min(best, time.process_time() - start)
    return best / samples * 1e6


def measure_effect_costs(repeats: int = 3, progress: Callable[[str], None] | None = None) -> list[EffectCost]:
    """Run every link of EFFECT_CHAIN `repeats` times; returns their costs in chain order."""
    costs = []
    for step in EFFECT_CHAIN:
        if progress is not None:
            progress(step.label)
        model = step_model(step)
        cpu = []
        for _ in range(repeats):
            trajectory, seconds = timed(lambda: simulate(model))
            cpu.append(seconds)
        simulated = trajectory.t_end - trajectory.t_start
        stats = trajectory.stats
        costs.append(
            EffectCost(
                step.label,
                step.adds,
                len(model.state_names()),
                rhs_microseconds(model, trajectory),
                stats.nfev / simulated,
                stats.steps / simulated,
                stats.events / simulated,
                statistics.median(cpu) / simulated,
                trajectory.status,
            )
        )
    return costs


def effect_cost_table(costs: list[EffectCost]) -> str:
    """The costs as a markdown table, with each link's CPU per simulated second relative to the first."""
    lines = [
        "| effects | states | one RHS [us] | RHS evaluations / s | steps / s | mode changes / s | "
        "CPU / simulated s [s] | x constant J |",
        "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for cost in costs:
        lines.append(
            f"| {cost.label} | {cost.states} | {cost.rhs_us:.2f} | {cost.rhs_per_s:,.0f} | "
            f"{cost.steps_per_s:,.0f} | {cost.events_per_s:.1f} | {cost.cpu_per_s:.4f} | "
            f"{cost.cpu_per_s / costs[0].cpu_per_s:,.0f} |"
        )
    return "\n".join(lines) + "\n"


def effect_cost_section(costs: list[EffectCost]) -> str:
    """The section of docs/accuracy/README.md on what each effect costs: how it is measured, the table, and
    what each link adds."""
    lines = [
        "",
        "## What each effect costs",
        "",
        f"The `{BASE_SCENE}` machine built up one effect at a time, every link run through the same scenario "
        "(6 N m, the load thrown off at 0.5 s, 1.5 s) with DOP853 at rtol 1e-8. *One RHS* is the CPU time of one "
        "right-hand-side evaluation timed alone at the run's states: the price of computing the effect. The "
        "evaluations and steps per simulated second show what the effect does to the solver (a table with "
        "kinks makes it reject steps; a stuck sleeve lets it stride). `mech-regulator describe SCENE` lists "
        "what a scene computes.",
        "",
        effect_cost_table(costs),
        "| link | adds |",
        "| --- | --- |",
    ]
    lines += [f"| {cost.label} | {cost.adds} |" for cost in costs]
    return "\n".join(lines) + "\n"
