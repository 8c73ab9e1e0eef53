"""Analysis of a run: steady state and speed fluctuation over the dynamic period, energy balance,
the flywheel formulas, a governor's statics and stability and its answer to load changes;
the two-mass machine's periods and the coupling an inverse problem needs;
`summarise` and `analyse_governor` gather them for the command line."""

from __future__ import annotations

import dataclasses

import numpy as np

from mech_regulator.analysis.drivetrain import drive_train_summary
from mech_regulator.analysis.energy import EnergyBalance, energy_balance, energy_swing, flywheel_for_constant_inertia
from mech_regulator.analysis.load_response import LoadResponse, ResponseWindow, cycle_mean_speed, load_responses
from mech_regulator.analysis.periodic import PeriodSpeeds, SteadyState, analyse_steady_state
from mech_regulator.analysis.stability import (
    FloquetStability,
    LinearStability,
    critical_damping,
    floquet_stability,
    is_periodic,
    linear_stability,
)
from mech_regulator.analysis.statics import (
    Droop,
    OperatingPoint,
    StaticCharacteristic,
    droop,
    operating_point,
    static_characteristic,
)
from mech_regulator.analysis.stream import RunDigest, simulate_streamed
from mech_regulator.analysis.two_mass import MotionPeriods, RequiredCoupling, motion_periods, required_coupling
from mech_regulator.model import MachineModel
from mech_regulator.solvers import Trajectory
from mech_regulator.solvers.compiled import runs_compiled
from mech_regulator.solvers.cosim import CoSimulation


def summarise(model: MachineModel, trajectory: Trajectory, digest: RunDigest | None = None) -> dict:
    """Everything the summary reports, as plain data (JSON-ready). digest: the run's stream (analysis/stream.py), what
    it took of the dense output the trajectory dropped."""
    if not trajectory.interpolants:  # the solver refused before its first step
        return {
            "scene": model.scene.name,
            "status": trajectory.status,
            "message": trajectory.message,
            "t_end": trajectory.t_start,
            "phi_end": model.scene.scenario.initial.phi,
            "omega_end": model.scene.scenario.initial.omega,
            "steady": None,
            "energy": None,
            "governor": None,
            "two_mass": None,
            "drive_train": None,
            "solver": _solver_summary(model, trajectory),
        }
    streamed = digest if digest is not None and trajectory.steps_dropped else None
    steady = analyse_steady_state(model, trajectory, stopped_at=streamed.stopped_at if streamed else None)
    balance = energy_balance(model, trajectory, streamed.works if streamed else None)
    end = trajectory(trajectory.t_end)
    steps_read = streamed.works.steps if streamed else 0  # the solver steps the stream read and dropped
    return {
        "scene": model.scene.name,
        "status": trajectory.status,
        "message": trajectory.message,
        "t_end": trajectory.t_end,
        "phi_end": float(end[0]),
        "omega_end": float(end[1]),
        "steady": {
            "steady": steady.steady,
            "t_steady": steady.t_steady,
            "dynamic_period_rad": steady.period,
            "periods": steady.periods,
            "note": steady.note,
            "last_period": dataclasses.asdict(steady.last) if steady.last is not None else None,
        },
        "energy": dataclasses.asdict(balance),
        "solver": _solver_summary(model, trajectory),
        "governor": (
            _governed_run(model, trajectory, streamed.windows if streamed else None)
            if model.governor is not None
            else None
        ),
        "two_mass": (
            dataclasses.asdict(
                motion_periods(model, trajectory, steady, streamed.coupling if streamed else None, steps_read)
            )
            if model.coupling is not None
            else None
        ),
        "drive_train": (
            drive_train_summary(model, trajectory, streamed.sections if streamed else None, steps_read)
            if model.driven is not None
            else None
        ),
    }


def cosimulation_ending(run: CoSimulation) -> tuple[str, str]:
    """How a co-simulated run ended, (status, message): its solver's status and message, except that a run which
    played to its end after an overspeed trip is `tripped` (the machine's throttle closed from tripped_at on), never
    `complete`."""
    if run.status == "complete" and run.tripped_at is not None:
        return "tripped", f"overspeed trip at t = {run.tripped_at:.6g} s: throttle closed from then on"
    return run.status, run.message


def summarise_cosimulation(
    model: MachineModel,
    run: CoSimulation,
    exchange_step: float,
    coupling: str = "hold",
    exchange_tolerance: float | None = None,
) -> dict:
    """The summary of a co-simulated run (in process or by the ROS nodes), as plain data: how it ended
    (cosimulation_ending), the exchange step [s], the adaptive step's tolerance [-] (None: fixed) and coupling
    (solvers.cosim), the steps taken between its exchange times (count, min, median, max [s]), the final speed, the
    governor's answer to each load change (from the run sampled at its exchange times) and the overspeed trip."""
    trajectory = run.trajectory(model)
    status, message = cosimulation_ending(run)
    steps = np.diff(run.times)
    return {
        "scene": model.scene.name,
        "status": status,
        "message": message,
        "exchange_step": exchange_step,
        "exchange_tolerance": exchange_tolerance,
        "exchange_steps": {
            "count": int(steps.size),
            "min": float(steps.min()) if steps.size else None,
            "median": float(np.median(steps)) if steps.size else None,
            "max": float(steps.max()) if steps.size else None,
        },
        "coupling": coupling,
        "samples": int(run.times.size),
        "t_end": float(run.times[-1]),
        "omega_end": float(run.states[1, -1]),
        "tripped_at": run.tripped_at,
        "governor": _governed_run(model, trajectory) if model.governor is not None and run.times.size > 1 else None,
    }


def _governed_run(model: MachineModel, trajectory: Trajectory, windows: list[ResponseWindow] | None = None) -> dict:
    """The governor's part of a run's summary: its predicted operating point, its answer to each load
    change (windows: those a streamed run read in part) and how often it changed mode."""
    responses = load_responses(model, trajectory, windows)
    return {
        "operating_point": dataclasses.asdict(operating_point(model, model.external_load(0.0))),
        "load_responses": [dataclasses.asdict(response) for response in responses],
        "events": len(trajectory.events),
    }


def analyse_governor(model: MachineModel) -> dict:
    """Statics and stability of a governed scene, as plain data (JSON-ready): static characteristic,
    statism, insensitivity, operating points for every load level of the scenario, droop, linear
    stability of the averaged model (eigenvalues, dominant mode, Vyshnegradsky A and B, critical sleeve
    damping) and, for a machine periodic in phi without a driven part behind a coupling or clutch, the Floquet
    multipliers of the periodic orbit."""
    governor = model.governor
    assert governor is not None, "analyse_governor is for a governed scene"
    load = model.external_load(0.0)
    point = operating_point(model, load)
    levels = [load] + [event.torque for event in model.scene.scenario.load_events]
    linear = linear_stability(model, point)
    sensor = governor.sensor
    if sensor is None:  # no sleeve (a PI governor: isochronous within the valve's travel, docs/theory.md §8.10)
        characteristic, statism, insensitivity = None, 0.0, 0.0
    else:
        characteristic = static_characteristic(sensor)
        statism = characteristic.statism
        insensitivity = (
            sensor.equilibrium_speed(point.sleeve, sensor.static_friction)
            - sensor.equilibrium_speed(point.sleeve, -sensor.static_friction)
        ) / point.speed
    result = {
        "scene": model.scene.name,
        "kind": governor.kind,
        **governor.summary(),
        "set_speed": governor.set_speed(),
        "characteristic": None
        if characteristic is None
        else {
            key: value.tolist() if hasattr(value, "tolist") else value
            for key, value in dataclasses.asdict(characteristic).items()
        },
        "statism": statism,
        "insensitivity_at_operating_point": insensitivity,
        "operating_points": [dataclasses.asdict(operating_point(model, level)) for level in levels],
        "droop": dataclasses.asdict(droop(model)),
        "linear": {
            "state_names": list(linear.state_names),
            "eigenvalues": [[value.real, value.imag] for value in linear.eigenvalues],
            "dominant": [linear.dominant.real, linear.dominant.imag],
            "damping_ratio": linear.damping_ratio,
            "period": linear.period,
            "stable": linear.stable,
            "polynomial": linear.polynomial.tolist(),
            "vyshnegradsky": list(linear.vyshnegradsky) if linear.vyshnegradsky else None,
            "pi_loop": list(linear.pi_loop) if linear.pi_loop else None,
            "critical_damping": critical_damping(model, point),
        },
        "floquet": None,
    }
    if is_periodic(model) and model.driven is None:  # the period map carries the crank's and governor's states only
        floquet = floquet_stability(model, point, linear)
        result["floquet"] = {
            "cycle_time": floquet.cycle_time,
            "mean_speed": floquet.mean_speed,
            "residual": floquet.residual,
            "multipliers": [[value.real, value.imag] for value in floquet.multipliers],
            "averaged_multipliers": [[value.real, value.imag] for value in floquet.averaged_multipliers],
            "stable": floquet.stable,
            "orbit": floquet.orbit.tolist(),
        }
    return result


__all__ = [
    "Droop",
    "EnergyBalance",
    "FloquetStability",
    "LinearStability",
    "LoadResponse",
    "MotionPeriods",
    "OperatingPoint",
    "RequiredCoupling",
    "RunDigest",
    "motion_periods",
    "required_coupling",
    "PeriodSpeeds",
    "StaticCharacteristic",
    "SteadyState",
    "analyse_governor",
    "analyse_steady_state",
    "critical_damping",
    "cycle_mean_speed",
    "drive_train_summary",
    "droop",
    "energy_balance",
    "energy_swing",
    "flywheel_for_constant_inertia",
    "floquet_stability",
    "is_periodic",
    "linear_stability",
    "load_responses",
    "operating_point",
    "simulate_streamed",
    "static_characteristic",
    "summarise",
    "summarise_cosimulation",
]


def _solver_summary(model: MachineModel, trajectory: Trajectory) -> dict:
    """The summary's solver entry: the method, the path that stepped it (fast: the compiled steppers; reference:
    scipy and the model's Python right-hand side) and the trajectory's counts (steps, evaluations, switches, ...)."""
    path = "fast" if runs_compiled(model.scene.solver) else "reference"
    return {"method": trajectory.method, "path": path, **dataclasses.asdict(trajectory.stats)}
