"""The centrifugal sensor's interface (docs/theory.md §8.2): what the governor, its statics and stability, the fast
path's code generator, the drawings and the nodes need from a sensor, whatever its linkage.

A sensor has one degree of freedom, its arm angle a [rad] (the states arm_angle, arm_rate of the governor); the
sleeve's rise z(a) [m] grows with a. Forces on the sleeve are upward forces along the spindle [N]: the lift F(a,
omega) is the generalised force of Lagrange's equation divided by dz/da, so the sleeve is in equilibrium where F = 0
and sticks while |F| <= static friction. A sensor's formulas are plain functions of the arm angle and its numbers
(`kernels`, `kernel_parameters`), written with `math` only: its methods call them on the reference path, and the
fast path compiles their very source (solvers/compiled/codegen.py), so each formula is written once.
"""

from __future__ import annotations

import functools
import math
from abc import ABC, abstractmethod
from collections.abc import Callable

import numpy as np
from scipy import optimize

from mech_regulator.governors.drawing import BOUNDS_SAMPLES, STEEL_DENSITY
from mech_regulator.mechanisms.drawing import outline_extent, with_margin


class CentrifugalSensor(ABC):
    """A centrifugal sensor. Its dataclass fields include, SI: ball_mass m [kg] (each of two balls), damping c
    [N s/m], kinetic_friction and static_friction [N] (Coulomb, on the sleeve), ratio = omega_g / omega [-], gravity
    g [m/s^2], stroke (z_low, z_high) [m] between the sleeve's hard stops."""

    ball_mass: float
    damping: float
    kinetic_friction: float
    static_friction: float
    ratio: float
    gravity: float
    stroke: tuple[float, float]

    name: str = ""  # the sensor's name in `describe` and the docs

    @abstractmethod
    def kernels(self) -> tuple[Callable[..., float], Callable[..., float], Callable[..., float]]:
        """The sensor's formulas as plain functions (math only; one module-level function each, numba-compilable),
        each taking kernel_parameters() after its own arguments: sleeve(a, *params) -> z [m], lift(a, omega,
        *params) -> F [N], arm_acceleration(a, a', omega, friction, *params) -> a'' [rad/s^2]."""

    @abstractmethod
    def kernel_parameters(self) -> tuple[float, ...]:
        """The numbers the kernels read after their own arguments (SI)."""

    @abstractmethod
    def arm_angle(self, sleeve: float) -> float:
        """Arm angle a [rad] at a sleeve position z [m] (the inverse of sleeve)."""

    @abstractmethod
    def sleeve_lever(self, arm_angle: float) -> float:
        """dz/da [m/rad]: the sleeve's velocity per arm rate."""

    @abstractmethod
    def equilibrium_speed(self, sleeve: float, friction: float = 0.0) -> float:
        """Crank speed [rad/s] holding the sleeve at z against a friction force pushing down [N] (with friction =
        +-F_s it bounds the insensitivity band); NaN where no speed can hold the sleeve."""

    @abstractmethod
    def describe(self) -> str:
        """One line for `describe`: the sensor's kind and numbers."""

    @abstractmethod
    def outline(self, arm_angle: float, spindle_angle: float) -> dict[str, np.ndarray]:
        """The drawing's parts at arm angle a [rad] and spindle angle psi [rad], metres, y up (governors/drawing.py:
        spindle, stops, upper_arms, lower_links, sleeve as polylines; balls, spindle_mark as points; sensor_parts)."""

    @functools.cached_property
    def bound_kernels(self) -> tuple[tuple[Callable[..., float], Callable[..., float], Callable[..., float]], tuple]:
        """(kernels(), kernel_parameters()) read once: the reference path's right-hand side calls the formulas on
        every evaluation, the same functions on the same numbers (a sensor is frozen)."""
        return self.kernels(), self.kernel_parameters()

    def sleeve(self, arm_angle: float) -> float:
        """Sleeve rise z(a) [m]."""
        kernels, parameters = self.bound_kernels
        return kernels[0](arm_angle, *parameters)

    def lift(self, arm_angle: float, omega: float) -> float:
        """Net upward force on the sleeve at rest at crank speed omega [rad/s] [N]."""
        kernels, parameters = self.bound_kernels
        return kernels[1](arm_angle, omega, *parameters)

    def arm_acceleration(self, arm_angle: float, arm_rate: float, omega: float, friction: float) -> float:
        """Arm angular acceleration a'' [rad/s^2] from Lagrange's equation, friction the signed Coulomb force
        opposing the sleeve's motion [N]."""
        kernels, parameters = self.bound_kernels
        return kernels[2](arm_angle, arm_rate, omega, friction, *parameters)

    def sleeve_rate(self, arm_angle: float, arm_rate: float) -> float:
        """Sleeve velocity z' = dz/da a' [m/s]."""
        return self.sleeve_lever(arm_angle) * arm_rate

    def stop_angles(self) -> tuple[float, float]:
        """Arm angles [rad] at the two hard stops of the sleeve."""
        return self.arm_angle(self.stroke[0]), self.arm_angle(self.stroke[1])

    def characteristic_range(self) -> tuple[float, float]:
        """The part of the stroke [m] where some speed holds the sleeve (the whole stroke unless a sensor says)."""
        return self.stroke[0], self.stroke[1]

    def equilibrium_sleeve(self, omega: float) -> float:
        """Sleeve position [m] where the lift vanishes at crank speed omega, clipped to the stroke (the lift falls
        with z where the sensor is statically stable, so the root is unique there)."""
        low, high = self.stroke

        def lift_at(z: float) -> float:
            return self.lift(self.arm_angle(z), omega)

        if lift_at(low) <= 0.0:
            return low
        if lift_at(high) >= 0.0:
            return high
        return optimize.brentq(lift_at, low, high, xtol=1e-15, rtol=4 * np.finfo(float).eps)

    def ball_radius(self) -> float:
        """Radius [m] of a steel sphere of the ball mass m: r = (3 m / (4 pi rho))^(1/3)."""
        return (3.0 * self.ball_mass / (4.0 * math.pi * STEEL_DENSITY)) ** (1.0 / 3.0)

    def bounds(self) -> tuple[float, float, float, float]:
        """(xmin, xmax, ymin, ymax) [m, y up] framing the drawing over the whole stroke: the extent of its outline
        (balls with their radius) at BOUNDS_SAMPLES arm angles between the stops, grown by the mechanisms' margin."""
        angles = np.linspace(*self.stop_angles(), BOUNDS_SAMPLES)
        outlines = [self.outline(arm_angle, 0.0) for arm_angle in angles]
        return with_margin(outline_extent(outlines, self.ball_radius()))
