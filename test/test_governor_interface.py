"""The governor level's interface (governors/kind.py): every kind of governor the scene knows is built through it, and
nothing outside governors/ reads which kind a governor is (docs/governors.md, Adding a governor)."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
import pytest
from pydantic import Field

from mech_regulator.analysis import operating_point
from mech_regulator.effects.definition import union_members
from mech_regulator.governors import GovernorKind, kind
from mech_regulator.model import build_model
from mech_regulator.scene import governor_keys, key_types
from mech_regulator.scene.loading import load_scene

PACKAGE = Path(__file__).resolve().parent.parent / "mech_regulator"
GOVERNED_SCENES = (
    "engine_direct",
    "engine_indirect_none",
    "engine_indirect_rigid",
    "engine_indirect_isodromic",
    "engine_hartnell",
    "engine_pi",
)
# what reading a governor's kind outside its module looks like: its class, its module, a test of its kind or type
KIND_READS = re.compile(
    r"ElectronicGovernor|governors\.(mechanical|pi)\b|governors import (mechanical|pi)\b|"
    r"\.kind [!=]= \"(pi|direct|indirect|hartnell)\"|"
    r"isinstance\([^)]*Governor\b|governor\.type [!=]= \""
)


def test_every_governor_entry_of_the_scene_has_a_registered_builder():
    members = union_members(governor_keys.Governor)
    assert len(members) == 4  # direct, indirect, hartnell, pi
    for member in members:
        assert callable(kind.builder_of(member.model_construct()))


@pytest.mark.parametrize("name", GOVERNED_SCENES)
def test_each_bundled_governor_goes_through_the_interface(name):
    model = build_model(load_scene(name))
    governor = model.governor
    assert isinstance(governor, GovernorKind)
    assert len(governor.state_units) == len(governor.state_names)
    assert model.state_names()[2 : 2 + len(governor.state_names)] == governor.state_names
    y = model.initial_state()
    signals = governor.signals(y)
    for _, position, velocity in governor.joints():
        assert position == "throttle" or position in signals
        assert velocity is None or velocity in signals
    assert governor.plotted()[0] in signals
    point = operating_point(model, model.external_load(0.0))
    state = governor.equilibrium_state(point)
    assert state.shape == governor.state_scale(point).shape == (len(governor.state_names),)
    rates = governor.derivatives(None, ideal=True)(np.concatenate([[0.0, point.speed], state]))
    assert np.allclose(rates, 0.0, atol=1e-6)  # the equilibrium of its averaged statics is at rest
    assert len(governor.linear_guards(governor.initial_mode(y))) == len(governor.guards(governor.initial_mode(y)))


@pytest.mark.parametrize("name", GOVERNED_SCENES)
def test_a_governor_s_signals_of_one_state_are_those_of_the_same_state_among_many(name):
    """signals(y) of one state (a node's every exchange) and of states along the last axis (the recording's columns)
    are computed apart: for the sleeve z(a) and its velocity z' = dz/da a' they agree, and z' is the derivative of
    z(a(t)) along a' (a central difference of the sleeve)."""
    governor = build_model(load_scene(name)).governor
    states = np.repeat(build_model(load_scene(name)).initial_state()[:, None], 3, axis=1)
    states[2] += np.array([-0.05, 0.0, 0.05])  # a centrifugal governor's arm angle a [rad], a PI's integral part
    if states.shape[0] > 3:
        states[3] = np.array([0.3, -1.2, 2.0])  # the arm's rate a' [rad/s]
    many = governor.signals(states)
    for index in range(3):
        one = governor.signals(states[:, index])
        assert set(one) == set(many)
        assert all(float(one[key]) == float(np.asarray(many[key])[index]) for key in one)
    if "sleeve" in many:
        step = 1e-6
        moved = states.copy()
        moved[2] += step * states[3]
        back = states.copy()
        back[2] -= step * states[3]
        rate = (governor.signals(moved)["sleeve"] - governor.signals(back)["sleeve"]) / (2 * step)
        assert np.allclose(many["sleeve_velocity"], rate, rtol=1e-6, atol=1e-12)


def test_no_module_above_the_governors_reads_a_governor_s_kind():
    """The floors above governors/ (model, solvers, analysis, bench, viz, cli, nodes): the scene's schema below them
    holds the governor entries themselves (and checks the scenario's initial sleeve and servo against them)."""
    readers = [
        f"{path.relative_to(PACKAGE)}:{number}: {line.strip()}"
        for path in sorted(PACKAGE.rglob("*.py"))
        if not {"governors", "scene"} & set(path.relative_to(PACKAGE).parts)
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1)
        if KIND_READS.search(line)
    ]
    assert readers == []


def test_the_check_of_kinds_names_a_governor_entry_without_a_builder():
    class Unbuilt(key_types.SceneModel):
        type: Literal["unbuilt"]

    union = Annotated[governor_keys.DirectGovernor | Unbuilt, Field(discriminator="type")]
    with pytest.raises(TypeError, match="Unbuilt"):
        kind.check_covered(union)
    kind.check_covered(governor_keys.Governor)
