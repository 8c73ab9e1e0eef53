"""Every command on every valid linkage: a generated family of linkage scenes (test/linkage_family.py: every dyad type
RRR, RRP, RPR, PRP, RPP, with and without sliders, a redundant link, outputs on a slider's joint and on links,
random valid dimensions from a seeded RNG), each written as a YAML file as a user writes it and put through
`structure`, `kinematics`, `simulate` (with `--record`, `--plot`, `--out`, and `--exchange-step` as the nodes run
it), `flywheel`, `governor` and `sweep`: each works, or refuses at once with exit 2 and the reason (`governor`
without a governor). The recording is read back (rerun.chunk.RrdReader): the speed it holds is the CSV's and the
mechanism's drawing has every link and slider block. test_main_job_scenes.py plays two members through the nodes.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from linkage_family import MEMBERS, member
from rerun.chunk import RrdReader
from support import run_cli
from test_recording import scalars

from mech_regulator.analysis.kinematics import reactions_table
from mech_regulator.mechanisms import build_reduced
from mech_regulator.scene import config_dir, load_scene, mechanism_keys

SEED = 7
NAMES = list(MEMBERS)


@pytest.fixture(scope="module")
def scenes(tmp_path_factory) -> dict[str, tuple]:
    """name -> (the scene file, what structure must find) for every member of the family."""
    folder = tmp_path_factory.mktemp("family")
    written = {}
    for name in NAMES:
        data = member(name, SEED)
        expected = data.pop("expected")
        path = folder / f"{name}.yaml"
        path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
        written[name] = (path, expected)
    return written


def read_csv(path) -> dict[str, np.ndarray]:
    with open(path, newline="") as handle:
        rows = list(csv.reader(handle))
    return {key: np.array([float(row[index]) for row in rows[1:]]) for index, key in enumerate(rows[0])}


def strip_counts(path, entity: str) -> set[int]:
    """The number of line strips in each animation frame of a LineStrips2D entity of a recording."""
    counts = set()
    for chunk in RrdReader(path).store().stream():
        if chunk.entity_path == entity and not chunk.is_static:
            counts |= {len(strips) for strips in chunk.to_record_batch().column("LineStrips2D:strips").to_pylist()}
    return counts


def test_the_family_covers_every_dyad_type_with_and_without_sliders(scenes):
    kinds = {kind for _, expected in scenes.values() for kind in expected["groups"]}
    assert {"RRR", "RRP", "RPR", "PRP", "RPP", "redundant link"} <= kinds
    assert {expected["sliders"] for _, expected in scenes.values()} == {True, False}
    assert {expected["governed"] for _, expected in scenes.values()} == {True, False}


@pytest.mark.parametrize("name", NAMES)
def test_structure_finds_the_groups_drawn(scenes, name, tmp_path, capsys):
    path, expected = scenes[name]
    plot = tmp_path / "structure.png"
    code, out, err = run_cli(capsys, "structure", str(path), "--plot", str(plot), "--json")
    assert code == 0, err
    summary = json.loads(out)
    assert [group["type"] for group in summary["groups"]] == expected["groups"]
    assert summary["W"] == 1 and plot.stat().st_size > 0


@pytest.mark.parametrize("name", NAMES)
def test_kinematics_tables_every_point_and_the_reactions_where_determinate(scenes, name, tmp_path, capsys):
    """Reactions for a statically determinate linkage, whose balancing moment is what the reduced model needs at
    constant speed (M_b = 1/2 J' omega^2 - M_weight); for the redundant link, none, and why."""
    path, expected = scenes[name]
    out, plot = tmp_path / "k.csv", tmp_path / "k.png"
    code, stdout, err = run_cli(
        capsys,
        "kinematics",
        str(path),
        "--points",
        "25",
        "--omega",
        "12",
        "--out",
        str(out),
        "--plot",
        str(plot),
        "--json",
    )
    assert code == 0, err
    summary = json.loads(stdout)
    columns = read_csv(out)
    assert columns["phi"].size == 25 and plot.stat().st_size > 0
    assert all(np.all(np.isfinite(values)) for values in columns.values())
    if "redundant link" in expected["groups"]:
        assert "reactions" not in summary and "statically indeterminate" in summary["no_reactions"]
        assert not any(key.startswith("R_") for key in columns)
        return
    scene = load_scene(str(path))
    mechanism, gravity = scene.machine.mechanism, tuple(scene.machine.gravity)
    reduced = build_reduced(mechanism, gravity)
    wanted = [0.5 * reduced(phi)[1] * 12.0**2 - reduced(phi)[2] for phi in columns["phi"]]
    scale = np.max(np.abs(wanted))
    assert scale > 0.0 and np.max(np.abs(columns["M_balancing"] - wanted)) <= 1e-9 * scale
    assert reactions_table(mechanism, gravity, 12.0, columns["phi"][:1]).keys() == {
        key for key in columns if key.startswith("R_")
    } | {"M_balancing"}


@pytest.mark.parametrize("name", NAMES)
def test_simulate_records_plots_and_writes_the_run(scenes, name, tmp_path, capsys):
    """The recording holds the CSV's speed at the CSV's times, and every frame of the mechanism draws each link but
    the crank and one block per prismatic joint (none without sliders)."""
    path, expected = scenes[name]
    out, plot, rrd = tmp_path / "run.csv", tmp_path / "run.png", tmp_path / "run.rrd"
    code, stdout, err = run_cli(
        capsys, "simulate", str(path), "--quiet", "--json", "--out", str(out), "--plot", str(plot), "--record", str(rrd)
    )
    assert code == 0, err
    assert json.loads(stdout)["status"] == "complete"
    columns = read_csv(out)
    times, omega = scalars(rrd, "/speed/omega")
    np.testing.assert_allclose(times * 1e-9, columns["t"], rtol=0.0, atol=1e-9)
    np.testing.assert_allclose(omega, columns["omega"], rtol=1e-9)
    mechanism = yaml.safe_load(path.read_text())["machine"]["mechanism"]
    prismatic = sum(joint["type"] == "prismatic" for joint in mechanism["joints"].values())
    assert (prismatic > 0) == expected["sliders"]
    assert strip_counts(rrd, "/mechanism/links") == {len(mechanism["links"]) - 1}
    assert strip_counts(rrd, "/mechanism/sliders") == {prismatic}
    assert plot.stat().st_size > 0


@pytest.mark.parametrize("name", NAMES)
def test_the_lockstep_co_simulation_plays_it_without_a_trip(scenes, name, capsys):
    """`simulate --exchange-step` (what the nodes run): complete, with no overspeed trip unless asked; with one asked
    just above the initial speed (every member's motor speeds it up from 30 rad/s at first), `tripped`, not
    `complete` (exit 0: the run played to its end)."""
    path, _ = scenes[name]
    code, stdout, err = run_cli(capsys, "simulate", str(path), "--quiet", "--json", "--exchange-step", "0.01")
    assert code == 0, err
    summary = json.loads(stdout)
    assert summary["status"] == "complete" and summary["tripped_at"] is None and summary["t_end"] == pytest.approx(0.3)
    code, stdout, err = run_cli(
        capsys, "simulate", str(path), "--quiet", "--json", "--exchange-step", "0.01", "--overspeed-trip", "30.001"
    )
    summary = json.loads(stdout)
    assert code == 0 and summary["tripped_at"] is not None, err
    assert summary["status"] == "tripped" and summary["message"].startswith("overspeed trip at t = "), summary


@pytest.mark.parametrize("name", NAMES)
def test_flywheel_or_governor_and_the_other_refused_with_the_reason(scenes, name, tmp_path, capsys):
    path, expected = scenes[name]
    if expected["governed"]:
        code, stdout, err = run_cli(capsys, "governor", str(path), "--json", "--plot", str(tmp_path / "g.png"))
        assert code == 0, err
        assert json.loads(stdout)["linear"]["stable"] in (True, False)
        return
    code, stdout, err = run_cli(capsys, "governor", str(path))
    assert code == 2 and "has no governor" in err, err
    code, stdout, err = run_cli(
        capsys, "flywheel", str(path), "--delta", "1/20", "--quiet", "--json", "--plot", str(tmp_path / "f.png")
    )
    assert code == 0, err
    answer = json.loads(stdout)
    assert answer and (tmp_path / "f.png").stat().st_size > 0


@pytest.mark.parametrize("name", NAMES)
def test_a_sweep_runs_the_linkage(scenes, name, tmp_path, capsys):
    path, _ = scenes[name]
    code, stdout, err = run_cli(
        capsys,
        "sweep",
        str(path),
        "--grid",
        "machine.inertia=0.5,1.0",
        "--jobs",
        "1",
        "--path",
        "reference",
        "--out",
        str(tmp_path / "sweep"),
        "--quiet",
    )
    assert code == 0, err
    with open(tmp_path / "sweep" / "sweep.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 2 and all(math.isfinite(float(row["omega_end"])) for row in rows), rows


def test_joint_friction_on_a_redundant_link_is_refused_at_once(scenes, tmp_path, capsys):
    """Joint friction reads the joint reactions, which a redundant link leaves indeterminate: the scene is refused
    with exit 2 and the reason (it once ended in a traceback from the kinetostatics)."""
    path, _ = scenes["parallelogram"]
    data = yaml.safe_load(path.read_text())
    data["machine"]["joint_friction"] = {"coefficient": 0.1, "journals": {"A": {"radius": 0.01}}}
    changed = tmp_path / "friction.yaml"
    changed.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    code, _, err = run_cli(capsys, "simulate", str(changed), "--quiet")
    assert code == 2 and "joint_friction needs the joint reactions" in err and "statically indeterminate" in err, err


def test_kinematics_help_says_it_takes_any_linkage(capsys):
    with pytest.raises(SystemExit):
        run_cli(capsys, "kinematics", "--help")
    out = capsys.readouterr().out
    assert "any linkage (type: linkage" in " ".join(out.split())


def test_a_branch_on_a_group_with_one_assembly_is_refused(scenes, tmp_path, capsys):
    """PRP and RPP groups have one assembly: a branch given for them would be ignored, so it is refused."""
    path, _ = scenes["yoke_and_wedge"]
    data = yaml.safe_load(path.read_text())
    data["machine"]["mechanism"]["branches"] = {"C": -1}
    changed = tmp_path / "branch.yaml"
    changed.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    code, _, err = run_cli(capsys, "structure", str(changed))
    assert (
        code == 2 and "branches names ['C'], which are not the internal joint of a group with two assemblies" in err
    ), err


def documented_six_bar() -> str:
    """The YAML of the complete scene file in docs/linkages.md ("Your own linkage: a complete scene file")."""
    text = (Path(__file__).resolve().parents[1] / "docs" / "linkages.md").read_text(encoding="utf-8")
    section = text.split("### Your own linkage: a complete scene file", 1)[1]
    return section.split("```yaml\n", 1)[1].split("```", 1)[0]


def test_the_documented_six_bar_shows_every_key_and_its_csv_j_holds_the_constant_part(tmp_path, capsys):
    """The scene file of docs/linkages.md validates, gives the key of every linkage setting (output: one of its
    two, which exclude each other; a joint's gear keys are the geared scenes' of the page, "Gears") and runs; its CSV's J is machine.inertia + flywheel.inertia ratio^2 + J_links(phi),
    J_links counting the crank's constant m |c - p|^2 + I, as the page says (its number at phi = 0 too)."""
    data = yaml.safe_load(documented_six_bar())
    mechanism = data["machine"]["mechanism"]
    assert set(mechanism_keys.Linkage.model_fields) <= set(mechanism)
    assert set(mechanism_keys.LinkageLink.model_fields) <= {key for link in mechanism["links"].values() for key in link}
    gear_keys = {"teeth", "radii", "internal", "centres", "carrier", "phase_deg"}
    lower_pair_keys = set(mechanism_keys.LinkageJoint.model_fields) - gear_keys
    assert lower_pair_keys <= {key for joint in mechanism["joints"].values() for key in joint}
    gears_section = (Path(__file__).resolve().parents[1] / "docs" / "linkages.md").read_text(encoding="utf-8")
    gears_section = gears_section.split("\n### Gears", 1)[1].split("\n### ", 1)[0]
    assert all(f"{key}:" in gears_section for key in gear_keys)
    assert len(mechanism["output"]) == 1 and set(mechanism["output"]) <= set(mechanism_keys.LinkageOutput.model_fields)
    path, out = tmp_path / "my_six_bar.yaml", tmp_path / "run.csv"
    path.write_text(documented_six_bar(), encoding="utf-8")
    code, _, err = run_cli(
        capsys, "simulate", str(path), "--quiet", "--set", "scenario.duration=0.1", "--out", str(out)
    )
    assert code == 0, err
    columns = read_csv(out)
    scene = load_scene(str(path))
    machine = scene.machine
    constant = machine.inertia + machine.flywheel.inertia * machine.flywheel.ratio**2
    reduced = build_reduced(machine.mechanism, tuple(machine.gravity))
    links = np.array([reduced(phi)[0] for phi in columns["phi"]])
    np.testing.assert_allclose(columns["J"], constant + links, rtol=1e-9)
    assert round(float(columns["J"][0]), 4) == 21.0892  # docs/linkages.md, "J in the run's CSV"
    crank = data["machine"]["mechanism"]["links"]["crank"]
    without = load_scene(str(path), ["machine.mechanism.links.crank.mass=0", "machine.mechanism.links.crank.inertia=0"])
    bare = build_reduced(without.machine.mechanism, tuple(machine.gravity))
    pivot = np.array(crank["points"]["A"])
    own = crank["mass"] * float(np.sum((np.array(crank["centre"]) - pivot) ** 2)) + crank["inertia"]
    assert own > 0.0
    for phi in columns["phi"][::10]:
        assert reduced(phi)[0] - bare(phi)[0] == pytest.approx(own, rel=1e-9)


def test_every_linkage_command_takes_a_linkage_behind_a_coupling(scenes, tmp_path, capsys):
    """A member driven through an elastic coupling (the bundled press_coupling with its crank-slider replaced):
    `structure` and `kinematics` analyse the driven part's linkage (kinematics once said the scene had no
    mechanism), simulate records it."""
    path, expected = scenes["watt_six_bar"]
    member_data = yaml.safe_load(path.read_text())
    data = yaml.safe_load((config_dir() / "scenes" / "press_coupling.yaml").read_text())
    data["machine"]["coupling"]["driven"]["mechanism"] = member_data["machine"]["mechanism"]
    data["machine"]["coupling"]["driven"]["loads"] = [{"type": "rocker_viscous", "coefficient": 1.0}]
    data["scenario"]["duration"] = 0.2
    coupled = tmp_path / "coupled.yaml"
    coupled.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    code, out, err = run_cli(capsys, "structure", str(coupled), "--json")
    assert code == 0 and [group["type"] for group in json.loads(out)["groups"]] == expected["groups"], err
    code, out, err = run_cli(capsys, "kinematics", str(coupled), "--points", "13", "--json")
    assert code == 0, err
    summary = json.loads(out)
    assert summary["mechanism"] == "linkage" and summary["driven_part"] is True and "F" in summary["joints"]
    rrd = tmp_path / "coupled.rrd"
    code, _, err = run_cli(capsys, "simulate", str(coupled), "--quiet", "--record", str(rrd))
    assert code == 0, err
    assert strip_counts(rrd, "/mechanism/links") == {len(member_data["machine"]["mechanism"]["links"]) - 1}
