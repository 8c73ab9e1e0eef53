"""numba's disk cache keyed on the package's source (mech_regulator/numba_cache.py): the stamp follows every module
compiled code can reach, every cached function of the package gets the package's locator (in numba's own cache
folder), other functions keep numba's, and a numba whose caching module moved leaves numba's keying with a warning."""

from __future__ import annotations

import abc
import ast
import shutil
import types
from pathlib import Path

import numpy as np
import pytest
from numba import njit
from numba.core import caching, config
from numba.core.registry import CPUDispatcher
from test_architecture import FLOORS

from mech_regulator import numba_cache
from mech_regulator.mechanisms.linkage import flat
from mech_regulator.solvers.compiled import events, integrators, kernels, steppers, steps

fresh_hash = numba_cache.reach_source_hash.__wrapped__  # without the once-per-process memo


def _locator(function) -> object:
    """The cache locator numba picks for the plain Python function (as a dispatcher with cache=True would)."""
    return caching.FunctionCache(function)._impl.locator


def _numba_own_locator(function) -> object:
    """The locator numba itself would pick for the function (its list without the package's locator)."""
    path = str(Path(function.__code__.co_filename))
    for own_class in caching.CacheImpl._locator_classes:
        if own_class.__name__ != "PackageSourceLocator":
            own = own_class.from_function(function, path)
            if own is not None:
                return own
    raise AssertionError("numba has no locator for the function")


def test_stamp_follows_a_sibling_module_and_not_the_commands(tmp_path):
    copy = tmp_path / "mech_regulator"
    shutil.copytree(numba_cache.PACKAGE_ROOT, copy, ignore=shutil.ignore_patterns("__pycache__"))
    original = fresh_hash(copy)
    assert original == numba_cache.reach_source_hash()  # the copy is the package

    steps_file = copy / "solvers" / "compiled" / "steps.py"
    steps_source = steps_file.read_text(encoding="utf-8")
    steps_file.write_text(steps_source + "# a comment\n", encoding="utf-8")
    assert fresh_hash(copy) != original  # a stepper's cache (steppers.py) is stale after an edit of steps.py
    steps_file.write_text(steps_source, encoding="utf-8")
    assert fresh_hash(copy) == original

    (copy / "mechanisms" / "linkage" / "flat_new_helper.py").write_text("X = 1\n", encoding="utf-8")
    assert fresh_hash(copy) != original  # a new module the solver may call counts too
    (copy / "mechanisms" / "linkage" / "flat_new_helper.py").unlink()

    main = copy / "cli" / "main.py"
    main.write_text(main.read_text(encoding="utf-8") + "# a comment\n", encoding="utf-8")
    assert fresh_hash(copy) == original  # the commands are above anything compiled


def test_the_hash_leaves_out_exactly_the_floors_above_the_solvers():
    above = FLOORS[FLOORS.index("mech_regulator.solvers") + 1 :]
    names = {floor.split(".")[1] for floor in above if floor.startswith("mech_regulator.")}
    assert names == {name.removesuffix(".py") for name in numba_cache.COMPILED_REACH_EXCLUDES}


def test_cached_functions_of_the_package_get_its_locator():
    dispatchers = [
        value
        for module in (steps, events, integrators, kernels)
        for value in vars(module).values()
        if isinstance(value, CPUDispatcher) and value._cache.__class__ is caching.FunctionCache
    ]
    functions = [dispatcher.py_func for dispatcher in dispatchers]
    functions += [flat.compiled("solve_poses").py_func, flat.compiled("reduced").py_func]
    functions += [function for function, _ in steppers._STEPPERS.values()]
    assert len(dispatchers) > 30  # the module-level cached functions of the compiled path
    for function in functions:
        locator = _locator(function)
        own = _numba_own_locator(function)
        assert type(locator).__name__ == "PackageSourceLocator", function.__qualname__
        assert locator.get_cache_path() == own.get_cache_path()  # numba's own folder (__pycache__, NUMBA_CACHE_DIR)
        assert locator.get_disambiguator() == own.get_disambiguator()
        assert locator.get_source_stamp() == (own.get_source_stamp(), numba_cache.reach_source_hash())


GENERATED_CODE_COMPILERS = {"mechanisms/linkage/symbolic.py"}
"""Modules whose njit(cache=True) compiles a function of the cache folder (mech_regulator/cache.py), not of the
package: numba keys it on its generated file, whose name holds the hash of what generated it."""


def test_every_cached_function_of_the_package_is_defined_after_install():
    calls = 0
    for path in sorted(numba_cache.PACKAGE_ROOT.rglob("*.py")):
        relative = path.relative_to(numba_cache.PACKAGE_ROOT).as_posix()
        tree = ast.parse(path.read_text(encoding="utf-8"))
        cached = [
            node.lineno
            for node in ast.walk(tree)
            if isinstance(node, ast.Call)
            and any(word.arg == "cache" and ast.literal_eval(word.value) is True for word in node.keywords)
        ]
        installs = [
            node.lineno
            for node in ast.walk(tree)
            if isinstance(node, ast.Call) and ast.unparse(node.func) == "numba_cache.install"
        ]
        calls += len(installs)
        if cached and relative not in GENERATED_CODE_COMPILERS:
            assert installs and min(installs) < min(cached), f"{relative}: numba_cache.install() before cache=True"
    assert calls >= 6  # the compiled path's five modules and the linkage solver's compiled()


def _outside(x):
    """A function outside the package: numba's own keying."""
    return x + 1.0


def test_a_function_outside_the_package_keeps_numba_locator():
    numba_cache.install()
    assert type(_locator(_outside)) is type(_numba_own_locator(_outside))


def test_a_changed_package_source_makes_the_cached_code_stale(tmp_path, monkeypatch):
    monkeypatch.setattr(config, "CACHE_DIR", str(tmp_path))
    function = steps._rms.py_func
    njit(cache=True)(function)(np.ones(3))  # compiled (a second or so) and saved under tmp_path
    assert caching.FunctionCache(function)._cache_file._load_index()  # loaded by the next process
    monkeypatch.setattr(numba_cache, "reach_source_hash", lambda: "another source")
    assert not caching.FunctionCache(function)._cache_file._load_index()  # compiled anew


def test_registering_twice_adds_one_locator():
    assert numba_cache.register(caching) and numba_cache.register(caching)
    names = [locator.__name__ for locator in caching.CacheImpl._locator_classes]
    assert names.count("PackageSourceLocator") == 1
    assert names[0] == "PackageSourceLocator"


def test_a_moved_numba_api_warns_and_leaves_numba_keying():
    moved = types.ModuleType("moved")
    moved.CacheLocatorBase = caching._CacheLocator
    with pytest.warns(RuntimeWarning, match="no CacheImpl._locator_classes list.*keyed on each function's own file"):
        assert not numba_cache.register(moved)


def test_a_locator_asked_for_more_warns_and_leaves_numba_keying():
    class AskingMore(caching._CacheLocator):
        @abc.abstractmethod
        def get_source_digest(self):
            """A method a later numba might ask of every locator."""

    class Impl:
        _locator_classes: list[type] = []

    moved = types.ModuleType("moved")
    moved._CacheLocator, moved.CacheImpl = AskingMore, Impl
    with pytest.warns(
        RuntimeWarning, match="must have get_source_digest; its disk cache is keyed on each function's own file"
    ):
        assert not numba_cache.register(moved)
    assert Impl._locator_classes == []
