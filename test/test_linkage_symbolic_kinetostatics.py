"""A linkage's kinetostatics as generated straight-line code (mechanisms/linkage/symbolic.py, joint_loads_source)
against the general solver (flat_kinetostatics.joint_loads: each group's poses by its closed form with angles, its
multipliers from A^T lambda = b with the inverse of its 6 x 6 constraint matrix, an independent way to the same
numbers).

Every dyad type with masses on every link, the six-bar, every bundled linkage scene and the presets: R0, R1, the
ratios and the balancing moment's parts equal to 1e-12 of each quantity's largest size over random (phi, omega, Q),
with and without gravity; the compiled code gives the plain Python code's numbers; the reference path's
make_joint_loads runs it; a linkage with a redundant link has no generated kinetostatics (statically
indeterminate)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from test_linkage import DYADS, parallelogram_linkage, six_bar_linkage
from test_linkage_symbolic import GRAVITY, _weighted

from mech_regulator.mechanisms import build_kinetostatics, linkage_of
from mech_regulator.mechanisms.linkage import checked, flat_kinetostatics, flat_program, symbolic
from mech_regulator.mechanisms.linkage.model import Linkage
from mech_regulator.scene import load_scene

SCENES = [
    "compressor_friction",
    "press",
    "four_bar_rocker",
    "six_bar_press_friction",
    "shaper",
    "sieve_shaker",
    "walking_beam_linkage",
    "walking_beam",
    "engine_inline4",
]
STATES = 24


def _cases():
    cases = [(f"dyad-{name}", lambda build=build: _weighted(build())) for name, build in DYADS.items()]
    cases.append(("six-bar", lambda: _weighted(six_bar_linkage())))
    return cases + [(name, lambda name=name: load_scene(name).machine.mechanism) for name in SCENES]


def _program(case, gravity):
    """The case's program (flat_program.encode) with this gravity."""
    if isinstance(case, Linkage):
        linkage, structure = case, checked(case)
    else:
        linkage, structure, _ = linkage_of(case)
    return flat_program.encode(linkage, structure.groups, gravity)


def _states(seed: int):
    """Random (phi [rad], omega [rad/s], Q) over the turn, Q zero in one of four."""
    rng = np.random.default_rng(seed)
    return [
        (rng.uniform(0.0, 2.0 * math.pi), rng.uniform(-20.0, 20.0), 0.0 if k % 4 == 0 else rng.uniform(-900, 900))
        for k in range(STATES)
    ]


def _generated(program):
    """The product's generated kinetostatics of a program (compiled, what both paths run)."""
    return symbolic.reference_function(symbolic.joint_loads_source(program)[0])


def plain_python(name: str, source: str):
    """A generated source run as plain Python (no numba)."""
    namespace = {"math": math, "np": np}
    exec(source, namespace)
    return namespace[name]


def _table(loads) -> np.ndarray:
    """One row of floats of a joint_loads result: Re, Im of R0, of R1, the ratios, M_b0, M_b1."""
    R0, R1, ratios, constant, per_epsilon = loads
    return np.concatenate([np.real(R0), np.imag(R0), np.real(R1), np.imag(R1), ratios, [constant, per_epsilon]])


@pytest.mark.parametrize("name, build", _cases(), ids=[name for name, _ in _cases()])
@pytest.mark.parametrize("gravity", [None, GRAVITY], ids=["weightless", "gravity"])
def test_generated_joint_loads_equal_the_general_solver(name, build, gravity):
    program = _program(build(), gravity)
    generated = _generated(program)
    ours, theirs = [], []
    for phi, omega, force in _states(len(name)):
        ours.append(_table(generated(phi, omega, force, program, 0)))
        theirs.append(_table(flat_kinetostatics.joint_loads(phi, omega, force, program, 0)))
    ours, theirs = np.array(ours), np.array(theirs)
    n = len(flat_kinetostatics.joint_loads(0.0, 0.0, 0.0, program, 0)[0])
    reaction = np.abs(theirs[:, : 4 * n]).max()  # the reactions against the largest reaction
    assert np.all(np.abs(ours[:, : 4 * n] - theirs[:, : 4 * n]) <= 1e-12 * reaction), (
        np.abs(ours[:, : 4 * n] - theirs[:, : 4 * n]).max() / reaction
    )
    ratio = np.abs(theirs[:, 4 * n : 5 * n]).max()  # the ratios against the largest ratio (some are zero throughout)
    assert np.all(np.abs(ours[:, 4 * n : 5 * n] - theirs[:, 4 * n : 5 * n]) <= 1e-12 * ratio)
    scales = np.abs(theirs[:, 5 * n :]).max(axis=0)  # M_b0 and M_b1 each against its largest
    assert np.all(np.abs(ours[:, 5 * n :] - theirs[:, 5 * n :]) <= 1e-12 * scales)
    assert reaction > 0.0 and np.ptp(theirs[:, -2]) > 0.0  # reactions and M_b0 vary: not a comparison of zeros


def test_compiled_code_gives_the_plain_python_numbers():
    """The source the fast path compiles (numba) and the reference path runs (Python): the same numbers to 1e-13 of
    the largest reaction, tuples of complex numbers and floats (what joint_friction.friction_acceleration reads)."""
    from numba import njit

    for name in ("six_bar_press_friction", "shaper"):
        program = _program(load_scene(name).machine.mechanism, GRAVITY)
        function_name, source = symbolic.joint_loads_source(program)
        compiled = njit(plain_python(function_name, source))
        for phi, omega, force in _states(7)[:6]:
            plain = _table(plain_python(function_name, source)(phi, omega, force, program.tolist(), 0))
            fast = compiled(phi, omega, force, program, 0)
            assert isinstance(fast[0], tuple) and isinstance(fast[0][0], complex)
            fast = _table(fast)
            assert np.all(np.abs(fast - plain) <= 1e-13 * np.abs(plain).max())


def test_the_reference_path_runs_the_generated_code():
    """mechanisms.build_kinetostatics (linkage.make_joint_loads) gives the generated function's numbers as
    JointLoads, and flat_kinetostatics.joint_loads' to 1e-12."""
    mechanism = load_scene("six_bar_press_friction").machine.mechanism
    loads, names = build_kinetostatics(mechanism, GRAVITY)
    program = _program(mechanism, GRAVITY)
    phi, omega, force = 1.1, 9.0, 300.0
    result = loads(phi, omega, force)
    generated = _generated(program)(phi, omega, force, program, 0)
    assert (result.constant, result.per_epsilon, result.ratios, result.balancing) == (
        generated[0],
        generated[1],
        generated[2],
        generated[3:],
    )
    assert len(names) == len(result.constant)
    general = _table(flat_kinetostatics.joint_loads(phi, omega, force, program, 0))
    reordered = _table((result.constant, result.per_epsilon, result.ratios, *result.balancing))
    assert np.all(np.abs(reordered - general) <= 1e-12 * np.abs(general).max())


def test_a_redundant_link_has_no_generated_kinetostatics():
    linkage = _weighted(replace(parallelogram_linkage(1.0), output_link="5"))
    with pytest.raises(ValueError, match="redundant link is statically indeterminate"):
        symbolic.joint_loads_source(flat_program.encode(linkage, checked(linkage).groups, None))
