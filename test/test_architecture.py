"""The house's order: each floor of mech_regulator imports only from the floors below it, no two modules import each
other (directly or round a circle), and the physics core stays free of ROS and of the viewer."""

import ast
import graphlib
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

FLOORS = (
    "mech_regulator",
    "mech_regulator.scene",
    "mech_regulator.mechanisms",
    "mech_regulator.effects",
    "mech_regulator.governors",
    "mech_regulator.model",
    "mech_regulator.solvers",
    "mech_regulator.analysis",
    "mech_regulator.bench",
    "mech_regulator.viz",
    "mech_regulator.cli.report",
    "mech_regulator.nodes",
    "mech_regulator.cli",
    "mech_regulator.__main__",
    "launch",
)
"""The floors from the bottom up, each a module or package name: a module stands on the floor of the longest of
these names it starts with. The bottom floor is the package's own modules (errors and exit codes, the on-disk
cache, processes); cli/report/ (what a run shows and writes: summaries, progress, JSON and CSV) serves the nodes
as well as the commands; the other commands stand above the nodes, since `run` starts them; `launch` is the ROS 2
launch files (launch/*.launch.py). README.md, Layout, describes each floor."""
CORE = FLOORS[: FLOORS.index("mech_regulator.analysis") + 1]
"""The physics core: the floors up to the analysis, free of rclpy and rerun."""


def module_files(package: Path, launch_folder: Path | None = None) -> dict[str, tuple[Path, bool]]:
    """Each module of `package` (a folder) and of the launch files in `launch_folder`, by its dotted name: its file
    and whether it is a package's __init__."""
    modules = {}
    for path in package.rglob("*.py"):
        parts = path.relative_to(package.parent).with_suffix("").parts
        is_package = parts[-1] == "__init__"
        modules[".".join(parts[:-1] if is_package else parts)] = (path, is_package)
    for path in sorted(launch_folder.glob("*.launch.py")) if launch_folder else []:
        modules[f"launch.{path.name.removesuffix('.launch.py')}"] = (path, False)
    return modules


def executed_imports(tree: ast.AST) -> list[ast.Import | ast.ImportFrom]:
    """The import statements of a module's syntax tree that can run: anywhere (inside a function too), except
    under `if TYPE_CHECKING:`, which only a type checker reads."""
    if isinstance(tree, (ast.Import, ast.ImportFrom)):
        return [tree]
    if isinstance(tree, ast.If) and "TYPE_CHECKING" in ast.unparse(tree.test):
        return [node for child in tree.orelse for node in executed_imports(child)]
    return [node for child in ast.iter_child_nodes(tree) for node in executed_imports(child)]


def import_graph(modules: dict[str, tuple[Path, bool]], package: str) -> dict[str, set[str]]:
    """The modules of `package` each module imports (executed_imports): `from a.b import c` imports a.b.c when that
    is a module, else a.b."""
    graph: dict[str, set[str]] = {}
    for name, (path, is_package) in modules.items():
        graph[name] = set()
        for node in executed_imports(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            else:
                here = name.split(".") if is_package else name.split(".")[:-1]
                base = ".".join(
                    here[: len(here) - node.level + 1] + [node.module or ""] if node.level else [node.module or ""]
                ).strip(".")
                targets = [
                    f"{base}.{alias.name}" if f"{base}.{alias.name}" in modules else base for alias in node.names
                ]
            for target in targets:
                while target not in modules and "." in target:
                    target = target.rsplit(".", 1)[0]
                if target.split(".")[0] == package and target in modules and target != name:
                    graph[name].add(target)
    return graph


def floor(module: str, floors: tuple[str, ...]) -> int:
    """The floor (index into floors) `module` stands on."""
    return floors.index(max((name for name in floors if module == name or module.startswith(f"{name}.")), key=len))


def upward_imports(graph: dict[str, set[str]], floors: tuple[str, ...]) -> list[str]:
    """'a -> b' for each import of a module on a higher floor."""
    return sorted(
        f"{module} -> {imported}"
        for module, imports in graph.items()
        for imported in imports
        if floor(imported, floors) > floor(module, floors)
    )


def import_circle(graph: dict[str, set[str]]) -> list[str]:
    """A circle of imports (each module imports the next, the last the first), [] when there is none."""
    try:
        graphlib.TopologicalSorter(graph).prepare()
    except graphlib.CycleError as error:
        return error.args[1]
    return []


def package_graph() -> dict[str, set[str]]:
    """The import graph of mech_regulator and of the ROS 2 launch files."""
    return import_graph(module_files(ROOT / "mech_regulator", ROOT / "launch"), "mech_regulator")


def test_each_floor_imports_only_from_the_floors_below_it():
    upward = upward_imports(package_graph(), FLOORS)
    assert not upward, "imports of a higher floor (test_architecture.FLOORS):\n" + "\n".join(upward)


def test_no_module_imports_itself_round_a_circle():
    circle = import_circle(package_graph())
    assert not circle, "an import circle: " + " -> ".join(circle)


def test_every_floor_holds_modules():
    """A floor named in FLOORS that no module stands on (misspelt, or its package gone) would check nothing."""
    assert {floor(module, FLOORS) for module in package_graph()} == set(range(len(FLOORS)))


def _synthetic_package(folder: Path, files: dict[str, str]) -> dict[str, tuple[Path, bool]]:
    for name, source in files.items():
        path = folder / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(source)
    return module_files(folder / "toy")


def test_the_checks_find_an_upward_import_and_a_circle(tmp_path):
    """On a package written here: a lazy import of an upper floor inside a function, and two modules of one floor
    importing each other (one relatively); plain downward imports are neither, nor is an import for the type
    checker only."""
    modules = _synthetic_package(
        tmp_path,
        {
            "toy/__init__.py": "",
            "toy/low/__init__.py": "from toy.low.a import helper\n",
            "toy/low/a.py": "import os\n\ndef helper():\n    from toy.high.top import shown\n    return shown\n",
            "toy/low/b.py": "from . import c\n",
            "toy/low/c.py": "from typing import TYPE_CHECKING\nfrom toy.low import b\n\n"
            "if TYPE_CHECKING:\n    from toy.high.top import shown\n",
            "toy/high/__init__.py": "",
            "toy/high/top.py": "from ..low import b\nfrom toy.low.c import nothing\nshown = 1\n",
        },
    )
    graph = import_graph(modules, "toy")
    floors = ("toy", "toy.low", "toy.high")
    assert graph["toy.high.top"] == {"toy.low.b", "toy.low.c"}
    assert upward_imports(graph, floors) == ["toy.low.a -> toy.high.top"]
    assert upward_imports(graph, ("toy", "toy.high.top", "toy.low", "toy.high")) == [
        "toy.high.top -> toy.low.b",
        "toy.high.top -> toy.low.c",
    ]  # a module floor below its package's
    assert sorted(import_circle(graph)[1:]) == ["toy.low.b", "toy.low.c"]


def test_the_checks_pass_a_package_in_order(tmp_path):
    modules = _synthetic_package(
        tmp_path,
        {
            "toy/__init__.py": "",
            "toy/low/__init__.py": "from .a import helper\n",
            "toy/low/a.py": "def helper():\n    return 1\n",
            "toy/high/top.py": "from toy.low import helper\n",
        },
    )
    graph = import_graph(modules, "toy")
    assert upward_imports(graph, ("toy", "toy.low", "toy.high")) == []
    assert import_circle(graph) == []


def test_the_core_imports_neither_rclpy_nor_rerun():
    imports = "; ".join(f"import {package}" for package in CORE)
    script = (
        f"import sys; {imports}; "
        "print(sorted(name for name in sys.modules if name.split('.')[0] in ('rclpy', 'rerun')))"
    )
    found = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True).stdout.strip()
    assert found == "[]"


def test_the_check_sees_an_import_of_rerun():
    """The check above can fail: importing the recording layer does pull rerun in."""
    script = "import sys; import mech_regulator.viz.recording; print('rerun' in sys.modules)"
    assert (
        subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True).stdout.strip()
        == "True"
    )


def test_the_package_imported_first_fixes_openblas_s_kernels_unless_they_are_set():
    """mech_regulator/__init__.py: on an x86-64 CPU with AVX2 and FMA, OPENBLAS_CORETYPE=Haswell before numpy loads
    OpenBLAS (the same rounding on AVX2 and AVX-512 machines: docs/speed.md, "The same numbers on every machine");
    a value set before is kept."""
    import platform

    import mech_regulator

    expected = (
        "Haswell"
        if platform.machine().lower() in ("x86_64", "amd64") and {"avx2", "fma"} <= mech_regulator._cpu_flags()
        else "unset"
    )
    show = "import os, mech_regulator; print(os.environ.get('OPENBLAS_CORETYPE', 'unset'))"
    environment = {key: value for key, value in os.environ.items() if key != "OPENBLAS_CORETYPE"}
    for given, printed in ((None, expected), ("Zen", "Zen")):
        if given is not None:
            environment["OPENBLAS_CORETYPE"] = given
        done = subprocess.run([sys.executable, "-c", show], env=environment, capture_output=True, text=True, check=True)
        assert done.stdout.strip() == printed, done
