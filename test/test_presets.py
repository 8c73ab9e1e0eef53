"""The preset mechanisms built as linkages (mechanisms/presets.py) against the presets' closed forms
(test/closed_forms.py: the hand-written reductions and kinetostatics the product ran before).

For every bundled scene's mechanism and for random geometries (an offset, a crank mass and centre, V engines,
four-bars open and crossed at any frame angle, walking beams with other masses and angles): the product's reduction
(mechanisms.build_reduced: the code generated from the linkage's groups) and the general solver's (flat_poses.reduced,
compiled) equal the closed forms (J_links, dJ/dphi, M_weight, q, dq/dphi) to 1e-12 of each quantity's largest size
over the turn, with and without gravity; a multi-cylinder engine's every piston (its guide's travel) too; the
preset's named point motions equal the closed forms'; the joint loads joint friction reads
(mechanisms.build_kinetostatics, the linkage's by groups) equal the hand-written d'Alembert's; and a whole machine
with joint friction (compressor_friction, four_bar_rocker) written as a scene's linkage equals the preset machine.
"""

from __future__ import annotations

import math
from dataclasses import replace

import closed_forms
import numpy as np
import pytest
from support import linkage_scene_entry, model_of

from mech_regulator.mechanisms import (
    build_kinetostatics,
    build_reduced,
    kinetostatics,
    mechanism_geometry,
    point_motions,
    presets,
)
from mech_regulator.mechanisms.linkage import checked, make_reduced
from mech_regulator.scene import load_scene, mechanism_keys

ANGLES = np.linspace(0.0, 2.0 * math.pi, 37)[:-1] + 0.0123
GRAVITY = (0.7, -9.81)
TOLERANCE = 1e-12
BUNDLED = [
    "compressor",
    "crank_slider_bench",
    "engine",
    "engine_inline4",
    "four_bar_rocker",
    "press",
    "press_coupling",
    "walking_beam",
]


def bundled_mechanism(name: str):
    """The bundled scene's mechanism (press_coupling's: its driven part's)."""
    machine = load_scene(name).machine
    return machine.mechanism if machine.mechanism is not None else machine.coupling.driven.mechanism


def random_crank_slider(rng, cylinders=None) -> mechanism_keys.CrankSlider:
    crank = rng.uniform(0.03, 0.1)
    offset = rng.uniform(-0.4, 0.4) * crank
    return mechanism_keys.CrankSlider(
        type="crank_slider",
        crank=crank,
        rod=(abs(offset) + crank) * rng.uniform(1.3, 4.0),
        offset=offset,
        crank_mass=rng.uniform(0.5, 3.0),
        crank_cg=rng.uniform(-0.5, 0.8) * crank,
        rod_mass=rng.uniform(0.2, 5.0),
        rod_cg=rng.uniform(0.1, 0.6) * 0.1,
        rod_inertia=rng.uniform(1e-4, 0.05),
        slider_mass=rng.uniform(0.1, 10.0),
        cylinders=cylinders,
    )


def random_four_bar(rng, branch: str) -> mechanism_keys.FourBar:
    """A Grashof crank-rocker (the crank shortest, s + l < p + q) at a random frame angle."""
    while True:
        crank = rng.uniform(0.02, 0.05)
        coupler, rocker, frame = rng.uniform(0.06, 0.2, 3)
        lengths = sorted((crank, coupler, rocker, frame))
        if lengths[0] == crank and lengths[0] + lengths[3] < lengths[1] + lengths[2] - 0.01:
            return mechanism_keys.FourBar(
                type="four_bar",
                crank=crank,
                coupler=coupler,
                rocker=rocker,
                frame=frame,
                frame_angle_deg=rng.uniform(-180.0, 180.0),
                branch=branch,
                crank_mass=rng.uniform(0.1, 1.0),
                crank_cg=rng.uniform(-0.5, 1.0) * crank,
                coupler_mass=rng.uniform(0.1, 2.0),
                coupler_cg=rng.uniform(-0.2, 1.0) * coupler,
                coupler_inertia=rng.uniform(1e-5, 1e-3),
                rocker_mass=rng.uniform(0.1, 2.0),
                rocker_cg=rng.uniform(-0.2, 1.0) * rocker,
                rocker_inertia=rng.uniform(1e-5, 1e-3),
            )


def random_walking_beam(rng) -> mechanism_keys.WalkingBeam:
    """The bundled walking beam with random masses, centres and inertias, its frame and beam turned together by a
    random angle (the parallelograms then never flatten either)."""
    data = bundled_mechanism("walking_beam").model_dump()
    turn = rng.uniform(-40.0, 40.0)
    data["frame_angle_deg"] += turn
    data["beam_angle_deg"] += turn
    for key in (
        "crank_mass",
        "coupler_mass",
        "rocker_mass",
        "tie_mass",
        "side_mass",
        "shuttle_mass",
        "coupler_inertia",
        "rocker_inertia",
        "side_inertia",
    ):
        data[key] = data[key] * rng.uniform(0.3, 3.0)
    for key in ("crank_cg", "coupler_cg", "rocker_cg", "side_cg"):
        data[key] = data[key] * rng.uniform(-1.0, 2.0) if key != "coupler_cg" else data[key] * rng.uniform(0.0, 2.0)
    data["coupler_cg_angle_deg"] = rng.uniform(-180.0, 180.0)
    return mechanism_keys.WalkingBeam(**data)


def random_mechanisms():
    rng = np.random.default_rng(21)
    mechanisms = [random_crank_slider(rng) for _ in range(3)]
    mechanisms.append(
        random_crank_slider(
            rng,
            [
                mechanism_keys.Cylinder(),
                mechanism_keys.Cylinder(throw_deg=rng.uniform(0, 360), bank_deg=rng.uniform(-90, 90)),
                mechanism_keys.Cylinder(throw_deg=rng.uniform(0, 360), bank_deg=rng.uniform(-90, 90)),
            ],
        )
    )
    mechanisms += [random_four_bar(rng, branch) for branch in ("open", "crossed", "open", "crossed")]
    mechanisms += [random_walking_beam(rng) for _ in range(2)]
    return mechanisms


CASES = [(name, bundled_mechanism(name)) for name in BUNDLED] + [
    (f"random-{k}-{m.type}", m) for k, m in enumerate(random_mechanisms())
]


def _scales(rows: np.ndarray) -> np.ndarray:
    """Each column's largest size over the turn (the scale of that quantity), at least the smallest normal float."""
    return np.maximum(np.max(np.abs(rows), axis=0), np.finfo(float).tiny)


def _pistons(linkage, structure, guides):
    """Every piston's (x_i, x_i') from the built linkage: the travel of its guide (flat_poses.reduced_from_poses's
    formula, the linkage with that guide as its output)."""
    reductions = [make_reduced(replace(linkage, output_joint=guide), structure, None) for guide in guides]
    return lambda phi: [reduced(phi)[3:] for reduced in reductions]


def closed_form_reduced(mechanism, gravity):
    """The preset's hand-written reduced(phi) (closed_forms.py); a multi-cylinder engine's with the pistons' tuples."""
    geometry = mechanism_geometry(mechanism)
    if isinstance(mechanism, mechanism_keys.CrankSlider) and mechanism.cylinders is not None:
        return closed_forms.multi_cylinder_reduced(
            geometry, [c.throw_deg for c in mechanism.cylinders], [c.bank_deg for c in mechanism.cylinders], gravity
        )
    build = {
        mechanism_keys.CrankSlider: closed_forms.crank_slider_reduced,
        mechanism_keys.FourBar: closed_forms.four_bar_reduced,
        mechanism_keys.WalkingBeam: closed_forms.walking_beam_reduced,
    }[type(mechanism)]
    return build(geometry, gravity)


@pytest.mark.parametrize("name, mechanism", CASES, ids=[name for name, _ in CASES])
@pytest.mark.parametrize("gravity", [None, GRAVITY], ids=["weightless", "gravity"])
def test_preset_linkage_reduces_as_the_preset(name, mechanism, gravity):
    """J_links, dJ/dphi, M_weight, q, q' of the product (the generated code) and of the general solver against the
    closed form's, each to 1e-12 of its largest size over the turn (a four-bar's rocker angle too: the linkage reports
    it within pi of its angle at phi = 0, as link_angles does). A multi-cylinder engine: the sums, and each piston's
    x_i, x_i' (its guide's travel)."""
    linkage = presets.preset_linkage(mechanism)
    structure = checked(linkage)
    theirs = closed_form_reduced(mechanism, gravity)
    several = isinstance(mechanism, mechanism_keys.CrankSlider) and mechanism.cylinders is not None
    general = make_reduced(linkage, structure, gravity)
    pistons = _pistons(linkage, structure, presets.guide_joints(mechanism)) if several else None
    products = [
        build_reduced(mechanism, gravity),
        (lambda phi: (*general(phi)[:3], tuple(x for x, _ in pistons(phi)), tuple(dx for _, dx in pistons(phi))))
        if several
        else general,
    ]
    rows = np.array([np.array(_flat(theirs(phi))) for phi in ANGLES])
    scales = _scales(rows)
    for ours in products:
        differences = np.array([_flat(ours(phi)) for phi in ANGLES]) - rows
        assert np.all(np.abs(differences) <= TOLERANCE * scales), (np.max(np.abs(differences), axis=0), scales)
    assert np.all(rows[:, 2] == 0.0) if gravity is None else np.any(rows[:, 2] != 0.0)  # weights compared, not zeros


def _flat(values) -> list[float]:
    """(J, dJ, weight, q, dq) with a multi-cylinder engine's tuples (x_1.., x_1'..) as x_1, x_1', x_2, ..."""
    if isinstance(values[3], tuple):
        return [*values[:3], *(value for pair in zip(values[3], values[4]) for value in pair)]
    return list(values)


def test_multi_cylinder_engine_has_a_crank_pin_rod_and_piston_per_cylinder():
    """engine_inline4: one crank with four pins, four RRP groups; the guides in cylinder order, the first the
    linkage's output."""
    mechanism = bundled_mechanism("engine_inline4")
    linkage = presets.preset_linkage(mechanism)
    assert presets.guide_joints(mechanism) == ["guide_1", "guide_2", "guide_3", "guide_4"]
    assert linkage.output_joint == "guide_1"
    assert sorted(linkage.link("crank").points) == ["B", "crank_bearing"] + [f"crank_pin_{i}" for i in range(1, 5)]
    assert [group.kind for group in checked(linkage).groups] == ["RRP"] * 4
    assert presets.guide_joints(bundled_mechanism("engine")) == ["guide"]


@pytest.mark.parametrize("name, mechanism", CASES, ids=[name for name, _ in CASES])
def test_preset_points_move_as_the_presets(name, mechanism):
    """mechanisms.point_motions' points (crank-slider and four-bar B, C; walking beam A..E) under the same names
    from the linkage: position, P', P'' to 1e-12 of the mechanism's size."""
    linkage = presets.preset_linkage(mechanism)
    ours, theirs = point_motions(mechanism), closed_forms.preset_point_motions(mechanism)
    for phi in ANGLES[::3]:
        reference, found = theirs(phi), ours(phi)
        size = max(abs(value) for motion in reference.values() for value in motion)
        assert set(reference) == set(linkage.points) and set(reference) <= set(found)
        for point, motion in reference.items():
            assert found[point] == pytest.approx(motion, abs=TOLERANCE * size), point


def _kinetostatics_cases():
    rng = np.random.default_rng(7)
    cases = [bundled_mechanism("compressor"), bundled_mechanism("press"), bundled_mechanism("four_bar_rocker")]
    return cases + [random_crank_slider(rng) for _ in range(2)] + [random_four_bar(rng, b) for b in ("open", "crossed")]


@pytest.mark.parametrize("mechanism", _kinetostatics_cases())
@pytest.mark.parametrize("gravity", [None, GRAVITY], ids=["weightless", "gravity"])
def test_preset_linkage_joint_loads_are_the_presets(mechanism, gravity):
    """linkage.make_joint_loads against kinetostatics.py, field by field at random (phi, omega, Q): the joint names;
    every reaction's R0 and R1 (each joint lists its outer link first: the preset's F_ij) and the balancing moment
    to 1e-12 of the largest; the ratios equal for the bearings and the guide, opposite for the pins (the linkage's
    theta_first' - theta_second' is the outer link's, the preset's the inner link's)."""
    ours, names = build_kinetostatics(mechanism, gravity)
    geometry, weight = mechanism_geometry(mechanism), gravity if gravity is not None else (0.0, 0.0)
    if isinstance(mechanism, mechanism_keys.CrankSlider):
        theirs, preset_names = (
            closed_forms.crank_slider_kinetostatics(geometry, weight),
            kinetostatics.CRANK_SLIDER_JOINTS,
        )
    else:
        theirs, preset_names = closed_forms.four_bar_kinetostatics(geometry, weight), kinetostatics.FOUR_BAR_JOINTS
    assert names == preset_names
    signs = np.array([1.0, -1.0, -1.0, 1.0])
    rng = np.random.default_rng(3)
    for phi, omega, force in zip(rng.uniform(0, 2 * math.pi, 25), rng.uniform(-80, 80, 25), rng.uniform(-800, 800, 25)):
        first, second = ours(phi, omega, force), theirs(phi, omega, force)
        scale = max(abs(value) for value in second.constant)
        rate_scale = max(abs(value) for value in second.per_epsilon)
        assert np.abs(np.subtract(first.constant, second.constant)).max() <= TOLERANCE * scale
        assert np.abs(np.subtract(first.per_epsilon, second.per_epsilon)).max() <= TOLERANCE * rate_scale
        assert first.balancing[0] == pytest.approx(
            second.balancing[0], abs=TOLERANCE * (abs(second.balancing[0]) + scale * 0.1)
        )
        assert first.balancing[1] == pytest.approx(second.balancing[1], abs=TOLERANCE * rate_scale * 0.1)
        assert np.abs(np.array(first.ratios) - signs * second.ratios).max() <= TOLERANCE * max(map(abs, second.ratios))


def test_four_bar_output_angle_follows_the_rocker_beyond_pi():
    """four_bar.link_angles' th4 is continuous around the direction D->A (it may leave [-pi, pi]); the linkage reports
    its output link's angle within pi of its angle at phi = 0 (Linkage.output_reference), so the two agree where th4
    lies beyond pi too: with the frame at 150 deg the rocker hangs around th1 + pi = 330 deg over the whole turn. A
    reference 2 pi away gives the angle 2 pi away (the reference is what is read)."""
    mechanism = bundled_mechanism("four_bar_rocker").model_copy(update={"frame_angle_deg": 150.0})
    theirs = closed_form_reduced(mechanism, None)
    expected = np.array([theirs(phi)[3] for phi in ANGLES])
    assert np.all(expected > math.pi)
    linkage = presets.preset_linkage(mechanism)
    for ours in (build_reduced(mechanism, None), make_reduced(linkage, checked(linkage), None)):
        assert np.abs(np.array([ours(phi)[3] for phi in ANGLES]) - expected).max() <= TOLERANCE * math.pi
    shifted = replace(linkage, output_reference=linkage.output_reference - 2.0 * math.pi)
    moved = make_reduced(shifted, checked(shifted), None)
    assert np.abs(np.array([moved(phi)[3] for phi in ANGLES]) - (expected - 2.0 * math.pi)).max() <= 1e-12 * math.pi


# ----------------------------------------------------------------------------------------------
# the whole machine with joint friction


def _same_friction(preset, linkage, seed: int) -> None:
    """At random states the two models' crank accelerations (the implicit equation with friction) and every joint's
    friction and reaction, by the same joint names, agree to 1e-12 (relative to the state's largest)."""
    rng = np.random.default_rng(seed)
    first, second = preset.rhs(), linkage.rhs()
    assert set(linkage.joint_friction.names) == set(preset.joint_friction.names)
    for phi, omega in zip(rng.uniform(0.0, 2.0 * math.pi, 30), rng.uniform(-40.0, 40.0, 30)):
        y = np.array([phi, omega])
        epsilon = first(0.0, y)[1]
        assert second(0.0, y)[1] == pytest.approx(epsilon, rel=1e-12, abs=1e-12 * abs(omega) ** 2)
        q, dq = preset.reduced(phi)[3:]
        force = preset._output_force(True)(0.0, phi, omega, q, dq, 1.0)
        ours = linkage.joint_friction.joint_values(phi, omega, epsilon, force)
        theirs = preset.joint_friction.joint_values(phi, omega, epsilon, force)
        by_name = dict(zip(linkage.joint_friction.names, zip(ours[0], ours[1])))
        scale = max(theirs[1])
        for name, friction, reaction in zip(preset.joint_friction.names, theirs[0], theirs[1]):
            assert by_name[name] == pytest.approx((friction, reaction), abs=1e-12 * scale), name
        assert ours[2] == pytest.approx(theirs[2], rel=1e-12)


def test_compressor_friction_on_the_preset_linkage_is_the_preset_machine():
    """compressor_friction with its crank-slider replaced by presets.preset_linkage's linkage (written as the scene's
    `type: linkage` entry), its journals named as the preset's joints (crank_bearing, crank_pin, wrist_pin) and the
    guide friction on the prismatic joint 'guide': the same acceleration, friction and reactions, to 1e-12. The
    compressor's crank is massless, so the linkage's crank has no inertia either and machine.inertia stays."""
    scene = load_scene("compressor_friction")
    data = scene.model_dump(exclude_none=True)
    data["machine"]["mechanism"] = linkage_scene_entry(presets.preset_linkage(scene.machine.mechanism))
    friction = data["machine"]["joint_friction"]
    friction["journals"] = friction.pop("joints")
    _same_friction(model_of(scene.model_dump(exclude_none=True)), model_of(data), seed=5)


def test_four_bar_friction_on_the_preset_linkage_is_the_preset_machine():
    """four_bar_rocker with journals in its four joints, and the same machine on presets.preset_linkage's linkage with
    the same journals by the same names: the scene refuses the crank's negative inertia about its centre
    (-m cg^2), so the crank's inertia is set to 0 there and machine.inertia lowered by m cg^2 (the same J)."""
    radii = {"crank_bearing": 0.012, "crank_pin": 0.008, "rocker_pin": 0.006, "rocker_bearing": 0.01}
    data = load_scene("four_bar_rocker").model_dump(exclude_none=True)
    data["machine"]["joint_friction"] = {
        "coefficient": 0.08,
        "joints": {name: {"radius": radius, "fit": "new"} for name, radius in radii.items()},
    }
    preset = model_of(data)
    mechanism = preset.scene.machine.mechanism
    linkage = presets.preset_linkage(mechanism)
    crank = linkage.link("crank")
    linkage = replace(
        linkage, links=tuple(replace(link, inertia=0.0) if link is crank else link for link in linkage.links)
    )
    data["machine"]["mechanism"] = linkage_scene_entry(linkage)
    data["machine"]["inertia"] -= mechanism.crank_mass * mechanism.crank_cg**2
    data["machine"]["joint_friction"]["journals"] = data["machine"]["joint_friction"].pop("joints")
    _same_friction(preset, model_of(data), seed=7)
