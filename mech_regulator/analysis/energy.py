"""Energy bookkeeping of a run, and the energy swing that sizes a flywheel.

Energy balance (docs/theory.md §2.4, energy form): the work of all moments equals the change of
kinetic energy, `sum_k integral M_k omega dt = 1/2 J(phi) omega^2 |_0^T`. A two-mass machine adds
the driven part's works (at omega_driven; its links' weight included), the coupling damper's work
-c (omega - omega_driven)^2 and the coupling's elastic energy integral_0^twist M_elastic dtwist
(1/2 k twist^2 for a linear coupling) to the stored energy, 1/2 I2(phi_driven) omega_driven^2 to the
kinetic energy; a friction clutch the work lost in its slip, -T (omega - omega_driven) (T the moment it
passes: +-kinetic_torque while slipping). The works are integrated
by Gauss-Legendre quadrature on every solver step of the dense output, so the residual measures
the integration error of the run, not a sampling error.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from mech_regulator.model import MachineModel
from mech_regulator.solvers import Trajectory
from mech_regulator.solvers.trajectory import sample_times_within

GAUSS_NODES, GAUSS_WEIGHTS = np.polynomial.legendre.leggauss(4)
BALANCE_CHUNK_STEPS = 50_000  # solver steps whose works energy_balance evaluates at once (some 100 MB of columns)


@dataclass(frozen=True)
class EnergyBalance:
    """Works of the moments over the run [J], change of the stored energy (kinetic, plus the coupling's
    elastic energy) [J] and the residual `sum(works) - delta_kinetic` [J], also relative to the largest
    energy involved."""

    works: dict[str, float]
    delta_kinetic: float
    residual: float
    relative_residual: float


@dataclass
class WorksSoFar:
    """What a streamed run (analysis/stream.py) has summed of its energy balance before dropping the dense output:
    works [J] by name over its first `steps` solver steps (whole chunks of BALANCE_CHUNK_STEPS), and the state at its
    start (None until the first chunk)."""

    works: dict[str, float] = field(default_factory=dict)
    steps: int = 0
    start: np.ndarray | None = None


def energy_balance(model: MachineModel, trajectory: Trajectory, so_far: WorksSoFar | None = None) -> EnergyBalance:
    """The works [J] of the moments over the run, each the integral of its power (`powers`) by 4-point
    Gauss-Legendre quadrature on every solver step (step_edges: the dense output is one polynomial per step, so the
    quadrature's error stays far below the solver's), against the change of the stored energy between the run's
    ends [J]. The steps are taken BALANCE_CHUNK_STEPS at a time, so that its memory does not grow with the run's
    steps (a 10 000-s run of an engine takes millions); so_far: the chunks a streamed run summed already, before the
    steps its trajectory still holds."""
    so_far = so_far or WorksSoFar()
    edges = step_edges(trajectory)
    works = dict(so_far.works)
    for chunk, _ in step_chunks(trajectory, edges, so_far.steps):
        add_works(model, trajectory, chunk, works)
    if so_far.start is None:
        states = trajectory(np.array([edges[0], edges[-1]]))
    else:
        states = np.column_stack([so_far.start, trajectory(edges[-1:])[:, 0]])
    ends = model.columns(np.array([trajectory.t_start, edges[-1]]), states)
    stored = ends["E_kinetic"] + ends.get("E_elastic", 0.0)
    delta_kinetic = float(stored[1] - stored[0])
    residual = sum(works.values()) - delta_kinetic
    scale = max(sum(abs(w) for w in works.values()), float(np.max(stored)), 1e-300)
    return EnergyBalance(works, delta_kinetic, residual, residual / scale)


def add_works(
    model: MachineModel, trajectory: Trajectory, edges: np.ndarray, works: dict[str, float]
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Add to works [J] the quadrature of each moment's power over the solver steps between consecutive edges [s]
    (one chunk of energy_balance); returns the quadrature's nodes [s] and the output columns there."""
    left, width = edges[:-1], np.diff(edges)
    nodes = (left[:, None] + 0.5 * width[:, None] * (GAUSS_NODES[None, :] + 1.0)).ravel()
    weights = (0.5 * width[:, None] * GAUSS_WEIGHTS[None, :]).ravel()
    columns = model.columns(nodes, trajectory(nodes))
    for name, power in powers(model, columns).items():
        works[name] = works.get(name, 0.0) + float(np.sum(weights * power))
    return nodes, columns


def powers(model: MachineModel, columns: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The power of every moment that exchanges energy with the outside [W], by name: M_k omega for the
    crank's moments, M_driven_k omega_driven for the driven part's, and -c (omega - omega_driven)^2 for the
    coupling's damper (the coupling's spring only stores energy) and -T (omega - omega_driven) for a clutch's
    slip (T = clutch_torque). Section torques (M_section_*) are internal moments and do no work on the machine."""
    result = {}
    for name, moment in columns.items():
        if not name.startswith("M_") or name in ("M_load", "M_coupling") or name.startswith("M_section_"):
            continue
        speed = columns["omega_driven"] if name.startswith("M_driven_") else columns["omega"]
        result[name[2:]] = moment * speed
    if model.coupling is not None:
        result["coupling_damping"] = -model.coupling.damping * (columns["omega"] - columns["omega_driven"]) ** 2
    if model.clutch is not None:
        result["clutch_slip"] = -columns["clutch_torque"] * columns["slip_speed"]
    return result


def step_edges(trajectory: Trajectory) -> np.ndarray:
    """Every solver step's boundary over the run [s], ascending from t_start to t_end: the start, then the step
    ends each piece recorded (Trajectory.step_ends; a piece of the fast path spans a whole compiled call's steps).
    Empty for a run without a step."""
    return np.concatenate([trajectory.piece_edges[:1], *trajectory.step_ends])


def step_chunks(
    trajectory: Trajectory, edges: np.ndarray, steps_done: int
) -> Iterator[tuple[np.ndarray, float | None]]:
    """The chunks of BALANCE_CHUNK_STEPS solver steps after the run's first steps_done, in order: each chunk's step
    edges [s] (a slice of edges, step_edges of the trajectory) and the edge that follows it (None after the last).
    A summary reads the rest of a run in these, after those a streamed run read (analysis/stream.py); one chunk for
    a run without a step."""
    for first in range(steps_done - trajectory.steps_dropped, max(edges.size - 1, 1), BALANCE_CHUNK_STEPS):
        end = first + BALANCE_CHUNK_STEPS
        yield edges[first : end + 1], float(edges[end + 1]) if end + 1 < edges.size else None


def planned_samples(model: MachineModel, trajectory: Trajectory, low: float, high: float) -> np.ndarray:
    """The output sample times [s] of the run's planned grid (its start to the scene's duration, at its sample
    rate) in [low, high]."""
    solver, duration = model.scene.solver, model.scene.scenario.duration
    return sample_times_within(trajectory.t_start, duration, solver.sample_rate, low, high)


def energy_swing(
    model: MachineModel, omega: float, phi_start: float = 0.0, points: int = 7200
) -> tuple[np.ndarray, np.ndarray]:
    """dE(phi) = integral_{phi_start}^{phi} (M_d + M_c) dphi over one dynamic period [J] at a fixed speed
    omega [rad/s] and t = 0 (for moments that read omega, the swing at that speed). A coupled driven part
    turns at omega too, at phi_driven = phi, its moments added to the crank's.

    Midpoint rule on a grid that contains every switch angle, so on-off moments integrate exactly.
    Returns (phi [rad], dE [J]).
    """
    period = model.dynamic_period()
    grid = np.linspace(phi_start, phi_start + period, points + 1)
    for angle, switch_period in model.switch_angles():
        first = angle + switch_period * math.ceil((phi_start - angle) / switch_period)
        grid = np.union1d(grid, np.arange(first, phi_start + period, switch_period))
    middles = 0.5 * (grid[:-1] + grid[1:])
    states = np.vstack([middles, np.full_like(middles, omega)])
    if model.coupling is not None:  # rigid at constant speed: the driven part turns with the crank (twist 0)
        states = np.vstack([states, np.zeros_like(middles), np.full_like(middles, omega)])
    if model.clutch is not None:  # stuck at constant speed
        states = np.vstack([states, np.full_like(middles, omega)])
    columns = model.columns(np.zeros_like(middles), states)
    net = columns["M_drive"] + columns["M_load"] + columns.get("M_weight", 0.0)
    if model.driven is not None:  # the driven part's moments (loads, weight, external load) in place of the
        #                            coupling's or clutch's moment
        driven = sum(values for name, values in columns.items() if name.startswith("M_driven_"))
        passed = -columns["M_coupling"] if model.coupling is not None else columns["clutch_torque"]
        net = net + passed + driven
    return grid, np.concatenate([[0.0], np.cumsum(net * np.diff(grid))])


def flywheel_for_constant_inertia(energy_swing_max: float, omega_m: float, delta: float, inertia: float) -> float:
    """Flywheel inertia [kg m^2] for a constant-J machine: `J_fw = dE_max / (omega_m^2 [delta]) - J0`
    (docs/theory.md §3.3); exact when the moments do not depend on omega, since
    omega_max^2 - omega_min^2 = 2 delta omega_m^2 with omega_m = (omega_max + omega_min) / 2."""
    return energy_swing_max / (omega_m**2 * delta) - inertia
