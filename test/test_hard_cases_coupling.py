"""Hard cases of the two-mass machine (docs/theory.md §7.1): a stiff elastic coupling.

Oracles: the linear two-mass machine (constant inertias, constant drive, viscous loads) solved exactly by
the matrix exponential; the rigid one-mass machine as the stiff limit; the relative mode's frequency
sqrt(k / J_r); conservation of energy including the coupling's elastic energy.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from scipy.linalg import expm
from support import run_cli, simulate_complete, write_scene

from mech_regulator.analysis import energy_balance
from mech_regulator.model import build_model
from mech_regulator.scene import SceneError, load_scene, validate_scene
from mech_regulator.solvers import simulate
from mech_regulator.solvers.advice import (
    coupling_modes,
    rk4_amplification,
    rk4_largest_stable_step,
    rk4_stability_refusal,
    stiffness_advice,
)
from mech_regulator.solvers.cosim import cosimulate
from mech_regulator.solvers.time_domain import integrate_time_domain

J1, I2 = 0.5, 0.2  # crank side and driven part [kg m^2]
DRIVE, VISCOUS_1, VISCOUS_2, LOAD = 40.0, 0.05, 0.1, 10.0  # [N m], [N m s/rad], [N m s/rad], [N m]


def linear_scene(stiffness: float, damping: float, method: str = "Radau", duration: float = 0.3, **solver) -> dict:
    """Constant drive on J1, viscous loads on both parts, a constant external load on the driven part."""
    return {
        "name": "linear_two_mass",
        "machine": {
            "inertia": J1,
            "drive": {"type": "constant", "torque": DRIVE},
            "loads": [{"type": "viscous", "coefficient": VISCOUS_1}],
            "coupling": {
                "stiffness": stiffness,
                "damping": damping,
                "driven": {"inertia": I2, "loads": [{"type": "viscous", "coefficient": VISCOUS_2}]},
            },
        },
        "scenario": {"initial": {"omega": 10.0, "twist": 0.0}, "duration": duration, "external_load": LOAD},
        "solver": {"method": method, "rtol": 1e-8, "atol": 1e-10, **solver},
    }


def exact_linear(stiffness: float, damping: float, times: np.ndarray) -> np.ndarray:
    """The linear two-mass machine's state [phi, omega, twist, omega2] at `times` by the matrix exponential
    of the augmented system x' = A x + b: J1 omega' = M - c1 omega - M_m, I2 omega2' = M_m - c2 omega2 - L,
    M_m = k twist + c (omega - omega2)."""
    k, c = stiffness, damping
    A = np.array(
        [
            [0, 1, 0, 0],
            [0, -(VISCOUS_1 + c) / J1, -k / J1, c / J1],
            [0, 1, 0, -1],
            [0, c / I2, k / I2, -(VISCOUS_2 + c) / I2],
        ],
        dtype=float,
    )
    b = np.array([0.0, DRIVE / J1, 0.0, -LOAD / I2])
    augmented = np.zeros((5, 5))
    augmented[:4, :4], augmented[:4, 4] = A, b
    x0 = np.array([0.0, 10.0, 0.0, 10.0, 1.0])
    return np.array([(expm(augmented * t) @ x0)[:4] for t in times]).T


@pytest.mark.parametrize("stiffness, damping", [(1e4, 5.0), (1e6, 50.0), (1e8, 500.0)])
def test_stiff_coupling_matches_the_matrix_exponential(stiffness, damping):
    """Radau on a coupling up to 1e8 N m/rad: speeds, twist and the coupling moment equal the exact linear
    solution (oracle: matrix exponential); the run does not blow up and needs few steps."""
    model = build_model(validate_scene(linear_scene(stiffness, damping)))
    trajectory = simulate_complete(model)
    times = np.linspace(0.0, 0.3, 61)
    exact = exact_linear(stiffness, damping, times)
    states = trajectory(times)
    assert np.max(np.abs(states[1] - exact[1])) < 1e-5 * np.max(np.abs(exact[1]))
    assert np.max(np.abs(states[3] - exact[3])) < 1e-5 * np.max(np.abs(exact[3]))
    columns = model.columns(times, states)
    exact_moment = stiffness * exact[2] + damping * (exact[1] - exact[3])
    # After the first fast transient the coupling carries the driven part's load and acceleration.
    late = times > 0.05
    assert np.max(np.abs(-columns["M_coupling"][late] - exact_moment[late])) < 1e-4 * np.max(np.abs(exact_moment))
    assert trajectory.stats.steps < 2000


def test_explicit_method_on_a_stiff_coupling_stays_stable_but_pays_in_steps_and_is_told():
    """DOP853 on k = 1e8 N m/rad over 0.5 s: no blow-up (same answer as the oracle), its step count is at
    least the stability bound duration |lambda| / 6, several times Radau's once the start-up transient has
    decayed, and the advice names an implicit method once the duration makes it costly."""
    stiffness, damping = 1e8, 500.0
    model = build_model(validate_scene(linear_scene(stiffness, damping, "DOP853", duration=0.5)))
    trajectory = simulate_complete(model)
    times = np.linspace(0.0, 0.5, 11)
    exact = exact_linear(stiffness, damping, times)
    assert np.max(np.abs(trajectory(times)[1] - exact[1])) < 1e-5 * np.max(np.abs(exact[1]))
    fastest = abs(coupling_modes(model).fastest)
    assert trajectory.stats.steps >= 0.5 * fastest / 6.0
    radau = simulate_complete(build_model(validate_scene(linear_scene(stiffness, damping, duration=0.5))))
    assert trajectory.stats.steps > 3 * radau.stats.steps
    assert stiffness_advice(model) is None  # 0.5 s: a few thousand steps, no note
    long_run = build_model(validate_scene(linear_scene(stiffness, damping, "DOP853", duration=10.0)))
    advice = stiffness_advice(long_run)
    assert advice is not None and "Radau" in advice and "stiff" in advice
    assert (
        stiffness_advice(build_model(validate_scene(linear_scene(stiffness, damping, "Radau", duration=10.0)))) is None
    )


def test_relative_mode_frequency_and_damping_ratio():
    """Free vibration of the coupling (no drive, no loads, twist released from 0.01 rad): the twist
    oscillates about 0 at sqrt(k / J_r) with J_r = J1 I2 / (J1 + I2) and decays at zeta omega_n
    (oracle: the damped oscillator's closed form)."""
    k, c = 2e4, 4.0
    scene = linear_scene(k, c, "DOP853", duration=0.2, rtol=1e-10, atol=1e-12)
    scene["machine"]["drive"] = None
    scene["machine"]["loads"] = []
    scene["machine"]["coupling"]["driven"]["loads"] = []
    scene["scenario"] = {"initial": {"omega": 0.0, "twist": 0.01}, "duration": 0.2}
    model = build_model(validate_scene(scene))
    modes = coupling_modes(model)
    reduced = J1 * I2 / (J1 + I2)
    assert modes.reduced_inertia == pytest.approx(reduced, rel=1e-12)
    assert modes.natural_frequency == pytest.approx(math.sqrt(k / reduced), rel=1e-12)
    assert modes.damping_ratio == pytest.approx(c / (2 * math.sqrt(k * reduced)), rel=1e-12)
    times = np.linspace(0.0, 0.2, 4001)
    twist = simulate_complete(model)(times)[2]
    zeta, natural = modes.damping_ratio, modes.natural_frequency
    damped = natural * math.sqrt(1 - zeta**2)
    exact = (
        0.01
        * np.exp(-zeta * natural * times)
        * (np.cos(damped * times) + zeta / math.sqrt(1 - zeta**2) * np.sin(damped * times))
    )
    assert np.max(np.abs(twist - exact)) < 1e-8


def test_stiff_limit_is_the_rigid_machine():
    """As k grows the two-mass engine-generator of two_mass tends to the one-mass machine with J = J1 + I2
    and the generator's fan on the crank (oracle: the rigid model): the cycle-mean speed differs by O(1/k).
    Measured: 0.01736 and 0.001762 rad/s at k = 1e6 and 1e7 N m/rad; at rtol 1e-8 they are those of rtol 1e-9 to
    7e-7 rad/s (4e-4 of the smaller), the integration error far below what is compared, at 0.6 of the CPU."""
    overrides = [
        "scenario.duration=0.6",
        "scenario.load_events.0.time=0.3",
        "solver.method=Radau",
        "solver.rtol=1e-8",
        "solver.atol=1e-8",
    ]
    rigid_scene = load_scene(
        "two_mass",
        overrides
        + [
            "machine.coupling=null",
            "machine.inertia=0.12",
            "machine.loads=[{type: viscous, coefficient: 0.02}, {type: fan, coefficient: 2.56e-4}]",
        ],
    )
    rigid = simulate_complete(build_model(rigid_scene))
    times = np.linspace(0.0, 0.6, 601)
    differences = []
    for stiffness in (1e6, 1e7):
        coupled = build_model(
            load_scene(
                "two_mass", overrides + [f"machine.coupling.stiffness={stiffness}", "machine.coupling.damping=200"]
            )
        )
        run = simulate_complete(coupled)
        differences.append(np.max(np.abs(run(times)[1] - rigid(times)[1])))
    assert differences[1] < differences[0] / 5  # ten times stiffer: about ten times closer
    assert differences[1] < 0.02  # [rad/s] at about 230 rad/s


def test_energy_balance_includes_the_coupling():
    """Works of the drive, both parts' loads, the external load and the coupling damper equal the change of
    kinetic plus elastic energy (oracle: conservation of energy); the damper's work is -c integral dw^2 < 0."""
    model = build_model(load_scene("two_mass", ["scenario.duration=1.5", "solver.rtol=1e-10", "solver.atol=1e-12"]))
    balance = energy_balance(model, simulate_complete(model))
    assert abs(balance.relative_residual) < 1e-7
    assert balance.works["coupling_damping"] < 0.0
    assert set(balance.works) == {"drive", "viscous", "driven_fan", "driven_external", "coupling_damping"}


def test_default_twist_carries_the_driven_loads():
    """Without scenario.initial.twist the coupling starts at the static twist k twist = L + fan(omega): the
    driven part's acceleration at t = 0 is zero (oracle: its equation of motion)."""
    model = build_model(load_scene("two_mass"))
    y = model.initial_state()
    twist = y[model.coupling_index]
    assert twist == pytest.approx((6.0 + 2.56e-4 * 230.0**2) / 5000.0, rel=1e-12)
    rates = model.rhs(model.piece_at(0.0))(0.0, y)
    assert rates[3] == pytest.approx(0.0, abs=1e-12)
    assert rates[2] == 0.0


def test_co_simulation_keeps_the_state_order_with_a_governor_and_a_coupling():
    """A governed two-mass machine co-simulated: the rows follow MachineModel.state_names and converge to
    the monolithic run (oracle: the monolithic model) as the exchange step shrinks."""
    scene = load_scene("two_mass", ["scenario.duration=0.4", "scenario.load_events=[]"])
    data = scene.model_dump(exclude_none=True)
    data["governor"] = load_scene("engine_direct").governor.model_dump(exclude_none=True)
    data["scenario"]["initial"]["sleeve"] = 0.03
    model = build_model(validate_scene(data))
    assert model.state_names() == ("phi", "omega", "arm_angle", "arm_rate", "twist", "omega_driven")
    monolithic = simulate_complete(model)
    errors = []
    for step in (4e-3, 1e-3):
        run = cosimulate(model, step)
        assert run.status == "complete" and run.states.shape[0] == 6
        errors.append(np.max(np.abs(run.states - monolithic(run.times)), axis=1))
    assert np.all(errors[1][[1, 4, 5]] < errors[0][[1, 4, 5]])
    assert errors[1][4] < 1e-4  # twist [rad]


def test_scene_errors_for_the_coupling(capsys):
    """The energy method refuses a two-mass machine with a message naming the key; twist without a coupling is
    refused. (The ROS nodes play a two-mass machine: test_main_job_scenes.)"""
    code, _, err = run_cli(capsys, "simulate", "two_mass", "--set", "solver.method=energy")
    assert code == 2 and "solver.method 'energy'" in err and "Radau" in err
    code, _, err = run_cli(capsys, "simulate", "engine", "--set", "scenario.initial.twist=0.1")
    assert code == 2 and "scenario.initial.twist" in err
    code, out, _ = run_cli(capsys, "describe", "two_mass")
    assert code == 0 and "coupling: M_m = 5000 twist" in out and "natural frequency 261.6 rad/s" in out


def test_rk4_largest_stable_step_closed_forms():
    """RK4's stability boundary, |R(z)| = 1, R(z) = 1 + z + z^2/2 + z^3/6 + z^4/24: on the imaginary axis at
    |z| = 2 sqrt 2 (|R(iy)|^2 = 1 - y^6/72 + y^8/576), on the negative real axis at the real root of
    R(z) - 1 = z (1 + z/2 + z^2/6 + z^3/24), i.e. of z^3 + 4 z^2 + 12 z + 24 (-2.785)."""
    assert rk4_largest_stable_step(2000j) == pytest.approx(2.0 * math.sqrt(2.0) / 2000.0, rel=1e-9)
    real_root = min(root.real for root in np.roots([1.0, 4.0, 12.0, 24.0]) if abs(root.imag) < 1e-12)
    assert rk4_largest_stable_step(-500.0) == pytest.approx(-real_root / 500.0, rel=1e-9)
    assert rk4_amplification(-1.0) == pytest.approx(math.exp(-1.0), abs=1e-2)  # one step of y' = -y, h = 1


def test_rk4_beyond_its_stability_limit_is_refused_and_would_blow_up(capsys, tmp_path):
    """A lightly damped coupling (k = 1e6 N m/rad, zeta = 0.026): RK4 at 0.9 of the largest stable step for its
    fastest mode keeps the vibration bounded and the speeds near the matrix exponential's; at 1.1 of it the
    integration itself (run without the check) grows the twist a thousandfold; simulate and the command refuse
    that step with a message naming solver.step and the largest step, and so does the co-simulation."""
    stiffness, damping = 1e6, 20.0
    model = build_model(validate_scene(linear_scene(stiffness, damping)))
    largest = rk4_largest_stable_step(coupling_modes(model).fastest)
    times = np.linspace(0.0, 0.3, 31)
    exact = exact_linear(stiffness, damping, times)
    stable = build_model(validate_scene(linear_scene(stiffness, damping, "RK4", step=0.9 * largest)))
    assert rk4_stability_refusal(stable) is None
    run = simulate_complete(stable)
    assert np.max(np.abs(run(times)[2])) < 2.0 * np.max(np.abs(exact[2]))
    assert np.max(np.abs(run(times)[1] - exact[1])) < 1e-2 * np.max(np.abs(exact[1]))
    unstable = build_model(validate_scene(linear_scene(stiffness, damping, "RK4", step=1.1 * largest)))
    grown = integrate_time_domain(unstable)
    assert grown.status == "failed" or np.max(np.abs(grown(times)[2])) > 1e3 * np.max(np.abs(exact[2]))
    with pytest.raises(SceneError, match=r"solver.step = .*: RK4 is unstable .* expected solver.step <= "):
        simulate(unstable)
    with pytest.raises(
        SceneError, match="RK4 is unstable"
    ):  # the co-simulated machine too (the nodes, --exchange-step)
        cosimulate(unstable, 1e-3)
    path = write_scene(tmp_path, yaml.safe_dump(linear_scene(stiffness, damping, "RK4", step=1.1 * largest)))
    code, _, err = run_cli(capsys, "simulate", str(path), "--quiet")
    assert code == 2 and f"{largest:.3g}" in err, err
