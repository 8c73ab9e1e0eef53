"""What joint friction reads of a mechanism's kinetostatics (docs/theory.md §6.1, source 001): the joint reactions
at a state, affine in the crank's acceleration epsilon, `R = R0(phi, omega, Q) + R1(phi) epsilon`, as complex numbers
F = Fx + i Fy [N] in the mechanism plane (y up), and the balancing moment. Every mechanism is a linkage (a preset's,
mechanisms/presets.py, or a scene's own), solved by groups from the farthest inward (linkage/kinetostatics.py,
`make_joint_loads`); this module holds the form of the result and the presets' joint names.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

CRANK_SLIDER_JOINTS = ("crank_bearing", "crank_pin", "wrist_pin", "guide")
FOUR_BAR_JOINTS = ("crank_bearing", "crank_pin", "rocker_pin", "rocker_bearing")


class JointLoads(NamedTuple):
    """The joint reactions at one (phi, omega, Q), affine in epsilon, in the order of the mechanism's joint names.

    constant, per_epsilon: reactions R = constant + per_epsilon * epsilon as complex Fx + i Fy [N] and
    [N s^2/rad]: the crank bearing F_01, the crank pin F_12, then F_23 (wrist pin / rocker pin) and the
    guide's normal force i N (crank–slider) or the rocker bearing F_03 (four-bar); a linkage's in its joints'
    order (linkage.make_joint_loads), a prismatic joint's as i N in the guide's own frame, as the crank–slider's;
    balancing: (M_b0 [N m], M_b1 [kg m^2]), the balancing moment M_b = M_b0 + M_b1 epsilon on the crank;
    ratios: the relative angular speed of the two links of each joint over omega [-] (for the guide, the
    slider's velocity over omega, dx/dphi [m/rad]).
    """

    constant: tuple[complex, ...]
    per_epsilon: tuple[complex, ...]
    balancing: tuple[float, float]
    ratios: tuple[float, ...]


Kinetostatics = Callable[[float, float, float], JointLoads]
