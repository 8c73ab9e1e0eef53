"""The fast path (solvers/compiled): the generated right-hand side and guards equal the reference model's at random
states for every kernel and mode; whole runs on the fast path equal the reference path's; one module per scene
structure, loaded from numba's disk cache by a fresh process; clear refusals of what is not compiled."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest

from mech_regulator.model import LoadPiece
from mech_regulator.scene import SceneError, load_scene, validate_scene
from mech_regulator.scene.loading import read_scene_data, resolve_scene_path
from mech_regulator.solvers.compiled.codegen import (CACHE_VARIABLE, SLEEVE_CODE, compile_scene, generate,
                                                     mode_rows)
from support import model_of, run_cli, scene

RNG = np.random.default_rng(7)


def bundled(name: str) -> dict:
    """A bundled scene's data (its base resolved)."""
    return read_scene_data(resolve_scene_path(name))


# Scenes whose structures, together with the bundled ones, call every kernel.
PLAIN = {"name": "plain", "machine": {
    "inertia": 0.4,
    "drive": {"type": "table", "angle_deg": [0.0, 90.0, 200.0], "torque": [30.0, 50.0, 10.0], "period_deg": 360.0},
    "loads": [{"type": "constant", "torque": 3.0}, {"type": "viscous", "coefficient": 0.05},
              {"type": "fan", "coefficient": 1e-3},
              {"type": "table", "angle_deg": [10.0, 100.0, 150.0], "torque": [5.0, 25.0, 0.0], "period_deg": 180.0},
              {"type": "cutting", "torque": 12.0, "intervals_deg": [[20.0, 90.0], [200.0, 260.0]]}]},
    "scenario": {"initial": {"omega": 20.0}, "duration": 1.0, "external_load": 2.0}}


def four_bar_governed(feedback: dict) -> dict:
    """The four-bar rocker with rocker loads of every kind and an indirect governor with dead band, speed limit and
    sleeve friction."""
    data = bundled("four_bar_rocker")
    data["machine"]["loads"].append({"type": "rocker_constant", "torque": -0.4})
    data["governor"] = {"type": "indirect", "ball_mass": 1.0, "arm_length": 0.2, "sleeve_mass": 5.0, "damping": 100.0,
                        "friction": 2.0, "static_friction": 3.0, "ratio": 0.8, "stroke": [0.02, 0.08],
                        "pilot_neutral": 0.05, "servo": {"gain": 100.0, "max_speed": 2.0, "dead_band": 0.002,
                                                         "travel": [0.0, 1.0]}, "feedback": feedback}
    data["scenario"]["initial"] = {"omega": 70.0}
    return data


def compressor_direct() -> dict:
    """The compressor with every slider load and a direct governor on a table valve, with sleeve friction."""
    data = bundled("compressor")
    data["machine"]["loads"].append({"type": "slider_constant", "force": -40.0})
    data["governor"] = {"type": "direct", "ball_mass": 1.0, "arm_length": 0.2, "sleeve_mass": 5.0, "damping": 200.0,
                        "friction": 2.0, "ratio": 0.8, "stroke": [0.02, 0.08],
                        "valve": {"type": "table", "sleeve": [0.02, 0.05, 0.08], "throttle": [1.0, 0.6, 0.0]}}
    data["scenario"]["initial"] = {"omega": 120.0}
    return data


def driven_four_bar() -> dict:
    """two_mass with a four-bar, weighing links and rocker loads on the driven part and a Coulomb resistance."""
    data = bundled("two_mass")
    mechanism = {key: value for key, value in bundled("four_bar_rocker")["machine"]["mechanism"].items()}
    data["machine"]["gravity"] = [0.0, -9.81]
    data["machine"]["coupling"]["driven"] = {
        "inertia": 0.1, "mechanism": mechanism,
        "loads": [{"type": "fan", "coefficient": 2.56e-4}, {"type": "constant", "torque": 1.5},
                  {"type": "rocker_viscous", "coefficient": 0.05}, {"type": "rocker_spring", "stiffness": 5.0,
                                                                    "free_position": 1.6},
                  {"type": "table", "angle_deg": [0.0, 180.0], "torque": [0.0, 2.0]}]}
    return data


SLEEVE_MODES = list(SLEEVE_CODE)


def governor_modes(model) -> list:
    """Every (sleeve, servo) mode of a governed model (servo '' for a direct governor)."""
    servo = ["free", "low", "high"] if model.governor.kind == "indirect" else [""]
    return [(sleeve, s) for sleeve in SLEEVE_MODES for s in servo]


def random_state(model) -> np.ndarray:
    """A state near the scene's initial one: phi anywhere, speeds and governor states perturbed."""
    y = model.initial_state().astype(float)
    y[0] = RNG.uniform(-20.0, 20.0)
    y[1] = y[1] * RNG.uniform(0.8, 1.2) + RNG.uniform(-5.0, 5.0)
    if model.governor is not None:
        y[2] += RNG.uniform(-0.1, 0.1)
        y[3] = RNG.uniform(-2.0, 2.0)
        for index in range(4, 2 + len(model.governor.state_names)):
            y[index] = RNG.uniform(0.0, 1.0) if index == 4 else RNG.uniform(-0.01, 0.01)
    if model.coupling is not None:
        y[model.coupling_index] = RNG.uniform(-0.15, 0.15)
        y[model.driven_speed_index] = y[1] * RNG.uniform(0.5, 1.5)
    return y


def assert_same_rhs(model, modes, states: int = 6, window=None, piece=None):
    """Compiled rhs and guards equal model.rhs / model.guards (1e-12 relative) at random states in every mode."""
    compiled = compile_scene(model)
    n = len(model.state_names())
    for mode in modes:
        for _ in range(states):
            y = random_state(model)
            t = RNG.uniform(0.0, 5.0)
            chosen = piece or LoadPiece(0.0, 10.0, RNG.uniform(0.0, 8.0), RNG.uniform(-1.0, 1.0))
            if model.coupling is not None:  # the driven part's guards read the scenario's load at t
                chosen = model.piece_at(t)
            if window is not None:
                y[0] = RNG.uniform(*window)
            p = compiled.parameters_for(chosen, mode, window)
            expected = np.array(model.rhs(chosen, window, mode)(t, y), dtype=float)
            got = np.zeros(n)
            compiled.rhs(t, y, p, got)
            np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12 * np.max(np.abs(expected)))
            levels = np.zeros(compiled.n_guards)
            compiled.guards(t, y, p, levels)
            reference = [guard.level(t, y) for guard in model.guards(mode, y)]
            count = len(reference)
            np.testing.assert_allclose(levels[:count], reference, rtol=1e-12, atol=1e-12)
            window_guards = 2 if compiled.window_slot is not None else 0
            assert np.all(np.isinf(levels[count:compiled.n_guards - window_guards]))
            rows = mode_rows(model, mode)  # linear rows reproduce the levels of the guards they claim
            assert len(rows) == count
            for row, level in zip(rows, reference):
                if row is not None:
                    assert row[1] + row[2:] @ y == pytest.approx(level, rel=1e-12, abs=1e-12)


def test_plain_kernels_equal_reference_in_and_out_of_a_switch_window():
    model = model_of(PLAIN)
    assert_same_rhs(model, [None], states=20, window=(0.4, 1.5))
    compiled = compile_scene(model)
    y, p = np.array([1.0, 20.0]), compiled.parameters_for(None, None, (0.4, 1.5))
    levels = np.zeros(compiled.n_guards)
    compiled.guards(0.0, y, p, levels)
    assert levels.tolist() == pytest.approx([1.0 - 0.4, 1.5 - 1.0])  # phi - lo, hi - phi
    assert compiled.linear(None, (0.4, 1.5))[:, :4].tolist() == [[1.0, -0.4, 1.0, 0.0], [1.0, 1.5, -1.0, 0.0]]
    # a held throttle (co-simulation) scales the drive only
    piece = LoadPiece(0.0, 1.0, 2.0, 0.0, throttle=0.6)
    assert_same_rhs(model, [None], states=3, window=(0.4, 1.5), piece=piece)


@pytest.mark.parametrize("name", ["startup", "lathe", "compressor", "four_bar_rocker", "engine"])
def test_bundled_machines_equal_reference(name):
    model = model_of(bundled(name))
    grid = model.switch_grid()
    window = (grid[0], grid[1]) if grid else None
    assert_same_rhs(model, [None], window=window)


@pytest.mark.parametrize("gravity", [[0.0, -9.81], None])
def test_mechanisms_with_and_without_weight_equal_reference(gravity):
    for data in (compressor_direct(), four_bar_governed({"type": "isodromic", "gain": 0.3, "time_constant": 1.5})):
        data["machine"]["gravity"] = gravity
        model = model_of(data)
        assert model.has_weight == (gravity is not None)
        assert_same_rhs(model, governor_modes(model), states=3)


@pytest.mark.parametrize("feedback", [{"type": "none"}, {"type": "rigid", "gain": 0.12},
                                      {"type": "isodromic", "gain": 0.3, "time_constant": 1.5}])
def test_indirect_governor_every_feedback_and_mode(feedback):
    model = model_of(four_bar_governed(feedback))
    assert_same_rhs(model, governor_modes(model), states=3)


@pytest.mark.parametrize("name", ["engine_direct", "engine_indirect_rigid"])
def test_engine_governors_every_mode(name):
    model = model_of(bundled(name))
    assert_same_rhs(model, governor_modes(model), states=3)


@pytest.mark.parametrize("data", [bundled("two_mass"), bundled("press_coupling"), driven_four_bar()],
                         ids=["linear", "table", "driven_four_bar"])
def test_coupling_in_every_driven_mode(data):
    model = model_of(data)
    assert_same_rhs(model, [("forward",), ("backward",), ("held",)], states=5)


def test_source_depends_on_structure_not_numbers():
    base = bundled("engine_indirect_isodromic")
    other = scene(base, machine__flywheel__inertia=0.5, governor__damping=50.0, scenario__external_load=0.0)
    other["machine"]["drive"]["pressure"] = other["machine"]["drive"]["pressure"][:20]
    other["machine"]["drive"]["angle_deg"] = other["machine"]["drive"]["angle_deg"][:20]
    first, second = compile_scene(model_of(base)), compile_scene(model_of(other))
    assert first.source == second.source and first.path == second.path
    assert first.rhs is second.rhs  # one module, compiled once
    assert first.parameters.size != second.parameters.size
    changed = scene(base, governor__feedback={"type": "rigid", "gain": 0.12})
    assert generate(model_of(changed))[0] != first.source


def test_only_the_scene_s_kernels_are_called():
    startup = generate(model_of(bundled("startup")))[0]
    assert "reduced" not in startup and "sleeve" not in startup and "clamped" not in startup
    assert "k.linear_motor" in startup and "k.viscous_load" in startup
    lathe = generate(model_of(bundled("lathe")))[0]
    assert "k.cutting_load(clamped" in lathe and "linear_motor" not in lathe


def test_cache_folder_that_cannot_be_made(tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("")
    monkeypatch.setenv(CACHE_VARIABLE, str(blocker / "cache"))
    model = model_of(scene(PLAIN, machine__inertia=0.123))
    with pytest.raises(SceneError, match=CACHE_VARIABLE):
        compile_scene(model)


def test_a_fresh_process_loads_the_compiled_scene_from_numba_s_cache():
    model = model_of(bundled("startup"))
    compiled = compile_scene(model)
    files = set(os.listdir(compiled.path.parent / "__pycache__"))
    script = ("import json\nfrom mech_regulator.model import build_model\nfrom mech_regulator.scene import load_scene\n"
              "from mech_regulator.solvers.compiled.codegen import compile_scene\n"
              "c = compile_scene(build_model(load_scene('startup')))\n"
              "print(json.dumps([sum(c.rhs.stats.cache_hits.values()), sum(c.rhs.stats.cache_misses.values()), "
              "sum(c.guards.stats.cache_hits.values())]))\n")
    environment = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    output = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True,
                            env=environment).stdout
    assert json.loads(output.splitlines()[-1]) == [1, 0, 1]
    assert set(os.listdir(compiled.path.parent / "__pycache__")) == files  # nothing compiled anew


def test_refusals_name_the_key():
    from mech_regulator.solvers.compiled.run import fast_path_refusal

    cases = {"clutch_start": "machine.clutch", "compressor_friction": "machine.joint_friction",
             "engine_inline4": "machine.mechanism.cylinders", "walking_beam": "machine.mechanism: walking_beam"}
    for name, key in cases.items():
        reason = fast_path_refusal(load_scene(name, ["solver.path=fast"]))
        assert reason.startswith(f"solver.path: 'fast' does not compile {key}"), reason
    branched = bundled("two_mass")
    branched["machine"]["coupling"]["driven"]["branches"] = [{"name": "pump", "inertia": 0.01, "ratio": 2.0}]
    assert "machine.coupling.driven.branches" in fast_path_refusal(validate_scene(branched))
    assert "solver.method: 'Radau'" in fast_path_refusal(load_scene("startup", ["solver.method=Radau"]))
    assert "solver.method: 'energy'" in fast_path_refusal(load_scene("lathe", ["solver.method=energy"]))
    assert fast_path_refusal(load_scene("two_mass")) is None
    with pytest.raises(SceneError, match="Rosenbrock23' runs only on the compiled fast path"):
        load_scene("startup", ["solver.method=Rosenbrock23"])


@pytest.mark.parametrize("name, overrides, expected", [
    ("clutch_start", [], "does not compile machine.clutch yet"),
    ("startup", ["solver.method=BDF"], "does not run solver.method: 'BDF'"),
    ("startup", ["solver.method=Rosenbrock23", "solver.path=reference"], "runs only on the compiled fast path")])
def test_cli_refusals_exit_2(capsys, name, overrides, expected):
    sets = [item for override in ["solver.path=fast"] + overrides for item in ("--set", override)]
    code, _, err = run_cli(capsys, "simulate", name, "--quiet", *sets)
    assert code == 2 and expected in err
