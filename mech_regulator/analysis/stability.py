"""Stability of a governed machine at its operating point (docs/theory.md §8.7).

Linear: the cycle-averaged machine J_m omega' = throttle M_d(omega) + M_c(omega) with the governor
(without Coulomb friction, dead band, speed limit and stops: they have no linearisation; dry friction
shows as the insensitivity band instead) is linearised by central differences; its eigenvalues give
the damping and period of the dominant mode. A direct governor gives the classic cubic
p^3 + a2 p^2 + a1 p + a0, whose Vyshnegradsky parameters A = a2 / a0^(1/3), B = a1 / a0^(2/3) make it
stable iff A B > 1 (Hurwitz: a1 a2 > a0).

Periodic: when J or a moment varies with phi, the steady state is a periodic orbit. It is found by
Newton shooting on the map over one dynamic period in phi, and its Floquet multipliers (eigenvalues of
that map's Jacobian) decide stability; for comparison the averaged model predicts exp(lambda T).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from scipy import integrate, optimize

from mech_regulator.analysis.statics import OperatingPoint
from mech_regulator.governors import GovernorKind
from mech_regulator.model import LoadPiece, MachineModel

SHOOTING_TOLERANCE = 1e-8  # the periodic orbit is found when |P(x) - x| is below this, relative to x's scale


@dataclass(frozen=True)
class LinearStability:
    """Eigen-analysis of the linearised cycle-averaged model at an operating point.

    state_names: the linearised states (omega and the governor's); jacobian; eigenvalues [1/s];
    dominant: the eigenvalue with the largest real part; damping_ratio = -Re/|lambda| of the dominant
    mode; period [s] of the dominant mode (inf if it does not oscillate); stable: all Re < 0;
    polynomial: characteristic polynomial coefficients, highest power first (leading 1);
    vyshnegradsky: (A, B) for a governor whose loop is Vyshnegradsky's cubic (a direct governor's) when all its
    coefficients are positive, else None; pi_loop: the closed forms of the loop's polynomial where the governor has
    them (GovernorKind.loop_coefficients: a PI governor's (a1, a0) of p^2 + a1 p + a0), else None.
    """

    state_names: tuple[str, ...]
    jacobian: np.ndarray
    eigenvalues: np.ndarray
    dominant: complex
    damping_ratio: float
    period: float
    stable: bool
    polynomial: np.ndarray
    vyshnegradsky: tuple[float, float] | None
    pi_loop: tuple[float, float] | None = None


def _governor_of(model: MachineModel) -> GovernorKind:
    """The governor of a governed machine (the analyses here need one)."""
    assert model.governor is not None, "the stability analysis reads a machine with a governor"
    return model.governor


def averaged_rhs(model: MachineModel, external_load: float):
    """The cycle-averaged governed machine x' = F(x), x = [omega, governor states...]:
    omega' = (throttle M_d(omega) + M_c(omega)) / J_m, the governor in its smooth (ideal) form."""
    governor = _governor_of(model)
    rates = governor.derivatives(("free", "free"), ideal=True)
    inertia = model.cycle_averages(1.0, external_load)[0]

    def F(x: np.ndarray) -> np.ndarray:
        y = np.concatenate([[0.0], x])
        _, drive, other = model.cycle_averages(x[0], external_load)
        return np.array([(governor.throttle(y) * drive + other) / inertia, *rates(y)])

    return F


def equilibrium_state(model: MachineModel, point: OperatingPoint) -> np.ndarray:
    """The averaged model's state at an operating point: [omega, the governor's states there
    (GovernorKind.equilibrium_state)]."""
    return np.concatenate([[point.speed], _governor_of(model).equilibrium_state(point)])


def linear_stability(model: MachineModel, point: OperatingPoint) -> LinearStability:
    """Linearise the averaged model at the operating point and analyse its eigenvalues."""
    governor = _governor_of(model)
    F = averaged_rhs(model, point.external_load)
    x0 = equilibrium_state(model, point)
    scale = _state_scale(model, point, x0.size)
    jacobian = np.empty((x0.size, x0.size))
    for j in range(x0.size):
        h = 1e-6 * scale[j]
        step = np.zeros(x0.size)
        step[j] = h
        jacobian[:, j] = (F(x0 + step) - F(x0 - step)) / (2.0 * h)
    eigenvalues = np.linalg.eigvals(jacobian)
    dominant = eigenvalues[np.argmax(eigenvalues.real)]
    polynomial = np.real(np.poly(jacobian))
    vyshnegradsky = None
    if governor.vyshnegradsky_cubic and np.all(polynomial > 0.0):
        a2, a1, a0 = polynomial[1:]
        vyshnegradsky = (a2 / a0 ** (1.0 / 3.0), a1 / a0 ** (2.0 / 3.0))
    magnitude = abs(dominant)
    return LinearStability(
        state_names=("omega",) + governor.state_names,
        jacobian=jacobian,
        eigenvalues=eigenvalues,
        dominant=complex(dominant),
        damping_ratio=-dominant.real / magnitude if magnitude > 0 else math.nan,
        period=2.0 * math.pi / abs(dominant.imag) if dominant.imag != 0.0 else math.inf,
        stable=bool(np.all(eigenvalues.real < 0.0)),
        polynomial=polynomial,
        vyshnegradsky=vyshnegradsky,
        pi_loop=governor.loop_coefficients(model, point),
    )


def critical_damping(model: MachineModel, point: OperatingPoint, upper: float = 1e7) -> float | None:
    """Sleeve damping [N s/m] at which the averaged model's dominant eigenvalue crosses the imaginary
    axis (stable above it), or None if the stability does not change between 0 and `upper` or the governor has no
    sleeve (GovernorKind.with_damping: a PI governor)."""
    governor = _governor_of(model)
    if governor.with_damping(0.0) is None:
        return None

    def growth(damping: float) -> float:
        varied = dataclasses.replace(model, governor=governor.with_damping(damping))
        return linear_stability(varied, point).dominant.real

    if growth(0.0) * growth(upper) > 0.0:
        return None
    return optimize.brentq(growth, 0.0, upper, xtol=1e-9, rtol=1e-10)


@dataclass(frozen=True)
class FloquetStability:
    """Stability of the periodic steady state of a machine whose J or moments vary with phi.

    orbit: the state [omega, governor states...] at phi = 0 on the periodic orbit; cycle_time [s]: the
    time for one dynamic period; mean_speed [rad/s]; multipliers: Floquet multipliers of the map over
    one dynamic period; averaged_multipliers: exp(lambda T) of the averaged model's eigenvalues, for
    comparison; stable: all |multipliers| < 1; residual: |P(x) - x| of the orbit found.
    """

    orbit: np.ndarray
    cycle_time: float
    mean_speed: float
    multipliers: np.ndarray
    averaged_multipliers: np.ndarray
    stable: bool
    residual: float


def is_periodic(model: MachineModel) -> bool:
    """Whether the machine's J or some moment varies with phi (its steady state is then an orbit)."""
    return model.reduced is not None or "phi" in model.depends_on()


def floquet_stability(
    model: MachineModel, point: OperatingPoint, linear: LinearStability, rtol: float = 1e-10
) -> FloquetStability:
    """Find the periodic orbit by Newton shooting on the map over one dynamic period Phi in phi,
    x(phi + Phi) = P(x(phi)), integrating dx/dphi = f(x) / omega; multipliers = eig(dP/dx)."""
    period = model.dynamic_period()
    rhs = model.rhs(LoadPiece(0.0, math.inf, point.external_load, 0.0), mode=("free", "free"), ideal=True)

    def in_phi(phi: float, x: np.ndarray) -> list[float]:
        rates = rhs(0.0, np.concatenate([[phi], x[:-1]]))
        return [rate / x[0] for rate in rates[1:]] + [1.0 / x[0]]

    def cycle(x: np.ndarray) -> tuple[np.ndarray, float]:
        solution = integrate.solve_ivp(
            in_phi, (0.0, period), np.append(x, 0.0), method="DOP853", rtol=rtol, atol=rtol * 1e-2
        )
        return solution.y[:-1, -1], solution.y[-1, -1]

    x = equilibrium_state(model, point)
    scale = _state_scale(model, point, x.size)
    step = rtol ** (1.0 / 3.0)  # central differences: truncation ~ step^2 balances integration noise ~ rtol / step
    monodromy = _map_jacobian(cycle, x, step * scale)
    for _ in range(30):  # chord Newton: the map's Jacobian hardly changes between the guess and the orbit
        residual = cycle(x)[0] - x
        if np.all(np.abs(residual) < SHOOTING_TOLERANCE * scale):
            break
        x = x - np.linalg.solve(monodromy - np.eye(x.size), residual)
    monodromy = _map_jacobian(cycle, x, step * scale)
    end, cycle_time = cycle(x)
    multipliers = np.linalg.eigvals(monodromy)
    return FloquetStability(
        orbit=x,
        cycle_time=cycle_time,
        mean_speed=period / cycle_time,
        multipliers=multipliers,
        averaged_multipliers=np.exp(linear.eigenvalues * cycle_time),
        stable=bool(np.all(np.abs(multipliers) < 1.0)),
        residual=float(np.max(np.abs(end - x) / scale)),
    )


def _state_scale(model: MachineModel, point: OperatingPoint, size: int) -> np.ndarray:
    """Typical size of each averaged-model state (omega, then the governor's: GovernorKind.state_scale) for difference
    steps and tolerances."""
    return np.concatenate([[max(abs(point.speed), 1.0)], _governor_of(model).state_scale(point)])[:size]


def _map_jacobian(cycle, x: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """Jacobian of the period map by central differences with the given step per state."""
    jacobian = np.empty((x.size, x.size))
    for j in range(x.size):
        h = steps[j]
        step = np.zeros(x.size)
        step[j] = h
        jacobian[:, j] = (cycle(x + step)[0] - cycle(x - step)[0]) / (2.0 * h)
    return jacobian
