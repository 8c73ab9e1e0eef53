"""Helpers shared by the tests: run `mech-regulator` in-process, write scene files, vary scene data, simulate a
model to the end."""

from __future__ import annotations

import copy
import math
import runpy
import sys
import types
from pathlib import Path

import pytest

from mech_regulator.cli.main import main
from mech_regulator.model import MachineModel, build_model
from mech_regulator.scene import validate_scene
from mech_regulator.solvers import Trajectory, simulate

SOURCE_TREE = Path(__file__).resolve().parents[1]


def run_cli(capsys, *argv: str) -> tuple[int, str, str]:
    """Run the command with argv; returns (exit code, stdout, stderr). A traceback is always a failure."""
    code = main(list(argv))
    captured = capsys.readouterr()
    assert "Traceback" not in captured.out + captured.err
    return code, captured.out, captured.err


def write_scene(folder: Path, text: str, name: str = "scene.yaml") -> Path:
    """Write text to folder/name (creating subfolders) and return the path."""
    path = folder / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    return path


def simulate_complete(model) -> Trajectory:
    """Simulate a model's scenario and check the run completed over its whole duration."""
    trajectory = simulate(model)
    assert trajectory.status == "complete", trajectory.message
    assert trajectory.t_end == pytest.approx(model.scene.scenario.duration, abs=1e-12)
    return trajectory


def scene(base: dict, **changes) -> dict:
    """A deep copy of base with keys replaced along '__'-separated paths, e.g. governor__damping=10."""
    result = copy.deepcopy(base)
    for key, value in changes.items():
        *path, last = key.split("__")
        target = result
        for part in path:
            target = target[part]
        target[last] = value
    return result


def model_of(data: dict) -> MachineModel:
    """The model of scene data (validated)."""
    return build_model(validate_scene(data))


def setup_arguments() -> dict:
    """The keyword arguments setup.py passes to setup(), read by running it with a stand-in of setuptools
    (it may not be installed: Python 3.12's venv has none)."""
    captured: dict = {}
    stand_in = types.ModuleType("setuptools")
    stand_in.setup = lambda **arguments: captured.update(arguments)
    stand_in.find_packages = lambda *args, **kwargs: []
    with pytest.MonkeyPatch.context() as patch:
        patch.setitem(sys.modules, "setuptools", stand_in)
        patch.chdir(SOURCE_TREE)  # its globs are relative to the source tree
        runpy.run_path(str(SOURCE_TREE / "setup.py"), run_name="__main__")
    assert captured, "setup.py did not call setup()"
    return captured


def linkage_scene_entry(linkage) -> dict:
    """The scene's `type: linkage` mechanism entry (scene.mechanism_keys.Linkage) of a mechanisms.linkage.Linkage whose frame
    is named 'frame': the inverse of mechanisms.presets.linkage_core (angles in degrees)."""

    def xy(point: complex) -> list[float]:
        return [point.real, point.imag]

    entry = {
        "type": "linkage",
        "frame": {name: xy(p) for name, p in linkage.link("frame").points.items()},
        "crank": linkage.crank,
        "links": {
            link.name: {
                "points": {name: xy(p) for name, p in link.points.items()},
                "mass": link.mass,
                "centre": xy(link.centre),
                "inertia": link.inertia,
            }
            for link in linkage.links
            if link.name != linkage.frame
        },
        "joints": {
            joint.name: {
                "type": joint.kind,
                "links": list(joint.links),
                "direction_deg": math.degrees(joint.direction),
                "slider_angle_deg": math.degrees(joint.slider_angle),
            }
            for joint in linkage.joints
        },
        "branches": dict(linkage.branches),
        "points": list(linkage.points),
    }
    if linkage.output_joint is not None:
        entry["output"] = {"joint": linkage.output_joint}
    elif linkage.output_link is not None:
        entry["output"] = {"link": linkage.output_link}
    return entry


def preset_reduced(geometry, gravity):
    """The product's reduced(phi) of a preset's geometry (crank_slider.CrankSliderGeometry, four_bar.FourBarGeometry
    or walking_beam.WalkingBeamGeometry): its linkage (mechanisms/presets.py) through the code generated from its
    groups (mechanisms/linkage/symbolic.py), what mechanisms.build_reduced runs for the scene."""
    from mech_regulator.mechanisms import crank_slider, four_bar, presets, walking_beam
    from mech_regulator.mechanisms.linkage import checked, symbolic

    build = {
        crank_slider.CrankSliderGeometry: presets.crank_slider_linkage,
        four_bar.FourBarGeometry: presets.four_bar_linkage,
        walking_beam.WalkingBeamGeometry: presets.walking_beam_linkage,
    }[type(geometry)]
    linkage = build(geometry)
    return symbolic.make_reduced(linkage, checked(linkage), gravity)


SMOOTH_GOVERNED_MACHINE = {  # constant inertia (cheap per step), a linear motor and a viscous load
    "inertia": 0.5,
    "drive": {"type": "linear_motor", "stall_torque": 200.0, "no_load_speed": 150.0},
    "loads": [{"type": "viscous", "coefficient": 0.3}],
}
SMOOTH_DIRECT_GOVERNOR = {  # a direct-action Porter governor without friction, its stops not reached
    "type": "direct",
    "ball_mass": 1.0,
    "arm_length": 0.2,
    "sleeve_mass": 5.0,
    "damping": 200.0,
    "friction": 0.0,
    "ratio": 0.16,
    "stroke": [0.02, 0.08],
    "valve": {"open_at": 0.02, "closed_at": 0.08},
}


def refused_line(code: int, out: str, err: str) -> str:
    """The one line of a refusal: exit 2, nothing on stdout (no 'wrote'), a single line on stderr."""
    assert code == 2, (code, out, err)
    assert out == "", out
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("mech-regulator: "), err
    return lines[0]
