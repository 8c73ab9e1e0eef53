"""The Porter-type centrifugal sensor (docs/theory.md §8.2-§8.3): statics and the sleeve's equation of motion.

Two balls of mass m on arms of length l, hinged on the spindle, with links of the same length down to
a sleeve of mass M; a is the arm angle from the spindle axis, the sleeve rises z = 2 l (1 - cos a).
The spindle turns at omega_g = ratio * omega. Watt's governor is M = 0; a spring on the sleeve gives
the spring-loaded kind. Forces on the sleeve are written as upward forces along the spindle [N].
The formulas are the module's functions porter_sleeve, porter_lift and porter_arm_acceleration, which both
paths run (governors/sensor.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mech_regulator.governors.drawing import porter_outline
from mech_regulator.governors.sensor import CentrifugalSensor


def porter_sleeve(arm, m, l, M, k, z_free, c, g, ratio):
    """Sleeve rise z = 2 l (1 - cos a) [m]."""
    return 2.0 * l * (1.0 - math.cos(arm))


def porter_lift(arm, omega, m, l, M, k, z_free, c, g, ratio):
    """Net upward force on the sleeve at rest [N]: F = m l omega_g^2 cos a - (m + M) g - k (z - z_free),
    omega_g = ratio omega. It is the generalised force of Lagrange's equation divided by dz/da = 2 l sin a, so it
    stays finite at a = 0."""
    omega_g = ratio * omega
    spring = k * (porter_sleeve(arm, m, l, M, k, z_free, c, g, ratio) - z_free)
    return m * l * omega_g * omega_g * math.cos(arm) - (m + M) * g - spring


def porter_arm_acceleration(arm, arm_rate, omega, friction, m, l, M, k, z_free, c, g, ratio):
    """Arm angular acceleration a'' [rad/s^2] from Lagrange's equation

    (2 m l^2 + 4 M l^2 sin^2 a) a'' + 2 M l^2 sin(2a) a'^2 = 2 l sin a [F(a, omega) - c z' - friction],

    with z' = 2 l sin a a' and friction the signed Coulomb force opposing the sleeve's motion [N]."""
    sin_a = math.sin(arm)
    lever = 2.0 * l * sin_a
    force = porter_lift(arm, omega, m, l, M, k, z_free, c, g, ratio) - c * lever * arm_rate - friction
    mass = 2.0 * m * l * l + 4.0 * M * l * l * sin_a * sin_a
    return (lever * force - 2.0 * M * l * l * math.sin(2.0 * arm) * arm_rate * arm_rate) / mass


@dataclass(frozen=True)
class PorterSensor(CentrifugalSensor):
    """Parameters of the sensor, SI: ball_mass m [kg] (each ball), arm_length l [m], sleeve_mass M [kg],
    stiffness k [N/m] and free_position [m] of the sleeve spring, damping c [N s/m], kinetic and static
    Coulomb friction [N], ratio = omega_g / omega [-], gravity g [m/s^2], stroke (z_low, z_high) [m]."""

    ball_mass: float
    arm_length: float
    sleeve_mass: float
    stiffness: float
    free_position: float
    damping: float
    kinetic_friction: float
    static_friction: float
    ratio: float
    gravity: float
    stroke: tuple[float, float]

    name = "Porter"

    def kernels(self):
        """porter_sleeve, porter_lift, porter_arm_acceleration (CentrifugalSensor.kernels)."""
        return porter_sleeve, porter_lift, porter_arm_acceleration

    def kernel_parameters(self) -> tuple[float, ...]:
        """(m, l, M, k, z_free, c, g, ratio)."""
        return (
            self.ball_mass,
            self.arm_length,
            self.sleeve_mass,
            self.stiffness,
            self.free_position,
            self.damping,
            self.gravity,
            self.ratio,
        )

    def arm_angle(self, sleeve: float) -> float:
        """Arm angle a = arccos(1 - z / (2 l)) [rad] for a sleeve position z [m]."""
        return math.acos(1.0 - sleeve / (2.0 * self.arm_length))

    def sleeve_lever(self, arm_angle: float) -> float:
        """dz/da = 2 l sin a [m/rad]."""
        return 2.0 * self.arm_length * math.sin(arm_angle)

    def equilibrium_speed(self, sleeve: float, friction: float = 0.0) -> float:
        """Crank speed [rad/s] holding the sleeve at z against a friction force pushing down [N]:

        omega_g^2 = ((m + M) g + k (z - z_free) + friction) / (m l cos a), omega = omega_g / ratio.
        With friction = +-F_s this bounds the insensitivity band. NaN where no speed can hold the sleeve.
        """
        m, l = self.ball_mass, self.arm_length
        cos_a = 1.0 - sleeve / (2.0 * l)
        pull = (m + self.sleeve_mass) * self.gravity + self.stiffness * (sleeve - self.free_position) + friction
        if pull <= 0.0 or cos_a <= 0.0:
            return math.nan
        return math.sqrt(pull / (m * l * cos_a)) / self.ratio

    def characteristic_range(self) -> tuple[float, float]:
        """The part of the stroke [m] where some speed holds the sleeve: below z = z_free - (m + M) g / k
        a spring in tension lifts the sleeve by itself, and the static characteristic starts above it."""
        low, high = self.stroke
        if self.stiffness > 0.0:
            lifted_up_to = self.free_position - (self.ball_mass + self.sleeve_mass) * self.gravity / self.stiffness
            low = max(low, lifted_up_to + 1e-9 * (high - low))
        return low, high

    def describe(self) -> str:
        """The Porter sensor's numbers."""
        return (
            f"Porter sensor: m = {self.ball_mass:g} kg, l = {self.arm_length:g} m, M = {self.sleeve_mass:g} kg, "
            f"spindle ratio {self.ratio:g}"
        )

    def outline(self, arm_angle: float, spindle_angle: float) -> dict[str, np.ndarray]:
        """governors/drawing.py's porter_outline."""
        return porter_outline(self.arm_length, self.stroke, arm_angle, spindle_angle)
