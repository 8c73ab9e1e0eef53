"""The presets' hand-written closed forms (the product runs every preset as a linkage, mechanisms/presets.py,
through the code generated from its groups, mechanisms/linkage/symbolic.py): kept here as the independent reference
the tests hold the product to (test_presets.py and the mechanism tests) — the crank–slider's, four-bar's, walking
beam's and multi-cylinder engine's reduced inertia, dJ/dphi, weight moment and output, and the crank–slider's and
four-bar's joint reactions by d'Alembert (docs/theory.md §2.1-§2.2 and §6.1), each written from its own equations.
"""

from __future__ import annotations

import cmath
import math
from collections.abc import Callable, Sequence

from mech_regulator.mechanisms import crank_slider
from mech_regulator.mechanisms.crank_slider import CrankSliderGeometry, slider_kinematics
from mech_regulator.mechanisms.four_bar import FourBarGeometry, link_angles
from mech_regulator.mechanisms.kinetostatics import JointLoads, Kinetostatics
from mech_regulator.mechanisms.walking_beam import WalkingBeamGeometry, _loop_points, arm, side


def crank_slider_reduced(
    geometry: CrankSliderGeometry, gravity: tuple[float, float] | None
) -> Callable[[float], tuple[float, float, float, float, float]]:
    """Build `reduced(phi) -> (J_links, dJ_links/dphi, M_weight, x, x')` for this crank–slider.

    J_links = m_rod |S'|^2 + J_rod theta'^2 + m_slider x'^2 (docs/theory.md §2.1), with the rod's
    centre S = B + rho (C - B), rho = rod_cg / l; dJ/dphi = 2 m_rod S'.S'' + 2 J_rod theta' theta''
    + 2 m_slider x' x''. M_weight = g . sum_k m_k S_k' (zero and not computed without gravity).
    The crank's own inertia belongs to the machine's constant inertia.
    """
    R, l, e = geometry.crank, geometry.rod, geometry.offset
    rho = geometry.rod_cg / l
    m_rod, J_rod, m_slider = geometry.rod_mass, geometry.rod_inertia, geometry.slider_mass
    m_crank_r = geometry.crank_mass * geometry.crank_cg
    gx, gy = gravity if gravity is not None else (0.0, 0.0)
    with_weight = gravity is not None and (gx != 0.0 or gy != 0.0)

    def reduced(phi: float) -> tuple[float, float, float, float, float]:
        x, dx, ddx, _theta, dtheta, ddtheta = slider_kinematics(phi, R, l, e)
        sin_phi, cos_phi = math.sin(phi), math.cos(phi)
        # S' = (1 - rho) B' + rho C',  B' = R(-sin, cos), C' = (x', 0); likewise S''.
        dSx = -(1.0 - rho) * R * sin_phi + rho * dx
        dSy = (1.0 - rho) * R * cos_phi
        ddSx = -(1.0 - rho) * R * cos_phi + rho * ddx
        ddSy = -(1.0 - rho) * R * sin_phi
        J = m_rod * (dSx * dSx + dSy * dSy) + J_rod * dtheta * dtheta + m_slider * dx * dx
        dJ = 2.0 * (m_rod * (dSx * ddSx + dSy * ddSy) + J_rod * dtheta * ddtheta + m_slider * dx * ddx)
        weight = 0.0
        if with_weight:
            weight = gx * (-m_crank_r * sin_phi + m_rod * dSx + m_slider * dx) + gy * (
                m_crank_r * cos_phi + m_rod * dSy
            )
        return J, dJ, weight, x, dx

    return reduced


def make_centre_motions(geometry: FourBarGeometry) -> Callable[[float], tuple[tuple[float, ...], tuple[complex, ...]]]:
    """Build `motions(phi) -> ((th3, th3', th3'', th4, th4', th4''), (e^{i phi}, e^{i th3}, e^{i th4}, S3', S3'',
    S4', S4''))`: the link angles of `link_angles` and the derivatives with respect to phi of the centres of mass
    `S3 = B + u3 e^{i th3}` (coupler) and `S4 = D + u4 e^{i th4}` (rocker) [m/rad, m/rad^2]:
    `S3' = i a e^{i phi} + i u3 th3' e^{i th3}`, `S3'' = -a e^{i phi} + u3 (i th3'' - th3'^2) e^{i th3}`,
    `S4' = i u4 th4' e^{i th4}`, `S4'' = u4 (i th4'' - th4'^2) e^{i th4}`."""
    g = geometry
    a, b, c, d, th1, sign = g.crank, g.coupler, g.rocker, g.frame, g.frame_angle, g.branch_sign
    u3, u4 = g.coupler_cg, g.rocker_cg

    def motions(phi: float) -> tuple[tuple[float, ...], tuple[complex, ...]]:
        angles = link_angles(phi, a, b, c, d, th1, sign)
        th3, dth3, ddth3, th4, dth4, ddth4 = angles
        e2, e3, e4 = cmath.exp(1j * phi), cmath.exp(1j * th3), cmath.exp(1j * th4)
        return angles, (
            e2,
            e3,
            e4,
            1j * (a * e2 + u3 * dth3 * e3),
            -a * e2 + u3 * complex(-dth3 * dth3, ddth3) * e3,
            1j * u4 * dth4 * e4,
            u4 * complex(-dth4 * dth4, ddth4) * e4,
        )

    return motions


def four_bar_reduced(
    geometry: FourBarGeometry, gravity: tuple[float, float] | None
) -> Callable[[float], tuple[float, float, float, float, float]]:
    """Build `reduced(phi) -> (J_links, dJ_links/dphi, M_weight, th4, th4')` for this four-bar.

    With the centres' derivatives S3', S3'', S4', S4'' of `make_centre_motions`:
    `J_links = m3 |S3'|^2 + J3 th3'^2 + m4 |S4'|^2 + J4 th4'^2`, `dJ = 2 sum (m Re(conj(S') S'') + J th' th'')`,
    `M_weight = g . sum_k m_k S_k'` (docs/theory.md §2.2). The output coordinate is the rocker angle.
    """
    g = geometry
    m3, J3, m4, J4 = g.coupler_mass, g.coupler_inertia, g.rocker_mass, g.rocker_inertia
    m2r = g.crank_mass * g.crank_cg
    gravity_c = complex(*gravity) if gravity is not None else 0j
    with_weight = gravity_c != 0j
    motions = make_centre_motions(geometry)

    def reduced(phi: float) -> tuple[float, float, float, float, float]:
        (_, dth3, ddth3, th4, dth4, ddth4), (e2, _, _, dS3, ddS3, dS4, ddS4) = motions(phi)
        J = m3 * abs(dS3) ** 2 + J3 * dth3 * dth3 + m4 * abs(dS4) ** 2 + J4 * dth4 * dth4
        dJ = 2.0 * (
            m3 * (dS3.conjugate() * ddS3).real
            + J3 * dth3 * ddth3
            + m4 * (dS4.conjugate() * ddS4).real
            + J4 * dth4 * ddth4
        )
        weight = 0.0
        if with_weight:
            weight = (gravity_c.conjugate() * (m2r * 1j * e2 + m3 * dS3 + m4 * dS4)).real
        return J, dJ, weight, th4, dth4

    return reduced


def walking_beam_reduced(
    geometry: WalkingBeamGeometry, gravity: tuple[float, float] | None
) -> Callable[[float], tuple[float, float, float, float, float]]:
    """Build `reduced(phi) -> (J_links, dJ_links/dphi, M_weight, x_C, x_C')` for this walking beam.

    By the definition of the reduced inertia (docs/theory.md §2.1), J_links = sum_k m_k |S_k'|^2 + J_k th_k'^2:
    coupler S2 = A + u2 e^{i (th3 + gamma2)} turning with th3; the two rockers (identical) S3 = O2 + u3 e^{i th4}
    and its copy, turning with th4; the tie B E translating with B; the side link S6 = E + u6 e^{i th6},
    th6 = th3 + arg(BC) turning with th3; the shuttle bar translating with C. dJ/dphi = 2 sum_k
    (m_k Re(conj(S_k') S_k'') + J_k th_k' th_k''); M_weight = Re(conj(g) sum_k m_k S_k') with the crank's
    m1 u1 i e^{i phi}. The output coordinate is the shuttle bar's horizontal position x_C = Re C.
    The crank's own inertia belongs to the machine's constant inertia.
    """
    g = geometry
    bc = side(g)
    side_angle = cmath.phase(bc)
    m2, u2, gamma2, J2 = g.coupler_mass, g.coupler_cg, g.coupler_cg_angle, g.coupler_inertia
    m3, u3, J3 = 2.0 * g.rocker_mass, g.rocker_cg, 2.0 * g.rocker_inertia  # both rockers move alike
    m4, m6, u6, J6, m7 = g.tie_mass, g.side_mass, g.side_cg, g.side_inertia, g.shuttle_mass
    J_coupler_side = J2 + J6  # both turn with th3
    m1u1 = g.crank_mass * g.crank_cg
    O2 = g.frame * cmath.exp(1j * g.frame_angle)
    gravity_c = complex(*gravity) if gravity is not None else 0j
    with_weight = gravity_c != 0j

    def reduced(phi: float) -> tuple[float, float, float, float, float]:
        (th3, dth3, ddth3, th4, dth4, ddth4), A, B, C = _loop_points(phi, g, O2)
        dS2, ddS2 = arm(A, u2, th3 + gamma2, dth3, ddth3)[1:]
        dS3, ddS3 = arm((O2, 0j, 0j), u3, th4, dth4, ddth4)[1:]
        dS6, ddS6 = arm(B, u6, th3 + side_angle, dth3, ddth3)[1:]  # about E = B + s: the derivatives of B's arm
        dB, ddB, dC, ddC = B[1], B[2], C[1], C[2]
        J = (
            m2 * abs(dS2) ** 2
            + m3 * abs(dS3) ** 2
            + m4 * abs(dB) ** 2
            + m6 * abs(dS6) ** 2
            + m7 * abs(dC) ** 2
            + J_coupler_side * dth3 * dth3
            + J3 * dth4 * dth4
        )
        dJ = 2.0 * (
            m2 * (dS2.conjugate() * ddS2).real
            + m3 * (dS3.conjugate() * ddS3).real
            + m4 * (dB.conjugate() * ddB).real
            + m6 * (dS6.conjugate() * ddS6).real
            + m7 * (dC.conjugate() * ddC).real
            + J_coupler_side * dth3 * ddth3
            + J3 * dth4 * ddth4
        )
        weight = 0.0
        if with_weight:
            weight = (
                gravity_c.conjugate()
                * (m1u1 * 1j * cmath.exp(1j * phi) + m2 * dS2 + m3 * dS3 + m4 * dB + m6 * dS6 + m7 * dC)
            ).real
        return J, dJ, weight, C[0].real, dC.real

    return reduced


def cylinder_shifts(throws_deg: Sequence[float], banks_deg: Sequence[float]) -> tuple[float, ...]:
    """Each cylinder's own crank angle minus phi [rad]: `phi_i - phi = throw_i - bank_i`."""
    return tuple(math.radians(throw - bank) for throw, bank in zip(throws_deg, banks_deg))


def multi_cylinder_reduced(
    geometry: crank_slider.CrankSliderGeometry,
    throws_deg: Sequence[float],
    banks_deg: Sequence[float],
    gravity: tuple[float, float] | None,
) -> Callable[[float], tuple[float, float, float, tuple[float, ...], tuple[float, ...]]]:
    """Build `reduced(phi) -> (J_links, dJ_links/dphi, M_weight, (x_1..x_n), (x_1'..x_n'))` of n identical
    cylinders on one crankshaft: each term is the single cylinder's at its own crank angle phi_i = phi +
    throw_i - bank_i (d phi_i / d phi = 1), its gravity turned into the cylinder's frame
    `g_i = (gx cos b + gy sin b, -gx sin b + gy cos b)`, b = bank_i. Kinetic energy and power do not depend on
    the frame, so `J = sum_i J_1(phi_i)`, `J' = sum_i J_1'(phi_i)`, `M_weight = sum_i M_weight,i`. The crank
    mass counts once per cylinder (each throw's share of the crankshaft)."""
    parts = []
    for shift, bank in zip(cylinder_shifts(throws_deg, banks_deg), banks_deg):
        turned = None
        if gravity is not None:
            c, s = math.cos(math.radians(bank)), math.sin(math.radians(bank))
            turned = (gravity[0] * c + gravity[1] * s, -gravity[0] * s + gravity[1] * c)
        parts.append((shift, crank_slider_reduced(geometry, turned)))

    def reduced(phi: float) -> tuple[float, float, float, tuple[float, ...], tuple[float, ...]]:
        J = dJ = weight = 0.0
        xs, dxs = [], []
        for shift, single in parts:
            J_i, dJ_i, weight_i, x_i, dx_i = single(phi + shift)
            J += J_i
            dJ += dJ_i
            weight += weight_i
            xs.append(x_i)
            dxs.append(dx_i)
        return J, dJ, weight, tuple(xs), tuple(dxs)

    return reduced


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

        def solve(
            a_S1: complex, a_S3: complex, alpha3: float, a_S4: complex, alpha4: float, gravity_: complex, q: float
        ):
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


def preset_point_motions(mechanism) -> Callable[[float], dict]:
    """`motions(phi) -> {point: (P, P', P'')}` of a preset's named points by its closed forms (complex x + i y):
    crank–slider crank pin B = R e^{i phi}, slider C = x + i e (slider_kinematics' x, x', x''); four-bar B = a e^{i phi},
    C = d e^{i th1} + c e^{i th4} (link_angles); walking beam A..E (walking_beam.solve)."""
    from mech_regulator.mechanisms import walking_beam
    from mech_regulator.mechanisms.four_bar import BRANCH_SIGN
    from mech_regulator.scene import mechanism_keys

    if isinstance(mechanism, mechanism_keys.CrankSlider):
        R, rod, e = mechanism.crank, mechanism.rod, mechanism.offset

        def crank_slider_motions(phi: float) -> dict:
            x, dx, ddx, *_ = slider_kinematics(phi, R, rod, e)
            return {"B": arm((0j, 0j, 0j), R, phi, 1.0, 0.0), "C": (complex(x, e), complex(dx), complex(ddx))}

        return crank_slider_motions
    if isinstance(mechanism, mechanism_keys.FourBar):
        a, b, c, d = mechanism.crank, mechanism.coupler, mechanism.rocker, mechanism.frame
        th1, sign = math.radians(mechanism.frame_angle_deg), BRANCH_SIGN[mechanism.branch]

        def four_bar_motions(phi: float) -> dict:
            _, _, _, th4, dth4, ddth4 = link_angles(phi, a, b, c, d, th1, sign)
            return {
                "B": arm((0j, 0j, 0j), a, phi, 1.0, 0.0),
                "C": arm((d * cmath.exp(1j * th1), 0j, 0j), c, th4, dth4, ddth4),
            }

        return four_bar_motions
    geometry = walking_beam.geometry_from_scene(mechanism)
    return lambda phi: walking_beam.solve(phi, geometry)[1]
