"""Change points (docs/linkages.md "Change points"): source 001's parallelogram A B C D with the redundant link EF,
its crank AB turning fully, passes the change points (AB along AD, where the four-bar could fold into an
antiparallelogram) on the parallelogram: its coupler BC stays parallel to the frame AD (angle 0) over several turns,
on the general solver, the generated code and a run on the reference and the fast path. Without EF the same
four-bar is refused: nothing holds it at its change points.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mech_regulator.mechanisms.linkage import (
    Joint,
    Link,
    Linkage,
    assembly_failures,
    checked,
    make_reduced,
    solve,
    symbolic,
)
from mech_regulator.model import build_model
from mech_regulator.scene import SceneError, validate_scene
from mech_regulator.solvers import simulate

TURNS = np.linspace(0.0, 6.0 * math.pi, 145)  # three turns, the change points 0, pi, 2 pi, ... among them


def revolute(name: str, a: str, b: str) -> Joint:
    return Joint(name, "revolute", (a, b))


def parallelogram(with_ef: bool = True) -> Linkage:
    """Source 001, fig. 1.26: A B C D (AB = CD = 1, BC = AD = 2), E the middle of BC, F of AD, EF = 1; the crank AB
    turns fully; the coupler BC is the output link (q = its angle)."""
    links = (
        Link("0", {"A": 0j, "D": 2 + 0j, "F": 1 + 0j}),
        Link("1", {"A": 0j, "B": 1 + 0j}, mass=1.0, centre=0.5 + 0j, inertia=0.1),
        Link("2", {"B": 0j, "C": 2 + 0j, "E": 1 + 0j}, mass=2.0, centre=1 + 0.1j, inertia=0.7),
        Link("3", {"D": 0j, "C": 1 + 0j}, mass=1.0, centre=0.5 + 0j, inertia=0.1),
        Link("5", {"F": 0j, "E": 1 + 0j}, mass=0.5, centre=0.5 + 0j, inertia=0.05),
    )
    joints = (
        revolute("A", "0", "1"),
        revolute("B", "1", "2"),
        revolute("C", "2", "3"),
        revolute("D", "0", "3"),
        revolute("E", "2", "5"),
        revolute("F", "0", "5"),
    )
    if not with_ef:
        links, joints = links[:4], joints[:4]
    return Linkage(links, joints, "0", "1", output_link="2")


def test_the_parallelogram_runs_through_its_change_points():
    """W = 1 with EF's redundant constraint; the group is the parallelogram; it assembles at every 0.5 deg; over
    three turns the coupler's angle and its rates are 0, the rocker turns with the crank and EF with it, and J is
    the constant sum of the crank's, rocker's and EF's m c^2 + I and the coupler's mass times |AB|^2 (it translates
    at the crank pin's speed), on the general solver and the generated code."""
    linkage = parallelogram()
    structure = checked(linkage)
    assert structure.freedom == 1 and len(structure.redundant) == 1
    assert structure.groups[0].parallelogram is not None and "the parallelogram A B C D" in structure.report()[3]
    assert assembly_failures(linkage, structure) == []
    for phi in TURNS:
        poses = solve(linkage, structure, phi)
        assert (poses["2"][1], poses["2"][3], poses["2"][5]) == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)
        assert math.cos(poses["3"][1] - phi) == pytest.approx(1.0, abs=1e-12) and poses["3"][3] == pytest.approx(1.0)
        assert math.cos(poses["5"][1] - phi) == pytest.approx(1.0, abs=1e-12)
    J = (0.1 + 0.25) + 2.0 * 1.0 + (0.1 + 0.25) + (0.05 + 0.5 * 0.25)
    for reduced in (
        make_reduced(linkage, structure, (0.0, -9.81)),
        symbolic.make_reduced(linkage, structure, (0.0, -9.81)),
    ):
        for phi in TURNS:
            J_links, dJ, _, angle, rate = reduced(phi)
            assert (J_links, dJ, angle, rate) == pytest.approx((J, 0.0, 0.0, 0.0), abs=1e-12)


def test_without_the_redundant_link_the_change_point_is_refused():
    """The bare parallelogram four-bar keeps its branch and so meets its change points as dead points."""
    linkage = parallelogram(with_ef=False)
    structure = checked(linkage)
    assert structure.groups[0].parallelogram is None
    failures = assembly_failures(linkage, structure)
    assert len(failures) == 1 and "RRR group C (links 2, 3)" in failures[0]


def _scene(path: str) -> dict:
    """The parallelogram as a scene: a motor turning it from 3 rad/s for 4 s (several turns)."""
    return {
        "name": "parallelogram_change_points",
        "machine": {
            "inertia": 0.5,
            "gravity": [0.0, -9.81],
            "mechanism": {
                "type": "linkage",
                "frame": {"A": [0.0, 0.0], "D": [2.0, 0.0], "F": [1.0, 0.0]},
                "crank": "AB",
                "links": {
                    "AB": {"points": {"A": [0, 0], "B": [1, 0]}, "mass": 1.0, "inertia": 0.1},
                    "BC": {
                        "points": {"B": [0, 0], "C": [2, 0], "E": [1, 0]},
                        "mass": 2.0,
                        "centre": [1.0, 0.0],
                        "inertia": 0.7,
                    },
                    "CD": {"points": {"D": [0, 0], "C": [1, 0]}, "mass": 1.0, "inertia": 0.1},
                    "EF": {"points": {"F": [0, 0], "E": [1, 0]}, "mass": 0.5, "inertia": 0.05},
                },
                "joints": {
                    name: {"type": "revolute", "links": links}
                    for name, links in (
                        ("A", ["frame", "AB"]),
                        ("B", ["AB", "BC"]),
                        ("C", ["BC", "CD"]),
                        ("D", ["frame", "CD"]),
                        ("E", ["BC", "EF"]),
                        ("F", ["frame", "EF"]),
                    )
                },
                "output": {"link": "BC"},
            },
            "drive": {"type": "linear_motor", "stall_torque": 60.0, "no_load_speed": 8.0},
            "loads": [{"type": "viscous", "coefficient": 1.0}],
        },
        "scenario": {"initial": {"phi": 0.0, "omega": 3.0}, "duration": 4.0},
        "solver": {"method": "DOP853", "rtol": 1e-9, "atol": 1e-11, "path": path},
    }


@pytest.mark.parametrize("path", ["reference", "fast"])
def test_the_parallelogram_scene_runs_several_turns_on_both_paths(path):
    """A run of several turns (through a change point every half turn): the coupler's angle stays 0."""
    model = build_model(validate_scene(_scene(path)))
    trajectory = simulate(model)
    times = np.linspace(0.0, 4.0, 401)
    columns = model.columns(times, trajectory(times))
    assert columns["phi"][-1] > 4.0 * math.pi  # more than two turns: at least four change points
    assert np.max(np.abs(columns["theta_output"])) < 1e-9 and np.max(np.abs(columns["omega_output"])) < 1e-9


def test_a_scene_without_the_redundant_link_is_refused_at_its_change_point():
    data = _scene("reference")
    mechanism = data["machine"]["mechanism"]
    del mechanism["links"]["EF"], mechanism["joints"]["E"], mechanism["joints"]["F"]
    with pytest.raises(SceneError, match="RRR group C .* is at a dead point"):
        build_model(validate_scene(data))  # the mechanisms' checks run when a scene becomes a machine
