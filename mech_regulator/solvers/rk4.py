"""The classic fixed-step fourth-order Runge–Kutta method as a scipy OdeSolver, so it runs in the
same stepping loop as scipy's adaptive methods (breakpoints, switches, governor events)."""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import DenseOutput, OdeSolver


class RK4(OdeSolver):
    """Classic RK4 with the step shortened to divide [t0, t_bound] evenly (step [s] is the largest step).

    y_{n+1} = y_n + h/6 (k1 + 2 k2 + 2 k3 + k4); dense output by cubic Hermite interpolation of the
    states and their derivatives at the ends of each step (third order, continuous derivative).
    """

    def __init__(self, fun, t0: float, y0: np.ndarray, t_bound: float, step: float):
        super().__init__(fun, t0, y0, t_bound, vectorized=False)
        count = max(1, math.ceil((t_bound - t0) / step - 1e-9))
        self.h = (t_bound - t0) / count
        self.f = self.fun(self.t, self.y)
        self.y_old = self.f_old = None

    def _step_impl(self):
        t, y, h, k1 = self.t, self.y, self.h, self.f
        if self.t_bound - t < 1.5 * h:  # the last step lands exactly on t_bound
            h = self.t_bound - t
        k2 = self.fun(t + 0.5 * h, y + 0.5 * h * k1)
        k3 = self.fun(t + 0.5 * h, y + 0.5 * h * k2)
        k4 = self.fun(t + h, y + h * k3)
        self.y_old, self.f_old = y, k1
        self.y = y + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        self.t = t + h
        self.f = self.fun(self.t, self.y)
        return True, None

    def _dense_output_impl(self):
        return HermiteStep(self.t_old, self.t, self.y_old, self.y, self.f_old, self.f)


class HermiteStep(DenseOutput):
    """Cubic Hermite interpolant of one step from the end states y0, y1 and derivatives f0, f1."""

    def __init__(self, t_old: float, t: float, y0: np.ndarray, y1: np.ndarray, f0: np.ndarray, f1: np.ndarray):
        super().__init__(t_old, t)
        self.h = t - t_old
        self.y0, self.y1, self.f0, self.f1 = y0, y1, f0, f1

    def _call_impl(self, t):
        s = (np.asarray(t) - self.t_old) / self.h
        h10 = s * (1 - s) ** 2
        h01 = s * s * (3 - 2 * s)
        h11 = s * s * (s - 1)
        # y0 + h01 (y1 - y0) + h (h10 f0 + h11 f1): a state frozen over the step (y1 = y0, f = 0) stays exact
        change = self.y1 - self.y0
        if np.ndim(s) == 0:
            return self.y0 + h01 * change + self.h * (h10 * self.f0 + h11 * self.f1)
        return self.y0[:, None] + np.outer(change, h01) + self.h * (np.outer(self.f0, h10) + np.outer(self.f1, h11))
