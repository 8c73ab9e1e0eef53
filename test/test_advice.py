"""The stiffness advice's cheap path: advice.fastest_mode with a threshold computes the Jacobian's infinity norm first
and the eigenvalues only when the norm says one could exceed it; stiffness_refusal's verdicts and messages are those
of the full computation on every bundled scene and on stiff ones it refuses."""

from __future__ import annotations

import pytest

from mech_regulator.model import build_model
from mech_regulator.scene import bundled_scenes, load_scene
from mech_regulator.scene.limits import MAX_STEPS
from mech_regulator.solvers import advice

FULL_FASTEST_MODE = advice.fastest_mode
STIFF = [
    ("engine_indirect_rigid", ["governor.servo.gain=1e15", "scenario.load_events=[]", "scenario.duration=1"]),
    ("startup", ["machine.loads=[{type: fan, coefficient: 1e14}]"]),
    ("two_mass", ["machine.coupling.stiffness=1e13", "scenario.duration=10"]),
]


def model_of(name: str, overrides: list[str]):
    return build_model(load_scene(name, ["solver.method=RK45", *overrides]))


@pytest.mark.parametrize("name, overrides", [(name, []) for name in sorted(bundled_scenes())] + STIFF)
def test_the_cheap_path_keeps_every_verdict(monkeypatch, name, overrides):
    model = model_of(name, overrides)
    full = FULL_FASTEST_MODE(model)
    threshold = advice.STABILITY_LIMIT * MAX_STEPS / model.scene.scenario.duration
    cheap = FULL_FASTEST_MODE(model, at_least=threshold)
    assert cheap == full or (cheap is None and (full is None or full[0] <= threshold))
    if full is not None:  # the norm never hides a mode above the threshold, however close to it
        for below in (0.0, 0.5 * full[0], full[0] * (1.0 - 1e-12)):
            assert FULL_FASTEST_MODE(model, at_least=below) == full
    verdict = advice.stiffness_refusal(model)
    monkeypatch.setattr(advice, "fastest_mode", lambda model, at_least=0.0: FULL_FASTEST_MODE(model))
    assert verdict == advice.stiffness_refusal(model)
    if (name, overrides) in STIFF:
        assert verdict is not None and "for stability alone" in verdict


def test_the_eigenvalues_are_skipped_on_the_benchmark_s_machine():
    model = model_of("crank_slider_bench", [])
    threshold = advice.STABILITY_LIMIT * MAX_STEPS / model.scene.scenario.duration
    assert FULL_FASTEST_MODE(model) is not None and FULL_FASTEST_MODE(model, at_least=threshold) is None


@pytest.mark.parametrize("name", sorted(bundled_scenes()))
def test_every_state_of_a_bundled_scene_names_the_keys_that_set_its_speed(name):
    """The refusal names the keys behind the fastest state: every state a bundled scene's model has is listed."""
    names = build_model(load_scene(name)).state_names()
    assert [state for state in names if state not in advice.STATE_KEYS] == []
