"""The Porter-type centrifugal sensor (docs/theory.md §8.2-§8.3): statics and the sleeve's equation of motion.

Two balls of mass m on arms of length l, hinged on the spindle, with links of the same length down to
a sleeve of mass M; a is the arm angle from the spindle axis, the sleeve rises z = 2 l (1 - cos a).
The spindle turns at omega_g = ratio * omega. Watt's governor is M = 0; a spring on the sleeve gives
the spring-loaded kind. Forces on the sleeve are written as upward forces along the spindle [N].
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import optimize


@dataclass(frozen=True)
class PorterSensor:
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

    def sleeve(self, arm_angle: float) -> float:
        """Sleeve rise z = 2 l (1 - cos a) [m]."""
        return 2.0 * self.arm_length * (1.0 - math.cos(arm_angle))

    def arm_angle(self, sleeve: float) -> float:
        """Arm angle a = arccos(1 - z / (2 l)) [rad] for a sleeve position z [m]."""
        return math.acos(1.0 - sleeve / (2.0 * self.arm_length))

    def stop_angles(self) -> tuple[float, float]:
        """Arm angles [rad] at the two hard stops of the sleeve."""
        return self.arm_angle(self.stroke[0]), self.arm_angle(self.stroke[1])

    def lift(self, arm_angle: float, omega: float) -> float:
        """Net upward force on the sleeve at rest [N]: F = m l omega_g^2 cos a - (m + M) g - k (z - z_free).

        It is the generalised force of Lagrange's equation divided by dz/da = 2 l sin a, so it stays finite
        at a = 0; the sleeve is in equilibrium where F = 0 and sticks while |F| <= static friction.
        """
        m, l = self.ball_mass, self.arm_length
        omega_g = self.ratio * omega
        spring = self.stiffness * (self.sleeve(arm_angle) - self.free_position)
        return m * l * omega_g * omega_g * math.cos(arm_angle) - (m + self.sleeve_mass) * self.gravity - spring

    def arm_acceleration(self, arm_angle: float, arm_rate: float, omega: float, friction: float) -> float:
        """Arm angular acceleration a'' [rad/s^2] from Lagrange's equation

        (2 m l^2 + 4 M l^2 sin^2 a) a'' + 2 M l^2 sin(2a) a'^2 = 2 l sin a [F(a, omega) - c z' - friction],

        with z' = 2 l sin a a' and friction the signed Coulomb force opposing the sleeve's motion [N].
        """
        m, l, M = self.ball_mass, self.arm_length, self.sleeve_mass
        sin_a = math.sin(arm_angle)
        lever = 2.0 * l * sin_a
        sleeve_rate = lever * arm_rate
        force = self.lift(arm_angle, omega) - self.damping * sleeve_rate - friction
        mass = 2.0 * m * l * l + 4.0 * M * l * l * sin_a * sin_a
        return (lever * force - 2.0 * M * l * l * math.sin(2.0 * arm_angle) * arm_rate * arm_rate) / mass

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

    def equilibrium_sleeve(self, omega: float) -> float:
        """Sleeve position [m] where the lift vanishes at crank speed omega, clipped to the stroke
        (the lift falls monotonically with z, so the root is unique)."""
        low, high = self.stroke

        def lift_at(z: float) -> float:
            return self.lift(self.arm_angle(z), omega)

        if lift_at(low) <= 0.0:
            return low
        if lift_at(high) >= 0.0:
            return high
        return optimize.brentq(lift_at, low, high, xtol=1e-15, rtol=4 * np.finfo(float).eps)
