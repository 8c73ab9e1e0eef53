"""The suite's own organisation (test/conftest.py): the `physics` marker names existing modules that start no ROS
node, no subprocess and no fast path, and marks their tests only; the longest files come first."""

from __future__ import annotations

import ast
import types
from pathlib import Path

import pytest
from conftest import LONGEST_FILES, PHYSICS_MODULES, mark_physics, order_files

TESTS = Path(__file__).resolve().parent
NOT_PHYSICS = ("rclpy", "ros_support", "subprocess", "mech_regulator.solvers.compiled", "mech_regulator.nodes")


def imported_modules(path: Path) -> set[str]:
    """The modules a test file imports (import X, from X import ...), by their full dotted names."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
    return names


@pytest.mark.parametrize("module", sorted(PHYSICS_MODULES))
def test_a_physics_module_exists_and_imports_no_node_process_nor_compiled_path(module):
    path = TESTS / f"{module}.py"
    assert path.is_file(), f"conftest.PHYSICS_MODULES names {module}, which is not a file of test/"
    imported = imported_modules(path)
    assert not {name for name in imported if name.startswith(NOT_PHYSICS)}, (module, sorted(imported))
    assert "solver.path=fast" not in path.read_text(encoding="utf-8"), module


class _Item:
    """A stand-in of a collected test of a module: what mark_physics reads and calls."""

    def __init__(self, module: str, name: str = "test"):
        self.module = types.SimpleNamespace(__name__=module)
        self.path = TESTS / f"{module}.py"
        self.name = name
        self.markers: list[str] = []

    def add_marker(self, marker) -> None:
        self.markers.append(marker.name)


def test_the_physics_marker_is_on_the_physics_modules_tests_only():
    physics, other = _Item("test_dynamics"), _Item("test_ros_nodes")
    mark_physics([physics, other])
    assert (physics.markers, other.markers) == (["physics"], [])


def test_the_longest_files_exist_once_each():
    missing = [name for name in LONGEST_FILES if not (TESTS / f"{name}.py").is_file()]
    assert missing == [] and len(set(LONGEST_FILES)) == len(LONGEST_FILES), missing


def test_the_longest_files_come_first_then_the_others_by_their_number_of_tests():
    longest, second = LONGEST_FILES[:2]
    items = [
        _Item("test_dynamics", "a"),
        _Item(second, "b"),
        _Item("test_cli", "c"),
        _Item("test_cli", "d"),
        _Item(longest, "e"),
        _Item("test_dynamics", "f"),
        _Item("test_dynamics", "g"),
        _Item(second, "h"),
    ]
    order_files(items)
    assert [item.name for item in items] == ["e", "b", "h", "a", "f", "g", "c", "d"]
