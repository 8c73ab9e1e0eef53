"""The effect-cost chain adds one effect at a time, and its measurement runs every link to the end.

The chain is the evidence for "only the effects a scene calls for": each link's model must differ from
the previous one by exactly the effect it names, or the measured cost would be blamed on the wrong
effect. Costs themselves are printed by `mech-regulator bench accuracy`, never asserted.
"""

from __future__ import annotations

from mech_regulator.bench.effect_cost import EFFECT_CHAIN, effect_cost_table, measure_effect_costs, step_model


def test_each_link_adds_exactly_its_effect():
    """Model structure along the chain: mechanism, then the engine drive, then the governor, its friction,
    the shorter stroke, then the coupling, then joint friction; nothing else changes between neighbours."""
    models = [step_model(step) for step in EFFECT_CHAIN]
    assert [model.reduced is not None for model in models] == [False] + [True] * 7
    assert [model.effects[0].formula.startswith("engine") for model in models] == [False, False] + [True] * 6
    assert [model.governor is not None for model in models] == [False] * 3 + [True] * 5
    assert [model.governor is not None and model.governor.has_friction for model in models] == [False] * 4 + [True] * 4
    strokes = [model.scene.governor.stroke[1] for model in models[3:]]
    assert strokes[0] == strokes[1] > strokes[2] == strokes[3] == strokes[4]
    assert [model.coupling is not None for model in models] == [False] * 6 + [True] * 2
    assert [len(model.state_names()) for model in models] == [2, 2, 2, 4, 4, 4, 6, 6]
    assert [model.joint_friction is not None for model in models] == [False] * 7 + [True]
    assert models[-1].joint_friction.names == ("crank_bearing", "crank_pin", "wrist_pin", "guide")
    # the same loads everywhere: the coupling moves the fan to the driven part, it does not drop it
    fans = [
        sum(
            effect.name == "fan" for effect in model.effects + (model.coupling.driven_effects if model.coupling else ())
        )
        for model in models
    ]
    assert fans == [1] * 8


def test_measurement_runs_every_link_to_the_end():
    """One repeat of the chain: every run completes, the sleeve lands on its stop once stops are reached,
    and the table has a row per link."""
    costs = measure_effect_costs(repeats=1)
    assert [cost.status for cost in costs] == ["complete"] * len(EFFECT_CHAIN)
    assert costs[4].events_per_s < costs[5].events_per_s
    assert all(cost.rhs_us > 0 and cost.rhs_per_s > 0 for cost in costs)
    table = effect_cost_table(costs).splitlines()
    assert len(table) == 2 + len(EFFECT_CHAIN) and table[2].startswith("| constant J | 2 |")
