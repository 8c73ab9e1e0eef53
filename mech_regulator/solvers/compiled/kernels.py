"""Scalar numba kernels of the compiled fast path: one per physics piece, each a transcription of its pure-Python
original (named in its docstring, with the same equation), called by the right-hand side the code generator writes
for a scene (solvers/compiled/codegen.py). Tables are read from the parameter vector p at (offset, length), so no
number of a scene is compiled into the code. All arguments and results are SI, as in the originals.

The generated module's cache name includes this file's source: numba's own cache would not notice a changed kernel.
"""

from __future__ import annotations

import cmath
import math

import numpy as np
from numba import njit

# ---------------------------------------------------------------------------------------------------------------
# Tables (effects/tables.py) read from p: xs at p[offset : offset + n], ys at p[offset + n : offset + 2 n]


@njit(cache=True)
def periodic_linear(x, anchor, p, offset, n, period):
    """effects.tables.periodic_linear: y(x) linear between the n points, periodic with `period`, the last point
    joined to the first plus one period (np.interp(x, xs, ys, period=period)), here the line of the segment that holds
    `anchor` continued to x (anchor = x: the table itself)."""
    x0 = p[offset]
    u = np.fmod(anchor - x0, period)
    if u < 0.0:
        u += period
    i = n - 1
    while i > 0 and p[offset + i] - x0 > u:
        i -= 1
    lo = p[offset + i] - x0
    y_lo = p[offset + n + i]
    if i + 1 < n:
        hi, y_hi = p[offset + i + 1] - x0, p[offset + n + i + 1]
    else:
        hi, y_hi = period, p[offset + n]
    return y_lo + (y_hi - y_lo) / (hi - lo) * (u - lo + (x - anchor))


@njit(cache=True)
def clamped_linear(x, p, offset, n, anchor=np.nan):
    """effects.tables.clamped_linear: y(x) linear between the n points, held at the end values beyond them; with an
    anchor (not NaN), the piece that holds the anchor continued to x (an anchor on an end point: the end segment)."""
    at = x if np.isnan(anchor) else anchor
    if at < p[offset]:
        return p[offset + n]
    if at > p[offset + n - 1]:
        return p[offset + 2 * n - 1]
    i = n - 2
    while p[offset + i] > at:
        i -= 1
    return p[offset + n + i] + (p[offset + n + i + 1] - p[offset + n + i]) / (p[offset + i + 1] - p[offset + i]) * (
        x - p[offset + i])


@njit(cache=True)
def extrapolated_linear(x, p, offset, n, anchor=np.nan):
    """effects.tables.extrapolated_linear: y(x) linear between the n points, the end segments continued; with an
    anchor (not NaN), the segment that holds the anchor continued to x."""
    at = x if np.isnan(anchor) else anchor
    i = n - 2
    while i > 0 and p[offset + i] > at:
        i -= 1
    return p[offset + n + i] + (p[offset + n + i + 1] - p[offset + n + i]) / (p[offset + i + 1] - p[offset + i]) * (
        x - p[offset + i])


# ---------------------------------------------------------------------------------------------------------------
# Effects (effects/__init__.py): moments on the crank [N m]


@njit(cache=True)
def linear_motor(omega, stall, no_load):
    """Linear motor: M_d = M_stall (1 - omega / omega_0)."""
    return stall * (1.0 - omega / no_load)


@njit(cache=True)
def table_drive(phi, anchor, p, offset, n, period):
    """Table drive: M_d = M(phi), periodic linear table (on the segment that holds anchor)."""
    return periodic_linear(phi, anchor, p, offset, n, period)


@njit(cache=True)
def engine_gas_force(phi, anchor, p, offset, n, cycle, phase, area):
    """The gas force on the piston along +x: F = -p(phi + phase) A (it pushes the piston towards the crank) [N]
    (p on the segment that holds anchor + phase)."""
    return -periodic_linear(phi + phase, anchor + phase, p, offset, n, cycle) * area


@njit(cache=True)
def engine_gas(phi, anchor, dq, p, offset, n, cycle, phase, area):
    """Single-cylinder engine: M_d = -p(phi + phase) A dx/dphi (engine_gas_force reduced to the crank)."""
    return engine_gas_force(phi, anchor, p, offset, n, cycle, phase, area) * dq


@njit(cache=True)
def viscous_load(omega, c):
    """Viscous load: M_c = -c omega."""
    return -c * omega


@njit(cache=True)
def fan_load(omega, k):
    """Fan load: M_c = -k omega |omega|."""
    return -k * omega * abs(omega)


@njit(cache=True)
def table_load(phi, anchor, p, offset, n, period):
    """Table load: M_c = -M(phi), periodic linear table (on the segment that holds anchor)."""
    return -periodic_linear(phi, anchor, p, offset, n, period)


@njit(cache=True)
def cutting_load(phi, p, offset, n, period, start, torque):
    """Cutting (on-off) load: M_c = -torque while (phi - start) mod period lies in an interval [start_k, end_k);
    the n interval edges (relative to start, ascending) are at p[offset : offset + n]."""
    u = np.fmod(phi - start, period)
    if u < 0.0:
        u += period
    count = 0  # bisect_right(bounds, u)
    while count < n and p[offset + count] <= u:
        count += 1
    return -torque if count % 2 == 1 else 0.0


@njit(cache=True)
def output_constant(dq, value):
    """Constant force (slider) or moment (rocker) on the output link: M = Q dq/dphi."""
    return value * dq


@njit(cache=True)
def output_viscous(omega, dq, c):
    """Viscous force on the output link: M = -c (dq/dphi)^2 omega."""
    return -c * dq * dq * omega


@njit(cache=True)
def output_viscous_force(omega, dq, c):
    """The viscous force itself, Q = -c dq/dphi omega (what the joint friction's kinetostatics reads) [N or N m]."""
    return -c * dq * omega


@njit(cache=True)
def output_spring_force(q, k, free):
    """The spring's force on the output link: Q = -k (q - q_free) [N or N m]."""
    return -k * (q - free)


@njit(cache=True)
def output_spring(q, dq, k, free):
    """Spring on the output link: M = -k (q - q_free) dq/dphi (output_spring_force reduced to the crank)."""
    return output_spring_force(q, k, free) * dq


@njit(cache=True)
def held_position(anchor, p, offset, n):
    """effects.held_positions looked up: the n - 1 kink angles [rad] in [0, 2 pi) at p[offset:], then 2 pi, and the n
    held slider positions [m] after them; the one of the interval that holds anchor mod 2 pi."""
    u = np.fmod(anchor, p[offset + n - 1])
    if u < 0.0:
        u += p[offset + n - 1]
    j = 0  # bisect_right(kinks, u)
    while j < n - 1 and p[offset + j] <= u:
        j += 1
    return p[offset + n + j]


@njit(cache=True)
def slider_table(q, q_anchor, dq, p, offset, n):
    """Slider force table: M = F(x) dx/dphi, F clamped linear in x (on the piece that holds x = q_anchor [m])."""
    return clamped_linear(q, p, offset, n, q_anchor) * dq


# ---------------------------------------------------------------------------------------------------------------
# Mechanisms: reduced(phi) -> (J_links [kg m^2], dJ/dphi [kg m^2/rad], M_weight [N m], q, dq/dphi)


@njit(cache=True)
def slider_kinematics(phi, R, l, e):
    """mechanisms.crank_slider.slider_kinematics without theta: with s = e - R sin phi, w = sqrt(l^2 - s^2),
    x = R cos phi + w, theta' = s'/w; returns (x [m], x' [m/rad], x'' [m/rad^2], theta' [-], theta'' [1/rad])."""
    sin_phi, cos_phi = math.sin(phi), math.cos(phi)
    s = e - R * sin_phi
    ds = -R * cos_phi
    dds = R * sin_phi
    w = math.sqrt(l * l - s * s)
    dw = -s * ds / w
    ddw = -(ds * ds + s * dds + dw * dw) / w
    dtheta = ds / w
    ddtheta = (dds * w - ds * dw) / (w * w)
    return R * cos_phi + w, -R * sin_phi + dw, -R * cos_phi + ddw, dtheta, ddtheta


@njit(cache=True)
def crank_slider_reduced(phi, R, l, e, m_crank_r, rho, m_rod, J_rod, m_slider, gx, gy, with_weight):
    """mechanisms.crank_slider.make_reduced: with slider_kinematics, S' = (1 - rho) B' + rho C';
    J = m_rod |S'|^2 + J_rod theta'^2 + m_slider x'^2, dJ = 2 m_rod S'.S'' + 2 J_rod theta' theta'' + 2 m_slider
    x' x'', M_weight = g . sum m_k S_k' (m_crank_r = crank mass times its centre's radius, rho = rod_cg / l)."""
    x, dx, ddx, dtheta, ddtheta = slider_kinematics(phi, R, l, e)
    sin_phi, cos_phi = math.sin(phi), math.cos(phi)
    dSx = -(1.0 - rho) * R * sin_phi + rho * dx
    dSy = (1.0 - rho) * R * cos_phi
    ddSx = -(1.0 - rho) * R * cos_phi + rho * ddx
    ddSy = -(1.0 - rho) * R * sin_phi
    J = m_rod * (dSx * dSx + dSy * dSy) + J_rod * dtheta * dtheta + m_slider * dx * dx
    dJ = 2.0 * (m_rod * (dSx * ddSx + dSy * ddSy) + J_rod * dtheta * ddtheta + m_slider * dx * ddx)
    weight = 0.0
    if with_weight:
        weight = gx * (-m_crank_r * sin_phi + m_rod * dSx + m_slider * dx) + gy * (m_crank_r * cos_phi + m_rod * dSy)
    return J, dJ, weight, x, dx


@njit(cache=True)
def link_angles(phi, a, b, c, d, th1, sign):
    """mechanisms.four_bar.link_angles: (th3, th3', th3'', th4, th4', th4''), th4 = arg(B - D) + sign acos((c^2 + f^2
    - b^2) / (2 c f)), th3' = a sin(th4 - phi) / (b sin(th3 - th4)), th4' = a sin(phi - th3) / (c sin(th4 - th3)),
    second derivatives from the twice-differentiated loop; all NaN where the loop cannot close."""
    B = a * cmath.exp(1j * phi)
    D = d * cmath.exp(1j * th1)
    pv = B - D
    f = abs(pv)
    cos_gamma = (c * c + f * f - b * b) / (2.0 * c * f) if f > 0.0 else math.inf
    if not (-1.0 <= cos_gamma <= 1.0):
        return math.nan, math.nan, math.nan, math.nan, math.nan, math.nan
    towards_A = th1 + math.pi
    th4 = towards_A + cmath.phase(pv * cmath.exp(-1j * towards_A)) + sign * math.acos(cos_gamma)
    C = D + c * cmath.exp(1j * th4)
    th3 = cmath.phase(C - B)
    sin34 = math.sin(th3 - th4)
    dth3 = a * math.sin(th4 - phi) / (b * sin34)
    dth4 = a * math.sin(phi - th3) / (-c * sin34)
    e3, e4 = cmath.exp(1j * th3), cmath.exp(1j * th4)
    r = B + b * dth3 * dth3 * e3 - c * dth4 * dth4 * e4
    ddth3 = -(r / e4).real / (b * sin34)
    ddth4 = (r / e3).real / (-c * sin34)
    return th3, dth3, ddth3, th4, dth4, ddth4


@njit(cache=True)
def four_bar_centres(phi, a, b, c, d, th1, sign, u3, u4):
    """mechanisms.four_bar.make_centre_motions: link_angles and e^{i phi}, e^{i th3}, e^{i th4},
    S3' = i (a e^{i phi} + u3 th3' e^{i th3}), S3'' = -a e^{i phi} + u3 (i th3'' - th3'^2) e^{i th3},
    S4' = i u4 th4' e^{i th4}, S4'' = u4 (i th4'' - th4'^2) e^{i th4}; returns (th3', th3'', th4, th4', th4'', e2,
    e3, e4, S3', S3'', S4', S4'')."""
    th3, dth3, ddth3, th4, dth4, ddth4 = link_angles(phi, a, b, c, d, th1, sign)
    e2, e3, e4 = cmath.exp(1j * phi), cmath.exp(1j * th3), cmath.exp(1j * th4)
    dS3 = 1j * (a * e2 + u3 * dth3 * e3)
    ddS3 = -a * e2 + u3 * complex(-dth3 * dth3, ddth3) * e3
    dS4 = 1j * u4 * dth4 * e4
    ddS4 = u4 * complex(-dth4 * dth4, ddth4) * e4
    return dth3, ddth3, th4, dth4, ddth4, e2, e3, e4, dS3, ddS3, dS4, ddS4


@njit(cache=True)
def four_bar_reduced(phi, a, b, c, d, th1, sign, m2r, m3, u3, J3, m4, u4, J4, gx, gy, with_weight):
    """mechanisms.four_bar.make_reduced with four_bar_centres: J = m3 |S3'|^2 + J3 th3'^2 + m4 |S4'|^2 + J4 th4'^2,
    dJ = 2 sum (m Re(conj(S') S'') + J th' th''), M_weight = g . (m2 r2 i e^{i phi} + m3 S3' + m4 S4').
    NaN where the loop cannot close."""
    dth3, ddth3, th4, dth4, ddth4, e2, _, _, dS3, ddS3, dS4, ddS4 = four_bar_centres(phi, a, b, c, d, th1, sign, u3,
                                                                                       u4)
    if math.isnan(th4):
        return math.nan, math.nan, math.nan, math.nan, math.nan
    J = m3 * abs(dS3) ** 2 + J3 * dth3 * dth3 + m4 * abs(dS4) ** 2 + J4 * dth4 * dth4
    dJ = 2.0 * (m3 * (dS3.conjugate() * ddS3).real + J3 * dth3 * ddth3
                + m4 * (dS4.conjugate() * ddS4).real + J4 * dth4 * ddth4)
    weight = 0.0
    if with_weight:
        weight = (complex(gx, -gy) * (m2r * 1j * e2 + m3 * dS3 + m4 * dS4)).real
    return J, dJ, weight, th4, dth4


@njit(cache=True)
def arm(base, base_rate, base_rate2, length, angle, rate, rate2):
    """mechanisms.walking_beam.arm: P = base + length e^{i angle}, P' = base' + i length rate e^{i angle},
    P'' = base'' + length (i rate2 - rate^2) e^{i angle} (derivatives with respect to phi) [m, m/rad, m/rad^2]."""
    direction = length * cmath.exp(1j * angle)
    return base + direction, base_rate + 1j * rate * direction, base_rate2 + complex(-rate * rate, rate2) * direction


@njit(cache=True)
def walking_beam_reduced(phi, a, b, c, d, th1, sign, p_len, delta, u2, gamma2, m2, J_coupler_side, m3, u3, J3, m4,
                         m6, u6, side_angle, m7, m1u1, gx, gy, with_weight):
    """mechanisms.walking_beam.make_reduced: with link_angles, A = a e^{i phi}, B = O2 + c e^{i th4},
    C = A + p e^{i (th3 + delta)} and the centres S2 = A + u2 e^{i (th3 + gamma2)}, S3 = O2 + u3 e^{i th4} (both
    rockers: m3, J3 doubled), S6 = B + u6 e^{i (th3 + arg BC)} (about E = B + s), the tie moving with B, the shuttle
    with C: J = sum m |S'|^2 + (J2 + J6) th3'^2 + J3 th4'^2, dJ = 2 sum (m Re(conj(S') S'') + J th' th''),
    M_weight = Re(conj(g) (m1 u1 i e^{i phi} + sum m S')); returns (J, dJ, M_weight, x_C, x_C')."""
    th3, dth3, ddth3, th4, dth4, ddth4 = link_angles(phi, a, b, c, d, th1, sign)
    O2 = d * cmath.exp(1j * th1)
    A, dA, ddA = arm(0j, 0j, 0j, a, phi, 1.0, 0.0)
    B, dB, ddB = arm(O2, 0j, 0j, c, th4, dth4, ddth4)
    C, dC, ddC = arm(A, dA, ddA, p_len, th3 + delta, dth3, ddth3)
    _, dS2, ddS2 = arm(A, dA, ddA, u2, th3 + gamma2, dth3, ddth3)
    _, dS3, ddS3 = arm(O2, 0j, 0j, u3, th4, dth4, ddth4)
    _, dS6, ddS6 = arm(B, dB, ddB, u6, th3 + side_angle, dth3, ddth3)
    J = (m2 * abs(dS2) ** 2 + m3 * abs(dS3) ** 2 + m4 * abs(dB) ** 2 + m6 * abs(dS6) ** 2 + m7 * abs(dC) ** 2
         + J_coupler_side * dth3 * dth3 + J3 * dth4 * dth4)
    dJ = 2.0 * (m2 * (dS2.conjugate() * ddS2).real + m3 * (dS3.conjugate() * ddS3).real
                + m4 * (dB.conjugate() * ddB).real + m6 * (dS6.conjugate() * ddS6).real
                + m7 * (dC.conjugate() * ddC).real + J_coupler_side * dth3 * ddth3 + J3 * dth4 * ddth4)
    weight = 0.0
    if with_weight:
        weight = (complex(gx, -gy) * (m1u1 * 1j * cmath.exp(1j * phi) + m2 * dS2 + m3 * dS3 + m4 * dB
                                      + m6 * dS6 + m7 * dC)).real
    return J, dJ, weight, C.real, dC.real


# ---------------------------------------------------------------------------------------------------------------
# Joint friction (mechanisms/kinetostatics.py, effects/joint_friction.py): reactions as complex Fx + i Fy [N]


@njit(cache=True)
def cross(u, v):
    """kinetostatics._cross: z component of the planar cross product u x v."""
    return u.real * v.imag - u.imag * v.real


@njit(cache=True)
def _slider_group(a_S1, a_S2, alpha2, a_C, gravity, q, L, rho, m1, m2, J2, m3):
    """crank_slider_kinetostatics' solve: H = rho L x m2 (a_S2 - g) + J2 alpha2, F23x = m3 a_C - Q - m3 gx,
    F23y = (L_y F23x - H) / L_x, N = -F23y - m3 gy, F12 = m2 (a_S2 - g) + F23, F01 = m1 (a_S1 - g) + F12;
    returns (F01, F12, F23, i N)."""
    H = cross(rho * L, m2 * (a_S2 - gravity)) + J2 * alpha2
    F23x = m3 * a_C - q - m3 * gravity.real
    F23 = complex(F23x, (L.imag * F23x - H) / L.real)
    normal = -F23.imag - m3 * gravity.imag
    F12 = m2 * (a_S2 - gravity) + F23
    F01 = m1 * (a_S1 - gravity) + F12
    return F01, F12, F23, 1j * normal


@njit(cache=True)
def crank_slider_joint_loads(phi, omega, force, R, l, e, rho, m1, u1, m2, J2, m3, gx, gy):
    """mechanisms.kinetostatics.crank_slider_kinetostatics: the reactions R = R0 + R1 epsilon of the crank bearing,
    crank pin, wrist pin and guide (i N) at (phi, omega, slider force Q [N]), every acceleration a = s' epsilon +
    s'' omega^2; returns (R0, R1, ratios), ratios (1, 1 - theta', theta', x') the joints' relative speeds over
    omega."""
    x, dx, ddx, dtheta, ddtheta = slider_kinematics(phi, R, l, e)
    e2 = cmath.exp(1j * phi)
    B = R * e2
    L = complex(x, e) - B
    dB, ddB = 1j * B, -B
    dS2 = (1.0 - rho) * dB + rho * dx
    ddS2 = (1.0 - rho) * ddB + rho * ddx
    w2 = omega * omega
    constant = _slider_group(u1 * -e2 * w2, ddS2 * w2, ddtheta * w2, ddx * w2, complex(gx, gy), force, L, rho, m1,
                             m2, J2, m3)
    per_epsilon = _slider_group(u1 * 1j * e2, dS2, dtheta, dx, 0j, 0.0, L, rho, m1, m2, J2, m3)
    return constant, per_epsilon, (1.0, 1.0 - dtheta, dtheta, dx)


@njit(cache=True)
def _four_bar_group(a_S1, a_S3, alpha3, a_S4, alpha4, gravity, q, e3, e4, coupler, rocker, det, u3, m1, m3, J3, u4,
                    m4, J4):
    """four_bar_kinetostatics' solve: H4 = u4 e4 x m4 (a_S4 - g) + J4 alpha4 - Q, H3 = u3 e3 x m3 (a_S3 - g)
    + J3 alpha3, F23 by Cramer's rule (det = c x b), F12 = m3 (a_S3 - g) + F23, F03 = m4 (a_S4 - g) - F23,
    F01 = m1 (a_S1 - g) + F12; returns (F01, F12, F23, F03)."""
    H4 = cross(u4 * e4, m4 * (a_S4 - gravity)) + J4 * alpha4 - q
    H3 = cross(u3 * e3, m3 * (a_S3 - gravity)) + J3 * alpha3
    F23 = complex(H4 * coupler.real + rocker.real * H3, rocker.imag * H3 + coupler.imag * H4) / det
    F12 = m3 * (a_S3 - gravity) + F23
    F03 = m4 * (a_S4 - gravity) - F23
    F01 = m1 * (a_S1 - gravity) + F12
    return F01, F12, F23, F03


@njit(cache=True)
def four_bar_joint_loads(phi, omega, moment, a, b, c, d, th1, sign, m1, u1, m3, u3, J3, m4, u4, J4, gx, gy):
    """mechanisms.kinetostatics.four_bar_kinetostatics: the reactions R = R0 + R1 epsilon of the crank bearing,
    crank pin, rocker pin and rocker bearing at (phi, omega, rocker moment Q [N m]); returns (R0, R1, ratios),
    ratios (1, 1 - th3', th3' - th4', th4')."""
    dth3, ddth3, _, dth4, ddth4, e2, e3, e4, dS3, ddS3, dS4, ddS4 = four_bar_centres(phi, a, b, c, d, th1, sign, u3,
                                                                                       u4)
    coupler, rocker = b * e3, c * e4
    det = cross(rocker, coupler)
    w2 = omega * omega
    constant = _four_bar_group(-u1 * e2 * w2, ddS3 * w2, ddth3 * w2, ddS4 * w2, ddth4 * w2, complex(gx, gy), moment,
                               e3, e4, coupler, rocker, det, u3, m1, m3, J3, u4, m4, J4)
    per_epsilon = _four_bar_group(1j * u1 * e2, dS3, dth3, dS4, dth4, 0j, 0.0, e3, e4, coupler, rocker, det, u3, m1,
                                  m3, J3, u4, m4, J4)
    return constant, per_epsilon, (1.0, 1.0 - dth3, dth3 - dth4, dth4)


@njit(cache=True)
def joint_friction_acceleration(omega, moment, inertia, collar, arms, ratios, constant, per_epsilon, with_joints,
                                tolerance, iterations, ratio_signs, normal_sign, guide):
    """JointFrictionModel.acceleration: epsilon [rad/s^2] solving J epsilon = M - sign(omega) F(epsilon),
    F = M_collar + sum_j rho_j |k_j| |R0_j + R1_j epsilon| by Newton's method from the friction at rest; at rest
    (omega = 0) 0 while |M| <= F(0), else breaking away in the direction of M; NaN without convergence.
    arms: rho_j [m] (f_guide for a guide) of the mechanism's joints (the presets' four, a linkage's all), 0 for a
    joint without friction (its terms add exact zeros); with_joints False: the collar alone (no kinetostatics).
    Between two corners (issue 19): ratio_signs s_j (0: |k_j|) read rho_j s_j k_j, normal_sign s_N (0: |R|) the
    guide's |N| (joint number `guide`, reaction i N; -1: none) as s_N N."""
    at_rest = 0.0
    if with_joints:
        for j in range(len(arms)):
            at_rest += arms[j] * _friction_weight(ratios[j], ratio_signs[j]) * _reaction_size(constant[j], j == guide,
                                                                                              normal_sign)
    at_rest = collar + at_rest
    if omega > 0.0:
        sign = 1.0
    elif omega < 0.0:
        sign = -1.0
    elif abs(moment) <= at_rest:
        return 0.0
    else:
        sign = 1.0 if moment > 0.0 else -1.0
    epsilon = (moment - sign * at_rest) / inertia
    if not with_joints:
        return epsilon
    for _ in range(iterations):
        friction, slope = collar, 0.0
        for j in range(len(arms)):
            weight = arms[j] * _friction_weight(ratios[j], ratio_signs[j])
            reaction = constant[j] + per_epsilon[j] * epsilon
            size = _reaction_size(reaction, j == guide, normal_sign)
            friction += weight * size
            if j == guide and normal_sign != 0.0:
                slope += weight * normal_sign * per_epsilon[j].imag
            elif size > 0.0:
                slope += weight * (per_epsilon[j].real * reaction.real + per_epsilon[j].imag * reaction.imag) / size
        step = (inertia * epsilon - moment + sign * friction) / (inertia + sign * slope)
        epsilon -= step
        if abs(step) <= tolerance * (abs(epsilon) + (abs(moment) + friction) / inertia):
            return epsilon
    return math.nan


@njit(cache=True)
def _friction_weight(ratio, sign):
    """|k_j| [-], or s_j k_j continued across its sign change when sign s_j is +-1 (JointFrictionModel._terms)."""
    return abs(ratio) if sign == 0.0 else sign * ratio


@njit(cache=True)
def _reaction_size(reaction, is_guide, normal_sign):
    """|R_j| [N], or for the guide (is_guide, reaction i N) s_N N continued across N = 0 when normal_sign s_N is +-1
    (JointFrictionModel.acceleration)."""
    return normal_sign * reaction.imag if is_guide and normal_sign != 0.0 else abs(reaction)


# ---------------------------------------------------------------------------------------------------------------
# Governor (governors/centrifugal.py, valve.py, governors/__init__.py)


@njit(cache=True)
def sleeve(arm, l):
    """PorterSensor.sleeve: z = 2 l (1 - cos a) [m]."""
    return 2.0 * l * (1.0 - math.cos(arm))


@njit(cache=True)
def lift(arm, omega, m, l, M, k, z_free, g, ratio):
    """PorterSensor.lift: F = m l omega_g^2 cos a - (m + M) g - k (z - z_free), omega_g = ratio omega [N]."""
    omega_g = ratio * omega
    spring = k * (sleeve(arm, l) - z_free)
    return m * l * omega_g * omega_g * math.cos(arm) - (m + M) * g - spring


@njit(cache=True)
def arm_acceleration(arm, arm_rate, omega, friction, m, l, M, k, z_free, c, g, ratio):
    """PorterSensor.arm_acceleration: (2 m l^2 + 4 M l^2 sin^2 a) a'' + 2 M l^2 sin(2a) a'^2
    = 2 l sin a [F(a, omega) - c z' - friction], z' = 2 l sin a a' [rad/s^2]."""
    sin_a = math.sin(arm)
    lever = 2.0 * l * sin_a
    sleeve_rate = lever * arm_rate
    force = lift(arm, omega, m, l, M, k, z_free, g, ratio) - c * sleeve_rate - friction
    mass = 2.0 * m * l * l + 4.0 * M * l * l * sin_a * sin_a
    return (lever * force - 2.0 * M * l * l * math.sin(2.0 * arm) * arm_rate * arm_rate) / mass


@njit(cache=True)
def linear_valve(z, open_at, closed_at):
    """governors.valve linear: throttle = (z_closed - z) / (z_closed - z_open), clipped to [0, 1]."""
    return min(max((closed_at - z) / (closed_at - open_at), 0.0), 1.0)


@njit(cache=True)
def rigid_feedback(gain, servo, reference):
    """Rigid feedback's share of the pilot opening: rho (s - s_ref) [m]."""
    return gain * (servo - reference)


@njit(cache=True)
def servo_command(opening, gain, max_speed, dead_band):
    """Governor.servo_command: s' = -gain * opening, the opening less the dead band, clipped to +-max_speed [1/s]."""
    if dead_band > 0.0:
        opening = math.copysign(max(abs(opening) - dead_band, 0.0), opening)
    return min(max(-gain * opening, -max_speed), max_speed)


# ---------------------------------------------------------------------------------------------------------------
# Drive train behind an elastic coupling (model/machine.py _train, model/drivetrain.py)


@njit(cache=True)
def driven_acceleration(direction, passed, weight, smooth, dI, omega2, I2, resistance):
    """domega2/dt of a turning driven part: (M_weight + M_m - s R - 1/2 I2' omega2^2 + M_smooth) / I2, s = +1
    forward, -1 backward (R: Coulomb resistances and the external load) [rad/s^2]."""
    total = weight + (passed - direction * resistance - 0.5 * dI * omega2 * omega2)
    return (total + smooth) / I2


@njit(cache=True)
def clutch_forces(clutch, part, F1, J, smooth, resistance, inertia, kinetic):
    """model.drivetrain.ClutchModel.forces in a train mode (clutch: 0 stuck, 1 slipping with the motor ahead, -1
    with the machine ahead; part: 0 forward, 1 backward, 2 held): stuck and held, everything at rest and the clutch
    passing F1; stuck and turning, (J + I) epsilon = F1 + M_smooth - s R and T = F1 - J epsilon; slipping,
    T = +-kinetic_torque, epsilon = (F1 - T) / J and I epsilon2 = T + M_smooth - s R (0 held). Returns (epsilon,
    epsilon2 [rad/s^2], T, push = T + M_smooth [N m])."""
    if clutch == 0.0:
        if part == 2.0:
            return 0.0, 0.0, F1, F1 + smooth
        s = 1.0 if part == 0.0 else -1.0
        acceleration = (F1 + smooth - s * resistance) / (J + inertia)
        torque = F1 - J * acceleration
        return acceleration, acceleration, torque, torque + smooth
    torque = kinetic if clutch == 1.0 else -kinetic
    driven = 0.0
    if part != 2.0:
        driven = (torque + smooth - (1.0 if part == 0.0 else -1.0) * resistance) / inertia
    return (F1 - torque) / J, driven, torque, torque + smooth


@njit(cache=True)
def driven_margin(passed, weight, smooth, dI, omega2, resistance, sign):
    """The holding margin of a driven part at rest, R + sign * push, push = M_m + M_weight + M_smooth
    - 1/2 I2' omega2^2 (MachineModel.drive_train_at, drivetrain._margin) [N m]."""
    return resistance + sign * (passed + (weight + smooth - 0.5 * dI * omega2 * omega2))


# ---------------------------------------------------------------------------------------------------------------
# A general linkage: not a transcription but the reference path's own functions (mechanisms/linkage/flat.py),
# compiled once; its program is read from p at an offset, flat.reduced(phi, p, offset) -> (J_links, dJ, weight, q, dq)
# and flat.joint_loads(phi, omega, Q, p, offset) -> (R0, R1, ratios, M_b0, M_b1) of its joints (joint friction)

from mech_regulator.mechanisms.linkage import flat  # noqa: E402  (appended: the kernels above stay as they were)

linkage_reduced = flat.compiled("reduced")
linkage_joint_loads = flat.compiled("joint_loads")
