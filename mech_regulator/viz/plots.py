"""PNG pictures of a run (matplotlib, no display needed)."""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (the backend must be chosen first)
import numpy as np  # noqa: E402

from mech_regulator.model import MachineModel  # noqa: E402
from mech_regulator.solvers import Trajectory  # noqa: E402


def plot_run(model: MachineModel, trajectory: Trajectory, summary: dict, path: Path) -> None:
    """Four panels: omega(t) with the steady band, moments against t, omega over the last dynamic
    period against the crank angle, and J(phi) with dJ/dphi (or the works of the moments)."""
    times = trajectory.samples(max(model.scene.solver.sample_rate, 2000.0 / max(trajectory.t_end, 1e-9)))
    columns = model.columns(times, trajectory(times))
    last = summary["steady"]["last_period"]
    figure, axes = plt.subplots(2, 2, figsize=(13, 8), constrained_layout=True)
    figure.suptitle(f"{model.scene.name}: {model.scene.solver.method}, {summary['status']}")

    speed = axes[0, 0]
    speed.plot(times, columns["omega"], color="tab:blue", lw=1.0, label="omega")
    if last is not None:
        speed.axhline(last["omega_m"], color="k", lw=0.8, ls="--", label=f"omega_m = {last['omega_m']:.4g} rad/s")
        speed.axhspan(last["omega_min"], last["omega_max"], color="tab:orange", alpha=0.25,
                      label=f"delta = {last['delta']:.3g}")
    for t in model.breakpoints():
        speed.axvline(t, color="tab:red", lw=0.8, ls=":")
    speed.set(xlabel="t [s]", ylabel="omega [rad/s]", title="crank speed")
    speed.legend(loc="lower right")

    moments = axes[0, 1]
    if last is not None:  # one dynamic period is readable; a whole run of an engine is a comb
        window = np.linspace(last["t_start"], last["t_end"], 1500)
        period_columns = model.columns(window, trajectory(window))
        angle = np.degrees(period_columns["phi"] - period_columns["phi"][0])
        moments.plot(angle, period_columns["M_drive"], lw=1.0, label="M_drive")
        moments.plot(angle, period_columns["M_load"], lw=1.0, label="M_load (all resisting)")
        if "M_weight" in period_columns:
            moments.plot(angle, period_columns["M_weight"], lw=1.0, label="M_weight")
        moments.legend(loc="lower right")
    moments.set(xlabel="crank angle within the last dynamic period [deg]", ylabel="reduced moment [N m]",
                title="moments on the crank")

    cycle = axes[1, 0]
    if last is not None:
        window = np.linspace(last["t_start"], last["t_end"], 1000)
        phi, omega = trajectory(window)
        cycle.plot(np.degrees(phi - phi[0]), omega, color="tab:blue")
        cycle.axhline(last["omega_max"], color="tab:orange", lw=0.8, ls="--", label="omega_max, omega_min")
        cycle.axhline(last["omega_min"], color="tab:orange", lw=0.8, ls="--")
        cycle.legend(loc="lower right")
    cycle.set(xlabel="crank angle within the last dynamic period [deg]", ylabel="omega [rad/s]",
              title="speed over the last dynamic period")

    right = axes[1, 1]
    if model.reduced is not None:
        phi = np.linspace(0.0, 2.0 * math.pi, 721)
        inertia = np.array([model.inertia(p) for p in phi])
        right.plot(np.degrees(phi), inertia[:, 0], color="tab:blue")
        right.set(xlabel="crank angle [deg]", ylabel="J(phi) [kg m^2]", title="reduced inertia and its derivative")
        slope = right.twinx()
        slope.plot(np.degrees(phi), inertia[:, 1], color="tab:red", lw=0.8)
        slope.set_ylabel("dJ/dphi [kg m^2/rad]", color="tab:red")
    else:
        works = summary["energy"]["works"]
        right.barh(list(works), list(works.values()), color="tab:green")
        right.set(xlabel="work over the run [J]", title=f"works (energy residual "
                                                         f"{summary['energy']['relative_residual']:.1g} relative)")
    figure.savefig(path, dpi=100)
    plt.close(figure)
