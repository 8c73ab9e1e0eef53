"""Guards that cannot be missed, on the reference path: time_domain._first_event checks each guard on its
polynomial over the whole step (interpolant at 9 Chebyshev points with an error bound, cut into monotone pieces,
checked on the guard itself where a piece ends near the level), so a dip below the level and back inside one step
is found however short. The compiled twin has the same check (test_compiled_integrators.py).

Oracles: closed forms of the dips, on a hand-made dense output of one step [0, 1] s. Cost: well under 1 s.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mech_regulator.governors import Guard
from mech_regulator.solvers.time_domain import PROBES_PER_STEP, _first_event


def parabola(depth: float):
    """A dense output y(t) = [(t - 0.5)^2 - depth, 2 (t - 0.5)]: below 0 on 0.5 -/+ sqrt(depth)."""

    def dense(t):
        t = np.asarray(t, dtype=float)
        return np.array([(t - 0.5) ** 2 - depth, 2.0 * (t - 0.5)])

    return dense


def no_transition(y):
    return ("free", ""), np.array(y, dtype=float)


@pytest.mark.parametrize("depth", [0.0064, 1e-4, 1e-8])
@pytest.mark.parametrize("nonlinear", [False, True], ids=["linear", "nonlinear"])
def test_a_dip_between_the_probes_is_found_and_located(depth, nonlinear):
    """A guard x (linear in the state) or exp(x) - 1 (not) with x = (t - 0.5)^2 - depth: below 0 for 0.16 s, 0.02 s,
    2e-4 s of a 1 s step, all between the switch probes (which see x > 0 everywhere); found, and located at
    t = 0.5 - sqrt(depth) to 1e-12 s."""
    dense = parabola(depth)
    probes = np.linspace(0.0, 1.0, PROBES_PER_STEP + 2)
    assert np.all(dense(probes)[0] > 0.0)
    value = (lambda y: math.expm1(y[0])) if nonlinear else (lambda y: y[0])
    event = _first_event(dense, 0.0, 1.0, [], [], [Guard("dips", value, no_transition)])
    assert event is not None
    time, state, _, guard, name, _ = event
    assert name == "dips" and time == pytest.approx(0.5 - math.sqrt(depth), abs=1e-12)


@pytest.mark.parametrize("depth, fires", [(-1e-10, False), (1e-10, True)])
def test_a_near_tangency_fires_only_when_it_dips(depth, fires):
    """x = (t - 0.5)^2 - depth: staying 1e-10 above 0 holds the mode, dipping 1e-10 below fires at 0.5 - 1e-5 s."""
    event = _first_event(parabola(depth), 0.0, 1.0, [], [], [Guard("dips", lambda y: y[0], no_transition)])
    assert (event is not None) == fires
    if fires:
        assert event[0] == pytest.approx(0.5 - 1e-5, abs=1e-9)


def test_a_guard_released_at_its_boundary_fires_only_past_the_tolerance():
    """A guard that starts the step at 0 (just released) and dips to -5e-13, within GUARD_TOLERANCE (1e-12), keeps
    its mode; one that dips to -1e-9 (a sleeve grazing back into its stop) fires where it passes -1e-12."""

    def dense_of(depth):
        def dense(t):
            t = np.asarray(t, dtype=float)
            return np.array([-4.0 * depth * t * (1.0 - t)])  # 0 at both ends, -depth at t = 0.5

        return dense

    guard = Guard("grazes", lambda y: y[0], no_transition)
    assert _first_event(dense_of(5e-13), 0.0, 1.0, [], [], [guard]) is None
    time = _first_event(dense_of(1e-9), 0.0, 1.0, [], [], [guard])[0]
    assert 4e-9 * time * (1.0 - time) == pytest.approx(1e-12, rel=1e-6)
