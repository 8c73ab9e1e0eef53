"""The speed benchmark's ROS measurements (bench/speed.py, ros=True): the lockstep main job on the whole engine_direct
for each exchange design and on the other governed scenes, the same co-simulation in this process with its error,
and their summary and the ROS target's measure."""

from __future__ import annotations

import functools
import json
import math
import os
import subprocess
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from mech_regulator.bench.accuracy import REFERENCE_RTOL, timed
from mech_regulator.bench.speed_runs import FAST, REFERENCE, Row, SpeedBenchmark
from mech_regulator.model import build_model
from mech_regulator.processes import command_line_child
from mech_regulator.scene import load_scene
from mech_regulator.solvers import simulate
from mech_regulator.solvers.cosim import DEFAULT_COUPLING, cosimulate

ROS_SCENE = "engine_direct"  # the whole scene (16 s), as `run` plays it
ROS_RUNS = (
    (REFERENCE, 1e-3, "hold"),
    (FAST, 1e-3, "hold"),
    (FAST, 2e-3, "waveform"),
    (FAST, 1e-2, "waveform"),
    (FAST, 1e-2, "corrected"),
    (FAST, 2e-2, "corrected"),
    (FAST, 4e-2, "corrected"),
)  # (path, exchange
# step [s], coupling: solvers.cosim); run's default (solvers.cosim.DEFAULT_EXCHANGE_STEP, DEFAULT_COUPLING) among them
ROS_OTHER_SCENES = (  # the other governed bundled scenes, at run's default only
    "engine_indirect_rigid",
    "engine_indirect_isodromic",
    "engine_indirect_none",
    "engine_hartnell",
    "engine_pi",
)


@functools.cache
def default_exchange_step(scene: str) -> float:
    """run's exchange step for a bundled scene [s]: its solver.exchange_step (solvers.cosim.DEFAULT_EXCHANGE_STEP
    unless the scene sets another)."""
    return load_scene(scene).solver.exchange_step


def failure_text(stderr: str) -> str:
    """What a failed `mech-regulator run` says of its failure, in one line: the launcher's lines naming the nodes that
    ended and how, and a fatal error's first line from the nodes' log it prints (a crash's traceback ends in the list
    of extension modules, which says nothing); else its last line."""
    lines = stderr.strip().splitlines()
    telling = [
        line.strip()
        for line in lines
        if line.startswith("mech-regulator: the ") or line.startswith("Fatal Python error")
    ]
    return "; ".join(telling) or (lines or [""])[-1]


def measure_ros(report: Callable[[Row], None]) -> list[Row]:
    """The lockstep ROS main job (`mech-regulator run`, four node processes) on the whole engine_direct, for each
    (path, exchange step, coupling) of ROS_RUNS, and on each of ROS_OTHER_SCENES at run's default (method 'nodes',
    setting the coupling): the wall time of the exchanges as the recorder measured it (from the first machine state
    to the last; the run's summary), the process's wall time with the nodes' start-up in the note; and the same
    co-simulation in this process (solvers.cosim.cosimulate, number for number what the nodes compute; method 'in
    process'): its CPU time and its achieved error, omega's largest difference from the monolithic run at
    REFERENCE_RTOL (fast path) at the exchange times, relative to max |omega| (the issue's bound is on it; the nodes'
    is the same), with the RMS difference in the note."""
    runs = [(ROS_SCENE, *run) for run in ROS_RUNS]
    runs += [(scene, FAST, default_exchange_step(scene), DEFAULT_COUPLING) for scene in ROS_OTHER_SCENES]
    rows, exact = [], {}
    with tempfile.TemporaryDirectory(prefix="mech-regulator-ros-") as folder:
        for scene, path, exchange, coupling in runs:
            settings = ["solver.path=fast"] if path == FAST else ["solver.path=reference"]
            output = os.path.join(folder, f"{scene}{path}{exchange:g}{coupling}.rrd")
            command = command_line_child(
                "run",
                scene,
                "--quiet",
                "--exchange-step",
                repr(exchange),
                "--coupling",
                coupling,
                "--out",
                output,
                *(item for setting in settings for item in ("--set", setting)),
            )
            start = time.perf_counter()
            done = subprocess.run(command, capture_output=True, text=True, check=False)
            process_wall = time.perf_counter() - start
            model = build_model(load_scene(scene, settings))
            duration = model.scene.scenario.duration
            default = (
                " (run's default)"
                if (path, exchange, coupling) == (FAST, default_exchange_step(scene), DEFAULT_COUPLING)
                else ""
            )
            row = Row(
                "ros",
                scene,
                path,
                "nodes",
                coupling,
                exchange,
                duration,
                steps=round(duration / exchange),
                note=f"process {process_wall:.3g} s with start-up{default}",
            )
            summary_path = Path(output).with_suffix(".json")
            pace = json.loads(summary_path.read_text()) if summary_path.exists() else {}
            if done.returncode != 0 or "wall_time_s" not in pace:
                row.note = f"exit {done.returncode}: {failure_text(done.stderr)}"
            else:
                row.cpu_s, row.simulated_s = pace["wall_time_s"], pace["t_end"]
            rows.append(row)
            report(row)
            run, cpu = timed(lambda: cosimulate(model, exchange, coupling=coupling))
            if scene not in exact:
                exact[scene] = simulate(
                    build_model(
                        load_scene(
                            scene,
                            [
                                "solver.path=fast",
                                f"solver.rtol={REFERENCE_RTOL!r}",
                                f"solver.atol={REFERENCE_RTOL * 1e2!r}",
                            ],
                        )
                    )
                )
            reference = exact[scene](run.times)[1]
            scale = np.max(np.abs(reference))
            largest = float(np.max(np.abs(run.states[1] - reference)) / scale)
            rms = float(np.sqrt(np.mean((run.states[1] - reference) ** 2)) / scale)
            rows.append(
                Row(
                    "ros",
                    scene,
                    path,
                    "in process",
                    coupling,
                    exchange,
                    duration,
                    cpu,
                    steps=run.times.size - 1,
                    error=largest,
                    note=f"RMS error {rms:.2g}{default}",
                )
            )
            report(rows[-1])
    return rows


def ros_summary(benchmark: SpeedBenchmark) -> list[dict[str, float | str]]:
    """Per (path, exchange step) of the ROS rows: the nodes' real-time factor over their exchanges (start-up
    excluded; missing when the run failed) and the in-process co-simulation's real-time factor (CPU) and achieved
    error."""
    found = []
    for scene, path, exchange, coupling in dict.fromkeys(
        (row.scene, row.path, row.value, row.setting) for row in benchmark.of("ros")
    ):
        item: dict[str, float | str] = {"scene": scene, "path": path, "exchange_step_s": exchange, "coupling": coupling}
        for row in benchmark.of("ros", scene=scene, path=path, value=exchange, setting=coupling):
            if row.method == "nodes" and math.isfinite(row.cpu_s):
                item["real_time_factor"] = row.simulated_s / row.cpu_s
            elif row.method == "in process":
                item.update(in_process_real_time_factor=row.simulated_s / row.cpu_s, max_error=row.error)
        item["default"] = (path, exchange, coupling) == (FAST, default_exchange_step(scene), DEFAULT_COUPLING)
        found.append(item)
    return found


def ros_target(benchmark: SpeedBenchmark) -> float:
    """The ROS target's measure: the lockstep nodes' real-time factor on the whole engine_direct at run's defaults
    (nan when not measured)."""
    for item in ros_summary(benchmark):
        if item["scene"] == ROS_SCENE and item.get("default"):
            return float(item.get("real_time_factor", math.nan))
    return math.nan
