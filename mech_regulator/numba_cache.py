"""numba's disk cache keyed on the package's source: a compiled function of the package is loaded from the cache only
if no module its machine code can hold has changed since it was compiled.

numba stamps a cached function (`njit(cache=True)`) with its own file's source alone. A compiled stepper
(solvers/compiled/steppers.py) holds the code of integrators.py, steps.py, events.py and solvers/time_domain.py, and
the linkage solver's `solve_poses` (mechanisms/linkage/flat_poses.py) that of the other flat_*.py modules: after an
edit of one of those (a `git pull` in an editable clone) numba would load the old machine code and give the old
numbers. So every cached function defined in the package is stamped with numba's own stamp plus a hash of the
source of every module compiled code can reach (`COMPILED_REACH_EXCLUDES`): any edit of one of them compiles anew.

numba has no public setting for this: `install()` puts `PackageSourceLocator` first in numba's list of cache locators
(numba.core.caching, a private API). It claims only the package's functions and keeps the cache folder numba would
have chosen (`__pycache__` beside the module, or NUMBA_CACHE_DIR, or the user-wide folder); should that API move in a
later numba, `install()` warns once and numba's own keying stays.
"""

from __future__ import annotations

import functools
import hashlib
import sys
import warnings
from pathlib import Path
from types import ModuleType
from typing import Any

PACKAGE_ROOT = Path(__file__).resolve().parent
"""The folder of the mech_regulator package."""

COMPILED_REACH_EXCLUDES = ("analysis", "bench", "viz", "cli", "nodes", "__main__.py")
"""The top-level modules and subpackages of the package that numba-compiled code cannot reach: the floors above the
solvers (README.md, Layout; compiled code lives in the solvers, the mechanisms and the effects, and imports only from
their floors and below). Every other .py file of the package is part of the stamp."""


@functools.cache
def reach_source_hash(root: Path = PACKAGE_ROOT) -> str:
    """The SHA-256 (hex) of the relative path and the bytes of every .py file under `root` that compiled code can
    reach (all but COMPILED_REACH_EXCLUDES), in sorted order: read once per process (about 2 MB, a few ms)."""
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        relative = path.relative_to(root)
        if relative.parts[0] in COMPILED_REACH_EXCLUDES:
            continue
        digest.update(relative.as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()


def _locator_class(caching: ModuleType) -> type:
    """The class of PackageSourceLocator for numba's caching module (numba's abstract locator is its base)."""

    class PackageSourceLocator(caching._CacheLocator):  # type: ignore[name-defined]
        """numba's own locator for a function of the package (its folder, its disambiguator), its source stamp
        extended by reach_source_hash()."""

        def __init__(self, own_locator: Any, py_file: str) -> None:
            self.own_locator = own_locator
            self._py_file = py_file  # the function's file, which numba's "cannot cache" warning names

        def ensure_cache_path(self) -> None:
            """Make numba's own cache folder for the function (raises OSError if it cannot be written)."""
            self.own_locator.ensure_cache_path()

        def get_cache_path(self) -> str:
            """The folder numba's own locator keeps the function in."""
            return self.own_locator.get_cache_path()

        def get_source_stamp(self) -> tuple[Any, str]:
            """numba's own stamp of the function's file and the hash of the source compiled code can reach."""
            return self.own_locator.get_source_stamp(), reach_source_hash()

        def get_disambiguator(self) -> str:
            """numba's own disambiguator (the function's first line)."""
            return self.own_locator.get_disambiguator()

        @classmethod
        def from_function(cls, py_func: Any, py_file: str) -> PackageSourceLocator | None:
            """The locator of a function defined in the package, wrapping the first of numba's own locators that
            takes it; None (numba's own locators decide) for any other function."""
            if not Path(py_file).resolve().is_relative_to(PACKAGE_ROOT):
                return None
            for own_class in _cache_impl(caching)._locator_classes:
                own_locator = None if own_class is cls else own_class.from_function(py_func, py_file)
                if own_locator is not None:
                    return cls(own_locator, py_file)
            return None

    return PackageSourceLocator


def _cache_impl(caching: ModuleType) -> Any:
    """numba's class that picks a cached function's locator (CacheImpl; _CacheImpl before numba 0.61), or None."""
    return getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl", None)


def register(caching: ModuleType) -> bool:
    """Put PackageSourceLocator first in `caching`'s (numba.core.caching's) list of locators: True if done (or done
    before); False, with a one-line warning, if that module lacks what it needs or asks a locator for more than
    PackageSourceLocator gives (numba's keying then stays)."""
    locators = getattr(_cache_impl(caching), "_locator_classes", None)
    if not isinstance(locators, list) or not isinstance(getattr(caching, "_CacheLocator", None), type):
        return _keyed_by_numba(caching, "no CacheImpl._locator_classes list or _CacheLocator class")
    locator_class = _locator_class(caching)
    missing = sorted(getattr(locator_class, "__abstractmethods__", ()))
    if missing:
        return _keyed_by_numba(caching, f"locators must have {', '.join(missing)}")
    if not any(getattr(locator, "__name__", "") == locator_class.__name__ for locator in locators):
        locators.insert(0, locator_class)
    return True


def _keyed_by_numba(caching: ModuleType, reason: str) -> bool:
    """Warn in one line that numba's own keying stays, and why (`reason`); False."""
    warnings.warn(
        f"mech_regulator: numba {getattr(sys.modules.get('numba'), '__version__', '?')}'s caching module "
        f"({caching.__name__}): {reason}; its disk cache is keyed on each function's own file only (after an edit of "
        "the package, delete its __pycache__/*.nb[ic] files to compile anew)",
        RuntimeWarning,
        stacklevel=3,
    )
    return False


@functools.cache
def install() -> bool:
    """Key numba's disk cache of the package's functions on the package's source (register with numba's caching
    module), once per process; to be called before a cached function of the package is defined (`njit(cache=True)`
    picks its locator there)."""
    from numba.core import caching

    return register(caching)
