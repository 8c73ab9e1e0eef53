"""The steady mean speed of the rigid machine whose moments read omega: where the cycle-mean drive balances the
resisting moments (docs/theory.md §3.2). The solvers' advice and the analysis both need it."""

from __future__ import annotations

from scipy import optimize

from mech_regulator.errors import SceneError
from mech_regulator.model.machine import MachineModel


def balance_speed(model: MachineModel, hint: str = "") -> float:
    """The speed [rad/s] at which the cycle-mean drive balances all resisting moments (a driven part's and the
    external load at t = 0 included): mean M_d(omega) + mean M_c(omega) = 0 (MachineModel.cycle_averages), the
    steady mean speed of the rigid machine. Bracketed by doubling from 1 rad/s, then brentq; SceneError (with
    `hint` appended) when the moments balance at no speed."""
    external = model.external_load(0.0)

    def mean_moment(omega: float) -> float:
        _, drive, other = model.cycle_averages(omega, external)
        return drive + other

    low, high = 1e-9, 1.0
    while mean_moment(high) > 0.0:
        low, high = high, 2.0 * high
        if high > 1e7:
            raise SceneError(
                f"scene '{model.scene.name}': the cycle-mean drive exceeds the resisting moments at every "
                f"speed up to 1e7 rad/s: the machine has no steady mean speed{hint}"
            )
    if mean_moment(low) <= 0.0:
        raise SceneError(
            f"scene '{model.scene.name}': the cycle-mean drive does not overcome the resisting moments "
            f"even at rest: the machine has no steady mean speed{hint}"
        )
    return optimize.brentq(mean_moment, low, high, xtol=1e-13, rtol=1e-14)
