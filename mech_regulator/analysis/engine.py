"""An engine at constant crank speed: piston kinematics, torque curves over the working cycle and their harmonics.

At constant omega (epsilon = 0) the moments on the crank of an engine scene are
- the gas moment of each cylinder, `M_gas,i = -p(theta_i) A dx_i/dphi` (the scene's engine drive at full
  throttle), and their sum;
- the inertia moment of the links (rods and pistons), `M_inertia = -1/2 J'(phi) omega^2` (docs/theory.md
  §4.4, §2.3: the part of J omega' + 1/2 J' omega^2 that remains at constant speed, moved to the right);
- the total `M_gas + M_inertia` (the weight of the links is left out).
Harmonics are in orders of the crank speed: `M(phi) = M_mean + sum_k A_k cos(order_k phi + phase_k)`, with
orders 0.5, 1, 1.5, ... over a 720 deg cycle and 1, 2, ... over 360 deg. The mean gas moment times the
cycle angle is the indicated work of all cylinders per cycle, `n * loop integral p dV`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import optimize

from mech_regulator.mechanisms import crank_slider
from mech_regulator.mechanisms.engine import (
    PistonMotion,
    firing_delays,
    mean_piston_speed,
    piston_motion,
    source_approximation,
    source_dead_centre_angles,
    source_from_exact,
)
from mech_regulator.model import MachineModel
from mech_regulator.model.machine import Reduced
from mech_regulator.scene import SceneError
from mech_regulator.scene.effect_keys import Engine
from mech_regulator.scene.mechanism_keys import CrankSlider
from mech_regulator.scene.schema import Scene

POINTS_PER_DEGREE = 4  # samples of the curves per degree of crank angle (table knots every 0.25 deg fall on it)


@dataclass(frozen=True)
class TorqueCurves:
    """Moments over one working cycle at constant crank speed omega [rad/s]: phi [rad] (uniform from 0, the end
    excluded), gas [N m] (one row per cylinder), inertia [N m]; cycle [rad]."""

    omega: float
    cycle: float
    phi: np.ndarray
    gas: np.ndarray
    inertia: np.ndarray

    @property
    def gas_total(self) -> np.ndarray:
        return self.gas.sum(axis=0)

    @property
    def total(self) -> np.ndarray:
        return self.gas_total + self.inertia


@dataclass(frozen=True)
class Harmonics:
    """Fourier series of a curve sampled uniformly over one cycle: `M(phi) = mean + sum_k amplitude_k
    cos(order_k phi + phase_k)`; orders [-] in multiples of the crank speed, amplitudes [N m], phases [rad]."""

    mean: float
    orders: np.ndarray
    amplitudes: np.ndarray
    phases: np.ndarray

    def __call__(self, phi: np.ndarray) -> np.ndarray:
        """The series summed at crank angles phi [rad]."""
        phi = np.asarray(phi, dtype=float)
        return self.mean + np.sum(
            self.amplitudes[:, None] * np.cos(np.outer(self.orders, phi.ravel()) + self.phases[:, None]), axis=0
        ).reshape(phi.shape)

    def largest(self, count: int) -> list[dict]:
        """The count harmonics of largest amplitude, largest first: order, amplitude [N m], phase [deg]."""
        ranked = np.argsort(-self.amplitudes, kind="stable")[:count]
        return [
            {
                "order": float(self.orders[k]),
                "amplitude": float(self.amplitudes[k]),
                "phase_deg": float(np.degrees(self.phases[k])),
            }
            for k in ranked
        ]


def harmonics(values: np.ndarray, cycle: float) -> Harmonics:
    """Fourier coefficients of values sampled at phi_j = j cycle / N, j = 0..N-1, by the real FFT:
    c_k = (1/N) sum_j M_j e^{-i 2 pi k j / N}; mean = c_0, amplitude_k = 2 |c_k| (|c_k| for the Nyquist term of
    an even N), phase_k = arg c_k, order_k = k 2 pi / cycle. The series reproduces the samples exactly."""
    count = len(values)
    coefficients = np.fft.rfft(values) / count
    k = np.arange(1, len(coefficients))
    amplitudes = 2.0 * np.abs(coefficients[1:])
    if count % 2 == 0:
        amplitudes[-1] /= 2.0
    return Harmonics(float(coefficients[0].real), k * (2.0 * math.pi / cycle), amplitudes, np.angle(coefficients[1:]))


def engine_parts(scene: Scene) -> tuple[CrankSlider, Engine]:
    """The crank–slider and the engine drive of an engine scene (the schema gives an engine drive a crank–slider);
    a SceneError naming the scene and what is expected for any other scene."""
    mechanism, drive = scene.machine.mechanism, scene.machine.drive
    if not isinstance(drive, Engine) or not isinstance(mechanism, CrankSlider):
        raise SceneError(
            f"scene '{scene.name}' is not an engine: expected mechanism.type crank_slider and drive.type "
            "engine (see docs/engines.md)"
        )
    return mechanism, drive


def _engine_reduced(model: MachineModel) -> Reduced:
    """The model's reduced mechanism, phi [rad] -> (J_links, dJ/dphi, M_weight, q, dq/dphi); an engine scene's
    model always has one (its crank–slider)."""
    assert model.reduced is not None, "an engine scene's model has its crank-slider's reduced mechanism"
    return model.reduced


def cylinder_count(model: MachineModel) -> int:
    """Number of cylinders of the model's crank–slider (1 without `cylinders`)."""
    cylinders = engine_parts(model.scene)[0].cylinders
    return 1 if cylinders is None else len(cylinders)


def torque_curves(model: MachineModel, omega: float) -> TorqueCurves:
    """Gas moment per cylinder and inertia moment of an engine scene over one working cycle at constant omega
    [rad/s] (module docstring). Cylinder i's gas moment is the drive with every other piston's velocity ratio
    set to zero (the drive is linear in them)."""
    engine = engine_parts(model.scene)[1]
    reduced = _engine_reduced(model)
    drive = next(effect for effect in model.effects if effect.role == "drive")
    cycle = math.radians(engine.cycle_deg)
    count = int(round(engine.cycle_deg)) * POINTS_PER_DEGREE
    phis = np.arange(count) * (cycle / count)
    cylinders = cylinder_count(model)
    gas = np.empty((cylinders, count))
    inertia = np.empty(count)
    for j, phi in enumerate(phis):
        _, dJ, _, q, dq = reduced(phi)
        inertia[j] = -0.5 * dJ * omega * omega
        if not isinstance(dq, tuple):  # one slider: dq is its dx/dphi
            gas[0, j] = drive.moment(0.0, phi, omega, q, dq)
            continue
        for i in range(cylinders):
            alone = tuple(ratio if k == i else 0.0 for k, ratio in enumerate(dq))
            gas[i, j] = drive.moment(0.0, phi, omega, q, alone)
    return TorqueCurves(omega, cycle, phis, gas, inertia)


def piston_table(model: MachineModel, omega: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Piston 1 over one turn at constant omega [rad/s]: phi [rad] (POINTS_PER_DEGREE per degree), the exact
    motion and source 002's approximation, both in the source's convention (from the top dead centre towards
    the crank axis), as arrays of shape (3, N): x [m], v [m/s], a [m/s^2]."""
    mechanism = engine_parts(model.scene)[0]
    R, l, e = mechanism.crank, mechanism.rod, mechanism.offset
    phis = np.arange(360 * POINTS_PER_DEGREE) * (2.0 * math.pi / (360 * POINTS_PER_DEGREE))
    exact = np.array([source_from_exact(piston_motion(phi, omega, R, l, e), R, l, e) for phi in phis]).T
    approximate = np.array([source_approximation(phi, omega, R, l, e) for phi in phis]).T
    return phis, exact, approximate


def indicated_work(model: MachineModel) -> float:
    """The indicated work of all cylinders per working cycle [J], W = integral over the cycle of M_gas(phi) dphi
    (= n * loop integral p dV, M_gas the drive at full throttle), by 8-point Gauss–Legendre quadrature between the
    knots of the pressure table as each cylinder sees it (table angle - phase + firing delay, mod the cycle): there
    the integrand is a straight piece of the table times the smooth dx_i/dphi, so the quadrature is exact to
    round-off (a sum over a uniform grid is not: the table's kinks cost it some 1e-6)."""
    mechanism, drive = engine_parts(model.scene)
    reduced = _engine_reduced(model)
    cycle = math.radians(drive.cycle_deg)
    if mechanism.cylinders:
        delays = firing_delays(
            [c.throw_deg for c in mechanism.cylinders],
            [c.bank_deg for c in mechanism.cylinders],
            drive.cycle_deg,
            drive.firing_order,
            drive.firing_deg,
        )
        shifts = [math.radians(drive.phase_deg - delay) for delay in delays]
    else:
        shifts = [math.radians(drive.phase_deg)]
    knots = sorted(
        {(math.radians(angle) - shift) % cycle for angle in drive.angle_deg for shift in shifts} | {0.0, cycle}
    )
    effect = next(effect for effect in model.effects if effect.role == "drive")
    nodes, weights = np.polynomial.legendre.leggauss(8)
    work = 0.0
    for low, high in zip(knots[:-1], knots[1:]):
        half = 0.5 * (high - low)
        for node, weight in zip(nodes, weights):
            phi = low + half * (node + 1.0)
            _, _, _, q, dq = reduced(phi)
            work += weight * half * effect.moment(0.0, phi, 0.0, q, dq)
    return work


def piston_extremes(
    omega: float, crank: float, rod: float, offset: float, phis: np.ndarray, exact: np.ndarray
) -> dict[str, float]:
    """The piston's largest |v| [m/s], largest and smallest a [m/s^2] at constant omega [rad/s] (source 002's
    convention), each located exactly: bounded Brent's method on the closed-form motion within one grid step of
    the grid's extremum (phis [rad], exact: piston_table's (x, v, a) rows on that grid)."""
    step = float(phis[1] - phis[0])

    def motion(phi: float) -> PistonMotion:
        return source_from_exact(piston_motion(phi, omega, crank, rod, offset), crank, rod, offset)

    def refined(values: np.ndarray, value: Callable[[float], float]) -> float:
        centre = float(phis[int(np.argmax(values))])
        found = optimize.minimize_scalar(
            lambda phi: -value(phi), bounds=(centre - step, centre + step), method="bounded", options={"xatol": 1e-13}
        )
        return max(-float(found.fun), float(values.max()))

    return {
        "v_max": refined(np.abs(exact[1]), lambda phi: abs(motion(phi).v)),
        "a_max": refined(exact[2], lambda phi: motion(phi).a),
        "a_min": -refined(-exact[2], lambda phi: -motion(phi).a),
    }


def engine_report(model: MachineModel, omega: float, largest: int = 8) -> dict:
    """Everything `mech-regulator engine` prints at crank speed omega [rad/s]: geometry (lambda, k, stroke, dead
    centres ours and the source's), piston kinematics (extremes, acceleration at the dead centres, mean piston
    speed, error of source 002's approximation), cylinders and firing, mean indicated moment, power and mean
    effective pressure, and the largest harmonics of the gas, inertia and total moments."""
    scene = model.scene
    mechanism, drive = engine_parts(scene)
    R, l, e = mechanism.crank, mechanism.rod, mechanism.offset
    stroke = crank_slider.stroke(R, l, e)
    top, bottom = crank_slider.dead_centres(R, l, e)
    alpha1, alpha2 = source_dead_centre_angles(R, l, e)
    phis, exact, approximate = piston_table(model, omega)
    error = np.max(np.abs(exact - approximate), axis=1)
    at_top, at_bottom = (piston_motion(angle, omega, R, l, e) for angle in (top, bottom))
    cylinders = mechanism.cylinders or []
    throws = [c.throw_deg for c in cylinders] or [0.0]
    banks = [c.bank_deg for c in cylinders] or [0.0]
    delays = firing_delays(throws, banks, drive.cycle_deg, drive.firing_order, drive.firing_deg)
    curves = torque_curves(model, omega)
    area = math.pi * drive.bore**2 / 4.0
    gas, inertia, total = (
        harmonics(values, curves.cycle) for values in (curves.gas_total, curves.inertia, curves.total)
    )
    work = indicated_work(model)
    extremes = piston_extremes(omega, R, l, e, phis, exact)
    return {
        "scene": scene.name,
        "omega": omega,
        "rpm": omega * 30.0 / math.pi,
        "geometry": {
            "crank": R,
            "rod": l,
            "offset": e,
            "lambda": R / l,
            "k": e / R,
            "stroke": stroke,
            "bore": drive.bore,
            "displacement": area * stroke * len(throws),
            "top_dead_centre_deg": math.degrees(top),
            "bottom_dead_centre_deg": math.degrees(bottom),
            "source_alpha1_deg": math.degrees(alpha1),
            "source_alpha2_deg": math.degrees(alpha2),
        },
        "piston": {
            "x_min": float(exact[0].min()),
            "x_max": float(exact[0].max()),
            **extremes,
            "j_top": -at_top.a,
            "j_bottom": -at_bottom.a,
            "j_top_central_formula": R * omega**2 * (1.0 + R / l),
            "j_bottom_central_formula": -R * omega**2 * (1.0 - R / l),
            "mean_speed": mean_piston_speed(stroke, omega),
            "approximation_error": dict(zip(PistonMotion._fields, map(float, error))),
        },
        "cylinders": {
            "count": len(throws),
            "throw_deg": throws,
            "bank_deg": banks,
            "cycle_deg": drive.cycle_deg,
            "firing_delay_deg": delays,
            "firing_order": [i + 1 for i in sorted(range(len(delays)), key=delays.__getitem__)],
        },
        "torque": {
            "mean_gas": work / curves.cycle,
            "mean_inertia": inertia.mean,
            "mean_total": total.mean,
            "indicated_power": work / curves.cycle * omega,
            "indicated_work_per_cycle": work,
            "mean_effective_pressure": work / (area * stroke * len(throws)),
            "total_max": float(curves.total.max()),
            "total_min": float(curves.total.min()),
            "gas_harmonics": gas.largest(largest),
            "inertia_harmonics": inertia.largest(largest),
            "total_harmonics": total.largest(largest),
        },
    }


def engine_curve_columns(model: MachineModel, omega: float) -> dict[str, np.ndarray]:
    """The curves over one working cycle at constant omega [rad/s], as output columns: phi_deg [deg], piston 1's
    exact x [m] (from the crank axis, as x_slider), v [m/s], a [m/s^2], M_gas_<i> per cylinder, M_gas,
    M_inertia and M_total [N m]."""
    mechanism = engine_parts(model.scene)[0]
    curves = torque_curves(model, omega)
    piston = np.array(
        [piston_motion(phi, omega, mechanism.crank, mechanism.rod, mechanism.offset) for phi in curves.phi]
    ).T
    columns = {"phi_deg": np.degrees(curves.phi), "x": piston[0], "v": piston[1], "a": piston[2]}
    columns.update({f"M_gas_{i + 1}": row for i, row in enumerate(curves.gas)})
    columns.update({"M_gas": curves.gas_total, "M_inertia": curves.inertia, "M_total": curves.total})
    return columns
