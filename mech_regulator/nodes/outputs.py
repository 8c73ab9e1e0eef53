"""A run's files: where the main job records by default, and the files beside its recording. The launcher, the
recorder node and the command line's `run` name them alike."""

from __future__ import annotations

import time
from pathlib import Path

from mech_regulator.scene.limits import output_stem


def default_recording(scene_name: str | None) -> Path:
    """runs/<scene>-<local time>.rrd, <scene> the scene's name made safe for a file name (limits.output_stem: no
    separator, no '..', no control character), so that the run's files stay in runs/ whatever the name says."""
    return Path("runs") / f"{output_stem(scene_name)}-{time.strftime('%Y%m%d-%H%M%S')}.rrd"


def run_files(recording: Path) -> list[Path]:
    """The files of a run: its recording, then next to it the parameter file and the nodes' log (main_job writes
    them) and the summary and the CSV (the recorder writes them); `run` checks them all before the nodes start."""
    return [recording] + [recording.with_suffix(suffix) for suffix in (".params.yaml", ".log", ".json", ".csv")]
