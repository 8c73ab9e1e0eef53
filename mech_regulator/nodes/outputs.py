"""A run's files: where the main job records by default, and the files beside its recording. The launcher, the
recorder node and the command line's `run` name them alike."""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING

from mech_regulator.scene.limits import output_stem

if TYPE_CHECKING:
    from mech_regulator.model import MachineModel


def default_recording(scene_name: str | None) -> Path:
    """runs/<scene>-<local time>.rrd, <scene> the scene's name made safe for a file name (limits.output_stem: no
    separator, no '..', no control character), so that the run's files stay in runs/ whatever the name says."""
    return Path("runs") / f"{output_stem(scene_name)}-{time.strftime('%Y%m%d-%H%M%S')}.rrd"


def run_files(recording: Path) -> list[Path]:
    """The files of a run: its recording, then next to it the parameter file and the nodes' log (main_job writes
    them) and the summary and the CSV (the recorder writes them); `run` checks them all before the nodes start."""
    return [recording] + [recording.with_suffix(suffix) for suffix in (".params.yaml", ".log", ".json", ".csv")]


def write_empty_run(
    model: MachineModel,
    path: Path,
    exchange_step: float,
    message: str = "interrupted before the first complete exchange: nothing recorded yet",
    extra: dict | None = None,
) -> None:
    """The files of a run stopped before its first complete exchange: the recording at `path` with its layout and
    no samples (unless one was written already) and the summary next to it (status interrupted, samples 0, `message`
    saying when it stopped, and `extra`: what was refused, what disturbed it). Free of rclpy: the launcher writes them
    when a Ctrl-C stopped the run early, perhaps while rclpy's C extension was loading (a second import of it fails)."""
    from mech_regulator.cli.report.data import to_json
    from mech_regulator.viz.recording import RunRecording

    if not path.exists():
        RunRecording(model, path=path).close()
    summary = {
        "scene": model.scene.name,
        "status": "interrupted",
        "message": message,
        "exchange_step": exchange_step,
        "samples": 0,
        "t_end": 0.0,
        "omega_end": model.scene.scenario.initial.omega,
        "tripped_at": None,
        "governor": None,
        "recording": str(path),
        **(extra or {}),
    }
    path.with_suffix(".json").write_text(to_json(summary))
