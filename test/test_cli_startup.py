"""First run to result: the command line answers `--help` without loading the heavy libraries (each command
imports what it needs), an optional extra that is missing is named with its pip command (exit 2, no traceback),
and `bench startup` measures what it says. No timing is asserted."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from support import run_cli

from mech_regulator.bench.startup import MEASURES, PATHS, script_refusal, script_text
from mech_regulator.model import build_model
from mech_regulator.scene import load_scene

HEAVY = (
    "numpy",
    "scipy",
    "numba",
    "llvmlite",
    "pydantic",
    "pydantic_core",
    "matplotlib",
    "rerun",
    "tqdm",
    "yaml",
    "rclpy",
    "mujoco",
    "dask",
)
"""Top-level packages that building the parser must not import."""


def modules_after(code: str) -> list[str]:
    """The heavy modules and the package's own core modules loaded in a fresh interpreter after `code`."""
    script = (
        f"import sys\n{code}\n"
        f"print(sorted(name for name in sys.modules if name.split('.')[0] in {HEAVY!r} or "
        "name.startswith(('mech_regulator.scene', 'mech_regulator.model', 'mech_regulator.solvers', "
        "'mech_regulator.analysis', 'mech_regulator.bench', 'mech_regulator.viz'))))"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True)
    return eval(done.stdout.strip().splitlines()[-1])  # a list of names printed by the child


def after_main(*argv: str) -> str:
    return f"from mech_regulator.cli.main import main\ntry:\n    main({list(argv)!r})\nexcept SystemExit:\n    pass"


@pytest.mark.parametrize(
    "argv",
    [
        ("--help",),
        ("simulate", "--help"),
        ("sweep", "--help"),
        ("flywheel", "--help"),
        ("bench", "speed", "--help"),
        ("bench", "startup", "--help"),
        ("bench", "soak", "--help"),
        ("bench", "first-run", "--help"),
        ("bench", "long", "--help"),
        ("run", "--help"),
        ("simulate", "lathe", "--no-such-option"),
    ],
    ids=lambda argv: " ".join(argv),
)
def test_the_parser_loads_no_heavy_library(argv):
    assert modules_after(after_main(*argv)) == []


def test_importing_the_command_line_loads_no_heavy_library():
    assert modules_after("import mech_regulator.cli.main; mech_regulator.cli.parser.build_parser()") == []


def test_the_entry_points_client_loads_no_heavy_library():
    """The entry point asks the command server first (cli/server_client.py): the standard library only."""
    assert (
        modules_after(
            "from mech_regulator.cli.server_client import through_server\n"
            "from mech_regulator.cli.server_key import server_key\nserver_key()\nthrough_server(['simulate', '--help'])"
        )
        == []
    )


def test_the_check_sees_a_heavy_import():
    """The checks above can fail: a command that reads a scene does load pydantic and the scene."""
    found = modules_after(after_main("scenes"))
    assert "pydantic" in found and "mech_regulator.scene" in found


def test_the_launcher_of_the_nodes_loads_no_numerics():
    """nodes.launch imports cli.report's terminal and machine_text (its progress and summary): that stays free of numpy, scipy and numba."""
    found = modules_after("import mech_regulator.nodes.launch")
    assert not [name for name in found if name.split(".")[0] in ("numpy", "scipy", "numba", "matplotlib", "rerun")]


def test_the_parsers_choices_are_the_sweeps():
    from mech_regulator.analysis import sweep
    from mech_regulator.cli import sweep as cli_sweep

    assert cli_sweep.ENGINES == sweep.ENGINES and cli_sweep.METRICS == sweep.METRICS


def test_bench_speed_without_mujoco_names_the_extra(capsys, monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "mujoco", None)  # import mujoco now fails; find_spec says None
    code, out, err = run_cli(
        capsys, "bench", "speed", "--quick", "--scenes", "crank_slider_bench", "--out", str(tmp_path)
    )
    assert code == 2 and out == ""
    assert err.startswith(
        "mech-regulator: bench speed: crank_slider_bench runs on MuJoCo too, and MuJoCo is not "
        "installed: pip install 'mech_regulator[bench]'"
    ), err
    assert "--no-mujoco" in err and not (tmp_path / "speed.csv").exists()


def test_sweep_on_dask_without_dask_names_the_extra_before_any_work(capsys, monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "dask.distributed", None)
    out = tmp_path / "sweep"
    code, stdout, err = run_cli(
        capsys, "sweep", "lathe", "--grid", "machine.flywheel.inertia=10,20", "--engine", "dask", "--out", str(out)
    )
    assert code == 2 and stdout == ""
    assert err == (
        "mech-regulator: --engine dask needs Dask distributed: pip install 'mech_regulator[distributed]' "
        "(or pip install 'dask[distributed]')\n"
    )
    assert not out.exists()


@pytest.mark.parametrize("name", ["crank_slider_bench", "lathe"])
def test_the_plain_script_computes_the_models_right_hand_side(name):
    """bench startup's solve_ivp script is the same machine: its rhs equals the model's at random states."""
    scene = load_scene(name)
    assert script_refusal(scene) is None
    namespace = {"__name__": "not_main"}
    exec(compile(script_text(scene), f"{name}_solve_ivp.py", "exec"), namespace)
    model = build_model(scene)
    state = model.initial_state()
    rhs = model.rhs(model.piece_at(0.0), None, model.initial_mode(state))
    for phi, omega in np.random.default_rng(17).uniform([-10.0, -20.0], [10.0, 150.0], (100, 2)):
        expected = np.asarray(rhs(0.0, np.array([phi, omega])))
        assert np.allclose(namespace["rhs"](0.0, [phi, omega]), expected, rtol=1e-12, atol=1e-12)


def test_the_script_refuses_what_it_cannot_write():
    assert "modes and events" in script_refusal(load_scene("engine_direct"))
    assert "slider_table" in script_refusal(load_scene("compressor"))


def test_bench_startup_json(capsys):
    code, out, err = run_cli(
        capsys, "bench", "startup", "--repeat", "1", "--scene", "lathe", "--skip-cold-fast", "--json"
    )
    assert code == 0, err
    found = json.loads(out)
    assert found["scene"] == "lathe" and found["repeat"] == 1 and found["cold_fast"] is False
    assert set(found["measures"]) == set(MEASURES)
    for measure, paths in found["measures"].items():
        assert set(paths) == set(PATHS)
        for path, timing in paths.items():
            if (measure, path) in (("help", "solve_ivp"), ("cold", "fast"), ("served", "solve_ivp")):
                assert timing is None
                continue
            assert timing["median_s"] > 0 and timing["min_s"] > 0 and len(timing["runs_s"]) == 1, (measure, path)
    assert found["python_startup"]["median_s"] > 0
    assert found["ratios"]["warm"]["fast / solve_ivp"] > 0 and found["ratios"]["served"]["fast / solve_ivp"] > 0
    omega = found["omega_end"]
    assert omega["reference"] == pytest.approx(omega["solve_ivp"], rel=1e-5)
    assert omega["fast"] == pytest.approx(omega["solve_ivp"], rel=1e-5)
    assert "bench startup: warm fast run 1/1" in err and "bench startup: warm fast through the server run 1/1" in err


def test_bench_startup_refuses_a_scene_the_script_cannot_write(capsys):
    code, out, err = run_cli(capsys, "bench", "startup", "--scene", "engine_direct")
    assert code == 2 and out == "" and "the plain solve_ivp script cannot reproduce it" in err
