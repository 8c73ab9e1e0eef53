"""The elastic coupling of a two-mass machine (docs/theory.md §7.1): its moment M_m = M_elastic(twist) + c
relative_speed, with M_elastic = k twist or a tabulated characteristic, its energy and stiffness, and the driven part
behind it (model/drivetrain.py)."""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from mech_regulator.effects import Effect
from mech_regulator.effects.tables import extrapolated_linear
from mech_regulator.model.drivetrain import DrivenModel


@dataclass(frozen=True)
class CouplingModel:
    """An elastic coupling and the driven part behind it (docs/theory.md §7.1).

    stiffness k [N m/rad] of a linear coupling, or table = (twist [rad], moment [N m]) knots of a nonlinear
    characteristic (linear between them, end segments continued); damping c [N m s/rad]; the driven part
    (model/drivetrain.py: inertia reduced to its shaft, its mechanism, its moments read at (t, phi2, omega2,
    q2, dq2)).
    """

    stiffness: float | None
    damping: float
    driven: DrivenModel
    table: tuple[np.ndarray, np.ndarray] | None = None

    @functools.cached_property
    def elastic(self) -> Callable[..., float]:
        """twist [rad] -> M_elastic [N m] for one twist, for the hot path (elastic_moment takes arrays); a table's
        also takes anchor= (effects.tables.extrapolated_linear)."""
        if self.table is None:
            stiffness = self.stiffness
            assert stiffness is not None, "a coupling without a table has a stiffness"
            return lambda twist: stiffness * twist
        return extrapolated_linear(self.table[0].tolist(), self.table[1].tolist())

    @property
    def driven_inertia(self) -> float:
        """I2 [kg m^2], branches included."""
        return self.driven.inertia

    @property
    def driven_effects(self) -> tuple[Effect, ...]:
        """The driven part's moments (effects of omega_driven), branches' reduced."""
        return self.driven.effects

    def moment(self, twist, relative_speed):
        """The moment the coupling passes to the driven part [N m]: M_m = M_elastic(twist) + c (omega - omega2)
        (the crank feels -M_m); twist [rad] and relative_speed [rad/s] scalars or arrays."""
        return self.elastic_moment(twist) + self.damping * relative_speed

    def _segments(self, twist):
        """Knots, values, index of the table segment of each twist (end segments beyond the table), slopes."""
        knots, values = self.table
        index = np.clip(np.searchsorted(knots, twist, side="right") - 1, 0, knots.size - 2)
        slopes = np.diff(values) / np.diff(knots)
        return knots, values, index, slopes

    def elastic_moment(self, twist):
        """M_elastic(twist) [N m]: k twist, or the table linear between knots (end segments continued)."""
        if self.table is None:
            return self.stiffness * np.asarray(twist, dtype=float)
        knots, values, i, slopes = self._segments(twist)
        return values[i] + slopes[i] * (twist - knots[i])

    def local_stiffness(self, twist):
        """dM_elastic/dtwist at twist [N m/rad]: k, or the slope of the table's segment there."""
        if self.table is None:
            return self.stiffness + 0.0 * np.asarray(twist, dtype=float)
        _, _, i, slopes = self._segments(twist)
        return slopes[i]

    def elastic_energy(self, twist):
        """E_elastic = integral_0^twist M_elastic dtwist [J]: 1/2 k twist^2, or exact for the piecewise-linear
        table (a quadratic on each segment)."""
        if self.table is None:
            return 0.5 * self.stiffness * np.asarray(twist, dtype=float) ** 2
        knots, values, i, slopes = self._segments(twist)
        at_knots = np.concatenate([[0.0], np.cumsum(0.5 * (values[1:] + values[:-1]) * np.diff(knots))])
        at_knots -= at_knots[int(np.flatnonzero(knots == 0.0)[0])]
        step = twist - knots[i]
        return at_knots[i] + values[i] * step + 0.5 * slopes[i] * step**2

    def twist_for(self, moment: float) -> float:
        """The twist [rad] at which the elastic moment equals `moment` [N m] (the characteristic is strictly
        increasing, so this is unique)."""
        if self.table is None:
            assert self.stiffness is not None, "a coupling without a table has a stiffness"
            return moment / self.stiffness
        knots, values = self.table
        i = int(np.clip(np.searchsorted(values, moment, side="right") - 1, 0, knots.size - 2))
        return float(knots[i] + (moment - values[i]) * (knots[i + 1] - knots[i]) / (values[i + 1] - values[i]))

    def driven_moment(self, t: float, omega_driven: float, phi_driven: float = 0.0) -> float:
        """Sum of the driven part's own moments (its loads and its links' weight) turning forward at phi_driven
        [rad] and omega_driven [rad/s] [N m] (negative: resisting)."""
        return self.driven.forward_moment(t, omega_driven, phi_driven)

    def required_moment(self, t: float, phi_driven: float, omega: float, external: float) -> float:
        """The coupling moment [N m] that keeps the driven part at constant speed omega [rad/s] at phi_driven
        [rad] against its moments and the external load [N m]: M_m = external - M_c2 + 1/2 I2' omega^2."""
        _, slope, *_ = self.driven.state(phi_driven)
        return external - self.driven_moment(t, omega, phi_driven) + 0.5 * slope * omega * omega
