"""Flywheel design (analysis.flywheel, `mech-regulator flywheel`): the energy-swing formula, the exact numerical
Wittenbauer construction and the flywheel refined by simulation, against source 000's lathe, a conservative
machine in closed form, the bundled press and an independent integration in phi; the ratio shaft; the command.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from rerun.chunk import RrdReader
from scipy import integrate
from support import run_cli, simulate_complete

from mech_regulator.analysis.flywheel import MACHINE_CLASSES, PeriodicMotion, design_flywheel, energy_diagram
from mech_regulator.model import build_model
from mech_regulator.scene import load_scene, validate_scene

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


# ---------------------------------------------------------------------------------------------
# 1: the lathe of source 000 (constant J): J_fw = pi F r / (4 omega_m^2 [delta]) - J_tt


@pytest.fixture(scope="module")
def lathe():
    return design_flywheel(load_scene("lathe"), 1.0 / 50.0)


def test_lathe_formula_and_wittenbauer_agree_exactly(lathe):
    F_r, omega_m, delta, J_tt = 100.0, 15.0, 1.0 / 50.0, 2.0
    expected = math.pi * F_r / (4.0 * omega_m**2 * delta) - J_tt  # 15.4533 kg m^2
    # omega_m: the scene's own steady motion through omega = 15.15 at phi = 0 has max 15.15 and min 14.85
    assert lathe.omega_m == pytest.approx(omega_m, rel=1e-13)
    # the on-off cutting load switches on grid points: the swing is exact to round-off
    assert lathe.diagram.swing == pytest.approx(math.pi * F_r / 4.0, rel=1e-12)
    assert lathe.energy_swing == pytest.approx(expected, rel=1e-12)
    assert lathe.wittenbauer == pytest.approx(expected, rel=1e-12)
    construction = lathe.construction
    assert construction.k_max == pytest.approx(omega_m**2 * (1 + delta) / 2, rel=1e-14)
    assert construction.k_min == pytest.approx(omega_m**2 * (1 - delta) / 2, rel=1e-14)
    # the rays touch the vertical E(J) segment at its ends: dE = 0 at phi = 0, dE = -25 pi at phi = 270 deg
    assert construction.a == pytest.approx(-construction.k_max * J_tt, rel=1e-12)
    assert construction.b == pytest.approx(-25.0 * math.pi - construction.k_min * J_tt, rel=1e-12)
    assert math.degrees(construction.tangent_max[0]) == pytest.approx(0.0, abs=1e-9)
    assert math.degrees(construction.tangent_min[0]) == pytest.approx(270.0, abs=1e-9)


def test_lathe_simulated_delta_and_refinement(lathe):
    """Constant J: omega_max^2 - omega_min^2 = 2 delta omega_m^2 exactly, so the formula's flywheel gives [delta]
    in simulation up to the solver's error (DOP853 is exact between switches here), far inside the O(delta^2)
    term (4e-4 relative); the refinement lands on it to 1e-6."""
    delta = 1.0 / 50.0
    for name in ("energy_swing", "wittenbauer", "refined"):
        speeds = lathe.runs[name].speeds
        assert speeds.omega_m == pytest.approx(15.0, rel=1e-9)
        assert speeds.delta == pytest.approx(delta, rel=1e-8), name
    assert lathe.refined == pytest.approx(lathe.energy_swing, rel=1e-6)
    # without a flywheel: delta = dE_max / (J_tt omega_m^2) = 25 pi / (2 * 225)
    assert lathe.runs["none"].speeds.delta == pytest.approx(25.0 * math.pi / 450.0, rel=1e-8)


def test_a_loose_delta_needs_no_flywheel():
    """Without a flywheel the lathe runs at delta = 25 pi / 450 = 0.175: for [delta] = 0.5 both formulas give
    J_fw < 0 and the refinement answers 0."""
    design = design_flywheel(load_scene("lathe"), 0.5)
    assert design.energy_swing < 0.0 and design.wittenbauer < 0.0
    assert design.refined == 0.0
    assert design.runs["refined"].speeds.delta == pytest.approx(25.0 * math.pi / 450.0, rel=1e-8)
    assert any("no flywheel needed" in note for note in design.notes)


# ---------------------------------------------------------------------------------------------
# 2: a conservative machine in closed form: no moments, omega^2 J(phi) = const


def conservative_scene(J0: float = 0.1, rod_inertia: float = 0.4, crank: float = 0.1, rod: float = 0.25):
    """A crank-slider whose only moving inertia is the rod's rotation: J = J0 + J_rod (R cos phi)^2 / (l^2 -
    R^2 sin^2 phi), largest J0 + J_rod (R/l)^2 at phi = 0 and 180 deg, smallest J0 at 90 and 270 deg (grid points
    of the energy diagram: the construction is exact there)."""
    return validate_scene(
        {
            "name": "conservative",
            "machine": {
                "inertia": J0,
                "mechanism": {"type": "crank_slider", "crank": crank, "rod": rod, "rod_inertia": rod_inertia},
            },
            "scenario": {"initial": {"omega": 10.0}, "duration": 1.0},
        }
    )


def test_conservative_machine_closed_form():
    J0, rod_inertia, crank, rod, delta = 0.1, 0.4, 0.1, 0.25, 0.05
    design = design_flywheel(conservative_scene(J0, rod_inertia, crank, rod), delta)
    J_max, J_min = J0 + rod_inertia * (crank / rod) ** 2, J0
    # omega_max / omega_min = sqrt((J_max + J_fw) / (J_min + J_fw)). Wittenbauer's slopes say
    # omega_max^2 / omega_min^2 = (1 + delta) / (1 - delta) = q: J_fw = (J_max - q J_min) / (q - 1)
    q = (1 + delta) / (1 - delta)
    assert design.wittenbauer == pytest.approx((J_max - q * J_min) / (q - 1), rel=1e-12)
    # the exact delta = (omega_max - omega_min) / omega_m means omega_max / omega_min = (2 + delta) / (2 - delta)
    r2 = ((2 + delta) / (2 - delta)) ** 2
    exact = (J_max - r2 * J_min) / (r2 - 1)
    assert design.refined == pytest.approx(exact, rel=1e-6)
    assert design.runs["refined"].speeds.delta == pytest.approx(delta, rel=1e-6)
    # the two differ by the O(delta^2) of omega_max,min^2 ~ omega_m^2 (1 +- delta): here 8e-4 relative
    assert abs(design.wittenbauer / exact - 1.0) > 1e-4
    # the constant-J formula sees no energy swing and misses the whole effect: J_fw = 0 - mean J < 0
    assert design.energy_swing == pytest.approx(-design.diagram.mean_inertia, rel=1e-12)
    assert design.energy_swing < 0.0 and "energy_swing" not in design.runs
    # the simulated run conserves energy: omega^2 (J(phi) + J_fw) is constant along it
    run = design.runs["refined"]
    model = build_model(conservative_scene(J0, rod_inertia, crank, rod))
    total = np.array([model.inertia(phi)[0] for phi in run.phi]) + run.flywheel
    energy = run.omega**2 * total
    assert np.ptp(energy) / energy.mean() < 1e-8


# ---------------------------------------------------------------------------------------------
# 3: the bundled press: variable J, a motor characteristic, a working stroke over part of the turn


@pytest.fixture(scope="module")
def press():
    return design_flywheel(load_scene("press"), 1.0 / 20.0)


def test_press_methods_agree_within_their_bounds(press):
    delta = 1.0 / 20.0
    assert press.speed_dependent and press.ratio == 14.0
    # the constant-J formula differs from Wittenbauer by at most max|J - J_mean| / delta (each k J(phi) term
    # moves the max or min by at most k max|J - J_mean|, and (k_max + k_min) / (k_max - k_min) = 1 / delta)
    spread = float(np.max(np.abs(press.diagram.inertia - press.diagram.mean_inertia)))
    assert 0.0 < abs(press.energy_swing - press.wittenbauer) <= spread / delta
    # and it is not negligible here: the ram's inertia varies by half the machine's own
    assert abs(press.energy_swing / press.wittenbauer - 1.0) > 0.02
    # Wittenbauer's flywheel gives [delta] up to the O(delta^2) term (and the motor's answer to the speed)
    assert abs(press.runs["wittenbauer"].speeds.delta / delta - 1.0) < delta**2
    # the constant-J formula errs by more than that: its flywheel is too big here
    assert press.runs["energy_swing"].speeds.delta < delta * (1.0 - delta**2)
    # the refinement reproduces [delta] in simulation
    assert press.runs["refined"].speeds.delta == pytest.approx(delta, rel=1e-6)
    assert abs(press.refined / press.wittenbauer - 1.0) < delta**2
    # the bundled scene carries the refined flywheel (rounded up to 1.0168 on the motor shaft)
    assert press.scene_flywheel / press.ratio**2 == pytest.approx(press.on_shaft(press.refined), rel=1e-4)
    assert press.scene_flywheel >= press.refined


def test_press_orbit_by_an_independent_integration_in_phi(press):
    """The refined run's periodic orbit, integrated again in phi with scipy's solve_ivp (domega/dphi =
    epsilon / omega from the same model): it closes on itself and has the same delta."""
    run = press.runs["refined"]
    motion = PeriodicMotion(_bare(load_scene("press")), press.diagram, press.ratio, True)
    model = motion.model(run.flywheel)
    rhs = model.rhs()

    def in_phi(phi, y):
        return [rhs(0.0, np.array([phi, y[0]]))[1] / y[0]]

    period = 2.0 * math.pi
    kinks = np.radians([290.0, 305.0, 335.0, 350.0, 360.0])  # the punching table's corners: integrate between them
    omega, start, phis, omegas = run.omega_start, 0.0, [], []
    for end in kinks:
        solution = integrate.solve_ivp(
            in_phi, (start, end), [omega], method="DOP853", rtol=1e-12, atol=1e-12, dense_output=True
        )
        grid = np.linspace(start, end, 2000)
        phis.append(grid)
        omegas.append(solution.sol(grid)[0])
        omega, start = solution.y[0, -1], end
    assert omega == pytest.approx(run.omega_start, rel=1e-7)  # periodic
    assert start == pytest.approx(period)
    omegas = np.concatenate(omegas)
    delta = (omegas.max() - omegas.min()) / (0.5 * (omegas.max() + omegas.min()))
    assert delta == pytest.approx(run.speeds.delta, rel=1e-5)  # sampled extrema: O(h^2) ~ 1e-6


def test_bundled_press_runs_steadily_at_its_permitted_delta():
    scene = load_scene("press")
    model = build_model(scene)
    from mech_regulator.analysis import analyse_steady_state

    steady = analyse_steady_state(model, simulate_complete(model))
    assert steady.steady
    assert steady.last.delta == pytest.approx(scene.analysis.permitted_delta, rel=1e-4)


# ---------------------------------------------------------------------------------------------
# 4: a flywheel on another shaft: J_x = J_fw (omega / omega_x)^2, as the scene format's {inertia, ratio}


def test_flywheel_on_a_geared_shaft_gives_the_same_motion(press):
    J_fw = press.refined
    on_crank = PeriodicMotion(_bare(load_scene("press")), press.diagram, 1.0, True)
    geared = PeriodicMotion(_bare(load_scene("press")), press.diagram, 14.0, True)
    assert geared.model(J_fw).scene.machine.flywheel.inertia == pytest.approx(J_fw / 14.0**2, rel=1e-15)
    assert geared.model(J_fw).inertia_constant == pytest.approx(on_crank.model(J_fw).inertia_constant, rel=1e-14)
    assert geared.run(J_fw).speeds.delta == pytest.approx(on_crank.run(J_fw).speeds.delta, rel=1e-9)
    assert press.on_shaft(J_fw) == pytest.approx(J_fw / 196.0, rel=1e-15)


def _bare(scene):
    """The scene's machine without its flywheel (what the design simulates)."""
    return scene.model_copy(update={"machine": scene.machine.model_copy(update={"flywheel": None})})


def test_energy_diagram_is_the_machine_without_its_flywheel():
    scene = load_scene("press")
    diagram = energy_diagram(build_model(_bare(scene)), 10.0)
    J_links = build_model(_bare(scene)).inertia(1.0)[0] - scene.machine.inertia
    assert np.interp(1.0, diagram.phi, diagram.inertia) == pytest.approx(scene.machine.inertia + J_links, rel=1e-6)


# ---------------------------------------------------------------------------------------------
# 5: the command


def test_command_end_to_end(capsys, tmp_path):
    png, rrd = tmp_path / "lathe.png", tmp_path / "lathe.rrd"
    code, out, err = run_cli(
        capsys,
        "flywheel",
        "lathe",
        "--delta",
        "1/50",
        "--ratio",
        "2",
        "--json",
        "--quiet",
        "--plot",
        str(png),
        "--record",
        str(rrd),
    )
    assert code == 0, err
    data = json.loads(out)
    expected = math.pi * 100.0 / (4.0 * 15.0**2 / 50.0) - 2.0
    assert data["delta"] == 0.02 and data["ratio"] == 2.0
    for name in ("energy_swing", "wittenbauer", "refined"):
        method = data["methods"][name]
        assert method["flywheel"] == pytest.approx(expected, rel=1e-6)
        assert method["on_shaft"] == pytest.approx(expected / 4.0, rel=1e-6)
        assert method["simulated"]["delta"] == pytest.approx(0.02, rel=1e-8)
    assert png.read_bytes().startswith(PNG_SIGNATURE)
    entities = {str(chunk.entity_path) for chunk in RrdReader(rrd).store().stream()}
    assert {
        "/speed/refined",
        "/speed/none",
        "/energy/dE",
        "/inertia/J",
        "/curve/E_of_J",
        "/curve/ray_k_max",
        "/construction/points",
        "/about",
    } <= entities


def test_command_text_report(capsys):
    code, out, err = run_cli(capsys, "flywheel", "lathe", "--delta", "0.02", "--quiet")
    assert code == 0, err
    assert "Wittenbauer (exact numerical form)" in out and "15.45329" in out and "E-axis intercepts" in out


def test_class_takes_its_strictest_delta(capsys):
    code, out, err = run_cli(capsys, "flywheel", "lathe", "--class", "machine_tool", "--json", "--quiet")
    assert code == 0, err
    data = json.loads(out)
    assert data["delta"] == pytest.approx(1.0 / 50.0, rel=1e-15) == MACHINE_CLASSES["machine_tool"].strictest
    assert "machine_tool" in data["delta_source"]
    code, out, _ = run_cli(capsys, "flywheel", "--classes")
    assert code == 0 and "generator" in out and "1/100 to 1/300" in out


@pytest.mark.parametrize(
    "argv, expected",
    [
        (["--delta", "abc"], "--delta 'abc'"),
        (["--delta", "1/0"], "--delta '1/0'"),
        (["--delta", "0"], "between 0 and 1"),
        (["--delta", "1.5"], "between 0 and 1"),
        (["--delta=-1/80"], "--delta '-1/80'"),
        (["--class", "lawnmower"], "pump, agricultural, machine_tool, engine, generator"),
        (["--delta", "1/80", "--class", "engine"], "not both"),
        ([], "no [delta]"),
        (["--delta", "1/50", "--set", "machine.drive.torque=90"], "net work"),
        (["--delta", "1/50", "--omega-m", "-3"], "--omega-m -3"),
        (["--delta", "1/50", "--ratio", "0"], "--ratio 0"),
    ],
)
def test_bad_input_is_a_clear_message(capsys, argv, expected):
    code, out, err = run_cli(capsys, "flywheel", "lathe", *argv)
    assert code == 2
    assert expected in err


def test_refusals_name_the_reason(capsys):
    code, _, err = run_cli(capsys, "flywheel", "press", "--omega-m", "12")
    assert code == 2 and "sets its own mean speed" in err
    code, _, err = run_cli(capsys, "flywheel", "engine_direct", "--delta", "1/80")
    assert code == 2 and "governor" in err
    code, _, err = run_cli(capsys, "flywheel")
    assert code == 2 and "give a SCENE" in err
