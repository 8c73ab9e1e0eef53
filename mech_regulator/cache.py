"""The package's cache folder on disk: generated source (the fast path's scene modules, solvers/compiled/codegen.py;
a linkage's generated reduced function, mechanisms/linkage/symbolic.py) and numba's machine code beside it.

It is $MECH_REGULATOR_CACHE, else $XDG_CACHE_HOME/mech_regulator/compiled, else ~/.cache/mech_regulator/compiled,
created on first use. Files are written atomically, since another process may be reading the same one.
"""

from __future__ import annotations

import os
from pathlib import Path

from mech_regulator.scene import SceneError

CACHE_VARIABLE = "MECH_REGULATOR_CACHE"


def folder() -> Path:
    """The cache folder (module docstring), created if missing; SceneError naming the variable if it cannot be."""
    name = os.environ.get(CACHE_VARIABLE)
    if not name:
        base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
        name = os.path.join(base, "mech_regulator", "compiled")
    path = Path(name)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise SceneError(f"{CACHE_VARIABLE}: cannot make the fast path's cache folder '{path}': "
                         f"{error.strerror or error}; expected a writable folder (set {CACHE_VARIABLE})") from None
    return path


def write(path: Path, text: str) -> None:
    """Write a file of the cache folder atomically (another process may be importing the same file)."""
    temporary = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        temporary.write_text(text, encoding="utf-8")
        os.replace(temporary, path)
    except OSError as error:
        raise SceneError(f"{CACHE_VARIABLE}: cannot write the fast path's cache folder '{path.parent}': "
                         f"{error.strerror or error}; expected a writable folder (set {CACHE_VARIABLE})") from None
