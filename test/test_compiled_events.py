"""The compiled event check's shortcuts (solvers/compiled/events.py): a guard's polynomial along a step told above its
level from its coefficients alone, and told monotone on the whole step, so that most steps find a crossing or none
without the roots of its derivative.

Oracle: the polynomial evaluated densely on [0, 1] and at its derivative's real roots. Cost: about 3 s (compiles).
"""

from __future__ import annotations

import numpy as np

from mech_regulator.solvers.compiled.events import _monotone_ends, _monotone_pieces, _polynomial, _stays_above

RANDOM_POLYNOMIALS = 3000


def lowest_on_unit_interval(line: np.ndarray) -> float:
    """The least value of sum_j line[j] theta^j on [0, 1]: at the ends, 10 001 points and its derivative's real
    roots inside."""
    slope = np.polynomial.polynomial.polyder(line)
    roots = np.polynomial.polynomial.polyroots(slope) if np.any(slope) else np.zeros(0)
    inside = roots[(np.abs(roots.imag) < 1e-9) & (roots.real > 0.0) & (roots.real < 1.0)].real
    points = np.concatenate((np.linspace(0.0, 1.0, 10_001), inside))
    values = np.zeros(points.size)
    for coefficient in line[::-1]:  # _polynomial's Horner scheme, the same operations in the same order
        values = values * points + coefficient
    assert values[-1] == _polynomial(points[-1], line)
    return float(values.min())


def random_steps(rng: np.random.Generator) -> list[tuple[np.ndarray, float]]:
    """Guards along a step as DOP853's dense output gives them (8 coefficients, the higher ones smaller), with a
    level: rising, falling, dipping and flat ones, at all scales."""
    cases = []
    for _ in range(RANDOM_POLYNOMIALS):
        scale = 10.0 ** rng.uniform(-6, 3)
        decay = rng.uniform(0.01, 1.5)
        line = scale * rng.normal(size=8) * decay ** np.arange(8)
        level = rng.choice([0.0, scale * rng.uniform(-1, 1)])
        cases.append((line, level))
    return cases


def test_a_polynomial_told_above_its_level_is_above_it_on_the_whole_step():
    """Whenever _stays_above says so, no point of [0, 1] evaluates below the level (thousands of random steps), and it
    says so for some hundreds of them, over a hundred of which the old test (line[0] - level >= sum |line[1:]|) left to the roots."""
    told, only_new = 0, 0
    for line, level in random_steps(np.random.default_rng(35)):
        if _stays_above(line, level):
            told += 1
            assert lowest_on_unit_interval(line) >= level, (line, level)
            only_new += line[0] - level < np.sum(np.abs(line[1:]))
    assert told > RANDOM_POLYNOMIALS // 10 and only_new > RANDOM_POLYNOMIALS // 50


def test_a_switch_edge_behind_the_crank_is_told_at_once_and_one_reached_is_not():
    """The edge behind a crank that left it (level 1e-12 above, rising at h omega) is above; the edge ahead that the
    step reaches (falling by more than it starts above) is not, nor is a guard that dips below and comes back."""
    h_omega = 1e-3 * 150.0
    behind = np.array([1e-12, h_omega, 1e-6, -2e-7, 1e-8, 0.0, 0.0, 0.0])
    ahead = np.array([0.1, -h_omega, -1e-6, 2e-7, -1e-8, 0.0, 0.0, 0.0])
    dip = np.array([0.001, -1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0])  # (theta - 0.5)^2 - 0.249: below 0 near the middle
    assert _stays_above(behind, 0.0)
    assert not _stays_above(ahead, 0.0) and lowest_on_unit_interval(ahead) < 0.0
    assert not _stays_above(dip, 0.0) and lowest_on_unit_interval(dip) < 0.0 < dip[0] and np.sum(dip) > 0.0


def test_a_polynomial_told_monotone_is_monotone_and_the_others_are_cut_at_their_roots():
    """_monotone_pieces gives the one piece (0, 1] only to polynomials whose derivative keeps its sign on [0, 1]
    (sampled at 10 001 points), and time_domain.monotone_ends' cuts to all others; some of the first are polynomials
    that monotone_ends cuts at the real parts of complex roots."""
    theta = np.linspace(0.0, 1.0, 10_001)
    dropped = 0
    for line, _ in random_steps(np.random.default_rng(36)):
        pieces, cuts = _monotone_pieces(line), _monotone_ends(line)
        if np.array_equal(pieces, np.ones(1)):
            slope = np.polynomial.polynomial.polyval(theta, np.polynomial.polynomial.polyder(line))
            assert np.all(slope > 0.0) or np.all(slope < 0.0), line
            dropped += not np.array_equal(cuts, pieces)
        else:
            np.testing.assert_array_equal(pieces, cuts)
    assert dropped > RANDOM_POLYNOMIALS // 100
