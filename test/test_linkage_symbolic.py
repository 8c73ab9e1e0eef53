"""A linkage's reduced(phi) as generated straight-line code (mechanisms/linkage/symbolic.py) against the
general solver (flat.py: each group placed by its closed form with angles and differentiated through its 6 x 6
constraint system, an independent way to the same numbers).

Every dyad type (RRR, RRP, RPR, PRP, RPP, a turned block, a moving guide), a redundant link, every bundled linkage
and the three presets: J_links, dJ/dphi, M_weight, q, dq/dphi equal to 1e-12 of each quantity's largest size over
the turn, with and without gravity; the compiled code gives the plain Python code's numbers; the source depends on
the linkage's structure and its exact zeros and ones only, and is read back from the cache folder; where a group
cannot assemble or is at a dead point, the general solver's message.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from test_linkage import DYADS, four_bar_linkage, parallelogram_linkage, six_bar_linkage

from mech_regulator.mechanisms import linkage_of
from mech_regulator.mechanisms.linkage import (
    LinkageError,
    analyse,
    checked,
    flat_program,
    make_reduced,
    solve,
    symbolic,
    symbolic_reduction,
)
from mech_regulator.scene import load_scene

ANGLES = np.linspace(0.0, 2.0 * math.pi, 73)[:-1] + 0.0071
GRAVITY = (0.4, -9.81)
BUNDLED = [
    "shaper",
    "sieve_shaker",
    "six_bar_press",
    "walking_beam_linkage",
    "crank_slider_bench",
    "engine_inline4",
    "four_bar_rocker",
    "walking_beam",
]


def _weighted(linkage):
    """The linkage with a mass, an off-axis centre and an inertia on every moving link (so that every term counts)."""
    links = tuple(
        link
        if link.name == linkage.frame
        else replace(link, mass=1.0 + 0.3 * k, centre=complex(0.05 * k, 0.02), inertia=0.01 * (k + 1))
        for k, link in enumerate(linkage.links)
    )
    return replace(linkage, links=links)


def _cases():
    cases = [(f"dyad-{name}", _weighted(build())) for name, build in DYADS.items()]
    cases += [
        ("redundant-link", _weighted(replace(parallelogram_linkage(1.0), output_link="5"))),
        ("six-bar", six_bar_linkage()),
    ]
    return cases + [(name, load_scene(name).machine.mechanism) for name in BUNDLED]


def _linkage_and_outputs(case):
    if hasattr(case, "joints") and hasattr(case, "frame") and not hasattr(case, "type"):
        return case, checked(case), ()
    return linkage_of(case)


@pytest.mark.parametrize("name, case", _cases(), ids=[name for name, _ in _cases()])
@pytest.mark.parametrize("gravity", [None, GRAVITY], ids=["weightless", "gravity"])
def test_generated_reduced_equals_the_general_solver(name, case, gravity):
    linkage, structure, outputs = _linkage_and_outputs(case)
    ours = symbolic.make_reduced(linkage, structure, gravity, outputs)
    general = [
        make_reduced(replace(linkage, output_joint=joint) if joint else linkage, structure, gravity)
        for joint in (outputs or (None,))
    ]
    rows, theirs = [], []
    for phi in ANGLES:
        rows.append(ours(phi))
        first = general[0](phi)
        theirs.append([*first[:3], *(value for reduced in general for value in reduced(phi)[3:])])
    rows, theirs = np.array(rows), np.array(theirs)
    scales = np.maximum(np.abs(theirs).max(axis=0), np.finfo(float).tiny)
    assert np.all(np.abs(rows - theirs) <= 1e-12 * scales), np.abs(rows - theirs).max(axis=0) / scales
    assert np.ptp(theirs[:, 0]) > 0.0 and np.ptp(theirs[:, 3]) > 0.0  # J and q vary: the comparison is not of constants


def test_compiled_code_gives_the_plain_python_numbers():
    """The source the fast path compiles (numba) and the reference path runs (Python): the same numbers to 1e-14."""
    from numba import njit

    linkage, structure, _ = linkage_of(load_scene("walking_beam_linkage").machine.mechanism)
    program = flat_program.encode(linkage, structure.groups, GRAVITY)
    name, source = symbolic.reduced_source(program)
    namespace = {"math": math, "np": np}
    exec(source, namespace)
    compiled = njit(namespace[name])
    for phi in ANGLES[::6]:
        plain = namespace[name](phi, program.tolist(), 0)
        assert compiled(phi, program, 0) == pytest.approx(plain, rel=1e-14, abs=1e-14 * max(map(abs, plain)))


def test_the_source_depends_on_structure_and_exact_zeros_only():
    """Two crank-sliders of other lengths and masses share one source; an offset (the guide off the crank's line: a
    number no longer exactly 0) or another branch changes it."""

    def key(linkage):
        return symbolic.program_key(flat_program.encode(linkage, checked(linkage).groups, GRAVITY), ())

    base = DYADS["RRP"]
    assert key(base(R=0.1, rod=0.35, e=0.03)) == key(base(R=0.2, rod=0.6, e=0.05))
    assert key(base(R=0.1, rod=0.35, e=0.03)) != key(base(R=0.1, rod=0.35, e=0.0))
    assert key(four_bar_linkage(branch=1)) != key(four_bar_linkage(branch=-1))


def test_a_cached_source_is_read_back_without_generating(monkeypatch, tmp_path):
    """The first call generates and writes the module <name>.py in the cache folder (its header, then the function);
    with generation made to fail, a fresh lookup reads that file and gives the same function."""
    monkeypatch.setenv("MECH_REGULATOR_CACHE", str(tmp_path))
    symbolic._source_by_key.cache_clear()
    linkage = four_bar_linkage(a=0.8, b=2.9, c=2.4, d=3.3)
    program = flat_program.encode(linkage, checked(linkage).groups, None)
    name, source = symbolic.reduced_source(program)
    assert (tmp_path / f"{name}.py").read_text() == symbolic.MODULE_HEADER + source

    def no_sympy(*_):
        raise AssertionError("generated again")

    monkeypatch.setattr(symbolic_reduction, "generate_reduced", no_sympy)
    symbolic._source_by_key.cache_clear()
    assert symbolic.reduced_source(program) == (name, source)
    symbolic._source_by_key.cache_clear()


def test_where_a_group_fails_the_general_solvers_message():
    """A four-bar whose rocker cannot reach over part of the turn, and a change-point four-bar at its dead point:
    the generated reduced raises the LinkageError the general solver gives there."""
    short = four_bar_linkage(c=0.8)
    with pytest.raises(LinkageError) as expected:
        solve(short, analyse(short), math.pi)
    with pytest.raises(LinkageError) as found:
        symbolic.make_reduced(short, analyse(short), None)(math.pi)
    assert str(found.value) == str(expected.value)
    change_point = four_bar_linkage(a=1.0, b=3.0, c=1.0, d=3.0, th1=0.0)
    with pytest.raises(LinkageError, match="is at a dead point at crank angle 180.000 deg"):
        symbolic.make_reduced(change_point, analyse(change_point), None)(math.pi)
