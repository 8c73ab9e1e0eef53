"""Friction clutch start-up, Coulomb-held driven parts and branched drives (docs/theory.md §7.4-§7.5).

Oracles: closed forms of the constant-moment clutch (two constant accelerations while slipping, a common one
while stuck, break-away where the stuck moment reaches the static torque under a ramping load); the elastic
coupling's crank oscillating against a held driven part; each branch's own equation on its shaft with the
speed differentiated numerically; conservation of energy with the clutch's slip work; the paper's estimate
(exact while slipping against Coulomb resistances); the rigid machine for a clutch that never slips.
"""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest
from scipy import optimize
from support import model_of, run_cli, scene, simulate_complete

from mech_regulator.analysis import energy_balance, summarise
from mech_regulator.scene import load_scene

J, I = 0.1, 0.4  # motor side and machine [kg m^2]
M, L = 20.0, 10.0  # motor moment, machine's constant resistance [N m]
KINETIC, STATIC = 25.0, 28.0  # clutch [N m]
W0 = 100.0  # motor speed when the clutch engages on the machine at rest [rad/s]
A1, A2 = (M - KINETIC) / J, (KINETIC - L) / I  # accelerations while slipping [rad/s^2]
T_LOCK = W0 / (A2 - A1)  # slip ends: W0 + A1 t = A2 t [s]
A_STUCK = (M - L) / (J + I)  # common acceleration once locked [rad/s^2]
RAMP_START, RAMP_RATE = 2.0, 100.0  # external load on the machine: 100 (t - 2) N m from 2 s
# Stuck, the clutch passes T = (M I + J R) / (J + I); it reaches STATIC when R = L + external is R*:
R_BREAK = (STATIC * (J + I) - M * I) / J
T_BREAK = RAMP_START + (R_BREAK - L) / RAMP_RATE


def omega_stuck(t):
    """Common speed while locked [rad/s]: (J + I) omega' = M - L - 100 (t - 2)^+ from A2 T_LOCK at T_LOCK."""
    ramp = np.maximum(np.asarray(t) - RAMP_START, 0.0)
    return A2 * T_LOCK + ((M - L) * (np.asarray(t) - T_LOCK) - 0.5 * RAMP_RATE * ramp**2) / (J + I)


OMEGA_BREAK = float(omega_stuck(T_BREAK))
# Slipping again, I omega2' = T_k - L - 100 (t - 2): omega2 = OMEGA_BREAK - (87.5 s + 125 s^2) with s = t - T_BREAK
# here, and the machine comes to rest where that is 0.
SLOWING, SLOWING_RATE = (RAMP_RATE * (T_BREAK - RAMP_START) - (KINETIC - L)) / I, 0.5 * RAMP_RATE / I
T_REST = T_BREAK + (-SLOWING + math.sqrt(SLOWING**2 + 4 * SLOWING_RATE * OMEGA_BREAK)) / (2 * SLOWING_RATE)

ENGAGEMENT = {
    "name": "engagement",
    "machine": {
        "inertia": J,
        "drive": {"type": "constant", "torque": M},
        "clutch": {
            "static_torque": STATIC,
            "kinetic_torque": KINETIC,
            "driven": {"inertia": I, "loads": [{"type": "constant", "torque": L}]},
        },
    },
    "scenario": {
        "initial": {"omega": W0, "omega_driven": 0.0},
        "duration": 3.0,
        "load_events": [{"time": RAMP_START, "torque": RAMP_RATE, "ramp": 1.0}],
    },
    "solver": {"method": "DOP853", "rtol": 1e-10, "atol": 1e-12, "sample_rate": 200.0},
}


@pytest.fixture(scope="module")
def engagement():
    model = model_of(ENGAGEMENT)
    return model, simulate_complete(model)


def test_slip_ends_when_the_closed_form_says(engagement):
    """Motor at 100 rad/s engaged on a machine at rest: the slip phase is two constant accelerations
    (M - T_k) / J and (T_k - L) / I, and the clutch locks at t* = W0 / (a2 - a1) = 1.142857 s (oracle: the
    closed form) with both at a2 t*; locked, both accelerate at (M - L) / (J + I) and the clutch passes
    (M I + J L) / (J + I) = 18 N m."""
    model, trajectory = engagement
    ((t_lock, what),) = [event for event in trajectory.events if event[0] < RAMP_START]
    assert what == "clutch locks (slip ends)"
    assert t_lock == pytest.approx(T_LOCK, abs=1e-9)
    slipping = np.linspace(0.0, 0.99 * T_LOCK, 50)
    states = trajectory(slipping)
    assert np.allclose(states[1], W0 + A1 * slipping, rtol=0, atol=1e-8)
    assert np.allclose(states[2], A2 * slipping, rtol=0, atol=1e-8)
    assert trajectory(t_lock)[2] == pytest.approx(A2 * T_LOCK, abs=1e-8)
    stuck = np.linspace(1.01 * T_LOCK, 0.99 * T_BREAK, 50)
    columns = model.columns(stuck, trajectory(stuck))
    assert np.allclose(columns["omega"], omega_stuck(stuck), rtol=0, atol=1e-8)
    before_ramp = stuck < RAMP_START
    assert np.allclose(columns["epsilon"][before_ramp], A_STUCK, rtol=1e-12)
    assert np.allclose(columns["epsilon_driven"], columns["epsilon"], rtol=1e-12)
    external = np.maximum(RAMP_RATE * (stuck - RAMP_START), 0.0)
    assert np.allclose(columns["clutch_torque"], (M * I + J * (L + external)) / (J + I), rtol=1e-12)
    assert set(columns["clutch_mode"]) == {0.0}
    slip = model.columns(slipping, states)
    assert np.all(slip["clutch_torque"] == KINETIC) and np.all(slip["clutch_mode"] == 1.0)


def test_stuck_is_exact_and_slip_resumes_at_the_static_torque(engagement):
    """While stuck the speeds are equal bit for bit; the ramping load makes the stuck moment reach the static
    torque at T_BREAK = 2.5 s (closed form), where the clutch breaks away with the motor ahead and the slip
    runs on the closed-form speeds until the machine, braked by the growing load, comes to rest at T_REST =
    2.8446 s and stays held; exactly these three events, no chattering."""
    model, trajectory = engagement
    assert [name for _, name in trajectory.events] == [
        "clutch locks (slip ends)",
        "clutch breaks away, motor ahead",
        "driven part comes to rest",
    ]
    assert trajectory.modes[-1][1] == ("slip+", "held")
    assert trajectory.events[2][0] == pytest.approx(T_REST, abs=1e-9)
    assert np.all(trajectory(np.linspace(trajectory.events[2][0] + 1e-9, 3.0, 50))[2] == 0.0)
    t_break = trajectory.events[1][0]
    assert t_break == pytest.approx(T_BREAK, abs=1e-9)
    stuck = np.linspace(trajectory.events[0][0], t_break, 997)[1:-1]
    states = trajectory(stuck)
    assert np.array_equal(states[1], states[2])
    before = model.columns(np.array([t_break - 1e-9]), trajectory(np.array([t_break - 1e-9])))
    assert before["clutch_torque"][0] == pytest.approx(STATIC, abs=1e-5)
    after = np.linspace(t_break + 0.01, 3.0, 20)
    states = trajectory(after)
    assert np.allclose(states[1], OMEGA_BREAK + A1 * (after - T_BREAK), rtol=0, atol=1e-7)
    slipping = after < T_REST
    s = after[slipping] - T_BREAK
    assert np.allclose(states[2][slipping], OMEGA_BREAK - SLOWING * s - SLOWING_RATE * s**2, rtol=0, atol=1e-7)
    summary = summarise(model, trajectory)["drive_train"]["clutch"]
    assert summary["lock_times"] == [trajectory.events[0][0]]
    assert [mode for _, _, mode in summary["slip_phases"]] == ["slip+", "slip+"]
    assert summary["slip_phases"][1][1] == 3.0  # slipping on after the machine has come to rest
    assert summary["slip_phases"][1][0] == t_break


def test_energy_balance_includes_the_clutch_slip_work(engagement):
    """The works of motor, resistances and external load plus the slip work -T (omega - omega_driven) equal
    the change of kinetic energy (oracle: conservation of energy); the slip work equals -T_k times the slip
    angle, integrated independently by the trapezoidal rule over the slip phases."""
    model, trajectory = engagement
    balance = energy_balance(model, trajectory)
    assert abs(balance.relative_residual) < 1e-9
    first = np.linspace(0.0, T_LOCK, 20001)
    second = np.concatenate([np.linspace(T_BREAK, T_REST, 20001), np.linspace(T_REST, 3.0, 20001)[1:]])
    slip_angle = sum(np.trapezoid(trajectory(times)[1] - trajectory(times)[2], times) for times in (first, second))
    assert balance.works["clutch_slip"] == pytest.approx(-KINETIC * slip_angle, rel=1e-6)


def test_motor_ahead_of_a_machine_turning_backwards_slips_until_the_machine_stops():
    """The clutch engages (slip+, motor at W0) on a machine turning backwards at 20 rad/s: the kinetic torque and the
    resistance both brake it, I omega2' = T_k + L, so it comes to rest at t = 20 I / (T_k + L) with the clutch
    still slipping (the lock guard is s (omega - omega2), s of the slip, not of the machine's direction)."""
    model = model_of(scene(ENGAGEMENT, scenario={"initial": {"omega": W0, "omega_driven": -20.0}, "duration": 0.3}))
    assert model.initial_mode(model.initial_state()) == ("slip+", "backward")
    trajectory = simulate_complete(model)
    assert trajectory.events[0] == (pytest.approx(20.0 * I / (KINETIC + L), rel=1e-9), "driven part comes to rest")


def test_machine_held_while_the_clutch_slips():
    """Motor and machine at rest, a clutch (static 9 N m) that cannot carry the start: it slips from the start,
    and its kinetic torque (8 N m) cannot overcome the machine's resistance (10 N m) never moves it:
    omega_driven stays exactly 0, the motor runs up at (M - T_k) / J, and the resistances take the clutch's
    torque (M_driven_constant = -8 N m); no event."""
    model = model_of(
        scene(
            ENGAGEMENT,
            machine__clutch__kinetic_torque=8.0,
            machine__clutch__static_torque=9.0,
            scenario={"initial": {"omega": 0.0}, "duration": 0.5},
        )
    )
    trajectory = simulate_complete(model)
    times = np.linspace(0.0, 0.5, 101)
    columns = model.columns(times, trajectory(times))
    assert np.all(columns["omega_driven"] == 0.0) and trajectory.events == []
    assert np.allclose(columns["omega"], (M - 8.0) / J * times, rtol=1e-12, atol=1e-12)
    assert np.all(columns["driven_mode"] == 0.0) and np.allclose(columns["M_driven_constant"], -8.0)
    assert trajectory.modes == [(0.0, ("slip+", "held"))]


def test_everything_held_when_the_motor_cannot_start_the_machine():
    """Motor moment 5 N m below the machine's resistance 10 N m, clutch able to pass it: motor and machine
    stay at rest exactly (stuck clutch on a held machine), the clutch passes the motor's moment."""
    model = model_of(scene(ENGAGEMENT, machine__drive__torque=5.0, scenario={"duration": 0.2}))
    trajectory = simulate_complete(model)
    times = np.linspace(0.0, 0.2, 11)
    columns = model.columns(times, trajectory(times))
    assert np.all(columns["omega"] == 0.0) and np.all(columns["omega_driven"] == 0.0)
    assert np.all(columns["clutch_torque"] == 5.0) and np.all(columns["phi"] == 0.0)


def test_coupled_driven_part_held_until_break_away():
    """Elastic coupling, constant drive from rest, driven part held by a constant resistance R: the crank
    oscillates against the held part, twist = (M / k)(1 - cos w t), w = sqrt(k / J1), and the part breaks away
    when k twist = R, at t = arccos(1 - R / M) / w (oracle: the closed form); until then omega_driven = 0
    exactly; the summary reports the held stretch."""
    k, J1, I2, drive, resistance = 2000.0, 0.2, 0.5, 30.0, 40.0
    model = model_of(
        {
            "name": "held",
            "machine": {
                "inertia": J1,
                "drive": {"type": "constant", "torque": drive},
                "coupling": {
                    "stiffness": k,
                    "driven": {"inertia": I2, "loads": [{"type": "constant", "torque": resistance}]},
                },
            },
            "scenario": {"initial": {"omega": 0.0, "twist": 0.0}, "duration": 0.1},
            "solver": {"rtol": 1e-11, "atol": 1e-13},
        }
    )
    trajectory = simulate_complete(model)
    w = math.sqrt(k / J1)
    t_break = math.acos(1.0 - resistance / drive) / w
    assert trajectory.events[0] == (pytest.approx(t_break, abs=1e-9), "driven part breaks away forwards")
    held = np.linspace(0.0, t_break, 200)
    states = trajectory(held)
    assert np.all(states[3] == 0.0)
    assert np.allclose(states[2], drive / k * (1.0 - np.cos(w * held)), rtol=0, atol=1e-10)
    summary = summarise(model, trajectory)["drive_train"]
    assert summary["held"][0] == [0.0, trajectory.events[0][0]]
    assert trajectory(0.1)[3] > 0.0


@pytest.fixture(scope="module")
def branched():
    model = model_of(load_scene("clutch_start", ["scenario.duration=2.5"]).model_dump(exclude_none=True))
    return model, simulate_complete(model)


def test_section_torques_against_each_branch_on_its_own_shaft(branched):
    """The section torque of each branch equals the branch's own equation on its shaft, M_n,c(omega_n) +
    I_n domega_n/dt with omega_n = omega_driven / i_1n and domega_n/dt by central differences of the run
    (oracle: an independent per-branch computation); the kinetic energy is the sum over motor, main shaft and
    branches at their own speeds."""
    model, trajectory = branched
    times = np.linspace(0.05, 2.45, 97)
    times = times[np.abs(times - 1.7959) > 0.01]  # not across the lock, where the acceleration jumps
    columns = model.columns(times, trajectory(times))
    h = 1e-5
    for name, inertia, ratio, resisting in (
        ("conveyor", 8.0, 10.0, lambda w: 80.0 + 0.0 * w),
        ("mixer", 1.5, 4.0, lambda w: 10.0 + 0.026 * w * np.abs(w)),
    ):
        speed = columns["omega_driven"] / ratio
        acceleration = (trajectory(times + h)[2] - trajectory(times - h)[2]) / (2 * h) / ratio
        expected = resisting(speed) + inertia * acceleration
        assert np.allclose(columns[f"M_section_{name}"], expected, rtol=1e-6, atol=1e-6)
    kinetic = (
        0.5 * 0.05 * columns["omega"] ** 2
        + 0.5 * 0.1 * columns["omega_driven"] ** 2
        + 0.5 * 8.0 * (columns["omega_driven"] / 10) ** 2
        + 0.5 * 1.5 * (columns["omega_driven"] / 4) ** 2
    )
    assert np.allclose(columns["E_kinetic"], kinetic, rtol=1e-12)
    balance = energy_balance(model, trajectory)
    assert abs(balance.relative_residual) < 1e-6
    assert balance.works["clutch_slip"] < 0.0


def test_paper_estimate_is_exact_while_slipping_against_coulomb_resistances():
    """Branches with constant resistances only: while the clutch slips the main shaft accelerates at
    (beta - 1) M_nom / I with beta M_nom = T_k, so the largest section torque is the paper's estimate
    M_n,nom + (I_n / i_1n) (beta - 1) M_nom / I (oracle: the paper's eq. 6-7, exact here), and beta = T_k / M_nom."""
    data = load_scene("clutch_start", ["scenario.duration=1.0"]).model_dump(exclude_none=True)
    data["machine"]["clutch"]["driven"]["branches"][1]["loads"] = [{"type": "constant", "torque": 20.0}]
    model = model_of(data)
    trajectory = simulate_complete(model)
    train = summarise(model, trajectory)["drive_train"]
    nominal = 2.0 + 80.0 / 10.0 + 20.0 / 4.0
    assert train["clutch"]["nominal_load"] == pytest.approx(nominal, rel=1e-12)
    assert train["clutch"]["beta"] == pytest.approx(32.0 / nominal, rel=1e-12)
    acceleration = (32.0 - nominal) / (0.1 + 8.0 / 100.0 + 1.5 / 16.0)
    for name, inertia, ratio, resisting in (("conveyor", 8.0, 10.0, 80.0), ("mixer", 1.5, 4.0, 20.0)):
        section = train["sections"][name]
        assert section["max"] == pytest.approx(resisting + inertia / ratio * acceleration, rel=1e-9)
        assert section["paper_estimate"] == pytest.approx(section["max"], rel=1e-9)


def test_clutch_that_never_slips_is_the_rigid_machine_and_keeps_the_governor_modes():
    """engine_direct's governed engine driving a generator rotor through a clutch too strong to slip, with
    sleeve friction and a load rejection at 0.3 s: the run equals the rigid machine with the rotor's inertia
    on the crank (oracle: the one-mass model, to the solvers' own accuracy at rtol 1e-8: about 1e-5 relative
    after 1 s of this engine, 1e-4 on the sleeve's rate), modes are the governor's (sleeve, servo) followed by the drive train's, and
    the governor's mode changes (sleeve breaks away, stops rising, ...) are the same."""
    overrides = [
        "scenario.duration=1.0",
        "scenario.load_events=[{time: 0.3, torque: 0.0}]",
        "governor.friction=1.0",
        "governor.static_friction=1.5",
    ]
    rigid = model_of(load_scene("engine_direct", overrides + ["machine.inertia=0.12"]).model_dump(exclude_none=True))
    clutched = model_of(
        load_scene(
            "engine_direct",
            overrides + ["machine.clutch={static_torque: 1000.0, kinetic_torque: 900.0, driven: {inertia: 0.1}}"],
        ).model_dump(exclude_none=True)
    )
    expected = simulate_complete(rigid)
    trajectory = simulate_complete(clutched)
    assert all(len(mode) == 4 and mode[2:] == ("stuck", "forward") for _, mode in trajectory.modes)
    assert [mode[:2] for _, mode in trajectory.modes] == [mode for _, mode in expected.modes]
    assert [name for _, name in trajectory.events] == [name for _, name in expected.events]
    assert len(expected.events) >= 3 and trajectory.events[0][1] == "sleeve breaks away upwards"
    assert np.allclose([t for t, _ in trajectory.events], [t for t, _ in expected.events], rtol=0, atol=1e-4)
    times = np.linspace(0.0, 1.0, 201)
    states = trajectory(times)
    assert np.array_equal(states[1], states[-1])
    reference = expected(times)
    assert np.all(np.max(np.abs(states[:-1] - reference), axis=1) < 2e-4 * np.max(np.abs(reference), axis=1))


def test_cli_end_to_end(tmp_path, capsys):
    """simulate the bundled clutch_start with CSV, PNG and JSON: the summary reports the lock time, slip
    phase and section maxima; the CSV has the clutch's and the sections' columns."""
    out, plot = tmp_path / "run.csv", tmp_path / "run.png"
    code, stdout, err = run_cli(
        capsys,
        "simulate",
        "clutch_start",
        "--quiet",
        "--json",
        "--out",
        str(out),
        "--plot",
        str(plot),
        "--set",
        "scenario.duration=2.5",
    )
    assert code == 0, err
    summary = json.loads(stdout)
    clutch = summary["drive_train"]["clutch"]
    assert len(clutch["lock_times"]) == 1 and 1.7 < clutch["lock_times"][0] < 1.9
    assert clutch["slip_phases"] == [[0.0, clutch["lock_times"][0], "slip+"]]
    assert set(summary["drive_train"]["sections"]) == {"conveyor", "mixer"}
    assert summary["energy"]["works"]["clutch_slip"] < 0.0
    with out.open() as handle:
        header = next(csv.reader(handle))
    for column in (
        "clutch_torque",
        "slip_speed",
        "clutch_mode",
        "omega_driven",
        "driven_mode",
        "M_section_conveyor",
        "M_section_mixer",
        "M_driven_conveyor_constant",
    ):
        assert column in header
    assert plot.read_bytes().startswith(b"\x89PNG")
    code, stdout, _ = run_cli(capsys, "simulate", "clutch_start", "--quiet", "--set", "scenario.duration=2.5")
    assert code == 0 and "slip ends (locks) at 1.79" in stdout and "conveyor: max" in stdout


@pytest.mark.parametrize(
    "options, shown",
    [
        (["--set", "machine.clutch.kinetic_torque=50"], "kinetic_torque = 50.0 N m exceeds static_torque = 40.0 N m"),
        (
            ["--set", "machine.coupling={stiffness: 1000.0, driven: {inertia: 1.0}}"],
            "machine.coupling and machine.clutch are both set",
        ),
        (["--set", "machine.clutch.driven.branches.1.name=conveyor"], "['conveyor'] appear more than once"),
        (["--set", "machine.clutch.driven.branches.0.ratio=0"], "ratio"),
        (["--set", "machine.clutch.driven.branches.0.name=belt conveyor"], "name"),
        (["--set", "solver.method=energy"], "a machine with a clutch has two masses"),
    ],
)
def test_bad_input_gets_a_clear_message(capsys, options, shown):
    """Bad clutch or branch data and unsupported runs end in exit code 2 with a message naming the key."""
    code, _, err = run_cli(capsys, "simulate", "clutch_start", "--quiet", *options)
    assert code == 2 and shown in err, err


def test_omega_driven_needs_a_driven_part(capsys):
    code, _, err = run_cli(capsys, "simulate", "startup", "--set", "scenario.initial.omega_driven=1.0")
    assert code == 2 and "scenario.initial.omega_driven" in err


def test_the_co_simulated_clutch_slips_and_locks_as_the_monolithic_run():
    """The nodes' co-simulation (machine stepped exchange by exchange, the load held) of the clutch start-up: with
    no governor and a constant load it differs from the monolithic run only by the restarts at the exchanges."""
    from mech_regulator.solvers.cosim import cosimulate

    model = model_of(load_scene("clutch_start", ["scenario.duration=2"]))
    run = cosimulate(model, 1e-3)
    assert run.status == "complete"
    reference = simulate_complete(model)(run.times)
    for index, name in ((1, "omega"), (2, "omega_driven")):
        error = np.max(np.abs(run.states[index] - reference[index])) / np.max(np.abs(reference[index]))
        assert error < 1e-5, f"{name}: {error:.3g} relative"
    columns = model.columns(run.times, run.states, run.throttle, run.external_load)
    slipping = columns["slip_speed"] != 0.0
    assert slipping[1] and not slipping[-1], "the clutch should slip at the start and be locked at 2 s"


# A clutch slip shorter than a solver step (a switch the solver must not step over): a crank-slider on the motor side
# makes the moment the stuck clutch passes swing over each turn (its reduced inertia and the 1/2 J' omega^2 term), and
# its highest swing tops the static torque for 1.65 ms, inside a 40 ms step the loose run takes when the clutch never
# slips.
def short_slip(static: float, rtol: float) -> dict:
    """Constant 5 N m drive on 0.05 kg m^2 and a crank-slider (0.1 m crank, 0.4 m rod, 3 kg slider), a clutch of
    `static` N m (kinetic 0.1 N m below) to a 0.5 kg m^2 shaft with a viscous load, both at 30 rad/s, for 0.5 s."""
    return {
        "name": "short_slip",
        "machine": {
            "inertia": 0.05,
            "drive": {"type": "constant", "torque": 5.0},
            "mechanism": {"type": "crank_slider", "crank": 0.1, "rod": 0.4, "slider_mass": 3.0},
            "clutch": {
                "static_torque": static,
                "kinetic_torque": static - 0.1,
                "driven": {"inertia": 0.5, "loads": [{"type": "viscous", "coefficient": 0.05}]},
            },
        },
        "scenario": {"initial": {"omega": 30.0, "omega_driven": 30.0}, "duration": 0.5},
        "solver": {"method": "DOP853", "rtol": rtol, "atol": rtol * 1e-2},
    }


def test_a_slip_shorter_than_a_step_is_seen():
    """Oracles: the never-slipping clutch (static torque 1000 N m) at rtol 1e-12 gives the stuck torque T(t), whose
    crossings of 21.7 N m bound the episode (t1, t2); a tight run (rtol 1e-12) gives the lock time. The loose run
    (rtol 1e-5, steps of ~30 ms) logs exactly a break-away at t1 and a lock near the tight run's (within 1e-5 s;
    measured 1e-6 s), and its mode log agrees with the torque bound: on 2000 samples of its stuck stretches |T| <=
    21.7 N m. Without the event the loose never-slipping run would stride over it: one of its steps spans the whole
    slip (measured 0.359-0.399 s)."""
    static = 21.7
    never = model_of(short_slip(1000.0, 1e-12))
    stuck_run = simulate_complete(never)

    def over_static(t: float) -> float:
        return never.columns(np.array([t]), stuck_run(np.array([t])))["clutch_torque"][0] - static

    samples = np.linspace(0.0, 0.5, 5001)
    over = np.array([over_static(t) for t in samples])
    ((first, second),) = [np.flatnonzero(np.diff(np.sign(over)))]  # exactly one episode above the static torque
    t1 = optimize.brentq(over_static, samples[first], samples[first + 1], xtol=1e-14)
    t2 = optimize.brentq(over_static, samples[second], samples[second + 1], xtol=1e-14)
    tight = simulate_complete(model_of(short_slip(static, 1e-12)))
    (_, _), (t_lock, locks) = tight.events
    assert locks == "clutch locks (slip ends)" and t_lock > t2

    model = model_of(short_slip(static, 1e-5))
    loose = simulate_complete(model)
    assert [name for _, name in loose.events] == ["clutch breaks away, motor ahead", "clutch locks (slip ends)"]
    assert loose.events[0][0] == pytest.approx(t1, abs=1e-5)
    assert loose.events[1][0] == pytest.approx(t_lock, abs=1e-5)
    starts = [start for start, _ in loose.modes] + [0.5]
    for (start, mode), end in zip(loose.modes, starts[1:]):
        if "stuck" in mode:
            times = np.linspace(start, end, 2000)
            assert np.max(np.abs(model.columns(times, loose(times))["clutch_torque"])) <= static * (1.0 + 1e-9)
    coarse = simulate_complete(model_of(short_slip(1000.0, 1e-5)))
    ends = np.concatenate(coarse.step_ends)
    assert any(a < t1 and t_lock < b for a, b in zip(ends, ends[1:]))
