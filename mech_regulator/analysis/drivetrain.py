"""The drive train's part of a run's summary: the clutch's slip phases and lock times, the driven part's
stretches held at rest, and the largest torque in each branch's section against the paper's estimate.

Paper (source 003, second paper, eq. 6-7; docs/theory.md §7.4-§7.5): the torque in the section of branch n is
`M_kr = M_n,c + (I_n / i_1n) domega/dt`; behind a friction clutch with a constant reduced inertia I the
machine's main shaft accelerates at most at (beta M_nom - M_nom) / I, beta M_nom = the clutch's torque, so

    M_kr,max ~ M_n,nom + (I_n / i_1n) (beta - 1) M_nom / I,

with M_nom, M_n,nom the nominal resisting moments (here: at the speed the run ends at) and beta = the
clutch's kinetic torque / M_nom (the clutch's reserve factor). With Coulomb resistances only it is exact
while the clutch slips.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mech_regulator.analysis.energy import planned_samples, step_chunks, step_edges
from mech_regulator.model import MachineModel
from mech_regulator.model.drivetrain import HELD, STUCK
from mech_regulator.solvers import Trajectory
from mech_regulator.solvers.trajectory import EVALUATION_CHUNK


@dataclass
class SectionsSoFar:
    """The largest section torque of each branch of a drive train over a run read so far (read_sections), chunk by
    chunk: branch name -> (M_section [N m], its time [s])."""

    peaks: dict[str, tuple[float, float]] = field(default_factory=dict)


def read_sections(model: MachineModel, trajectory: Trajectory, chunk: np.ndarray, so_far: SectionsSoFar) -> None:
    """Add to so_far the branches' section torques over a chunk of solver steps (chunk: their edges [s]) at the
    planned output samples and the events after its first edge (from the run's start on the first chunk), evaluated
    EVALUATION_CHUNK times at a time (clutch_start's 4246 steps over 10 000 s are one chunk of 1e7 samples: all at
    once took 6.7 GB); a larger torque than any before (the first one on a tie, as one argmax over the run) replaces
    the branch's peak."""
    driven = model.driven
    assert driven is not None, "read_sections is for a model with a driven part"
    low, high = float(chunk[0]), float(chunk[-1])
    times = np.union1d(planned_samples(model, trajectory, low, high), [t for t, _ in trajectory.events])
    times = times[((times > low) | (times == trajectory.t_start)) & (times <= high)]
    for start in range(0, times.size, EVALUATION_CHUNK):  # a chunk of few long steps holds many samples
        part = times[start : start + EVALUATION_CHUNK]
        columns = model.columns(part, trajectory(part))
        for branch in driven.branches:
            section = columns[f"M_section_{branch.name}"]
            peak = int(np.argmax(section))
            if branch.name not in so_far.peaks or section[peak] > so_far.peaks[branch.name][0]:
                so_far.peaks[branch.name] = (float(section[peak]), float(part[peak]))


def drive_train_summary(
    model: MachineModel, trajectory: Trajectory, so_far: SectionsSoFar | None = None, steps_done: int = 0
) -> dict:
    """Slip phases [(start, end, 'slip+' | 'slip-')] and lock times [s] of a clutch, stretches [(start, end)]
    in which the driven part was held at rest, and per branch the largest section torque (value [N m], time
    [s]) with the paper's estimate (module docstring), as plain data; for a model with a drive train. The section
    torques are read chunk by chunk (step_chunks; so_far: what a streamed run read of its first steps_done solver
    steps, analysis/stream.py)."""
    driven = model.driven
    assert driven is not None, "drive_train_summary is for a model with a driven part"
    result: dict[str, Any] = {
        "held": [[start, end] for start, end, mode in _spans(model, trajectory, -1) if mode == HELD],
        "events": [[t, name] for t, name in trajectory.events if "clutch" in name or "driven part" in name],
        "clutch": None,
        "sections": {},
    }
    if model.clutch is not None:
        result["clutch"] = {
            "slip_phases": [[start, end, mode] for start, end, mode in _spans(model, trajectory, 0) if mode != STUCK],
            "lock_times": [t for t, name in trajectory.events if name.startswith("clutch locks")],
        }
    if not driven.branches:
        return result
    sections = SectionsSoFar(dict(so_far.peaks)) if so_far is not None else SectionsSoFar()
    edges = step_edges(trajectory)
    for chunk, _ in step_chunks(trajectory, edges, steps_done):
        read_sections(model, trajectory, chunk, sections)
    end = {
        name: values[-1]
        for name, values in model.columns(
            np.array([trajectory.t_end]), trajectory(np.array([trajectory.t_end]))
        ).items()
    }
    nominal = -(end["M_driven_external"] + sum(end[f"M_driven_{effect.name}"] for effect in driven.effects))
    beta = model.clutch.kinetic_torque / nominal if model.clutch is not None and nominal > 0.0 else None
    if model.clutch is not None:
        result["clutch"].update(nominal_load=nominal, beta=beta)
    for branch in driven.branches:
        branch_nominal = -branch.ratio * sum(end[f"M_driven_{driven.effects[i].name}"] for i in branch.effects)
        estimate = None
        if beta is not None:
            estimate = branch_nominal + branch.inertia / branch.ratio * (beta - 1.0) * nominal / driven.inertia
        peak, time = sections.peaks[branch.name]
        result["sections"][branch.name] = {
            "max": peak,
            "time": time,
            "nominal": float(branch_nominal),
            "paper_estimate": estimate,
        }
    return result


def _spans(model: MachineModel, trajectory: Trajectory, part: int) -> list[tuple[float, float, str]]:
    """(start, end, mode) of each stretch of the run in one mode of a drive-train part (0: the clutch, -1: the
    driven part)."""
    changes = [(t, model.train_mode_of(mode)[part]) for t, mode in trajectory.modes]
    spans: list[tuple[float, float, str]] = []
    for (start, mode), (end, _) in zip(changes, changes[1:] + [(trajectory.t_end, None)]):
        if spans and spans[-1][2] == mode:
            spans[-1] = (spans[-1][0], end, mode)
        elif end > start:
            spans.append((start, end, mode))
    return spans
