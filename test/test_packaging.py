"""Packaging: a colcon (ament_python) build that works without ROS, the pip console script and
`python -m`, and package.xml agreeing with setup.py and mech_regulator.__version__ and declaring every
third-party package the code imports, with setup.py's version floors."""

from __future__ import annotations

import ast
import importlib.metadata
import importlib.util
import os
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from support import setup_arguments

import mech_regulator

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "mech_regulator"
EXECUTABLE = "mech-regulator"
BUNDLED = sorted(path.stem for path in (ROOT / "config" / "scenes").glob("*.yaml"))


def _run(command: list[str], timeout: float = 60, **kwargs) -> subprocess.CompletedProcess:
    """Run a command, failing the test with its output when it exits non-zero."""
    result = subprocess.run(command, capture_output=True, text=True, timeout=timeout, **kwargs)
    assert result.returncode == 0, (
        f"{' '.join(map(str, command))} exited {result.returncode}\n"
        f"--- stdout\n{result.stdout[-3000:]}\n--- stderr\n{result.stderr[-3000:]}"
    )
    return result


def _assert_lists_bundled_scenes(output: str) -> None:
    assert BUNDLED, "no config/scenes/*.yaml in the source tree"
    listed = [line.split()[0] for line in output.splitlines() if line.strip()]
    assert listed == BUNDLED, f"expected the bundled scenes {BUNDLED}, got:\n{output}"


def _colcon() -> str:
    """The colcon command of this Python environment; skip the test when it is not installed."""
    missing = [
        name
        for name in ("colcon_core", "colcon_ros", "catkin_pkg", "ament_package")
        if importlib.util.find_spec(name) is None
    ]
    if missing:
        pytest.skip(
            f"colcon is not installed in this Python ({', '.join(missing)} not importable); "
            f"install it with: pip install -e '.[test,colcon]'"
        )
    colcon = shutil.which("colcon", path=str(Path(sys.executable).parent)) or shutil.which("colcon")
    if colcon is None:
        pytest.skip("colcon_core is importable but no `colcon` executable is next to sys.executable or on PATH")
    return colcon


@pytest.fixture(scope="module")
def colcon_install(tmp_path_factory) -> Path:
    """The package built by colcon (ament_python) into a temporary install base; returns its prefix."""
    colcon = _colcon()
    folder = tmp_path_factory.mktemp("colcon")
    env = dict(
        os.environ,
        COLCON_HOME=str(folder / "colcon_home"),  # no user defaults.yaml
        PATH=os.pathsep.join([str(Path(sys.executable).parent), os.environ.get("PATH", "")]),
    )
    install = folder / "install"
    _run(
        [
            colcon,
            "--log-base",
            str(folder / "log"),
            "build",
            "--base-paths",
            str(ROOT),
            "--packages-select",
            PACKAGE,
            "--build-base",
            str(folder / "build"),
            "--install-base",
            str(install),
        ],
        timeout=180,
        cwd=folder,
        env=env,
    )
    return install / PACKAGE


def _install_python_path(prefix: Path) -> str:
    """PYTHONPATH for the colcon install without ROS: what its setup scripts would set up."""
    site_packages = [path for path in prefix.glob("lib/python*/site-packages") if (path / PACKAGE).is_dir()]
    assert len(site_packages) == 1, f"no single {PACKAGE} under {prefix}/lib/python*/site-packages"
    return os.pathsep.join([str(site_packages[0]), *filter(None, [os.environ.get("PYTHONPATH")])])


def test_colcon_build_installs_a_working_executable(colcon_install, tmp_path):
    prefix = colcon_install
    executable = prefix / "lib" / PACKAGE / EXECUTABLE  # where `ros2 run mech_regulator mech-regulator` looks
    assert executable.is_file() and os.access(executable, os.X_OK), (
        f"no executable {executable}; lib/ holds {sorted(str(p.relative_to(prefix)) for p in (prefix / 'lib').rglob('*'))}"
    )
    assert (prefix / "share" / "ament_index" / "resource_index" / "packages" / PACKAGE).is_file()
    assert (prefix / "share" / PACKAGE / "package.xml").is_file()
    share_config = prefix / "share" / PACKAGE / "config"
    assert sorted(path.stem for path in (share_config / "scenes").glob("*.yaml")) == BUNDLED
    assert (share_config / "params" / "main_job.yaml").is_file()
    # where `ros2 launch mech_regulator main_job.launch.py` looks
    assert (prefix / "share" / PACKAGE / "launch" / "main_job.launch.py").is_file()
    site_packages = [path for path in prefix.glob("lib/python*/site-packages") if (path / PACKAGE).is_dir()]
    assert len(site_packages) == 1, f"no single {PACKAGE} under {prefix}/lib/python*/site-packages"
    # every module of the source tree is installed (a subpackage without __init__.py once went missing)
    sources = {path.relative_to(ROOT).as_posix() for path in (ROOT / PACKAGE).rglob("*.py")}
    installed = {path.relative_to(site_packages[0]).as_posix() for path in (site_packages[0] / PACKAGE).rglob("*.py")}
    assert sources <= installed, f"modules missing from the colcon install: {sorted(sources - installed)}"

    # Without ROS, the install's site-packages on PYTHONPATH is what its setup scripts would set up.
    python_path = [str(site_packages[0]), *filter(None, [os.environ.get("PYTHONPATH")])]
    run_env = dict(os.environ, PYTHONPATH=os.pathsep.join(python_path))
    describe = _run([str(executable), "describe", "lathe"], cwd=tmp_path, env=run_env).stdout
    assert "scene: lathe" in describe
    _assert_lists_bundled_scenes(_run([str(executable), "scenes"], cwd=tmp_path, env=run_env).stdout)
    where = _run(
        [sys.executable, "-c", "import mech_regulator.scene.loading as m; print(m.__file__); print(m.config_dir())"],
        cwd=tmp_path,
        env=run_env,
    ).stdout.split("\n")
    assert Path(where[0]).is_relative_to(site_packages[0]), f"imported {where[0]}, not the colcon install"
    assert Path(where[1]) == share_config, f"bundled config read from {where[1]}, not {share_config}"


def test_module_and_console_script_list_bundled_scenes(tmp_path):
    # cwd=tmp_path so that `-m` imports the installed package, not the source tree in the working directory
    _assert_lists_bundled_scenes(_run([sys.executable, "-m", PACKAGE, "scenes"], cwd=tmp_path).stdout)
    script = Path(sys.executable).parent / EXECUTABLE
    if not script.is_file():
        try:
            location = Path(str(importlib.metadata.distribution(PACKAGE).locate_file(""))).resolve()
        except importlib.metadata.PackageNotFoundError:
            location = None
        if location is None or not location.is_relative_to(Path(sys.prefix).resolve()):
            pytest.skip(f"{PACKAGE} is not pip-installed in this Python ({sys.prefix}); run ./dev test")
        pytest.fail(f"{PACKAGE} is pip-installed in {sys.prefix} but its console script {script} is missing")
    _assert_lists_bundled_scenes(_run([str(script), "scenes"], cwd=tmp_path).stdout)


def _setup_py_version() -> str:
    tree = ast.parse((ROOT / "setup.py").read_text(encoding="utf-8"))
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "setup":
            for keyword in node.keywords:
                if keyword.arg == "version":
                    return ast.literal_eval(keyword.value)
    raise AssertionError("setup.py: no literal version= in the setup() call")


def test_package_xml_matches_setup_py():
    root = ET.parse(ROOT / "package.xml").getroot()
    assert root.tag == "package" and root.get("format") == "3", 'package.xml must be <package format="3">'
    assert root.findtext("name") == PACKAGE
    assert root.findtext("export/build_type") == "ament_python"
    version = root.findtext("version")
    assert version == _setup_py_version() == mech_regulator.__version__, (
        f"versions differ: package.xml {version}, setup.py {_setup_py_version()}, "
        f"mech_regulator.__version__ {mech_regulator.__version__}"
    )
    assert (ROOT / "resource" / PACKAGE).is_file(), "resource/mech_regulator is the ament index marker"


NODES = ("machine_node", "governor_node", "scenario_node", "recorder_node")


def test_colcon_install_runs_the_nodes(colcon_install, tmp_path):
    pytest.importorskip("rclpy", reason="the nodes need rclpy (pip install 'mech_regulator[ros]')")
    from ros_support import next_domain_id, ros_environment

    lib = colcon_install / "lib" / PACKAGE  # where `ros2 run mech_regulator machine_node` looks
    for node in NODES:
        assert (lib / node).is_file() and os.access(lib / node, os.X_OK), (
            f"no executable {lib / node}; {lib} holds {sorted(path.name for path in lib.iterdir())}"
        )
    example = lib / "pid_governor.py"  # `ros2 run mech_regulator pid_governor.py` (docs/ros.md, Your own controller)
    assert os.access(example, os.X_OK) and example.read_text().startswith("#!/usr/bin/env python3"), example
    env = dict(ros_environment(next_domain_id()), PYTHONPATH=_install_python_path(colcon_install))
    machine = str(lib / "machine_node")
    missing = tmp_path / "missing.yaml"
    result = subprocess.run(
        [machine, "--ros-args", "-p", f"scene_file:={missing}"],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=tmp_path,
        env=env,
        start_new_session=True,
    )
    assert result.returncode == 2 and f"scene '{missing}': no such file" in result.stderr, (
        f"exit {result.returncode}\n{result.stdout}\n{result.stderr}"
    )
    assert "Traceback" not in result.stderr
    # a short run of the ungoverned lathe, waiting for nobody
    result = _run(
        [
            machine,
            "--ros-args",
            "-p",
            "scene_file:=lathe",
            "-p",
            "lockstep_inputs:=['']",
            "-p",
            "peers:=['']",
            "-p",
            "duration:=0.01",
        ],
        cwd=tmp_path,
        env=env,
        start_new_session=True,
    )
    assert "finished at t = 0.01 s: complete" in result.stdout + result.stderr, result.stderr
    where = _run(
        [sys.executable, "-c", "import mech_regulator.nodes.machine as m; print(m.__file__)"], cwd=tmp_path, env=env
    ).stdout.strip()
    assert Path(where).is_relative_to(colcon_install), f"machine_node imported {where}, not the colcon install"


# -------------------------------------------------------------------------------------------------
# package.xml declares what the code imports


# import name -> (setup.py requirement, rosdep key in package.xml)
PYTHON_DEPENDENCIES = {
    "numpy": ("numpy", "python3-numpy"),
    "scipy": ("scipy", "python3-scipy"),
    "yaml": ("pyyaml", "python3-yaml"),
    "pydantic": ("pydantic", "python3-pydantic"),
    "matplotlib": ("matplotlib", "python3-matplotlib"),
    "tqdm": ("tqdm", "python3-tqdm"),
    "numba": ("numba", "python3-numba"),
    "sympy": ("sympy", "python3-sympy"),
    "rerun": ("rerun-sdk", "python3-rerun-sdk-pip"),  # no rosdep key: rosdep's convention for pip packages
    "mcap_ros2": ("mcap-ros2-support", "python3-mcap-ros2-support-pip"),  # (as rerun-sdk's; mcap comes with it)
}
# imported only by optional features, installed with an extra of setup.py, not by a ROS user's rosdep
OPTIONAL_IMPORTS = {
    "mujoco": "extra 'bench': `bench speed` compares against MuJoCo (mech_regulator/bench/)",
    "psutil": "extra 'bench': `bench soak` reads each node's memory (mech_regulator/bench/soak.py)",
    "dask": "extra 'distributed': `sweep --engine dask` only (mech_regulator/analysis/sweep.py)",
}
# declared but never imported: the `ros2 launch` command, for launch/main_job.launch.py
NOT_IMPORTED = {"ros2launch"}
VERSION_ATTRIBUTES = {
    ">=": "version_gte",
    ">": "version_gt",
    "<=": "version_lte",
    "<": "version_lt",
    "==": "version_eq",
}


def _third_party_imports() -> dict[str, set[str]]:
    """Top-level modules imported by the package and the launch file that are neither the standard library
    nor the package itself -> the files importing them."""
    imports: dict[str, set[str]] = {}
    for path in [*(ROOT / PACKAGE).rglob("*.py"), *(ROOT / "launch").glob("*.py")]:
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                modules = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                modules = [node.module]
            else:
                continue
            for module in modules:
                top = module.split(".")[0]
                if top not in sys.stdlib_module_names and top != PACKAGE:
                    imports.setdefault(top, set()).add(path.relative_to(ROOT).as_posix())
    return imports


def _exec_depends() -> dict[str, dict[str, str]]:
    """package.xml's exec_depend (and depend) keys -> their version attributes."""
    root = ET.parse(ROOT / "package.xml").getroot()
    return {element.text.strip(): dict(element.attrib) for element in [*root.iter("exec_depend"), *root.iter("depend")]}


def test_package_xml_declares_every_third_party_import():
    imports = _third_party_imports()
    assert {"numpy", "rclpy", "launch_ros"} <= set(imports), f"the import scan found only {sorted(imports)}"
    declared = _exec_depends()
    expected = {
        PYTHON_DEPENDENCIES[module][1] if module in PYTHON_DEPENDENCIES else module: module
        for module in imports
        if module not in OPTIONAL_IMPORTS
    }
    missing = {key: sorted(imports[module]) for key, module in expected.items() if key not in declared}
    assert not missing, f"imported but not an exec_depend of package.xml (key: importing files): {missing}"
    unused = set(declared) - set(expected) - NOT_IMPORTED
    assert not unused, f"exec_depends of package.xml nothing imports: {sorted(unused)}"
    stale = set(OPTIONAL_IMPORTS) - set(imports)
    assert not stale, f"OPTIONAL_IMPORTS lists modules nothing imports any more: {sorted(stale)}"


def test_package_xml_version_floors_equal_setup_py():
    requirements = [Requirement(text) for text in setup_arguments()["install_requires"]]
    by_requirement = {requirement: key for requirement, key in PYTHON_DEPENDENCIES.values()}
    unmapped = [requirement.name for requirement in requirements if requirement.name not in by_requirement]
    assert not unmapped, f"install_requires without a package.xml key in PYTHON_DEPENDENCIES: {unmapped}"
    declared = _exec_depends()
    for requirement in requirements:
        key = by_requirement[requirement.name]
        expected = {VERSION_ATTRIBUTES[specifier.operator]: specifier.version for specifier in requirement.specifier}
        assert declared.get(key) == expected, (
            f"{requirement}: package.xml should have <exec_depend {expected}>{key}</exec_depend>, has {declared.get(key)}"
        )


def test_imported_ros_interfaces_come_with_the_ros_extra():
    ros_extra = {Requirement(text).name for text in setup_arguments()["extras_require"]["ros"]}
    imported = {module for module in _third_party_imports() if module == "rclpy" or module.endswith(("_msgs", "_srvs"))}
    assert {"rclpy", "std_msgs"} <= imported, f"the import scan found only {sorted(imported)}"
    declared = _exec_depends()
    for module in sorted(imported | {key for key in declared if key.endswith(("_msgs", "_srvs"))}):
        wheels = {f"ros-kilted-{module.replace('_', '-')}", f"ros-{module.replace('_', '-')}"}
        assert wheels & ros_extra, f"{module}: none of {sorted(wheels)} in setup.py's extra 'ros' {sorted(ros_extra)}"


def test_package_xml_is_valid_for_catkin_pkg():
    catkin_package = pytest.importorskip("catkin_pkg.package", reason="catkin_pkg comes with the extra 'colcon'")
    package = catkin_package.parse_package(str(ROOT / "package.xml"))
    package.validate()
    floors = {dependency.name: dependency.version_gte for dependency in package.exec_depends}
    assert floors["python3-numpy"] == "1.26" and floors["rclpy"] is None, floors


# -------------------------------------------------------------------------------------------------
# ./dev: each command installs what it needs, once


def test_dev_is_valid_bash_and_ci_runs_the_checks_then_dev_test():
    _run(["bash", "-n", str(ROOT / "dev")])
    commands = [
        line.strip()
        for line in (ROOT / ".ci" / "run").read_text().splitlines()
        if line.strip() and not line.lstrip().startswith(("#", "set ", "cd "))
    ]
    assert commands == ["./dev check", "./dev test"], f".ci/run runs {commands}"


def test_dev_unknown_command_prints_usage_and_exits_2_without_setting_up(tmp_path):
    shutil.copy(ROOT / "dev", tmp_path / "dev")
    result = subprocess.run(["bash", str(tmp_path / "dev"), "frobnicate"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 2, result
    assert result.stderr.startswith("usage: ./dev run") and "./dev rerun FILE" in result.stderr, result.stderr
    assert not (tmp_path / ".venv").exists()


def _fake_venv_checkout(folder: Path) -> Path:
    """dev and the packaging files in folder, with a .venv whose python, mech-regulator and rerun only
    append their arguments to folder/calls.log. Returns the log."""
    for name in ("dev", "setup.py", "setup.cfg", "package.xml"):
        shutil.copy(ROOT / name, folder / name)
    log = folder / "calls.log"
    bin_folder = folder / ".venv" / "bin"
    bin_folder.mkdir(parents=True)
    for name in ("python", "mech-regulator", "rerun"):
        (bin_folder / name).write_text(f'#!/bin/sh\necho "{name} $*" >> "{log}"\n')
        (bin_folder / name).chmod(0o755)
    log.write_text("")
    return log


def test_dev_installs_each_commands_extras_once_and_again_when_packaging_changes(tmp_path):
    log = _fake_venv_checkout(tmp_path)

    def dev(*arguments: str) -> tuple[list[str], str]:
        """Run ./dev; returns the calls it made and what it told on stderr."""
        before = log.read_text().splitlines()
        result = _run(["bash", str(tmp_path / "dev"), *arguments], cwd=tmp_path)
        return log.read_text().splitlines()[len(before) :], result.stderr

    calls, told = dev("run", "lathe", "--quiet")
    assert calls == ["python -m pip install -e .[ros]", "mech-regulator run lathe --quiet"]
    assert "setting up .venv for ./dev run: installing core + ROS wheels (first time only" in told, told
    calls, told = dev("run")
    assert calls == ["mech-regulator run engine_direct"] and told == ""
    calls, told = dev("rerun", "runs/lathe.rrd")  # core is in already
    assert calls == ["rerun runs/lathe.rrd"]
    calls, told = dev("test", "-k", "packaging")  # completes the venv of ./dev run
    assert calls == [
        "python -m pip install -e .[ros,test,colcon,bench,distributed]",
        "python -m pytest -q -n auto --dist loadfile -k packaging",
    ]
    assert told.startswith("completing .venv for ./dev test: installing the extras test colcon bench distributed"), told
    calls, _ = dev("test")
    assert calls == ["python -m pytest -q -n auto --dist loadfile"]
    calls, _ = dev("check")  # the same extras as test: nothing to install
    assert calls == ["python -m ruff check .", "python -m ruff format --check .", "python -m mypy"]
    calls, _ = dev("run")
    assert calls == ["mech-regulator run engine_direct"]

    with open(tmp_path / "setup.py", "a") as setup_py:
        setup_py.write("# changed\n")
    calls, told = dev("run")
    assert calls == ["python -m pip install -e .[ros]", "mech-regulator run engine_direct"]
    assert "setting up .venv for ./dev run" in told
    calls, _ = dev("test")
    assert calls[0] == "python -m pip install -e .[ros,test,colcon,bench,distributed]"
    assert len(list((tmp_path / ".venv" / ".installed").iterdir())) == 1, "markers of the old setup.py are left"
