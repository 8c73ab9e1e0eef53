"""Every run checks itself: a run whose own bookkeeping shows more error than its tolerance allows is not
"complete" but "inaccurate" (the command line says which check, its value, what is allowed and how to fix it).

The check is the energy balance (analysis/energy.py): the works of all moments minus the change of the stored
energy, relative to the largest energy involved. It is the run's global integration error seen through a
conservation law, so it grows with the tolerance: an adaptive method's tolerance rtol allows ENERGY_PER_RTOL * rtol
(errors accumulate over thousands of steps, and tables with kinks cost the bundled engines up to 7.7e-6 at rtol
1e-9 — inside the bound; a table with near-vertical steps costs 1e-2, far outside it); the fixed-step methods (RK4,
the energy method) have no tolerance: FIXED_STEP_RESIDUAL.
"""

from __future__ import annotations

from mech_regulator.model import MachineModel

ENERGY_PER_RTOL = 1e4  # [-] the relative energy residual an adaptive method's rtol allows, per unit of rtol
FIXED_STEP_RESIDUAL = 1e-4  # [-] the relative energy residual allowed to RK4 and the energy method
FIXED_STEP_METHODS = ("RK4", "energy")


def self_checks(model: MachineModel, summary: dict) -> list[dict]:
    """The checks a run's summary (analysis.summarise) fails, each {check, value, allowed, fix}: empty when it
    passes or has no energy balance (nothing was computed)."""
    energy = summary.get("energy")
    if energy is None or energy["relative_residual"] != energy["relative_residual"]:  # none, or NaN
        return []
    solver = model.scene.solver
    if solver.method in FIXED_STEP_METHODS:
        allowed = FIXED_STEP_RESIDUAL
        fix = ("shorten solver.step" if solver.method == "RK4" else "shorten solver.phi_step_deg") + \
            ", or choose an adaptive method (e.g. DOP853)"
    else:
        allowed = ENERGY_PER_RTOL * solver.rtol
        fix = ("tighten solver.rtol, limit solver.max_step (a load switched on and off within a step needs it), "
               "or choose another method (Radau or BDF for a stiff scene)")
    value = abs(energy["relative_residual"])
    if value <= allowed:
        return []
    return [{"check": "energy residual (relative)", "value": value, "allowed": allowed, "fix": fix}]
