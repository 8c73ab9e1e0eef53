"""One step of each method of the compiled steppers, in the subset of Python numba compiles: the explicit Runge–Kutta
pairs RK45 and DOP853 (scipy's tableaux and step-size controller, their error norms and initial step), the classic
fixed-step RK4, and the linearly implicit Rosenbrock23 pair of ode23s with its Jacobian by differences; each step's
dense output as coefficients of powers of theta (integrators.py runs the steps, its docstring says the layout)."""

from __future__ import annotations

import numpy as np
from numba import njit
from scipy.integrate import DOP853, RK45
from scipy.integrate._ivp import dop853_coefficients

from mech_regulator import numba_cache

numba_cache.install()  # before the first njit(cache=True): keyed on the package's source

_RK4, _RK45, _DOP853, _ROSENBROCK23 = 0, 1, 2, 3
SAFETY, MIN_FACTOR, MAX_FACTOR = 0.9, 0.2, 10.0  # scipy's step-size controller (scipy.integrate._ivp.rk)

# scipy's tableaux, taken from scipy itself (numba freezes these global arrays into the compiled code)
RK45_A = np.ascontiguousarray(RK45.A, dtype=np.float64)
RK45_B = np.ascontiguousarray(RK45.B, dtype=np.float64)
RK45_C = np.ascontiguousarray(RK45.C, dtype=np.float64)
RK45_E = np.ascontiguousarray(RK45.E, dtype=np.float64)
RK45_P = np.ascontiguousarray(RK45.P, dtype=np.float64)
DOP853_STAGES = dop853_coefficients.N_STAGES  # 12; the step adds f(t + h, y_new), the dense output 3 more
DOP853_A = np.ascontiguousarray(dop853_coefficients.A, dtype=np.float64)  # (16, 16) with the extra stages
DOP853_B = np.ascontiguousarray(DOP853.B, dtype=np.float64)
DOP853_C = np.ascontiguousarray(dop853_coefficients.C, dtype=np.float64)  # (16,)
DOP853_E3 = np.ascontiguousarray(DOP853.E3, dtype=np.float64)
DOP853_E5 = np.ascontiguousarray(DOP853.E5, dtype=np.float64)
DOP853_D = np.ascontiguousarray(DOP853.D, dtype=np.float64)  # (4, 16)
ROSENBROCK_D = 1.0 / (2.0 + np.sqrt(2.0))  # ode23s's gamma
ROSENBROCK_E32 = 6.0 + np.sqrt(2.0)


@njit(cache=True)
def _rms(x):
    """Root mean square of x (scipy's norm for step control)."""
    return np.sqrt(np.sum(x * x) / x.size)


@njit(cache=True)
def _initial_step(rhs, t0, y0, f0, t_bound, max_step, order, rtol, atol, p, y1, f1):
    """scipy's select_initial_step (Hairer, Nørsett & Wanner, II.4): h0 from |y0| / |f0|, refined by the
    change of f over h0 so that h^(order+1) times it is about 0.01 (one rhs evaluation)."""
    interval = abs(t_bound - t0)
    scale = atol + np.abs(y0) * rtol
    d0 = _rms(y0 / scale)
    d1 = _rms(f0 / scale)
    h0 = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
    h0 = min(h0, interval)
    y1[:] = y0 + h0 * f0
    rhs(t0 + h0, y1, p, f1)
    d2 = _rms((f1 - f0) / scale) / h0
    if d1 <= 1e-15 and d2 <= 1e-15:
        h1 = max(1e-6, h0 * 1e-3)
    else:
        h1 = (0.01 / max(d1, d2)) ** (1.0 / (order + 1))
    return min(100.0 * h0, h1, interval, max_step)


@njit(cache=True)
def _stage_state(y, h, stage, weights, count, out):
    """out = y + h sum_{s < count} weights[s] stage[s]: the state a Runge–Kutta stage is evaluated at (plain
    loops over preallocated arrays: for a machine of a few states this is most of a step's cost)."""
    for i in range(y.size):
        total = 0.0
        for s in range(count):
            total += weights[s] * stage[s, i]
        out[i] = y[i] + h * total


@njit(cache=True)
def _rk_step(method, rhs, t, y, f, h, p, stage, y_new, f_new):
    """One explicit Runge–Kutta step as scipy's rk_step: stage[s] = f(t + c_s h, y + h sum_j a_sj stage[j]),
    y_new = y + h sum_s b_s stage[s], f_new = f(t + h, y_new) kept as the last stage (FSAL); the stage states
    are built in y_new. Returns the number of rhs evaluations."""
    if method == _DOP853:
        a, b, c, count = DOP853_A, DOP853_B, DOP853_C, DOP853_STAGES
    else:
        a, b, c, count = RK45_A, RK45_B, RK45_C, RK45_B.size
    stage[0] = f
    for s in range(1, count):
        _stage_state(y, h, stage, a[s], s, y_new)
        rhs(t + c[s] * h, y_new, p, stage[s])
    _stage_state(y, h, stage, b, count, y_new)
    rhs(t + h, y_new, p, f_new)
    stage[count] = f_new
    return count


@njit(cache=True)
def _error_norm(method, stage, h, y, y_new, rtol, atol):
    """scipy's error norm of an explicit step, scaled by scale_i = atol_i + rtol max(|y_i|, |y_new_i|): RK45's RMS
    of h sum_s e_s stage[s] / scale; DOP853's |h| |err5|^2 / sqrt(n (|err5|^2 + 0.01 |err3|^2)) with
    err5, err3 = sum_s e5_s stage[s] / scale, sum_s e3_s stage[s] / scale."""
    n = y.size
    if method == _RK45:
        total = 0.0
        for i in range(n):
            error = 0.0
            for s in range(RK45_E.size):
                error += RK45_E[s] * stage[s, i]
            error *= h / (atol[i] + max(abs(y[i]), abs(y_new[i])) * rtol)
            total += error * error
        return np.sqrt(total / n)
    err5_2, err3_2 = 0.0, 0.0
    for i in range(n):
        err5, err3 = 0.0, 0.0
        for s in range(DOP853_E5.size):
            err5 += DOP853_E5[s] * stage[s, i]
            err3 += DOP853_E3[s] * stage[s, i]
        scale = atol[i] + max(abs(y[i]), abs(y_new[i])) * rtol
        err5_2 += (err5 / scale) ** 2
        err3_2 += (err3 / scale) ** 2
    if err5_2 == 0.0 and err3_2 == 0.0:
        return 0.0
    return abs(h) * err5_2 / np.sqrt((err5_2 + 0.01 * err3_2) * n)


@njit(cache=True)
def _rk4_step(rhs, t, y, f, h, p, stage, y_new, f_new):
    """One classic RK4 step (k1 = f, k2, k3 at t + h/2, k4 at t + h; the stage states built in y_new) and
    f_new = f(t + h, y_new). Returns the number of rhs evaluations."""
    n = y.size
    for i in range(n):
        y_new[i] = y[i] + 0.5 * h * f[i]
    rhs(t + 0.5 * h, y_new, p, stage[1])
    for i in range(n):
        y_new[i] = y[i] + 0.5 * h * stage[1, i]
    rhs(t + 0.5 * h, y_new, p, stage[2])
    for i in range(n):
        y_new[i] = y[i] + h * stage[2, i]
    rhs(t + h, y_new, p, stage[3])
    for i in range(n):
        y_new[i] = y[i] + h / 6.0 * (f[i] + 2.0 * stage[1, i] + 2.0 * stage[2, i] + stage[3, i])
    rhs(t + h, y_new, p, f_new)
    return 4


@njit(cache=True)
def _derivatives(rhs, t, y, f, h, atol, rtol, p, jacobian, dfdt, y_work, f_work):
    """J = df/dy by forward differences (increment sqrt(eps) max(|y_i|, atol_i / rtol), as ode23s's
    threshold) and T = df/dt by a forward difference over min(sqrt(eps) max(|t|, |t + h|), h), as ode23s.
    Returns the number of rhs evaluations."""
    root_eps = np.sqrt(np.finfo(np.float64).eps)
    n = y.size
    for i in range(n):
        y_work[:] = y
        size = root_eps * max(abs(y[i]), atol[i] / rtol)
        if size == 0.0:
            size = root_eps
        y_work[i] = y[i] + size
        rhs(t, y_work, p, f_work)
        jacobian[:, i] = (f_work - f) / (y_work[i] - y[i])
    t_delta = (t + min(root_eps * max(abs(t), abs(t + h)), h)) - t
    rhs(t + t_delta, y, p, f_work)
    dfdt[:] = (f_work - f) / t_delta
    return n + 1


@njit(cache=True)
def _rosenbrock_step(rhs, t, y, f, h, jacobian, dfdt, rtol, atol, p, stage, y_new, f_new):
    """One ode23s step (formulas in rosenbrock23's docstring), one factorisation of W; stage[0..2] = k1, k2,
    k3, stage[3] = F1. Returns the error norm (scipy's RMS scaled by atol + rtol max(|y|, |y_new|))."""
    d = ROSENBROCK_D
    w_inverse = np.linalg.inv(np.eye(y.size) - h * d * jacobian)
    k1 = w_inverse @ (f + h * d * dfdt)
    rhs(t + 0.5 * h, y + 0.5 * h * k1, p, stage[3])
    k2 = w_inverse @ (stage[3] - k1) + k1
    y_new[:] = y + h * k2
    rhs(t + h, y_new, p, f_new)
    k3 = w_inverse @ (f_new - ROSENBROCK_E32 * (k2 - stage[3]) - 2.0 * (k1 - f) + h * d * dfdt)
    stage[0] = k1
    stage[1] = k2
    stage[2] = k3
    scale = atol + np.maximum(np.abs(y), np.abs(y_new)) * rtol
    return _rms(h / 6.0 * (k1 - 2.0 * k2 + k3) / scale)


@njit(cache=True)
def _dense_coefficients(method, rhs, t, y, f, h, y_new, f_new, p, stage, work, out):
    """The accepted step's dense output as powers of theta, out[i, j-1] the coefficient of h theta^j:
    RK45 stage^T P; the Hermite cubic from y, y_new, f, f_new; ode23s's
    y + h (theta (1 - theta) k1 + theta (theta - 2d) k2) / (1 - 2d); DOP853's nested form after 3 extra
    stages (work: room for a stage's state). Returns the number of rhs evaluations (DOP853's extra stages)."""
    if method == _RK45:
        for i in range(y.size):
            for j in range(RK45_P.shape[1]):
                total = 0.0
                for s in range(RK45_P.shape[0]):
                    total += stage[s, i] * RK45_P[s, j]
                out[i, j] = total
        return 0
    if method == _RK4:
        for i in range(y.size):
            slope = (y_new[i] - y[i]) / h
            out[i, 0] = f[i]
            out[i, 1] = 3.0 * slope - 2.0 * f[i] - f_new[i]
            out[i, 2] = f[i] + f_new[i] - 2.0 * slope
            out[i, 3] = 0.0
        return 0
    if method == _ROSENBROCK23:
        scale = 1.0 / (1.0 - 2.0 * ROSENBROCK_D)
        out[:, 0] = (stage[0] - 2.0 * ROSENBROCK_D * stage[1]) * scale
        out[:, 1] = (stage[1] - stage[0]) * scale
        out[:, 2:] = 0.0
        return 0
    return _dop853_dense(rhs, t, y, f, h, y_new, f_new, p, stage, work, out)


@njit(cache=True)
def _dop853_dense(rhs, t, y, f, h, y_new, f_new, p, stage, work, out):
    """scipy's DOP853 dense output: 3 extra stages, F = [dy, h f - dy, 2 dy - h (f_new + f), h D stage]
    (dy = y_new - y), y(theta) = y + x (F0 + (1 - x) (F1 + x (F2 + (1 - x) (F3 + ...)))) expanded into powers
    of theta and divided by h. Returns 3 (rhs evaluations)."""
    for s in range(DOP853_STAGES + 1, DOP853_A.shape[0]):
        _stage_state(y, h, stage, DOP853_A[s], s, work)
        rhs(t + DOP853_C[s] * h, work, p, stage[s])
    nested = np.empty(7)
    poly = np.empty(8)  # poly[j]: coefficient of theta^j
    for i in range(y.size):
        delta = y_new[i] - y[i]
        nested[0] = delta
        nested[1] = h * f[i] - delta
        nested[2] = 2.0 * delta - h * (f_new[i] + f[i])
        for row in range(DOP853_D.shape[0]):
            total = 0.0
            for s in range(DOP853_D.shape[1]):
                total += DOP853_D[row, s] * stage[s, i]
            nested[3 + row] = h * total
        poly[:] = 0.0
        for k in range(6, -1, -1):
            poly[0] += nested[k]
            if (6 - k) % 2 == 0:  # times theta
                for j in range(7, 0, -1):
                    poly[j] = poly[j - 1]
                poly[0] = 0.0
            else:  # times (1 - theta)
                for j in range(7, 0, -1):
                    poly[j] -= poly[j - 1]
        for j in range(7):
            out[i, j] = poly[j + 1] / h
    return 3
