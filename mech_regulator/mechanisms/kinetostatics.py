"""Kinetostatics (d'Alembert) of the crank–slider and the four-bar: the joint reactions at a state.

physics.md section 7 (source 001): with the inertia force `-m a_S` and moment `-J_S epsilon` added to every
link, each link is in equilibrium; the structural group beyond the crank (rod + slider, coupler + rocker)
is statically determinate, so its reactions follow from the group alone and the crank's equilibrium gives
the crank bearing's reaction and the balancing moment. Forces are complex numbers F = Fx + i Fy [N] in the
mechanism plane (y up); `F_ij` is the force of link i on link j, 0 being the frame.

Every acceleration is `a = s' epsilon + s'' omega^2` (kinematic transfer functions of
crank_slider.slider_kinematics / four_bar.make_centre_motions), so the reactions are affine in epsilon:
`R = R0(phi, omega, Q) + R1(phi) epsilon` with Q the generalised force on the output link (slider force
along +x [N], or moment on the rocker [N m]). `make_kinetostatics` returns both parts.

The crank's own moment of inertia belongs to the machine's constant inertia J0 (scene.schema.CrankSlider),
so the balancing moment here is the one the linkage asks of the crank: `M_b = B x F_12 - m1 S1 x g`,
equal to the reduced form `J_links epsilon + 1/2 J_links' omega^2 - M_weight - Q dq/dphi`.
"""

from __future__ import annotations

import cmath
from typing import Callable, NamedTuple

from mech_regulator.mechanisms.crank_slider import CrankSliderGeometry, slider_kinematics
from mech_regulator.mechanisms.four_bar import FourBarGeometry, make_centre_motions

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


def _cross(u: complex, v: complex) -> float:
    """z component of the planar cross product u x v."""
    return u.real * v.imag - u.imag * v.real


def crank_slider_kinetostatics(geometry: CrankSliderGeometry, gravity: tuple[float, float]) -> Kinetostatics:
    """`loads(phi, omega, Q) -> JointLoads` of a crank–slider (joints CRANK_SLIDER_JOINTS), Q the force on the
    slider along +x [N].

    Slider (point mass m3 at C, frictionless guide normal N):  F_23 + i N + m3 g + Q = m3 a_C, so
    `F_23x = m3 a_C - Q - m3 gx`; rod (m2, J2 about S2) about B: `(C - B) x F_32 = (S2 - B) x m2 (a_S2 - g)
    + J2 alpha2 =: H`, which with L = C - B gives `F_23y = (L_y F_23x - H) / L_x` and `N = -F_23y - m3 gy`;
    rod forces `F_12 = m2 (a_S2 - g) + F_23`; crank (m1 at S1) `F_01 = m1 (a_S1 - g) + F_12`.
    """
    R, l, e = geometry.crank, geometry.rod, geometry.offset
    rho = geometry.rod_cg / l
    m1, u1 = geometry.crank_mass, geometry.crank_cg
    m2, J2, m3 = geometry.rod_mass, geometry.rod_inertia, geometry.slider_mass
    g = complex(*gravity)

    def loads(phi: float, omega: float, force: float) -> JointLoads:
        x, dx, ddx, _theta, dtheta, ddtheta = slider_kinematics(phi, R, l, e)
        e2 = cmath.exp(1j * phi)
        B = R * e2
        L = complex(x, e) - B
        dB, ddB = 1j * B, -B
        dS2 = (1.0 - rho) * dB + rho * dx
        ddS2 = (1.0 - rho) * ddB + rho * ddx
        w2 = omega * omega

        def solve(a_S1: complex, a_S2: complex, alpha2: float, a_C: float, gravity_: complex, q: float):
            H = _cross(rho * L, m2 * (a_S2 - gravity_)) + J2 * alpha2
            F23x = m3 * a_C - q - m3 * gravity_.real
            F23 = complex(F23x, (L.imag * F23x - H) / L.real)
            normal = -F23.imag - m3 * gravity_.imag
            F12 = m2 * (a_S2 - gravity_) + F23
            F01 = m1 * (a_S1 - gravity_) + F12
            balancing = _cross(B, F12) - m1 * _cross(u1 * e2, gravity_)
            return (F01, F12, F23, 1j * normal), balancing

        constant, balancing0 = solve(u1 * -e2 * w2, ddS2 * w2, ddtheta * w2, ddx * w2, g, force)
        per_epsilon, balancing1 = solve(u1 * 1j * e2, dS2, dtheta, dx, 0j, 0.0)
        return JointLoads(constant, per_epsilon, (balancing0, balancing1), (1.0, 1.0 - dtheta, dtheta, dx))

    return loads


def four_bar_kinetostatics(geometry: FourBarGeometry, gravity: tuple[float, float]) -> Kinetostatics:
    """`loads(phi, omega, Q) -> JointLoads` of a four-bar (joints FOUR_BAR_JOINTS), Q the moment on the rocker [N m].

    Rocker (m4, J4 about S4) about D: `c x F_23 = (S4 - D) x m4 (a_S4 - g) + J4 alpha4 - Q =: H4`; coupler
    (m3, J3 about S3) about B: `b x F_23 = -[(S3 - B) x m3 (a_S3 - g) + J3 alpha3] =: -H3`, with b = C - B,
    c = C - D: two linear equations for F_23 (Cramer; the determinant c x b vanishes only at a toggle).
    Then `F_12 = m3 (a_S3 - g) + F_23`, `F_03 = m4 (a_S4 - g) - F_23`, `F_01 = m1 (a_S1 - g) + F_12`.
    """
    g_ = geometry
    a, b, c = g_.crank, g_.coupler, g_.rocker
    m1, u1 = g_.crank_mass, g_.crank_cg
    m3, u3, J3 = g_.coupler_mass, g_.coupler_cg, g_.coupler_inertia
    m4, u4, J4 = g_.rocker_mass, g_.rocker_cg, g_.rocker_inertia
    g = complex(*gravity)
    motions = make_centre_motions(geometry)

    def loads(phi: float, omega: float, moment: float) -> JointLoads:
        (_, dth3, ddth3, _, dth4, ddth4), (e2, e3, e4, dS3, ddS3, dS4, ddS4) = motions(phi)
        B = a * e2
        coupler, rocker = b * e3, c * e4
        det = _cross(rocker, coupler)
        w2 = omega * omega

        def solve(a_S1: complex, a_S3: complex, alpha3: float, a_S4: complex, alpha4: float, gravity_: complex,
                  q: float):
            H4 = _cross(u4 * e4, m4 * (a_S4 - gravity_)) + J4 * alpha4 - q
            H3 = _cross(u3 * e3, m3 * (a_S3 - gravity_)) + J3 * alpha3
            F23 = complex(H4 * coupler.real + rocker.real * H3, rocker.imag * H3 + coupler.imag * H4) / det
            F12 = m3 * (a_S3 - gravity_) + F23
            F03 = m4 * (a_S4 - gravity_) - F23
            F01 = m1 * (a_S1 - gravity_) + F12
            balancing = _cross(B, F12) - m1 * _cross(u1 * e2, gravity_)
            return (F01, F12, F23, F03), balancing

        constant, balancing0 = solve(-u1 * e2 * w2, ddS3 * w2, ddth3 * w2, ddS4 * w2, ddth4 * w2, g, moment)
        per_epsilon, balancing1 = solve(1j * u1 * e2, dS3, dth3, dS4, dth4, 0j, 0.0)
        return JointLoads(constant, per_epsilon, (balancing0, balancing1), (1.0, 1.0 - dth3, dth3 - dth4, dth4))

    return loads

