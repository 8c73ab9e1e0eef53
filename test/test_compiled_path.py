"""The fast path (solvers/compiled): the generated right-hand side and guards equal the reference model's at random
states for every kernel and mode; whole runs on the fast path equal the reference path's; one module per scene
structure, loaded from numba's disk cache by a fresh process; clear refusals of what is not compiled."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys

import numpy as np
import pytest
from support import model_of, run_cli, scene, simulate_complete

from mech_regulator.bench.effect_cost import BASE_SCENE, EFFECT_CHAIN, SCENARIO
from mech_regulator.cache import CACHE_VARIABLE
from mech_regulator.governors.mechanical import SLEEVE_CODE
from mech_regulator.model import LoadPiece, build_model
from mech_regulator.scene import SceneError, load_scene
from mech_regulator.scene.loading import read_scene_data, resolve_scene_path
from mech_regulator.solvers import simulate
from mech_regulator.solvers.compiled import fast_path_refusal, runs_compiled
from mech_regulator.solvers.compiled.codegen import compile_scene, generate, mode_rows
from mech_regulator.solvers.compiled.run import MAX_STEPS_PER_CALL

RNG = np.random.default_rng(7)


def bundled(name: str) -> dict:
    """A bundled scene's data (its base resolved)."""
    return read_scene_data(resolve_scene_path(name))


# Scenes whose structures, together with the bundled ones, call every kernel.
PLAIN = {
    "name": "plain",
    "machine": {
        "inertia": 0.4,
        "drive": {"type": "table", "angle_deg": [0.0, 90.0, 200.0], "torque": [30.0, 50.0, 10.0], "period_deg": 360.0},
        "loads": [
            {"type": "constant", "torque": 3.0},
            {"type": "viscous", "coefficient": 0.05},
            {"type": "fan", "coefficient": 1e-3},
            {"type": "table", "angle_deg": [10.0, 100.0, 150.0], "torque": [5.0, 25.0, 0.0], "period_deg": 180.0},
            {"type": "cutting", "torque": 12.0, "intervals_deg": [[20.0, 90.0], [200.0, 260.0]]},
        ],
    },
    "scenario": {"initial": {"omega": 20.0}, "duration": 1.0, "external_load": 2.0},
}


def four_bar_governed(feedback: dict) -> dict:
    """The four-bar rocker with rocker loads of every kind and an indirect governor with dead band, speed limit and
    sleeve friction."""
    data = bundled("four_bar_rocker")
    data["machine"]["loads"].append({"type": "rocker_constant", "torque": -0.4})
    data["governor"] = {
        "type": "indirect",
        "ball_mass": 1.0,
        "arm_length": 0.2,
        "sleeve_mass": 5.0,
        "damping": 100.0,
        "friction": 2.0,
        "static_friction": 3.0,
        "ratio": 0.8,
        "stroke": [0.02, 0.08],
        "pilot_neutral": 0.05,
        "servo": {"gain": 100.0, "max_speed": 2.0, "dead_band": 0.002, "travel": [0.0, 1.0]},
        "feedback": feedback,
    }
    data["scenario"]["initial"] = {"omega": 70.0}
    return data


def compressor_direct() -> dict:
    """The compressor with every slider load and a direct governor on a table valve, with sleeve friction."""
    data = bundled("compressor")
    data["machine"]["loads"].append({"type": "slider_constant", "force": -40.0})
    data["governor"] = {
        "type": "direct",
        "ball_mass": 1.0,
        "arm_length": 0.2,
        "sleeve_mass": 5.0,
        "damping": 200.0,
        "friction": 2.0,
        "ratio": 0.8,
        "stroke": [0.02, 0.08],
        "valve": {"type": "table", "sleeve": [0.02, 0.05, 0.08], "throttle": [1.0, 0.6, 0.0]},
    }
    data["scenario"]["initial"] = {"omega": 120.0}
    return data


def driven_four_bar() -> dict:
    """two_mass with a four-bar, weighing links and rocker loads on the driven part and a Coulomb resistance."""
    data = bundled("two_mass")
    mechanism = {key: value for key, value in bundled("four_bar_rocker")["machine"]["mechanism"].items()}
    data["machine"]["gravity"] = [0.0, -9.81]
    data["machine"]["coupling"]["driven"] = {
        "inertia": 0.1,
        "mechanism": mechanism,
        "loads": [
            {"type": "fan", "coefficient": 2.56e-4},
            {"type": "constant", "torque": 1.5},
            {"type": "rocker_viscous", "coefficient": 0.05},
            {"type": "rocker_spring", "stiffness": 5.0, "free_position": 1.6},
            {"type": "table", "angle_deg": [0.0, 180.0], "torque": [0.0, 2.0]},
        ],
    }
    return data


SLEEVE_MODES = [mode for mode in SLEEVE_CODE if mode]  # '' is a PI governor's, which has no sleeve


def governor_modes(model) -> list:
    """Every (sleeve, servo) mode of a governed model (servo '' for a direct governor; a PI governor's one mode)."""
    if model.governor.kind == "pi":
        return [("", "")]
    servo = ["free", "low", "high"] if model.governor.kind == "indirect" else [""]
    return [(sleeve, s) for sleeve in SLEEVE_MODES for s in servo]


def random_state(model) -> np.ndarray:
    """A state near the scene's initial one: phi anywhere, speeds and governor states perturbed."""
    y = model.initial_state().astype(float)
    y[0] = RNG.uniform(-20.0, 20.0)
    y[1] = y[1] * RNG.uniform(0.8, 1.2) + RNG.uniform(-5.0, 5.0)
    if model.governor is not None and model.governor.kind == "pi":  # its integral part, on and off the valve's stops
        y[2] = RNG.uniform(-0.5, 1.5)
    elif model.governor is not None:
        y[2] += RNG.uniform(-0.1, 0.1)
        y[3] = RNG.uniform(-2.0, 2.0)
        for index in range(4, 2 + len(model.governor.state_names)):
            y[index] = RNG.uniform(0.0, 1.0) if index == 4 else RNG.uniform(-0.01, 0.01)
    if model.coupling is not None:
        y[model.coupling_index] = RNG.uniform(-0.15, 0.15)
    if model.driven is not None:
        y[model.driven_speed_index] = y[1] * RNG.uniform(0.5, 1.5)
    return y


def assert_same_rhs(model, modes, states: int = 6, window=None, piece=None, speed=None):
    """Compiled rhs and guards equal model.rhs / model.guards (1e-12 relative) at random states in every mode
    (speed: the crank's omega in all of them)."""
    compiled = compile_scene(model)
    n = len(model.state_names())
    for mode in modes:
        for _ in range(states):
            y = random_state(model)
            t = RNG.uniform(0.0, 5.0)
            chosen = piece or LoadPiece(0.0, 10.0, RNG.uniform(0.0, 8.0), RNG.uniform(-1.0, 1.0))
            if model.driven is not None:  # the driven part's guards read the scenario's load at t
                chosen = model.piece_at(t)
            if window is not None:
                y[0] = RNG.uniform(*window)
            if speed is not None:
                y[1] = speed
            p = compiled.parameters_for(chosen, mode, window, y[1])
            expected = np.array(model.rhs(chosen, window, mode)(t, y), dtype=float)
            if model.constraint(mode) is not None:  # a stuck clutch: omega2 follows omega (train_source.clutch_lines)
                expected[model.driven_speed_index] = expected[1]
            got = np.zeros(n)
            compiled.rhs(t, y, p, got)
            np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12 * np.max(np.abs(expected)))
            levels = np.zeros(compiled.n_guards)
            compiled.guards(t, y, p, levels)
            reference = [guard.level(t, y) for guard in model.guards(mode, y)]
            count = len(reference)
            np.testing.assert_allclose(levels[:count], reference, rtol=1e-12, atol=1e-12)
            window_guards = 2 if compiled.window_slot is not None else 0
            normals = range(compiled.normal_slot or 0, (compiled.normal_slot or 0) + compiled.n_normals)
            for k, slot in enumerate(normals):  # a guide's guard reads its N while its held sign is 0 (hold_normal)
                normal = model.guide_normal(chosen, window, mode, guide=k)(t, y)
                assert levels[slot] == pytest.approx(normal, rel=1e-12, abs=1e-12 * (1.0 + abs(normal)))
            unused = [slot for slot in range(count, compiled.n_guards - window_guards) if slot not in normals]
            assert np.all(np.isinf(levels[unused]))
            rows = mode_rows(model, mode, y[1])  # linear rows reproduce the levels of the guards they claim
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
    # linear rows, flagged STEP_ONTO (2): a switch's state comes from a step onto it
    assert compiled.linear(None, (0.4, 1.5))[:, :4].tolist() == [[2.0, -0.4, 1.0, 0.0], [2.0, 1.5, -1.0, 0.0]]
    # a held throttle (co-simulation) scales the drive only
    piece = LoadPiece(0.0, 1.0, 2.0, 0.0, throttle=0.6)
    assert_same_rhs(model, [None], states=3, window=(0.4, 1.5), piece=piece)
    # the corrected coupling's throttle with the speed's action (a PI governor's command, clipped to its stops): on
    # the high stop at 200 rad/s, within the travel at 230 rad/s (docs/ros.md, "The throttle's sensitivity to the speed")
    commanded = LoadPiece(
        0.0, 10.0, 2.0, 0.0, 3.6, 0.01, -0.002, throttle_per_speed=-3.0 / 224.0, throttle_low=0.1, throttle_high=0.9
    )
    for speed, throttle in ((200.0, 0.9), (230.0, 3.6 - 230.0 * 3.0 / 224.0)):
        assert commanded.throttle_at(0.0, speed) == pytest.approx(throttle, abs=1e-12)
        assert_same_rhs(model, [None], states=3, window=(0.4, 1.5), piece=commanded, speed=speed)


@pytest.mark.parametrize(
    "name", ["startup", "lathe", "compressor", "four_bar_rocker", "engine", "engine_inline4", "walking_beam"]
)
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


def v_twin(name: str) -> dict:
    """A bundled single-cylinder engine scene made a 90 deg V-twin on one throw (cylinder 2's axis at 90 deg, so its
    gravity is turned), with offset, every mass, gravity with both components and a firing delay of 450 deg."""
    data = bundled(name)
    data["machine"]["gravity"] = [1.5, -9.81]
    data["machine"]["mechanism"].update(
        offset=0.006,
        crank_mass=1.2,
        crank_cg=0.01,
        cylinders=[{"throw_deg": 0.0}, {"throw_deg": 0.0, "bank_deg": 90.0}],
    )
    data["machine"]["drive"].update(firing_deg=[0.0, 450.0], phase_deg=30.0)
    return data


def driven_inline4() -> dict:
    """two_mass with engine_inline4's four-cylinder crankshaft (weighing) as the driven part's mechanism."""
    data = bundled("two_mass")
    data["machine"]["gravity"] = [0.0, -9.81]
    data["machine"]["coupling"]["driven"]["mechanism"] = bundled("engine_inline4")["machine"]["mechanism"]
    return data


def driven_walking_beam() -> dict:
    """two_mass with the bundled walking beam (weighing links) on the driven part, with shuttle loads of every kind."""
    data = bundled("two_mass")
    data["machine"]["gravity"] = [0.0, -9.81]
    data["machine"]["coupling"]["driven"]["mechanism"] = bundled("walking_beam")["machine"]["mechanism"]
    data["machine"]["coupling"]["driven"]["loads"] += [
        {"type": "shuttle_viscous", "coefficient": 150.0},
        {"type": "shuttle_constant", "force": -20.0},
        {"type": "shuttle_spring", "stiffness": 400.0, "free_position": 0.1},
    ]
    return data


def test_walking_beam_on_the_crank_and_behind_a_coupling_equals_reference():
    """The eight-bar's reduced inertia, its derivative, the weight of all seven links and the shuttle's x_C, x_C'
    (shuttle loads); on the crank with gravity along both axes, and as a coupled driven part."""
    data = bundled("walking_beam")
    data["machine"]["gravity"] = [2.0, -9.81]
    data["machine"]["loads"].append({"type": "shuttle_spring", "stiffness": 300.0, "free_position": 0.05})
    model = model_of(data)
    assert model.has_weight
    assert_same_rhs(model, [None], states=12)
    driven = model_of(driven_walking_beam())
    assert_same_rhs(driven, [("forward",), ("backward",), ("held",)], states=4)
    assert re.search(r"= linkage_reduced_\w+\(phi2, p, ", compile_scene(driven).source)


CLUTCH_MODES = [(clutch, part) for clutch in ("stuck", "slip+", "slip-") for part in ("forward", "backward", "held")]


def branched(driven: dict) -> dict:
    """A driven part with clutch_start's two branches (constant and fan loads on their shafts) added."""
    return {**driven, "branches": bundled("clutch_start")["machine"]["clutch"]["driven"]["branches"]}


def governed_clutch() -> dict:
    """engine_direct's governed engine driving clutch_start's branched machine through its clutch, with a viscous
    and a fan load on the main shaft."""
    data = bundled("engine_direct")
    data["machine"]["clutch"] = {
        "static_torque": 40.0,
        "kinetic_torque": 32.0,
        "driven": branched(
            {
                "inertia": 0.1,
                "loads": [
                    {"type": "constant", "torque": 2.0},
                    {"type": "viscous", "coefficient": 0.01},
                    {"type": "fan", "coefficient": 1e-4},
                ],
            }
        ),
    }
    return data


def test_clutch_and_branches_equal_reference():
    """The friction clutch in its nine train modes (stuck, slipping either way; driven part forward, backward,
    held) with its stick and slip guards, branches reduced to the main shaft (I_n / i^2, M_n(omega / i) / i) behind
    a clutch and behind a coupling, under a governor in every mode and without."""
    model = model_of(bundled("clutch_start"))
    assert_same_rhs(model, CLUTCH_MODES, states=6)
    governed = model_of(governed_clutch())
    assert_same_rhs(governed, [g + train for g in governor_modes(governed) for train in CLUTCH_MODES], states=1)
    coupled = bundled("two_mass")
    coupled["machine"]["coupling"]["driven"] = branched(coupled["machine"]["coupling"]["driven"])
    model = model_of(coupled)
    assert len(model.driven.branches) == 2
    assert_same_rhs(model, [("forward",), ("backward",), ("held",)], states=5)
    slip = compile_scene(model_of(bundled("clutch_start"))).linear(("slip-", "forward"), None)
    assert slip[0, :5].tolist() == [1.0, 0.0, 0.0, -1.0, 1.0]  # -(omega - omega2), located exactly


def test_multi_cylinder_engines_equal_reference():
    """Every cylinder's kinematics at its own crank angle, with its gravity turned into its frame, and the gas
    moments of every cylinder with its firing delay; behind a coupling too."""
    model = model_of(v_twin("engine_direct"))  # governed
    assert model.has_weight and len(model.reduced(0.3)[4]) == 2
    assert_same_rhs(model, governor_modes(model), states=3)
    source = compile_scene(model).source
    assert re.search(r"total, q, dq, q_2, dq_2 = linkage_reduced_\w+\(phi, ", source)  # one call, both pistons
    assert source.count("drives_engine_gas(") == 2
    driven = model_of(driven_inline4())
    assert_same_rhs(driven, [("forward",), ("backward",), ("held",)], states=4)
    assert len(re.findall(r"q2_4, dq2_4 = linkage_reduced_\w+\(phi2, ", compile_scene(driven).source)) == 2


JOURNALS = {
    "crank_bearing": {"radius": 0.02, "fit": "run_in"},
    "crank_pin": {"radius": 0.015},
    "rocker_pin": {"radius": 0.01, "fit": "new"},
    "rocker_bearing": {"radius": 0.012},
}
COLLAR = {"inner_radius": 0.02, "outer_radius": 0.035, "axial_load": 200.0, "state": "new"}


def with_joint_friction(data: dict, journals: list[str], guide: float = 0.0, collar: bool = True) -> dict:
    """Scene data with joint friction (f = 0.08) in the named journals, the guide and a thrust collar."""
    data["machine"]["joint_friction"] = {
        "coefficient": 0.08,
        "joints": {name: JOURNALS[name] for name in journals},
        "guide": guide,
        **({"thrust_collar": COLLAR} if collar else {}),
    }
    return data


def crank_at_rest(torque: float) -> dict:
    """test_joint_friction's crank–slider at rest in gravity, held by its crank bearing and collar (F(0) = 3 +
    0.1 / sqrt(1.01) 0.03 30 9.81 = 3.878 N m) or not, under a constant drive [N m]."""
    return {
        "machine": {
            "inertia": 0.2,
            "gravity": [0.0, -9.81],
            "drive": {"type": "constant", "torque": torque},
            "mechanism": {"type": "crank_slider", "crank": 0.05, "rod": 0.2, "crank_mass": 30.0, "slider_mass": 2.0},
            "joint_friction": {
                "coefficient": 0.1,
                "joints": {"crank_bearing": {"radius": 0.03}},
                "thrust_collar": {"inner_radius": 0.02, "outer_radius": 0.04, "axial_load": 1000.0},
            },
        },
        "scenario": {"initial": {"phi": 0.0, "omega": 0.0}, "duration": 0.5},
        "solver": {},
    }


@pytest.mark.parametrize("speed", [None, 0.0], ids=["turning", "at_rest"])
def test_joint_friction_equals_reference(speed):
    """The implicit epsilon of J epsilon = J epsilon_0 - sign(omega) F(epsilon) with the reactions of the
    kinetostatics at the output force of every load kind (crank–slider with guide, four-bar under an indirect
    governor that scales the drive's force, behind a coupling) or a collar alone (walking beam: no kinetostatics),
    turning and at rest (held while |M| <= F(0), else breaking away), and the crank's guard."""
    slider = with_joint_friction(compressor_direct(), ["crank_bearing", "crank_pin"], guide=0.05)
    four_bar = with_joint_friction(four_bar_governed({"type": "rigid", "gain": 0.12}), list(JOURNALS))
    coupled = with_joint_friction(bundled("two_mass"), ["crank_pin"], guide=0.1, collar=False)  # the gas force
    for data in (bundled("compressor_friction"), slider, four_bar, coupled):
        model = model_of(data)
        modes = governor_modes(model) if model.governor is not None else [None]
        if model.coupling is not None:
            modes = [("forward",), ("backward",), ("held",)]
        assert_same_rhs(model, modes, states=3, speed=speed)
    collar_only = model_of(with_joint_friction(bundled("walking_beam"), [], collar=True))
    assert "joint_loads" not in compile_scene(collar_only).source
    assert_same_rhs(collar_only, [None], states=4, speed=speed)
    at_rest = 3.0 + 0.1 / np.sqrt(1.01) * 0.03 * 30.0 * 9.81
    held, moving = model_of(crank_at_rest(0.9 * at_rest)), model_of(crank_at_rest(1.1 * at_rest))
    for model, expected in ((held, 0.0), (moving, 0.1 * at_rest / 0.2)):
        compiled, y = compile_scene(model), np.zeros(2)
        rates = np.zeros(2)
        compiled.rhs(0.0, y, compiled.parameters_for(None, None, None), rates)
        assert rates[1] == pytest.approx(model.rhs()(0.0, y)[1], rel=1e-12, abs=0.0)
        assert rates[1] == pytest.approx(expected, rel=1e-9, abs=0.0)
    # the crank's guard follows the sign of omega at the segment's start: 'crank starts' (-|omega|) from rest,
    # 'crank stops' (s omega) when turning, as model.guards(mode, y); only the latter is linear in the state
    levels, compiled = np.zeros(1), compile_scene(held)
    for start, state, level in (
        (0.0, 1e-6, -1e-6),
        (0.0, -2.0, -2.0),
        (3.0, 2.0, 2.0),
        (3.0, -1.0, -1.0),
        (-3.0, 2.0, -2.0),
    ):
        compiled.guards(0.0, np.array([0.0, state]), compiled.parameters_for(None, None, None, start), levels)
        (guard,) = held.guards(None, np.array([0.0, start]))
        assert levels[0] == level == guard.level(0.0, np.array([0.0, state]))
        rows = mode_rows(held, None, start)
        assert (rows[0] is None) == (start == 0.0)


@pytest.mark.parametrize(
    "feedback",
    [{"type": "none"}, {"type": "rigid", "gain": 0.12}, {"type": "isodromic", "gain": 0.3, "time_constant": 1.5}],
)
def test_indirect_governor_every_feedback_and_mode(feedback):
    model = model_of(four_bar_governed(feedback))
    assert_same_rhs(model, governor_modes(model), states=3)


@pytest.mark.parametrize("name", ["engine_direct", "engine_indirect_rigid", "engine_hartnell", "engine_pi"])
def test_engine_governors_every_mode(name):
    model = model_of(bundled(name))
    assert_same_rhs(model, governor_modes(model), states=3)


@pytest.mark.parametrize(
    "data",
    [bundled("two_mass"), bundled("press_coupling"), driven_four_bar()],
    ids=["linear", "table", "driven_four_bar"],
)
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
    assert "drives_linear_motor(" in startup and "loads_viscous_load(" in startup
    lathe = generate(model_of(bundled("lathe")))[0]
    assert "loads_cutting_load(k.inside_intervals(clamped" in lathe and "linear_motor" not in lathe


def test_cache_folder_that_cannot_be_made(tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("")
    monkeypatch.setenv(CACHE_VARIABLE, str(blocker / "cache"))
    model = model_of(scene(PLAIN, machine__inertia=0.123))
    with pytest.raises(SceneError, match=CACHE_VARIABLE):
        compile_scene(model)


def scene_cache_folder(compiled) -> str:
    """Where numba keeps the compiled scene's cache: the module's `__pycache__`, or a folder under NUMBA_CACHE_DIR
    when that is set (numba's own locator, read off the dispatcher)."""
    return compiled.rhs._cache.cache_path


def scene_cache_files(compiled) -> set[str]:
    """The files of numba's cache for a compiled scene module (its stem's): other processes (another test worker,
    another checkout's tests) add their own modules' files to the same folder meanwhile."""
    return {name for name in os.listdir(scene_cache_folder(compiled)) if name.startswith(compiled.path.stem)}


def test_a_fresh_process_loads_the_compiled_scene_from_numba_s_cache():
    model = model_of(bundled("startup"))
    compiled = compile_scene(model)
    files = scene_cache_files(compiled)
    assert files, sorted(os.listdir(scene_cache_folder(compiled)))
    script = (
        "import json\nfrom mech_regulator.model import build_model\nfrom mech_regulator.scene import load_scene\n"
        "from mech_regulator.solvers.compiled.codegen import compile_scene\n"
        "c = compile_scene(build_model(load_scene('startup')))\n"
        "print(json.dumps([sum(c.rhs.stats.cache_hits.values()), sum(c.rhs.stats.cache_misses.values()), "
        "sum(c.guards.stats.cache_hits.values())]))\nprint(c.path)\n"
    )
    environment = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    output = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, check=True, env=environment
    ).stdout
    counts, path = output.splitlines()[-2:]
    assert (json.loads(counts), path) == ([1, 0, 1], str(compiled.path)), sorted(os.listdir(compiled.path.parent))
    assert scene_cache_files(compiled) == files  # nothing compiled anew


def test_refusals_name_the_key():
    """Every machine compiles (multi-cylinder engines, walking beams, joint friction, clutches and branches were
    the last refused); solver methods without a compiled stepper are refused by name."""
    assert "solver.method: 'Radau'" in fast_path_refusal(load_scene("startup", ["solver.method=Radau"]))
    assert "solver.method: 'energy'" in fast_path_refusal(load_scene("lathe", ["solver.method=energy"]))
    for name in ("two_mass", "engine_inline4", "walking_beam", "compressor_friction", "clutch_start"):
        assert fast_path_refusal(load_scene(name)) is None
    with pytest.raises(SceneError, match="Rosenbrock23' runs only on the compiled fast path"):
        load_scene("startup", ["solver.method=Rosenbrock23", "solver.path=reference"])
    assert runs_compiled(load_scene("startup", ["solver.method=Rosenbrock23"]).solver)  # solver.path auto
    assert not runs_compiled(load_scene("startup").solver)  # auto is the reference path in the core


@pytest.mark.parametrize(
    "name, overrides, expected",
    [
        ("clutch_start", ["solver.method=LSODA"], "does not run solver.method: 'LSODA'"),
        ("startup", ["solver.method=BDF"], "does not run solver.method: 'BDF'"),
    ],
)
def test_cli_falls_back_to_the_reference_path_with_a_note(capsys, name, overrides, expected):
    sets = [item for override in ["solver.path=fast"] + overrides for item in ("--set", override)]
    code, out, err = run_cli(capsys, "simulate", name, "--quiet", "--json", *sets)
    assert code == 0 and expected in err and "this run uses the reference path" in err, err
    assert json.loads(out)["solver"]["method"] == overrides[0].split("=")[1]


def test_cli_refuses_rosenbrock23_on_the_reference_path(capsys):
    code, _, err = run_cli(
        capsys,
        "simulate",
        "startup",
        "--quiet",
        "--set",
        "solver.method=Rosenbrock23",
        "--set",
        "solver.path=reference",
    )
    assert code == 2 and "runs only on the compiled fast path" in err


# ---------------------------------------------------------------------------------------------------------------
# Whole runs: fast path against the reference path


def run_pair(data: dict):
    """(reference run, fast run) of scene data; both must complete."""
    reference = simulate_complete(model_of(data))
    fast = simulate_complete(model_of(scene(data, solver__path="fast")))
    return reference, fast


def relative_difference(first, second, samples: int = 1001) -> np.ndarray:
    """Per state: max |first - second| at the sample times over max |first|."""
    times = np.linspace(first.t_start, first.t_end, samples)
    a, b = first(times), second(times)
    return np.max(np.abs(a - b), axis=1) / np.max(np.abs(a), axis=1)


def assert_same_events(reference, fast, within: float = 1e-9):
    assert [name for _, name in fast.events] == [name for _, name in reference.events]
    assert np.allclose([t for t, _ in fast.events], [t for t, _ in reference.events], rtol=0.0, atol=within)
    assert fast.stats.switches == reference.stats.switches


def shortened(name: str, duration: float, **changes) -> dict:
    """A bundled scene run for `duration` [s] (load events after it dropped), with scene() changes."""
    data = bundled(name)
    events = [
        event for event in data["scenario"].get("load_events", []) if event["time"] + event.get("ramp", 0.0) <= duration
    ]
    return scene(data, **{"scenario__duration": duration, "scenario__load_events": events, **changes})


# Where the compiled integrator reproduces scipy's arithmetic step for step, the runs agree to round-off.
@pytest.mark.parametrize(
    "data",
    [
        scene(bundled("startup"), solver__method="DOP853"),
        scene(bundled("startup"), solver__method="RK45"),
        scene(bundled("startup"), solver__method="RK4", solver__step=1e-3),
        shortened("lathe", 3.0),
        shortened("lathe", 3.0, solver__method="RK45"),
        shortened("lathe", 2.0, solver__method="RK4", solver__step=1e-3),
        shortened("four_bar_rocker", 1.0, solver__method="RK45"),
        shortened("walking_beam", 1.0),
    ],
    ids=[
        "startup-DOP853",
        "startup-RK45",
        "startup-RK4",
        "lathe-DOP853",
        "lathe-RK45",
        "lathe-RK4",
        "four_bar-RK45",
        "walking_beam",
    ],
)
def test_runs_equal_reference_step_for_step(data):
    reference, fast = run_pair(data)
    assert np.all(relative_difference(reference, fast) < 1e-12)
    assert fast.stats.steps == reference.stats.steps and fast.stats.restarts == reference.stats.restarts
    assert abs(fast.stats.nfev - reference.stats.nfev) <= 2 * reference.stats.switches  # RK4: one f per restart
    assert_same_events(reference, fast)


# Elsewhere the step sequences part at round-off of the error estimate (the right-hand sides are equal bit for bit,
# test above) and the runs differ by the method's own error: the difference stays within 10 times the fast run's
# error (its distance to a fast run at 1/100 of the tolerances); a wrong moment, sign or mode would exceed it by
# orders of magnitude.
@pytest.mark.parametrize(
    "data",
    [
        shortened("compressor", 1.0),
        shortened("four_bar_rocker", 1.0),
        shortened("engine_direct", 2.2),
        shortened("engine_indirect_isodromic", 2.2),
        shortened("engine_indirect_rigid", 2.2, solver__method="RK45"),
        shortened("two_mass", 1.2),
        shortened("press_coupling", 1.0),
        shortened("press_coupling", 1.0, solver__method="RK45"),
        bundled("engine_inline4"),
        shortened("engine", 0.6, machine=v_twin("engine")["machine"]),
        shortened("two_mass", 0.6, machine=driven_walking_beam()["machine"]),
    ],
    ids=[
        "compressor",
        "four_bar",
        "engine_direct",
        "isodromic",
        "rigid-RK45",
        "two_mass",
        "press_coupling",
        "press_coupling-RK45",
        "engine_inline4",
        "v_twin",
        "driven_walking_beam",
    ],
)
def test_runs_equal_reference_within_their_accuracy(data):
    reference, fast = run_pair(data)
    settings = data.get("solver", {})
    tight = simulate_complete(
        model_of(
            scene(data, solver__path="fast", solver__rtol=settings["rtol"] / 100, solver__atol=settings["atol"] / 100)
        )
    )
    assert np.all(relative_difference(reference, fast) <= 10.0 * relative_difference(tight, fast) + 1e-12)
    assert abs(fast.stats.steps - reference.stats.steps) <= 0.03 * reference.stats.steps
    # each MAX_STEPS_PER_CALL chunk of the fast path starts with the angle wrapped into one period, which can move
    # a later wrap of the angle (a restart) past the end: one restart more or less per chunk
    assert abs(fast.stats.restarts - reference.stats.restarts) <= fast.stats.steps // MAX_STEPS_PER_CALL
    assert_same_events(reference, fast)


def test_crank_stops_and_starts_as_on_the_reference_path():
    """Joint friction's crank guard on the fast path: a collar alone (M = f Q (r1 + r2)/2 = 3 N m) stops J = 0.5,
    omega0 = 10 at t = J omega0 / M = 5/3 s, where the crank then stays (omega exactly 0); the crank–slider at rest
    stays under 0.9 F(0) and starts under 1.1 F(0) with the reference's 'crank starts' event, and then runs as on the
    reference path."""
    collar = {"inner_radius": 0.02, "outer_radius": 0.04, "axial_load": 1000.0}
    run_down = {
        "machine": {"inertia": 0.5, "joint_friction": {"coefficient": 0.1, "thrust_collar": collar}},
        "scenario": {"initial": {"omega": 10.0}, "duration": 2.0},
        "solver": {},
    }
    at_rest = 3.0 + 0.1 / np.sqrt(1.01) * 0.03 * 30.0 * 9.81
    reference, fast = run_pair(run_down)
    assert_same_events(reference, fast)
    assert np.all(relative_difference(reference, fast) < 1e-9)
    reference, fast = run_pair(crank_at_rest(0.9 * at_rest))  # held: exactly at rest
    assert fast.events == reference.events == [] and np.all(fast(np.linspace(0.0, 0.5, 11)) == 0.0)
    stopped = simulate_complete(model_of(scene(run_down, solver__path="fast")))
    assert stopped.events[0] == (pytest.approx(0.5 * 10.0 / 3.0, abs=1e-9), "crank stops")
    assert np.all(stopped(np.linspace(1.7, 2.0, 5))[1] == 0.0)
    # starting from rest, as the bundled compressor_friction does: within the runs' accuracy (10 times the fast
    # run's distance to one at 1/100 of the tolerances, as test_runs_equal_reference_within_their_accuracy)
    for data in (crank_at_rest(1.1 * at_rest), shortened("compressor_friction", 0.5)):
        reference, fast = run_pair(data)
        assert [name for _, name in reference.events] == ["crank starts"]
        assert_same_events(reference, fast)
        settings = model_of(data).scene.solver
        tight = simulate_complete(
            model_of(
                scene(data, solver__path="fast", solver__rtol=settings.rtol / 100, solver__atol=settings.atol / 100)
            )
        )
        assert np.all(relative_difference(reference, fast) <= 10.0 * relative_difference(tight, fast) + 1e-12)
        # the same restarts (the start, and on compressor_friction the crossings of its slider table's breakpoints);
        # the step sequences after each restart part at round-off (measured: 137 against 151 steps on
        # compressor_friction, 20 switches each; 179 against 187 before the breakpoints were located)
        # both keep their steps away from the branch points of the journals' |R| (docs/theory.md §6.5)
        assert fast.stats.switches == reference.stats.switches and fast.stats.restarts == reference.stats.restarts
        assert abs(fast.stats.steps - reference.stats.steps) <= 0.15 * reference.stats.steps


def test_governed_engine_with_coupling_and_joint_friction_as_on_the_reference_path():
    """The last link of `bench speed`'s effect chain (bench/effect_cost.py: the governed engine with sleeve friction,
    stops, an elastic coupling and joint friction), 0.6 s with the load rejection at 0.5 s. Its guide's N guard has a
    slot of its own after the mode guards, which are fewer in some modes (the driven part at rest has two, turning
    one): the fast path once read an N crossing as a mode guard there and failed (IndexError). A friction corner that
    falls on a table knot (the corners every 90 deg of the crank, the indicator diagram's knots every 720 deg) is one
    switch on both paths (the reference path counted it twice, a second restart at the same point). Same events,
    switches, restarts and steps; states within 10 times the fast run's own error."""

    def run(*changes):
        return simulate_complete(
            build_model(
                load_scene(BASE_SCENE, [*SCENARIO, *EFFECT_CHAIN[-1].overrides, "scenario.duration=0.6", *changes])
            )
        )

    reference, fast = run(), run("solver.path=fast")
    tight = run("solver.path=fast", "solver.rtol=1e-10", "solver.atol=1e-12")
    assert [name for _, name in reference.events] == ["sleeve breaks away downwards", "sleeve reaches the low stop"]
    assert_same_events(reference, fast)
    assert (fast.stats.restarts, fast.stats.steps) == (reference.stats.restarts, reference.stats.steps)
    assert np.all(relative_difference(reference, fast) <= 10.0 * relative_difference(tight, fast) + 1e-12)


@pytest.mark.parametrize(
    "data",
    [
        bundled("clutch_start"),
        shortened("clutch_start", 2.5, solver__method="RK45"),
        scene(governed_clutch(), scenario__duration=1.0, scenario__load_events=[]),
    ],
    ids=["clutch_start", "clutch_start-RK45", "governed_clutch"],
)
def test_clutch_runs_equal_reference_within_their_accuracy(data):
    """The clutch's stick-slip events on both paths: states within 10 times the fast run's own error (its distance
    to a run at 1/100 of the tolerances), the same events, their times within 10 times the fast run's own largest
    error of them (the slip ends tangentially: clutch_start's lock time is known to some 3e-6 s at rtol 1e-9; the
    governed engine's clutch sticks and slips with the firing pulses)."""
    reference, fast = run_pair(data)
    settings = model_of(data).scene.solver
    tight = simulate_complete(
        model_of(scene(data, solver__path="fast", solver__rtol=settings.rtol / 100, solver__atol=settings.atol / 100))
    )
    assert "clutch locks (slip ends)" in [name for _, name in reference.events]
    assert np.all(relative_difference(reference, fast) <= 10.0 * relative_difference(tight, fast) + 1e-12)
    assert (
        [name for _, name in fast.events]
        == [name for _, name in reference.events]
        == [name for _, name in tight.events]
    )
    times = [np.array([time for time, _ in run.events]) for run in (reference, fast, tight)]
    assert np.max(np.abs(times[1] - times[0])) <= 10.0 * np.max(np.abs(times[1] - times[2])) + 1e-9
    assert abs(fast.stats.steps - reference.stats.steps) <= 0.03 * reference.stats.steps


def governed_lathe() -> dict:
    """The lathe's cutting load (switch angles) under a direct governor with sleeve friction and a short stroke:
    the sleeve sticks, breaks away, hits both stops and leaves them as the load steps up and is thrown off."""
    data = bundled("lathe")
    data["machine"]["drive"] = {"type": "constant", "torque": 150.0}
    data["governor"] = {
        "type": "direct",
        "ball_mass": 1.0,
        "arm_length": 0.2,
        "sleeve_mass": 5.0,
        "damping": 20.0,
        "friction": 3.0,
        "static_friction": 4.0,
        "ratio": 1.22,
        "stroke": [0.03, 0.06],
        "valve": {"open_at": 0.02, "closed_at": 0.08},
    }
    data["scenario"] = {
        "initial": {"omega": 15.0},
        "duration": 3.0,
        "load_events": [{"time": 1.0, "torque": 60.0}, {"time": 2.0, "torque": -40.0}],
    }
    return data


@pytest.mark.parametrize("method", ["DOP853", "RK45"])
def test_switches_and_governor_events_equal_reference(method):
    reference, fast = run_pair(scene(governed_lathe(), solver__method=method))
    assert {name for _, name in reference.events} == {
        "sleeve breaks away downwards",
        "sleeve reaches the low stop",
        "sleeve leaves the low stop",
        "sleeve reaches the high stop",
    }
    assert reference.stats.switches > 20
    assert_same_events(reference, fast, within=1e-9)
    assert fast.modes == [(pytest.approx(t, abs=1e-9), mode) for t, mode in reference.modes]
    assert np.all(relative_difference(reference, fast) < 1e-10)


def test_rosenbrock23_on_a_stiff_coupling_equals_radau():
    """k = 1e7 N m/rad: a coupling vibrating at about 1.9 kHz; Rosenbrock23 at rtol 1e-6 against Radau at 1e-10."""
    data = shortened(
        "two_mass",
        0.15,
        machine__coupling__stiffness=1e7,
        machine__coupling__damping=200.0,
        scenario__load_events=[{"time": 0.05, "torque": 8.0}],
    )
    radau = simulate_complete(model_of(scene(data, solver__method="Radau", solver__rtol=1e-10, solver__atol=1e-12)))
    fast = simulate_complete(
        model_of(scene(data, solver__path="fast", solver__method="Rosenbrock23", solver__rtol=1e-6, solver__atol=1e-12))
    )
    times = np.linspace(0.0, 0.15, 501)
    a, b = radau(times), fast(times)
    speeds = [0, 1, 3]  # phi, omega, omega_driven to 1e-6 of their range
    assert np.max(np.abs(a[speeds] - b[speeds]) / np.max(np.abs(a[speeds]), axis=1)[:, None]) < 1e-6
    # the twist (a few 1e-6 rad: twist = M / k) and so the coupling moment to 1e-3 of its range
    assert np.max(np.abs(a[2] - b[2])) < 1e-3 * np.max(np.abs(a[2]))
    assert fast.stats.njev > 0 and fast.stats.nlu >= fast.stats.njev


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning", "ignore:invalid value:RuntimeWarning")
def test_failure_and_interruption_keep_what_was_computed():
    # RK4 with a step of 3.1 time constants is unstable (|R(-3.14)| = 1.68 per step): the speed grows every step; both
    # paths stop at the first step end beyond limits.MAX_SPEED (1e6 rad/s), t = 17 s (it would overflow at 1325 s)
    blown = scene(bundled("startup"), scenario__duration=2000.0, solver__method="RK4", solver__step=1.0)
    reference = simulate(model_of(blown))
    fast = simulate(model_of(scene(blown, solver__path="fast")))
    assert reference.status == fast.status == "failed"
    assert fast.message == reference.message
    assert fast.message.startswith("RK4: the run blew up at t = 17 s: omega = ") and "RK4 step too long" in fast.message
    assert fast.t_end == reference.t_end == 17.0
    assert abs(fast(17.0)[1]) > 1e6 > abs(fast(16.0)[1])
    assert fast(17.0) == pytest.approx(reference(17.0), rel=1e-12)

    def stop_at_half(t: float) -> None:
        if t > 0.5:
            raise KeyboardInterrupt

    model = model_of(shortened("engine", 1.0, solver__path="fast"))
    interrupted = simulate(model, progress=stop_at_half)
    assert interrupted.status == "interrupted" and "interrupted by the user" in interrupted.message
    assert 0.5 < interrupted.t_end < 1.0
    assert np.all(np.isfinite(interrupted(np.linspace(0.0, interrupted.t_end, 11))))


def test_cli_fast_path_run(capsys, tmp_path):
    # (the co-simulation, --exchange-step, on the fast path: test_cosim_fast.py)
    code, out, _ = run_cli(
        capsys,
        "simulate",
        "lathe",
        "--quiet",
        "--set",
        "solver.path=fast",
        "--set",
        "scenario.duration=1.0",
        "--out",
        str(tmp_path / "lathe.csv"),
    )
    assert code == 0 and (tmp_path / "lathe.csv").exists()
