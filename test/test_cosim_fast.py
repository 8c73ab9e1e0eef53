"""The co-simulation (solvers/cosim.py: what `simulate --exchange-step` and the ROS nodes run) on the compiled fast
path: the steppers step each subsystem's compiled twin (solvers/compiled/run.compiled_segment) and give the
reference co-simulation's numbers to the integration error (oracle: the reference path's co-simulation, itself
checked against the monolithic simulation in test_ros_nodes and test_hard_cases_coupling)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from support import model_of, run_cli, scene
from test_compiled_path import shortened

from mech_regulator.governors.mechanical import SLEEVE_CODE
from mech_regulator.scene import SceneError
from mech_regulator.solvers import simulate
from mech_regulator.solvers.compiled import run as compiled_run
from mech_regulator.solvers.compiled.codegen import compile_scene
from mech_regulator.solvers.cosim import GovernorStepper, MachineStepper, cosimulate, seconds, to_nanoseconds

EXCHANGE = 1e-3  # [s]
# Short runs that pass through the governor's modes: started fast (300 rad/s against about 224 on the orbit), the
# sleeve flies to its high stop and, indirect, the servo runs to its low stop; press_coupling starts with its
# driven part held at rest (a drive-train mode change in the machine's subsystem).
CASES = {
    "engine_direct": shortened("engine_direct", 0.5, scenario__initial__omega=300.0),
    "engine_indirect_none": shortened("engine_indirect_none", 0.5, scenario__initial__omega=300.0),
    "two_mass": shortened("two_mass", 0.3),
    "press_coupling": shortened("press_coupling", 0.3),
}
EXPECTED_EVENTS = {
    "engine_direct": ["sleeve reaches the high stop", "sleeve leaves the high stop"],
    "engine_indirect_none": ["sleeve reaches the high stop", "servo reaches its low stop"],
    "two_mass": [],
    "press_coupling": [],
}


def co_simulations(data: dict) -> tuple:
    """(reference model, reference co-simulation, fast co-simulation) of a scene at EXCHANGE."""
    reference = model_of(scene(data, solver__path="reference"))
    return (
        reference,
        cosimulate(reference, EXCHANGE),
        cosimulate(model_of(scene(data, solver__path="fast")), EXCHANGE),
    )


@pytest.mark.parametrize("name", CASES)
def test_fast_co_simulation_equals_the_reference(name):
    """The same exchange times, the same governor events (names, times within 1e-6 s) and states at every
    exchange time within 20 rtol of each state's largest magnitude. Measured: the compiled DOP853 takes scipy's
    steps over these short exchanges, so the runs agree to round-off (states within 1e-13 of their magnitude,
    event times within 1e-14 s); the bounds are the method's, for step sequences that part at round-off."""
    model, reference, fast = co_simulations(CASES[name])
    assert reference.status == fast.status == "complete", (reference.message, fast.message)
    np.testing.assert_array_equal(fast.times, reference.times)
    assert [what for _, what, _ in reference.events] == EXPECTED_EVENTS[name]
    assert [(what, mode) for _, what, mode in fast.events] == [(what, mode) for _, what, mode in reference.events]
    np.testing.assert_allclose([t for t, _, _ in fast.events], [t for t, _, _ in reference.events], rtol=0, atol=1e-6)
    scale = np.max(np.abs(reference.states), axis=1, keepdims=True)
    difference = np.abs(fast.states - reference.states) / scale
    rtol = model.scene.solver.rtol
    print(f"{name}: max |fast - reference| / max |state| = {difference.max():.3g} ({difference.max() / rtol:.2g} rtol)")
    assert np.all(difference <= 20.0 * rtol), np.max(difference, axis=1)
    np.testing.assert_allclose(fast.throttle, reference.throttle, rtol=0, atol=20.0 * rtol)


def test_the_tentative_throttle_stays_an_opening_when_the_servo_reaches_its_stop(monkeypatch):
    """The corrected coupling's tentative throttle over a step in which the servo reaches its low stop: the dense
    output there rounded past the stop (-7e-18), which the machine node refuses as a throttle (a bundled scene's run
    then waited peer_timeout and closed the throttle); every sample is within 0..1."""
    answers = []
    answer_corrected = GovernorStepper.answer_corrected

    def kept(self, *arguments):
        throttle, waveform, action = answer_corrected(self, *arguments)
        answers.append(waveform)
        return throttle, waveform, action

    monkeypatch.setattr(GovernorStepper, "answer_corrected", kept)
    run = cosimulate(
        model_of(scene(CASES["engine_indirect_none"], solver__path="reference")), 0.01, coupling="corrected"
    )
    assert run.status == "complete" and "servo reaches its low stop" in [what for _, what, _ in run.events]
    samples = [value for waveform in answers if waveform is not None for value in waveform[1]]
    assert len(samples) >= 2 * 49 and min(samples) == 0.0 and max(samples) <= 1.0, min(samples)


def test_the_machine_subsystem_keeps_its_drive_train_mode():
    """press_coupling's driven part is held at rest until the coupling's moment overcomes its resistance (3.1 ms
    in): the co-simulated machine plays that mode, as the monolithic run does (oracle: the monolithic run; the
    error is the hold's, first order in the exchange step: over these 0.3 s, measured 1.2e-6 rad/s on omega, and
    0.038 rad/s when the machine's subsystem ignored its modes)."""
    data = CASES["press_coupling"]
    for path in ("reference", "fast"):
        model = model_of(scene(data, solver__path=path))
        monolithic = simulate(model)
        assert [what for _, what in monolithic.events] == ["driven part breaks away forwards"]
        machine = MachineStepper(model)
        assert machine.mode == ("held",)
        machine.advance(0.01, 1.0, 0.0)
        assert machine.mode == ("forward",), path
        run = cosimulate(model, EXCHANGE)
        error = np.max(np.abs(run.states - monolithic(run.times)), axis=1)
        assert error[1] < 1e-5 and error[3] < 1e-5, (path, error)  # omega, omega_driven [rad/s]


def test_the_co_simulated_governor_compiles_without_the_machine():
    """The governor's subsystem (inertia 1, no effects, no mechanism) compiles to omega' = 0 exactly and phi' =
    omega in every sleeve mode, also for a crank-slider machine with weight, where J(phi) and the weight moment
    would otherwise enter (oracle: the subsystem's definition; the reference right-hand side gives the same
    governor rates)."""
    data = scene(CASES["engine_direct"], solver__path="fast", machine__gravity=[0.0, -9.81])
    data["machine"]["mechanism"].update(crank_mass=2.0, crank_cg=0.02, rod_mass=1.5)
    model = model_of(data)
    assert model.has_weight and model.reduced is not None
    stepper = GovernorStepper(model)
    compiled = compile_scene(stepper.regulator)
    random = np.random.default_rng(7)
    for mode in (("free", ""), ("up", ""), ("down", ""), ("stuck", ""), ("low", ""), ("high", "")):
        p = compiled.parameters_for(None, mode, None)
        assert p[3] == SLEEVE_CODE[mode[0]]
        for _ in range(5):
            y = np.array(
                [
                    random.uniform(-10.0, 10.0),
                    random.uniform(-300.0, 300.0),
                    random.uniform(0.2, 1.2),
                    random.uniform(-2.0, 2.0),
                ]
            )
            rates = np.full(4, np.nan)
            compiled.rhs(0.3, y, p, rates)
            assert rates[1] == 0.0 and rates[0] == y[1], (mode, y, rates)
            np.testing.assert_allclose(
                rates[2:], stepper.regulator.rhs(None, None, mode)(0.3, y)[2:], rtol=1e-12, atol=1e-12
            )
    before = stepper.state.copy()
    stepper.answer(0.01, 250.0)
    stepper.answer(0.02, 250.0)  # advanced over [0.01, 0.02] with 250 rad/s held: phi moves by 2.5 rad
    assert stepper.state[1] == 250.0
    assert stepper.state[0] == pytest.approx(before[0] + before[1] * 0.01 + 2.5, rel=1e-12)


def test_an_anticipating_fast_governor_answers_as_one_that_does_not():
    """As test_ros_nodes' anticipation test, on the fast path: answers, states, mode changes and solver counts are
    those of a governor that never anticipates (bit for bit), and close to the reference path's."""
    data = scene(CASES["engine_direct"], solver__path="fast")
    plain, anticipating = GovernorStepper(model_of(data)), GovernorStepper(model_of(data))
    reference = GovernorStepper(model_of(scene(data, solver__path="reference")))
    step = to_nanoseconds(1e-3)
    speeds = np.concatenate([np.full(150, 400.0), np.full(150, 150.0)])  # [rad/s] up to the high stop and off it
    for k, omega in enumerate(speeds):
        now = seconds(k * step)
        throttle = plain.answer(now, omega)
        assert anticipating.answer(now, omega) == throttle, f"throttle at t = {now} s"
        np.testing.assert_array_equal(anticipating.state, plain.state, err_msg=f"state at t = {now} s")
        assert (anticipating.mode, anticipating.events, anticipating.stats) == (plain.mode, plain.events, plain.stats)
        assert reference.answer(now, omega) == pytest.approx(throttle, abs=1e-6)
        anticipating.anticipate(seconds((k + (2 if k % 7 == 0 else 1)) * step))  # every 7th guess too far
    assert [event for _, event, _ in plain.events] == ["sleeve reaches the high stop", "sleeve leaves the high stop"]
    assert [event for _, event, _ in reference.events] == [event for _, event, _ in plain.events]
    np.testing.assert_allclose([t for t, _, _ in plain.events], [t for t, _, _ in reference.events], atol=1e-6)
    assert plain.stats.restarts >= 1


def test_a_scene_the_fast_path_refuses_is_refused_by_the_steppers():
    model = model_of(scene(CASES["engine_direct"], solver__path="fast", solver__method="Radau"))
    for stepper in (MachineStepper, GovernorStepper):
        with pytest.raises(SceneError, match="solver.method: 'Radau'; expected one of RK45"):
            stepper(model)


def test_cli_co_simulation_on_the_fast_path(capsys):
    """`simulate --exchange-step 1e-3 --set solver.path=fast` runs and gives the reference's summary (final speed,
    the governor's events); a scene the fast path does not cover runs on the reference path, with a note naming the
    key."""
    arguments = [
        "simulate",
        "engine_direct",
        "--quiet",
        "--json",
        "--exchange-step",
        "1e-3",
        "--set",
        "scenario.duration=0.5",
        "--set",
        "scenario.load_events=[]",
        "--set",
        "scenario.initial.omega=300",
    ]
    summaries = {}
    for path in ("reference", "fast"):
        code, out, err = run_cli(capsys, *arguments, "--set", f"solver.path={path}")
        assert code == 0, err
        summaries[path] = json.loads(out)
    reference, fast = summaries["reference"], summaries["fast"]
    assert fast["samples"] == reference["samples"] == 501 and fast["t_end"] == reference["t_end"] == 0.5
    assert fast["status"] == "complete" and fast["governor"]["events"] == reference["governor"]["events"] == 2
    assert fast["omega_end"] == pytest.approx(reference["omega_end"], rel=1e-7)
    code, out, err = run_cli(
        capsys,
        "simulate",
        "engine_direct",
        "--quiet",
        "--json",
        "--exchange-step",
        "1e-2",
        "--set",
        "scenario.duration=0.05",
        "--set",
        "scenario.load_events=[]",
        "--set",
        "solver.path=fast",
        "--set",
        "solver.method=Radau",
    )
    assert code == 0 and "does not run solver.method: 'Radau'" in err and "uses the reference path" in err, err
    assert json.loads(out)["status"] == "complete"


@pytest.mark.parametrize(
    "data, path",
    [
        (CASES["engine_direct"], "fast"),
        (CASES["engine_direct"], "reference"),
        (CASES["engine_indirect_none"], "fast"),
        (shortened("engine_pi", 0.3), "fast"),
    ],
)
def test_the_governor_s_two_passes_in_one_call_give_the_two_calls_numbers(monkeypatch, data, path):
    """The corrected coupling's governor steps its pass for good along the corrected speed and its tentative pass
    along the predicted one in the same calls (GovernorStepper._follow_then_try): the co-simulation's times, states,
    throttles, events and the governor's statistics are those of the two passes made one after the other, to the bit
    (the sleeve and the servo reaching their stops on the engines started fast; engine_pi's command in pieces with its
    speed action)."""
    model = model_of(scene(data, solver__path=path))
    merged, governors = [], []  # whether each exchange's two passes were made in one; the runs' governors
    follow_then_try, init = GovernorStepper._follow_then_try, GovernorStepper.__init__

    def noted(self, *arguments):
        stretch = follow_then_try(self, *arguments)
        merged.append(stretch is not None)
        return stretch

    def kept(self, *arguments):
        init(self, *arguments)
        governors.append(self)

    monkeypatch.setattr(GovernorStepper, "__init__", kept)
    monkeypatch.setattr(GovernorStepper, "_follow_then_try", noted)
    calls = []  # the compiled calls (fast path)
    step = compiled_run._step
    monkeypatch.setattr(compiled_run, "_step", lambda *arguments: calls.append(1) or step(*arguments))
    ours = cosimulate(model, 0.02, coupling="corrected")
    ours_calls = len(calls)
    monkeypatch.setattr(GovernorStepper, "_follow_then_try", lambda self, *arguments: None)
    theirs = cosimulate(model, 0.02, coupling="corrected")
    assert ours.status == theirs.status == "complete", (ours.message, theirs.message)
    assert merged.count(True) >= len(ours.times) - 3  # every exchange but the first two and the last in one
    for name in ("times", "states", "throttle", "external_load"):
        np.testing.assert_array_equal(getattr(ours, name), getattr(theirs, name), err_msg=name)
    assert ours.events == theirs.events and len(ours.events) >= (0 if "pi" in model.scene.name else 2), ours.events
    assert governors[0].stats == governors[1].stats
    if path == "fast":  # one compiled call fewer for most exchanges
        assert ours_calls <= len(calls) - ours_calls - 0.9 * merged.count(True), (ours_calls, len(calls) - ours_calls)
