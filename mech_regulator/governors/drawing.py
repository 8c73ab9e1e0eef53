"""Drawing geometry of the Porter governor (pure numpy): spindle, arms, balls, links, sleeve and stops.

Coordinates are metres in the plane of the arms, y UP, with the top hinge of the arms at the origin:
the linkage is drawn as in the textbooks, in the plane that turns with it, so the balls never hide
each other. The spindle's turning is shown by a mark on a collar above the hinge, which goes round a
flat ellipse (the collar seen slightly from above) at the spindle angle psi. Parts are polylines of
shape (n, 2) or bundles of polylines of shape (k, n, 2); `balls` and `spindle_mark` are points, the
balls drawn with radius `ball_radius(sensor)`. MOVING_PARTS move with the arm or spindle angle; the
others stay put.
"""

from __future__ import annotations

import math

import numpy as np

from mech_regulator.governors.centrifugal import PorterSensor
from mech_regulator.mechanisms.drawing import outline_extent, rectangle, with_margin

STEEL_DENSITY = 7850.0          # density of the drawn balls, which are steel spheres of the ball mass [kg/m^3]
SPINDLE_ABOVE_HINGE = 0.25      # spindle drawn above the top hinge, per arm length [-]
SPINDLE_BELOW_SLEEVE = 0.25     # spindle drawn below the lowest sleeve position (z = 0), per arm length [-]
SLEEVE_HALF_WIDTH = 0.12        # per arm length [-]
SLEEVE_HALF_HEIGHT = 0.06       # per arm length [-]
STOP_HALF_WIDTH = 0.2           # half length of the stop collars, per arm length [-]
BOUNDS_SAMPLES = 50             # arm angles sampled over the stroke to find the swept outline [-]

COLLAR_RADIUS = 0.12            # radius of the collar that carries the spindle mark, per arm length [-]
COLLAR_TILT = 0.35              # apparent height / width of the collar's ellipse (seen from above) [-]

MOVING_PARTS = ("upper_arms", "lower_links", "sleeve", "balls", "spindle_mark")


def ball_radius(sensor: PorterSensor) -> float:
    """Radius [m] of a steel sphere of the ball mass m: r = (3 m / (4 pi rho))^(1/3)."""
    return (3.0 * sensor.ball_mass / (4.0 * math.pi * STEEL_DENSITY)) ** (1.0 / 3.0)


def sleeve_height(sensor: PorterSensor, arm_angle: float) -> float:
    """Height [m] of the sleeve's centre (where the lower links meet the spindle) below the top hinge,
    negative: -2 l cos a. The lift from the lowest possible position (a = 0) is 2 l (1 - cos a)."""
    return -2.0 * sensor.arm_length * math.cos(arm_angle)


def governor_outline(sensor: PorterSensor, arm_angle: float, spindle_angle: float) -> dict[str, np.ndarray]:
    """The governor's parts at arm angle a [rad] (from the spindle) and spindle angle psi [rad], metres, y up.

    Top hinge H = (0, 0); balls at (+-l sin a, -l cos a) on the upper arms H-ball; lower links
    (length l, Porter: equal to the arms) from the balls to the sleeve's centre S = (0, -2 l cos a) on the
    spindle; the sleeve a rectangle around S; the stops two collars on the spindle, one under the sleeve's
    bottom at z_low and one over its top at z_high; the spindle from SPINDLE_ABOVE_HINGE l above H to
    SPINDLE_BELOW_SLEEVE l below the sleeve's lowest possible centre (0, -2 l); the spindle mark at
    (r cos psi, h + k r sin psi) with r = COLLAR_RADIUS l, k = COLLAR_TILT, h half way up the spindle's top.
    """
    l = sensor.arm_length
    reach = l * math.sin(arm_angle)
    collar = COLLAR_RADIUS * l
    ball_y = -l * math.cos(arm_angle)
    hinge = (0.0, 0.0)
    sleeve_y = sleeve_height(sensor, arm_angle)
    balls = np.array([[reach, ball_y], [-reach, ball_y]])
    half_height = SLEEVE_HALF_HEIGHT * l
    low_stop = sleeve_height(sensor, sensor.arm_angle(sensor.stroke[0])) - half_height
    high_stop = sleeve_height(sensor, sensor.arm_angle(sensor.stroke[1])) + half_height
    stop = STOP_HALF_WIDTH * l
    return {
        "spindle": np.array([[0.0, SPINDLE_ABOVE_HINGE * l], [0.0, -(2.0 + SPINDLE_BELOW_SLEEVE) * l]]),
        "stops": np.array([[[-stop, low_stop], [stop, low_stop]], [[-stop, high_stop], [stop, high_stop]]]),
        "upper_arms": np.array([[hinge, balls[0]], [hinge, balls[1]]]),
        "lower_links": np.array([[balls[0], (0.0, sleeve_y)], [balls[1], (0.0, sleeve_y)]]),
        "sleeve": rectangle((0.0, sleeve_y), SLEEVE_HALF_WIDTH * l, half_height),
        "balls": balls,
        "spindle_mark": np.array([[collar * math.cos(spindle_angle),
                                   0.5 * SPINDLE_ABOVE_HINGE * l + COLLAR_TILT * collar * math.sin(spindle_angle)]]),
    }


def governor_bounds(sensor: PorterSensor) -> tuple[float, float, float, float]:
    """(xmin, xmax, ymin, ymax) [m, y up] framing the governor over its whole stroke: the extent of its
    outline (balls with their radius) at BOUNDS_SAMPLES arm angles between the stops, grown by the
    mechanisms' margin."""
    angles = np.linspace(*sensor.stop_angles(), BOUNDS_SAMPLES)
    outlines = [governor_outline(sensor, arm_angle, 0.0) for arm_angle in angles]
    return with_margin(outline_extent(outlines, ball_radius(sensor)))
