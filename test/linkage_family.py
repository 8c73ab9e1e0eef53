"""A generated family of linkage scenes, written as a user writes them from docs/linkages.md: every class-II dyad
type (RRR, RRP, RPR, PRP, RPP), linkages with and without sliders, a redundant link, outputs on a slider's joint and
on links with and without a slider beside them, some governed. Dimensions and masses are drawn with a seeded RNG
(numpy's default_rng) and redrawn until the scene validates (the crank turns fully on the branch drawn), so a seed
gives the same family on every machine.

`family(seed)` -> [(name, scene data)]; each scene's `expected` (popped before it is written) gives the group types
`structure` must find, whether it has sliders and whether it is governed.
"""

from __future__ import annotations

import math

import numpy as np

from mech_regulator.scene import SceneError, validate_scene

ATTEMPTS = 200  # draws per linkage before the generator gives up (a bug in it, not bad luck)
DURATION = 0.3  # [s] of each scene's scenario
GOVERNOR = {
    "type": "direct",
    "ball_mass": 1.0,
    "arm_length": 0.2,
    "sleeve_mass": 5.0,
    "damping": 200.0,
    "friction": 0.0,
    "ratio": 0.5,
    "stroke": [0.02, 0.08],
    "valve": {"open_at": 0.02, "closed_at": 0.08},
}
# a Porter governor whose spindle at 0.5 x the crank speed holds it near 36 rad/s (its sleeve at 20..80 mm for
# 35.2..38.4 rad/s); the linear motor below runs at up to 40 rad/s with the throttle open


def _point(z: complex) -> list[float]:
    return [round(z.real, 6), round(z.imag, 6)]


def _plain(value):
    """value with numpy's numbers as Python's (what a YAML file holds)."""
    if isinstance(value, dict):
        return {key: _plain(item) for key, item in value.items()}
    if isinstance(value, list):
        return [_plain(item) for item in value]
    return value.item() if isinstance(value, np.generic) else value


def _link(rng, points: dict[str, complex], mass_scale: float = 5.0) -> dict:
    """A link with its points, a random mass [kg] at a random centre among its points and a random inertia."""
    values = list(points.values())
    centre = sum(values) / len(values) + complex(*rng.uniform(-0.01, 0.01, 2))
    span = max((abs(a - b) for a in values for b in values), default=0.0)
    mass = float(rng.uniform(0.3, 1.0) * mass_scale)
    link = {
        "points": {name: _point(z) for name, z in points.items()},
        "mass": round(mass, 4),
        "centre": _point(centre),
        "inertia": round(mass * (span * span / 12.0 + 1e-4), 6),
    }
    return link


def _revolute(first: str, second: str) -> dict:
    return {"type": "revolute", "links": [first, second]}


def _prismatic(guide: str, slider: str, direction_deg: float = 0.0) -> dict:
    return {"type": "prismatic", "links": [guide, slider], "direction_deg": round(direction_deg, 4)}


def _scene(name: str, mechanism: dict, governed: bool, groups: list[str]) -> dict:
    """The scene around a mechanism: a linear motor (throttled by a governor when governed), bearing friction, a
    viscous load on the output and a short scenario; `expected` for the tests."""
    output = mechanism.get("output", {})
    loads = [{"type": "viscous", "coefficient": 0.2}]
    if "joint" in output:
        loads.append({"type": "slider_viscous", "coefficient": 20.0})
    elif "link" in output:
        loads.append({"type": "rocker_viscous", "coefficient": 0.2})
    sliders = any(joint["type"] == "prismatic" for joint in mechanism["joints"].values())
    scene = {
        "name": name,
        "description": f"generated {'+'.join(groups)} linkage",
        "machine": {
            "inertia": 0.5,
            "gravity": [0.0, -9.81],
            "mechanism": mechanism,
            "drive": {"type": "linear_motor", "stall_torque": 400.0, "no_load_speed": 40.0},
            "loads": loads,
        },
        "scenario": {"initial": {"phi": 0.0, "omega": 30.0}, "duration": DURATION},
        "analysis": {"permitted_delta": 0.05},
        "expected": {"groups": groups, "sliders": sliders, "governed": governed},
    }
    if governed:
        scene["governor"] = dict(GOVERNOR)
        scene["scenario"]["initial"]["sleeve"] = 0.04
        scene["scenario"]["external_load"] = 5.0
        scene["scenario"]["load_events"] = [{"time": DURATION / 2, "torque": 15.0}]
    return _plain(scene)


def _four_bar(rng) -> tuple[dict, dict, dict, complex, complex]:
    """A crank-rocker: frame points, links and joints (crank A-B, coupler B-C, rocker D-C), the lever point D and
    the rocker's direction from D to C in its own coordinates (its x axis)."""
    a = rng.uniform(0.04, 0.08)
    b, c, d = rng.uniform(0.15, 0.35, 3)
    turn = complex(math.cos(t := rng.uniform(-0.5, 0.5)), math.sin(t))
    D = d * turn
    frame = {"A": 0j, "D": D}
    links = {
        "crank": _link(rng, {"A": 0j, "B": a + 0j}),
        "coupler": _link(rng, {"B": 0j, "C": b + 0j}),
        "rocker": _link(rng, {"D": 0j, "C": c + 0j, "E": -rng.uniform(0.1, 0.25) + 0j}, mass_scale=8.0),
    }
    joints = {
        "A": _revolute("frame", "crank"),
        "B": _revolute("crank", "coupler"),
        "C": _revolute("coupler", "rocker"),
        "D": _revolute("frame", "rocker"),
    }
    return frame, links, joints, D, turn


def _branches(rng, *joints: str) -> dict:
    return {joint: int(rng.choice([-1, 1])) for joint in joints}


def four_bar(rng) -> dict:
    """RRR: a crank-rocker, its output the rocker (no slider)."""
    frame, links, joints, _, _ = _four_bar(rng)
    return {
        "type": "linkage",
        "frame": {k: _point(v) for k, v in frame.items()},
        "crank": "crank",
        "links": links,
        "joints": joints,
        "branches": _branches(rng, "C"),
        "output": {"link": "rocker"},
    }


def watt_six_bar(rng) -> dict:
    """RRR + RRR: the crank-rocker's rocker extended to E drives a second rocker H-F through the rod E-F (all
    revolute), its output the second rocker."""
    frame, links, joints, D, turn = _four_bar(rng)
    rod, second = rng.uniform(0.2, 0.4), rng.uniform(0.15, 0.3)
    frame["H"] = D + turn * complex(rng.uniform(-0.5, 0.1), rng.uniform(-0.4, -0.1))
    links["rod"] = _link(rng, {"E": 0j, "F": rod + 0j})
    links["follower"] = _link(rng, {"F": 0j, "H": second + 0j})
    joints.update(E=_revolute("rocker", "rod"), F=_revolute("rod", "follower"), H=_revolute("frame", "follower"))
    return {
        "type": "linkage",
        "frame": {k: _point(v) for k, v in frame.items()},
        "crank": "crank",
        "links": links,
        "joints": joints,
        "branches": _branches(rng, "C", "F"),
        "output": {"link": "follower"},
    }


def crank_slider(rng) -> dict:
    """RRP: a crank-slider with an offset guide at a random angle, its output the slider's travel."""
    r = rng.uniform(0.04, 0.1)
    rod = rng.uniform(2.5, 4.0) * r
    angle = rng.uniform(-180.0, 180.0)
    along = complex(math.cos(math.radians(angle)), math.sin(math.radians(angle)))
    G = 1j * along * rng.uniform(-0.5, 0.5) * r
    links = {
        "crank": _link(rng, {"A": 0j, "B": r + 0j}),
        "rod": _link(rng, {"B": 0j, "C": rod + 0j}),
        "piston": _link(rng, {"C": 0j, "G": 0j}, mass_scale=10.0),
    }
    joints = {
        "A": _revolute("frame", "crank"),
        "B": _revolute("crank", "rod"),
        "C": _revolute("rod", "piston"),
        "G": _prismatic("frame", "piston", angle),
    }
    return {
        "type": "linkage",
        "frame": {"A": [0.0, 0.0], "G": _point(G)},
        "crank": "crank",
        "links": links,
        "joints": joints,
        "branches": _branches(rng, "C"),
        "output": {"joint": "G"},
    }


def six_bar_ram(rng) -> dict:
    """RRR + RRP: the crank-rocker's rocker extended to E drives a ram on a vertical guide through the rod E-F;
    the output is the rocker, a link with no slider, while the ram slides."""
    frame, links, joints, D, turn = _four_bar(rng)
    E = D + turn * complex(-rng.uniform(0.1, 0.25), 0.0)  # about where E swings
    frame["G"] = E + complex(rng.uniform(-0.05, 0.05), 0.0)
    links["rod"] = _link(rng, {"E": 0j, "F": rng.uniform(0.25, 0.4) + 0j})
    links["ram"] = _link(rng, {"F": 0j, "G": 0j}, mass_scale=20.0)
    joints.update(E=_revolute("rocker", "rod"), F=_revolute("rod", "ram"), G=_prismatic("frame", "ram", -90.0))
    return {
        "type": "linkage",
        "frame": {k: _point(v) for k, v in frame.items()},
        "crank": "crank",
        "links": links,
        "joints": joints,
        "branches": _branches(rng, "C", "F"),
        "output": {"link": "rocker"},
    }


def shaper(rng) -> dict:
    """RPR + RRP: a crank drives a slotted lever through a block (the slot a random offset beside the lever's
    axis); the lever's end drives the ram through a link; the output is the ram's travel."""
    r = rng.uniform(0.08, 0.12)
    d = rng.uniform(0.25, 0.35)
    lever = rng.uniform(0.45, 0.6)
    offset = rng.uniform(-0.2, 0.2) * r
    height = lever - d + rng.uniform(-0.02, 0.03)
    links = {
        "crank": _link(rng, {"O2": 0j, "A": r + 0j}),
        "block": _link(rng, {"A": 0j, "S": 0j}, mass_scale=0.5),
        "lever": _link(rng, {"O4": 0j, "S": complex(0.0, offset), "B": lever + 0j}, mass_scale=8.0),
        "link": _link(rng, {"B": 0j, "C": rng.uniform(0.15, 0.25) + 0j}),
        "ram": _link(rng, {"C": 0j, "G": 0j}, mass_scale=20.0),
    }
    joints = {
        "O2": _revolute("frame", "crank"),
        "A": _revolute("crank", "block"),
        "S": _prismatic("lever", "block"),
        "O4": _revolute("frame", "lever"),
        "B": _revolute("lever", "link"),
        "C": _revolute("link", "ram"),
        "G": _prismatic("frame", "ram"),
    }
    return {
        "type": "linkage",
        "frame": {"O2": [0.0, 0.0], "O4": [0.0, -round(d, 6)], "G": [0.0, round(height, 6)]},
        "crank": "crank",
        "links": links,
        "joints": joints,
        "branches": _branches(rng, "C"),
        "output": {"joint": "G"},
    }


def yoke_and_wedge(rng) -> dict:
    """RPP + PRP: a Scotch yoke (a block on the crank pin slides in the yoke's vertical slot, the yoke on the
    frame's horizontal guide), then a shoe sliding in the yoke's inclined slot pinned to a plunger on the frame's
    vertical guide: the wedge lifts the plunger. The output is the plunger's travel."""
    r = rng.uniform(0.04, 0.1)
    incline = rng.uniform(25.0, 65.0) * rng.choice([-1, 1])
    x0 = rng.uniform(0.15, 0.3)
    links = {
        "crank": _link(rng, {"A": 0j, "B": r + 0j}),
        "block": _link(rng, {"B": 0j, "K": 0j}, mass_scale=0.5),
        "yoke": _link(rng, {"K": 0j, "Y": 0j, "W": complex(x0, 0.0)}, mass_scale=6.0),
        "shoe": _link(rng, {"W": 0j, "C": 0j}, mass_scale=0.5),
        "plunger": _link(rng, {"C": 0j, "P": 0j}, mass_scale=3.0),
    }
    joints = {
        "A": _revolute("frame", "crank"),
        "B": _revolute("crank", "block"),
        "K": _prismatic("yoke", "block", 90.0),
        "Y": _prismatic("frame", "yoke"),
        "W": _prismatic("yoke", "shoe", incline),
        "C": _revolute("shoe", "plunger"),
        "P": _prismatic("frame", "plunger", 90.0),
    }
    return {
        "type": "linkage",
        "frame": {"A": [0.0, 0.0], "Y": [0.0, 0.0], "P": [round(x0, 6), 0.0]},
        "crank": "crank",
        "links": links,
        "joints": joints,
        "output": {"joint": "P"},
    }


def parallelogram(rng) -> dict:
    """Source 001's parallelogram A B C D with the redundant link EF (docs/linkages.md), scaled at random and
    rocked by a crank-rocker (crank O K, rod K B1); the output is the redundant link."""
    s = rng.uniform(0.2, 1.0)
    links = {
        "crank": _link(rng, {"O": 0j, "K": 0.2 * s + 0j}),
        "rod": _link(rng, {"K": 0j, "B1": 0.9 * s + 0j}),
        "link1": _link(rng, {"A": 0j, "B": s + 0j, "B1": 0.5 * s + 0j}),
        "link2": _link(rng, {"B": 0j, "C": 2 * s + 0j, "E": s + 0j}),
        "link3": _link(rng, {"D": 0j, "C": s + 0j}),
        "link5": _link(rng, {"F": 0j, "E": s + 0j}),
    }
    joints = {
        "O": _revolute("frame", "crank"),
        "K": _revolute("crank", "rod"),
        "B1": _revolute("rod", "link1"),
        "A": _revolute("frame", "link1"),
        "B": _revolute("link1", "link2"),
        "C": _revolute("link2", "link3"),
        "D": _revolute("frame", "link3"),
        "E": _revolute("link2", "link5"),
        "F": _revolute("frame", "link5"),
    }
    frame = {"O": [round(0.9 * s, 6), 0.0], "A": [0.0, 0.0], "D": [round(2 * s, 6), 0.0], "F": [round(s, 6), 0.0]}
    return {
        "type": "linkage",
        "frame": frame,
        "crank": "crank",
        "links": links,
        "joints": joints,
        "branches": {"B1": -1, "C": 1},
        "output": {"link": "link5"},
    }


MEMBERS = {  # name -> (generator, the groups structure finds, governed)
    "four_bar": (four_bar, ["RRR"], False),
    "watt_six_bar": (watt_six_bar, ["RRR", "RRR"], True),
    "crank_slider": (crank_slider, ["RRP"], True),
    "six_bar_ram": (six_bar_ram, ["RRR", "RRP"], False),
    "shaper": (shaper, ["RPR", "RRP"], False),
    "yoke_and_wedge": (yoke_and_wedge, ["RPP", "PRP"], True),
    "parallelogram": (parallelogram, ["RRR", "RRR", "redundant link"], False),
}


def member(name: str, seed: int) -> dict:
    """The scene data of one member of the family, the first of its draws (from default_rng((seed, index))) that
    validates."""
    generator, groups, governed = MEMBERS[name]
    rng = np.random.default_rng([seed, list(MEMBERS).index(name)])
    refusals = []
    for _ in range(ATTEMPTS):
        scene = _scene(name, generator(rng), governed, groups)
        data = {key: value for key, value in scene.items() if key != "expected"}
        try:
            validate_scene(data)
        except SceneError as error:
            refusals.append(str(error))
            continue
        return scene
    raise AssertionError(f"no valid {name} in {ATTEMPTS} draws; the last refusal: {refusals[-1]}")


def family(seed: int) -> list[tuple[str, dict]]:
    """Every member of the family for this seed."""
    return [(name, member(name, seed)) for name in MEMBERS]
