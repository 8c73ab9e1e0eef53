"""Analysis of a run: steady state and speed fluctuation over the dynamic period, energy balance,
and the flywheel formulas; `summarise` gathers them for the command line."""

from __future__ import annotations

import dataclasses

from mech_regulator.analysis.energy import EnergyBalance, energy_balance, energy_swing, flywheel_for_constant_inertia
from mech_regulator.analysis.periodic import PeriodSpeeds, SteadyState, analyse_steady_state
from mech_regulator.model import MachineModel
from mech_regulator.solvers import Trajectory


def summarise(model: MachineModel, trajectory: Trajectory) -> dict:
    """Everything the summary reports, as plain data (JSON-ready)."""
    if not trajectory.interpolants:  # the solver refused before its first step
        return {"scene": model.scene.name, "status": trajectory.status, "message": trajectory.message,
                "t_end": trajectory.t_start, "phi_end": model.scene.scenario.initial.phi,
                "omega_end": model.scene.scenario.initial.omega, "steady": None, "energy": None,
                "solver": {"method": trajectory.method, **dataclasses.asdict(trajectory.stats)}}
    steady = analyse_steady_state(model, trajectory)
    balance = energy_balance(model, trajectory)
    end = trajectory(trajectory.t_end)
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
        "solver": {"method": trajectory.method, **dataclasses.asdict(trajectory.stats)},
    }


__all__ = ["EnergyBalance", "PeriodSpeeds", "SteadyState", "analyse_steady_state", "energy_balance", "energy_swing",
           "flywheel_for_constant_inertia", "summarise"]
