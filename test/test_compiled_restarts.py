"""The compiled steppers' own restarts (solvers/compiled/integrators.py: _kink_restart on a switch window's edge,
_piece_restart into the next of the governor's speed pieces in a co-simulation) give the numbers of the outer loop's
restarts (solvers/compiled/run.py returning to Python at every edge and piece) bit for bit: the same steps, states,
dense output, events and solver statistics. Oracle: that outer loop, which the reference path checks
(test_compiled_path, test_cosim_fast)."""

from __future__ import annotations

import functools

import numpy as np
import pytest
from support import model_of, scene
from test_compiled_path import shortened

from mech_regulator.analysis.energy import step_edges
from mech_regulator.solvers.compiled import run
from mech_regulator.solvers.compiled.codegen import compile_scene
from mech_regulator.solvers.cosim import GovernorStepper, follow_samples
from mech_regulator.solvers.time_domain import integrate_time_domain

# started fast (300 rad/s against about 224 on the orbit): the sleeve flies to its high stop and leaves it again, so
# mode events fall between the engine's kinks (27 a cycle)
ENGINE = shortened("engine_direct", 0.5, scenario__initial__omega=300.0)


def outer_loop(model):
    """The model's compiled segment with every restart left to the outer loop (no kink grid, no pieces inside)."""
    compiled = compile_scene(model)
    layout = run._Layout.of(model, compiled)
    layout = layout._replace(fixed=layout.fixed._replace(kink_grid=np.zeros(0)), pieces_inside=False)
    return functools.partial(run._compiled_segment, compiled, layout)


@pytest.mark.parametrize("method, step", [("DOP853", None), ("RK45", None), ("RK4", 5e-4)])
def test_kinks_restarted_inside_the_stepper_are_the_outer_loop_s(method, step):
    settings = {"solver__method": method} | ({"solver__step": step} if step else {})
    model = model_of(scene(ENGINE, solver__path="fast", **settings))
    inside = integrate_time_domain(model, None, run.compiled_segment(model))
    outside = integrate_time_domain(model, None, outer_loop(model))
    assert inside.status == outside.status == "complete"
    assert inside.stats == outside.stats and inside.stats.switches > 200, inside.stats
    assert inside.events == outside.events and len(inside.events) >= 2, inside.events
    assert inside.modes == outside.modes
    assert len(inside.interpolants) * 10 < len(outside.interpolants)  # the restarts were made inside the calls
    edges = step_edges(outside)
    np.testing.assert_array_equal(step_edges(inside), edges)
    times = np.union1d(edges, np.linspace(0.0, outside.t_end, 1001))  # on every step's edge (kinks too) and between
    np.testing.assert_array_equal(inside(times), outside(times))


def test_speed_pieces_followed_inside_the_stepper_are_the_outer_loop_s():
    """The governor follows the engine's speed of the monolithic run (its ripple, and the sleeve reaching its high
    stop and leaving it) in exchange steps of 20 ms of eight quadratic pieces each (the corrected coupling's), on its
    own and with the outer loop."""
    model = model_of(scene(ENGINE, solver__path="fast"))
    engine = integrate_time_domain(model, None, run.compiled_segment(model))
    inside, outside = GovernorStepper(model), GovernorStepper(model)
    outside._follow_samples = functools.partial(follow_samples, outer_loop(outside.regulator))
    pieces_inside = pieces_outside = 0
    for start in np.arange(0.0, 0.5, 0.02):
        times = list(np.linspace(start, start + 0.02, 17))
        speeds = list(engine(np.array(times))[1])
        ours, theirs = inside.follow(times[-1], (times, speeds)), outside.follow(times[-1], (times, speeds))
        assert ours.stats == theirs.stats and ours.events == theirs.events
        np.testing.assert_array_equal(inside.state, outside.state)
        assert inside.mode == outside.mode
        probe = np.union1d(step_edges(theirs), np.linspace(start, start + 0.02, 41))
        np.testing.assert_array_equal(ours(probe), theirs(probe))
        pieces_inside += len(ours.interpolants)
        pieces_outside += len(theirs.interpolants)
    assert inside.stats == outside.stats and inside.events == outside.events
    assert [name for _, name, _ in inside.events][:2] == ["sleeve reaches the high stop", "sleeve leaves the high stop"]
    assert pieces_inside * 3 < pieces_outside  # most pieces were gone on into inside the calls
