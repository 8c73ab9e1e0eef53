"""The spring-loaded Hartnell-type centrifugal sensor (docs/theory.md §8.9): statics and the sleeve's equation of
motion.

Two bell cranks pivot on the frame that turns with the spindle, at a radius r0 from its axis. Each carries a ball of
mass m on its ball arm of length a (upright at theta = 0) and presses the sleeve of mass M with its sleeve arm of
length b (horizontal at theta = 0, pointing at the spindle). Turning the crank by theta moves the ball out to the
radius r = r0 + a sin theta and lifts the sleeve to z = b sin theta (z = 0: both arms square to the spindle). A spring
of stiffness k pushes the sleeve down with k (z - z_free). The spindle turns at omega_g = ratio * omega. Forces on the
sleeve are upward forces along the spindle [N]. The formulas are the module's functions hartnell_sleeve, hartnell_lift
and hartnell_arm_acceleration, which both paths run (governors/sensor.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mech_regulator.governors.drawing import SPINDLE_BELOW_SLEEVE, sensor_parts
from mech_regulator.governors.sensor import CentrifugalSensor


def hartnell_sleeve(theta, m, a, b, r0, M, k, z_free, c, g, ratio):
    """Sleeve rise z = b sin theta [m]."""
    return b * math.sin(theta)


def hartnell_lift(theta, omega, m, a, b, r0, M, k, z_free, c, g, ratio):
    """Net upward force on the sleeve at rest [N]: the generalised force on theta divided by dz/dtheta = b cos theta,

    F = 2 m a omega_g^2 r / b + 2 m g a tan(theta) / b - M g - k (z - z_free),   r = r0 + a sin theta:

    the balls' centrifugal forces m omega_g^2 r on the arms a cos theta and their weights on the arms a sin theta,
    against the sleeve's weight and the spring on the arms b cos theta (docs/theory.md §8.9)."""
    omega_g = ratio * omega
    radius = r0 + a * math.sin(theta)
    spring = k * (hartnell_sleeve(theta, m, a, b, r0, M, k, z_free, c, g, ratio) - z_free)
    return 2.0 * m * a * (omega_g * omega_g * radius + g * math.tan(theta)) / b - M * g - spring


def hartnell_arm_acceleration(theta, theta_rate, omega, friction, m, a, b, r0, M, k, z_free, c, g, ratio):
    """Bell crank angular acceleration theta'' [rad/s^2] from Lagrange's equation

    (2 m a^2 + M b^2 cos^2 theta) theta'' - M b^2 sin theta cos theta theta'^2 = b cos theta [F - c z' - friction],

    with z' = b cos theta theta' and friction the signed Coulomb force opposing the sleeve's motion [N]."""
    cos_t = math.cos(theta)
    lever = b * cos_t
    force = hartnell_lift(theta, omega, m, a, b, r0, M, k, z_free, c, g, ratio) - c * lever * theta_rate - friction
    mass = 2.0 * m * a * a + M * lever * lever
    return (lever * force + M * b * b * math.sin(theta) * cos_t * theta_rate * theta_rate) / mass


@dataclass(frozen=True)
class HartnellSensor(CentrifugalSensor):
    """Parameters of the sensor, SI: ball_mass m [kg] (each ball), ball_arm a [m], sleeve_arm b [m], pivot_radius r0
    [m], sleeve_mass M [kg], stiffness k [N/m] and free_position z_free [m] of the sleeve spring, damping c [N s/m],
    kinetic and static Coulomb friction [N], ratio = omega_g / omega [-], gravity g [m/s^2], stroke (z_low, z_high)
    [m]."""

    ball_mass: float
    ball_arm: float
    sleeve_arm: float
    pivot_radius: float
    sleeve_mass: float
    stiffness: float
    free_position: float
    damping: float
    kinetic_friction: float
    static_friction: float
    ratio: float
    gravity: float
    stroke: tuple[float, float]

    name = "Hartnell"

    def kernels(self):
        """hartnell_sleeve, hartnell_lift, hartnell_arm_acceleration (CentrifugalSensor.kernels)."""
        return hartnell_sleeve, hartnell_lift, hartnell_arm_acceleration

    def kernel_parameters(self) -> tuple[float, ...]:
        """(m, a, b, r0, M, k, z_free, c, g, ratio)."""
        return (
            self.ball_mass,
            self.ball_arm,
            self.sleeve_arm,
            self.pivot_radius,
            self.sleeve_mass,
            self.stiffness,
            self.free_position,
            self.damping,
            self.gravity,
            self.ratio,
        )

    def arm_angle(self, sleeve: float) -> float:
        """Bell crank angle theta = arcsin(z / b) [rad] for a sleeve position z [m]."""
        return math.asin(sleeve / self.sleeve_arm)

    def sleeve_lever(self, arm_angle: float) -> float:
        """dz/dtheta = b cos theta [m/rad]."""
        return self.sleeve_arm * math.cos(arm_angle)

    def equilibrium_speed(self, sleeve: float, friction: float = 0.0) -> float:
        """Crank speed [rad/s] holding the sleeve at z against a friction force pushing down [N] (hartnell_lift = 0):

        omega_g^2 = (b (M g + k (z - z_free) + friction) - 2 m g a tan theta) / (2 m a r),  omega = omega_g / ratio,

        sin theta = z / b, r = r0 + a z / b. NaN where no speed can hold the sleeve."""
        m, a, b = self.ball_mass, self.ball_arm, self.sleeve_arm
        theta = self.arm_angle(sleeve)
        radius = self.pivot_radius + a * sleeve / b
        pull = b * (
            self.sleeve_mass * self.gravity + self.stiffness * (sleeve - self.free_position) + friction
        ) - 2.0 * m * self.gravity * a * math.tan(theta)
        if pull <= 0.0 or radius <= 0.0:
            return math.nan
        return math.sqrt(pull / (2.0 * m * a * radius)) / self.ratio

    def describe(self) -> str:
        """The Hartnell sensor's numbers."""
        return (
            f"Hartnell sensor: m = {self.ball_mass:g} kg, ball arm a = {self.ball_arm:g} m, sleeve arm b = "
            f"{self.sleeve_arm:g} m, pivots at r0 = {self.pivot_radius:g} m, M = {self.sleeve_mass:g} kg, spring "
            f"k = {self.stiffness:g} N/m free at {self.free_position:g} m, spindle ratio {self.ratio:g}"
        )

    def outline(self, arm_angle: float, spindle_angle: float) -> dict[str, np.ndarray]:
        """The bell cranks at theta [rad]: pivots at (+-r0, -a), balls at (+-(r0 + a sin theta), -a + a cos theta) on
        the upper arms, sleeve arms from the pivots to (+-(r0 - b cos theta), -a + b sin theta) at the sleeve's centre
        height; the spindle down to SPINDLE_BELOW_SLEEVE a below the sleeve's lowest possible centre (-a - b)."""
        a, b, r0 = self.ball_arm, self.sleeve_arm, self.pivot_radius
        sin_t, cos_t = math.sin(arm_angle), math.cos(arm_angle)
        balls = np.array([[r0 + a * sin_t, -a + a * cos_t], [-(r0 + a * sin_t), -a + a * cos_t]])
        pivots = np.array([[r0, -a], [-r0, -a]])
        sleeve_y = -a + b * sin_t
        tips = np.array([[r0 - b * cos_t, sleeve_y], [-(r0 - b * cos_t), sleeve_y]])
        stops = (-a + self.stroke[0], -a + self.stroke[1])
        return sensor_parts(
            a,
            stops,
            balls,
            np.stack([pivots, balls], axis=1),
            np.stack([pivots, tips], axis=1),
            sleeve_y,
            spindle_angle,
            -a - b - SPINDLE_BELOW_SLEEVE * a,
        )
