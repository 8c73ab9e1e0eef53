"""A linkage's reduced(phi) as straight-line code, generated from its groups' closed forms (docs/theory.md §5.3).

The general solver (flat.py) places each group by its closed form and differentiates it through the group's 6 x 6
constraint system; that costs some 0.45 us per call on a crank–slider whose hand-written formula costs 0.025 us.
This module writes, once per kind of linkage, the function a designer would write by hand: each group's position
in closed form without angles (a link's pose is its origin r and its turn e^{i theta} = (cos theta, sin theta),
both algebraic in the known poses: no sine, cosine or arctangent but the crank's), and its first and second
derivatives with respect to phi by the chain rule, symbolically (sympy), common subexpressions shared (sympy.cse).
The fast path compiles the source into a scene's module and the reference path compiles the very same source
(reference_function), so both give the same numbers; flat.py stays the solver of everything else (structure, kinematics, the
messages of a group that cannot assemble) and the tests hold the two to 1e-12.

The generators are two modules: symbolic_reduction.py writes reduced(phi) (each group's closed form, the inertia
sums, the outputs), symbolic_kinetostatics.py the joint reactions joint friction reads (joint_loads_source); this
module keeps what both share: the key a generated source is cached under, the cache folder's files and their
compilation for the reference path (reference_function, make_reduced).

The numbers are read from the linkage's program (flat_program.encode) in p at `offset`, so the source depends only on
the linkage's structure and on which of its numbers are exactly 0, 1 or -1 (written as literals, so that a joint at a
link's origin or a guide along x costs nothing): two linkages of one kind share one source, kept in the cache folder
(mech_regulator.cache) under a hash of that key, so sympy runs once per kind of linkage and machine.
"""

from __future__ import annotations

import functools
import hashlib
import math
import sys
from collections.abc import Callable, Sequence

import numpy as np

from mech_regulator import cache
from mech_regulator.mechanisms.linkage import (
    flat,
    flat_derivatives,
    flat_kinetostatics,
    flat_poses,
    flat_positions,
    flat_program,
    symbolic_kinetostatics,
    symbolic_reduction,
)
from mech_regulator.mechanisms.linkage.model import Linkage, LinkageError
from mech_regulator.mechanisms.linkage.structure import Structure

FUNCTION_NAME = "linkage_reduced"
JOINT_LOADS_NAME = "linkage_joint_loads"


# ---------------------------------------------------------------------------------------------------------------
# The key: the program's structural entries exactly, its numbers as 0, 1, -1 or 'x'


def _structural_positions(program: np.ndarray) -> set[int]:
    """The positions in a program (flat_program.encode's layout, base 0) of its counts, codes, link indices, branches
    and joint-map entries (everything that is not a length, angle, mass or gravity)."""
    n_links, n_groups = int(program[0]), int(program[1])
    positions = {0, 1, 2, 3, 4}

    def joint(j):
        positions.update((j, j + 1, j + 2))
        if program[j] == flat_program.GEAR_MESH:
            positions.add(j + 9)  # the carrier link

    joint(5)
    g = flat_program.HEADER_SIZE + flat_program.LINK_SIZE * n_links
    for _ in range(n_groups):
        positions.update(range(g, g + 4))
        for k in range(3):
            joint(g + 4 + flat_program.JOINT_SIZE * k)
        if int(program[g]) == flat_program.CAM_FOLLOWER:  # where its law is (a cam law's pieces are read at run time)
            positions.add(g + 4 + 2 * flat_program.JOINT_SIZE + 3)
        g += flat_program.GROUP_SIZE
    positions.add(g)
    joint(g + 1)
    positions.update(range(g + 1 + flat_program.JOINT_SIZE, g + 1 + flat_program.JOINT_SIZE + 2 * int(program[g])))
    return positions


@functools.cache
def _generator_source_hash() -> str:
    """The hash of the generator's source (this module's, symbolic_reduction's and symbolic_kinetostatics') and the
    general solver's (flat.py and its flat_*.py modules; program_key)."""
    import inspect

    modules = (
        sys.modules[__name__],
        symbolic_reduction,
        symbolic_kinetostatics,
        flat,
        flat_program,
        flat_positions,
        flat_derivatives,
        flat_poses,
        flat_kinetostatics,
    )
    return hashlib.sha256("".join(inspect.getsource(module) for module in modules).encode()).hexdigest()


def program_key(program: np.ndarray, outputs: Sequence[int]) -> str:
    """The hash of what the generated source depends on: the structural entries of the program, the literal
    pattern of its numbers, the output joints' record positions and the generator's own source (_generator_source_hash:
    its three modules' and the general solver's, whose layout it reads: a changed generator never meets an old
    cached source)."""
    structural = _structural_positions(program)
    pattern = [
        repr(float(v)) if i in structural else repr(symbolic_reduction.literal(v)) for i, v in enumerate(program)
    ]
    text = f"{_generator_source_hash()}|{'|'.join(pattern)}|{tuple(outputs)}"
    return hashlib.sha256(text.encode()).hexdigest()[:20]


# a cached file is a module: this header, then the function (what the fast path adds to a scene's module)
MODULE_HEADER = '"""Generated by mech_regulator.mechanisms.linkage.symbolic (do not edit)."""\n\nimport math\n\nimport numpy as np\n\n\n'


@functools.cache
def _source_by_key(file_name: str) -> str | None:
    """The function's source in the cache folder's module of this name (None: not generated yet on this machine)."""
    path = cache.folder() / file_name
    if not path.exists():
        return None
    text = path.read_text(encoding="utf-8")
    return text[len(MODULE_HEADER) :] if text.startswith(MODULE_HEADER) else None


def _cached_source(file_name: str, generate: Callable[[], str]) -> str:
    """The source kept in the cache folder under file_name (a module: MODULE_HEADER and the function), generated now
    (sympy) and kept if not there yet."""
    source = _source_by_key(file_name)
    if source is None:
        source = generate()
        cache.write(cache.folder() / file_name, MODULE_HEADER + source)
        _source_by_key.cache_clear()
    return source


def reduced_source(program: np.ndarray, outputs: Sequence[int] = ()) -> tuple[str, str]:
    """(function name, source) of the generated reduced function of a linkage program (flat_program.encode, base 0) with
    these output joint records (prismatic joints' record positions; empty: the program's output), from the cache
    folder if generated before, else generated now (sympy) and cached."""
    key = program_key(program, outputs)
    name = f"{FUNCTION_NAME}_{key}"
    return name, _cached_source(_file_name(name), lambda: symbolic_reduction.generate_reduced(program, outputs, name))


def joint_loads_source(program: np.ndarray) -> tuple[str, str]:
    """(function name, source) of the generated kinetostatics of a linkage program (flat_program.encode, base 0) without
    a redundant link: `name(phi, omega, force, p, offset) -> (R0, R1, ratios, M_b0, M_b1)`,
    flat_kinetostatics.joint_loads' numbers with R0, R1 and ratios as tuples per joint in the linkage's order; from the
    cache folder if generated before, else generated now (sympy) and cached."""
    key = program_key(program, ())
    name = f"{JOINT_LOADS_NAME}_{key}"
    return name, _cached_source(_file_name(name), lambda: symbolic_kinetostatics.generate_joint_loads(program, name))


def _file_name(name: str) -> str:
    """The cache folder's module of a generated function."""
    return f"{name}.py"


def reference_function(name: str) -> Callable:
    """_reference_function(name) on the process's path: compiled, or plain within cache.run_uncompiled."""
    return _reference_function(name, cache.uncompiled())


@functools.cache
def _reference_function(name: str, plain: bool) -> Callable:
    """The generated function `name` (reduced_source or joint_loads_source made it: its module is in the cache
    folder) compiled by numba for the reference path, as the fast path compiles the same source into a scene's
    module: numba's disk cache beside the module keeps it, so it compiles once per kind of linkage and machine (said
    on stderr before it does, a second or a few; `plain`: the function as plain Python, not compiled). Plain Python
    ran it 3 to 8 times slower than the general solver compiled, which the reference path called before."""
    import importlib.util

    path = cache.folder() / _file_name(name)
    spec = importlib.util.spec_from_file_location(f"mech_regulator_generated_{name}", path)
    assert spec is not None and spec.loader is not None, f"{path}: a .py file has a source loader"
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # numba's cache finds the module's globals by its name
    spec.loader.exec_module(module)
    if plain:
        return getattr(module, name)
    from numba import njit
    from numba.core.caching import FunctionCache

    function = njit(cache=True, error_model="numpy")(getattr(module, name))  # as codegen compiles it
    if not FunctionCache(function.py_func)._cache_file._load_index():
        what = "joint reactions" if name.startswith(JOINT_LOADS_NAME) else "reduced inertia"
        print(
            f"note: compiling the linkage's generated {what} code once (a few seconds; later runs load it at once)",
            file=sys.stderr,
            flush=True,
        )
    return function


def output_records(program: np.ndarray, linkage: Linkage, joints: Sequence[str]) -> list[int]:
    """The record positions (in the program's joint map) of the named joints, for `reduced_source`'s outputs."""
    first = flat_kinetostatics.joint_map(program, 0) + 1 + flat_program.JOINT_SIZE
    index = {joint.name: k for k, joint in enumerate(linkage.joints)}
    return [int(program[first + 2 * index[name]]) for name in joints]


def make_reduced(
    linkage: Linkage, structure: Structure, gravity: tuple[float, float] | None, outputs: Sequence[str] = ()
) -> Callable[[float], tuple[float, ...]]:
    """`reduced(phi) -> (J_links, dJ/dphi, M_weight, q, dq/dphi)` of a linkage by its generated code
    (reference_function: compiled, the source the fast path compiles; with `outputs`, prismatic joints' names: q,
    dq/dphi of each in turn); where a group cannot assemble or is at a dead point (the code gives NaN or an infinity:
    a square root of a negative number, a division by zero), the LinkageError of the general solver
    (kinematics.make_solver) naming the group and why. Within cache.run_uncompiled it is the general solver's
    plain flat_poses.reduced instead when there are no `outputs` (no sympy: the same numbers to rounding, the tests
    compare them), else the generated code as plain Python."""
    from mech_regulator.mechanisms.linkage.kinematics import make_solver

    if cache.uncompiled() and not outputs:
        from mech_regulator.mechanisms.linkage.kinematics import make_reduced as general_reduced

        return general_reduced(linkage, structure, gravity)
    program = flat_program.encode(linkage, structure.groups, gravity)
    name, _ = reduced_source(program, output_records(program, linkage, outputs))
    function = reference_function(name)

    def reduced(phi: float) -> tuple[float, ...]:
        values = function(phi, program, 0)
        if not math.isfinite(sum(values)):  # a NaN or an infinity among them (one test, not one per value)
            make_solver(linkage, structure.groups)(phi)  # raises the group's LinkageError
            raise LinkageError(
                f"the linkage's reduced quantities are not finite at crank angle {math.degrees(phi):.3f} deg"
            )
        return values

    return reduced
