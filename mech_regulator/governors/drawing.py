"""Drawing geometry of the centrifugal sensors (pure numpy): spindle, arms, balls, links, sleeve and stops.

Coordinates are metres in the plane of the arms, y UP, with the top hinge of the arms at the origin:
the linkage is drawn as in the textbooks, in the plane that turns with it, so the balls never hide
each other. The spindle's turning is shown by a mark on a collar above the hinge, which goes round a
flat ellipse (the collar seen slightly from above) at the spindle angle psi. Parts are polylines of
shape (n, 2) or bundles of polylines of shape (k, n, 2); `balls` and `spindle_mark` are points, the
balls drawn with radius `sensor.ball_radius()` (governors/sensor.py). MOVING_PARTS move with the arm or spindle
angle; the others stay put.
"""

from __future__ import annotations

import math

import numpy as np

from mech_regulator.mechanisms.drawing import rectangle

STEEL_DENSITY = 7850.0  # density of the drawn balls, which are steel spheres of the ball mass [kg/m^3]
SPINDLE_ABOVE_HINGE = 0.25  # spindle drawn above the top hinge, per arm length [-]
SPINDLE_BELOW_SLEEVE = 0.25  # spindle drawn below the lowest sleeve position (z = 0), per arm length [-]
SLEEVE_HALF_WIDTH = 0.12  # per arm length [-]
SLEEVE_HALF_HEIGHT = 0.06  # per arm length [-]
STOP_HALF_WIDTH = 0.2  # half length of the stop collars, per arm length [-]
BOUNDS_SAMPLES = 50  # arm angles sampled over the stroke to find the swept outline [-]

COLLAR_RADIUS = 0.12  # radius of the collar that carries the spindle mark, per arm length [-]
COLLAR_TILT = 0.35  # apparent height / width of the collar's ellipse (seen from above) [-]

MOVING_PARTS = ("upper_arms", "lower_links", "sleeve", "balls", "spindle_mark")


def sensor_parts(
    scale: float,
    stop_heights: tuple[float, float],
    balls: np.ndarray,
    upper_arms: np.ndarray,
    lower_links: np.ndarray,
    sleeve_y: float,
    spindle_angle: float,
    bottom: float,
) -> dict[str, np.ndarray]:
    """The drawing's parts (MOVING_PARTS and the fixed spindle and stops) from a sensor's own geometry, metres, y up:
    scale [m] (the arm length the relative sizes above are per), the heights [m] of the sleeve's centre at its two
    stops, the two balls (2, 2), the upper arms and lower links (2, 2, 2), the sleeve's centre height [m], the spindle
    angle psi [rad] and the spindle's lower end [m]. The sleeve is a rectangle around (0, sleeve_y); the stops two
    collars, one under the sleeve's bottom at the low stop and one over its top at the high stop; the spindle from
    SPINDLE_ABOVE_HINGE scale above the origin down to `bottom`; the spindle mark at (r cos psi, h + k r sin psi) with
    r = COLLAR_RADIUS scale, k = COLLAR_TILT, h half way up the spindle's top."""
    collar = COLLAR_RADIUS * scale
    half_height = SLEEVE_HALF_HEIGHT * scale
    low_stop, high_stop = stop_heights[0] - half_height, stop_heights[1] + half_height
    stop = STOP_HALF_WIDTH * scale
    return {
        "spindle": np.array([[0.0, SPINDLE_ABOVE_HINGE * scale], [0.0, bottom]]),
        "stops": np.array([[[-stop, low_stop], [stop, low_stop]], [[-stop, high_stop], [stop, high_stop]]]),
        "upper_arms": upper_arms,
        "lower_links": lower_links,
        "sleeve": rectangle((0.0, sleeve_y), SLEEVE_HALF_WIDTH * scale, half_height),
        "balls": balls,
        "spindle_mark": np.array(
            [
                [
                    collar * math.cos(spindle_angle),
                    (0.5 * SPINDLE_ABOVE_HINGE * scale + COLLAR_TILT * collar * math.sin(spindle_angle)),
                ]
            ]
        ),
    }


def porter_sleeve_height(arm_length: float, arm_angle: float) -> float:
    """Height [m] of the Porter sleeve's centre (where the lower links meet the spindle) below the top hinge,
    negative: -2 l cos a. The lift from the lowest possible position (a = 0) is 2 l (1 - cos a)."""
    return -2.0 * arm_length * math.cos(arm_angle)


def porter_outline(
    arm_length: float, stroke: tuple[float, float], arm_angle: float, spindle_angle: float
) -> dict[str, np.ndarray]:
    """The Porter governor's parts at arm angle a [rad] (from the spindle) and spindle angle psi [rad], arm length
    l [m] and stroke (z_low, z_high) [m], metres, y up (sensor_parts).

    Top hinge H = (0, 0); balls at (+-l sin a, -l cos a) on the upper arms H-ball; lower links (length l, Porter:
    equal to the arms) from the balls to the sleeve's centre S = (0, -2 l cos a) on the spindle; the spindle down to
    SPINDLE_BELOW_SLEEVE l below the sleeve's lowest possible centre (0, -2 l).
    """
    l = arm_length
    reach, ball_y = l * math.sin(arm_angle), -l * math.cos(arm_angle)
    hinge = (0.0, 0.0)
    sleeve_y = porter_sleeve_height(l, arm_angle)
    balls = np.array([[reach, ball_y], [-reach, ball_y]])
    low, high = (porter_sleeve_height(l, math.acos(1.0 - z / (2.0 * l))) for z in stroke)
    stops = (low, high)
    return sensor_parts(
        l,
        stops,
        balls,
        np.array([[hinge, balls[0]], [hinge, balls[1]]]),
        np.array([[balls[0], (0.0, sleeve_y)], [balls[1], (0.0, sleeve_y)]]),
        sleeve_y,
        spindle_angle,
        -(2.0 + SPINDLE_BELOW_SLEEVE) * l,
    )
