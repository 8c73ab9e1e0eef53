"""Packaging: a colcon (ament_python) build that works without ROS, the pip console script and
`python -m`, and package.xml agreeing with setup.py and mech_regulator.__version__."""

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

import mech_regulator

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "mech_regulator"
EXECUTABLE = "mech-regulator"
BUNDLED = sorted(path.stem for path in (ROOT / "config" / "scenes").glob("*.yaml"))


def _run(command: list[str], timeout: float = 60, **kwargs) -> subprocess.CompletedProcess:
    """Run a command, failing the test with its output when it exits non-zero."""
    result = subprocess.run(command, capture_output=True, text=True, timeout=timeout, **kwargs)
    assert result.returncode == 0, (f"{' '.join(map(str, command))} exited {result.returncode}\n"
                                    f"--- stdout\n{result.stdout[-3000:]}\n--- stderr\n{result.stderr[-3000:]}")
    return result


def _assert_lists_bundled_scenes(output: str) -> None:
    assert BUNDLED, "no config/scenes/*.yaml in the source tree"
    listed = [line.split()[0] for line in output.splitlines() if line.strip()]
    assert listed == BUNDLED, f"expected the bundled scenes {BUNDLED}, got:\n{output}"


def _colcon() -> str:
    """The colcon command of this Python environment; skip the test when it is not installed."""
    missing = [name for name in ("colcon_core", "colcon_ros", "catkin_pkg", "ament_package")
               if importlib.util.find_spec(name) is None]
    if missing:
        pytest.skip(f"colcon is not installed in this Python ({', '.join(missing)} not importable); "
                    f"install it with: pip install -e '.[test,colcon]'")
    colcon = shutil.which("colcon", path=str(Path(sys.executable).parent)) or shutil.which("colcon")
    if colcon is None:
        pytest.skip("colcon_core is importable but no `colcon` executable is next to sys.executable or on PATH")
    return colcon


@pytest.fixture(scope="module")
def colcon_install(tmp_path_factory) -> Path:
    """The package built by colcon (ament_python) into a temporary install base; returns its prefix."""
    colcon = _colcon()
    folder = tmp_path_factory.mktemp("colcon")
    env = dict(os.environ, COLCON_HOME=str(folder / "colcon_home"),  # no user defaults.yaml
               PATH=os.pathsep.join([str(Path(sys.executable).parent), os.environ.get("PATH", "")]))
    install = folder / "install"
    _run([colcon, "--log-base", str(folder / "log"), "build", "--base-paths", str(ROOT),
          "--packages-select", PACKAGE, "--build-base", str(folder / "build"), "--install-base", str(install)],
         timeout=180, cwd=folder, env=env)
    return install / PACKAGE


def _install_python_path(prefix: Path) -> str:
    """PYTHONPATH for the colcon install without ROS: what its setup scripts would set up."""
    site_packages = [path for path in prefix.glob("lib/python*/site-packages") if (path / PACKAGE).is_dir()]
    assert len(site_packages) == 1, f"no single {PACKAGE} under {prefix}/lib/python*/site-packages"
    return os.pathsep.join([str(site_packages[0]), *filter(None, [os.environ.get("PYTHONPATH")])])


def test_colcon_build_installs_a_working_executable(colcon_install, tmp_path):
    prefix = colcon_install
    executable = prefix / "lib" / PACKAGE / EXECUTABLE  # where `ros2 run mech_regulator mech-regulator` looks
    assert executable.is_file() and os.access(executable, os.X_OK), \
        f"no executable {executable}; lib/ holds {sorted(str(p.relative_to(prefix)) for p in (prefix / 'lib').rglob('*'))}"
    assert (prefix / "share" / "ament_index" / "resource_index" / "packages" / PACKAGE).is_file()
    assert (prefix / "share" / PACKAGE / "package.xml").is_file()
    share_config = prefix / "share" / PACKAGE / "config"
    assert sorted(path.stem for path in (share_config / "scenes").glob("*.yaml")) == BUNDLED
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
    where = _run([sys.executable, "-c", "import mech_regulator.scene.loading as m; print(m.__file__); print(m.config_dir())"],
                 cwd=tmp_path, env=run_env).stdout.split("\n")
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
    assert root.tag == "package" and root.get("format") == "3", "package.xml must be <package format=\"3\">"
    assert root.findtext("name") == PACKAGE
    assert root.findtext("export/build_type") == "ament_python"
    version = root.findtext("version")
    assert version == _setup_py_version() == mech_regulator.__version__, (
        f"versions differ: package.xml {version}, setup.py {_setup_py_version()}, "
        f"mech_regulator.__version__ {mech_regulator.__version__}")
    assert (ROOT / "resource" / PACKAGE).is_file(), "resource/mech_regulator is the ament index marker"


NODES = ("machine_node", "governor_node", "scenario_node", "recorder_node")


def test_colcon_install_runs_the_nodes(colcon_install, tmp_path):
    pytest.importorskip("rclpy", reason="the nodes need rclpy (pip install 'mech_regulator[ros]')")
    from ros_support import next_domain_id, ros_environment

    lib = colcon_install / "lib" / PACKAGE  # where `ros2 run mech_regulator machine_node` looks
    for node in NODES:
        assert (lib / node).is_file() and os.access(lib / node, os.X_OK), \
            f"no executable {lib / node}; {lib} holds {sorted(path.name for path in lib.iterdir())}"
    env = dict(ros_environment(next_domain_id()), PYTHONPATH=_install_python_path(colcon_install))
    machine = str(lib / "machine_node")
    missing = tmp_path / "missing.yaml"
    result = subprocess.run([machine, "--ros-args", "-p", f"scene_file:={missing}"], capture_output=True, text=True,
                            timeout=60, cwd=tmp_path, env=env, start_new_session=True)
    assert result.returncode == 2 and f"scene '{missing}': no such file" in result.stderr, \
        f"exit {result.returncode}\n{result.stdout}\n{result.stderr}"
    assert "Traceback" not in result.stderr
    # a short run of the ungoverned lathe, waiting for nobody
    result = _run([machine, "--ros-args", "-p", "scene_file:=lathe", "-p", "lockstep_inputs:=['']", "-p",
                   "min_subscribers:=0", "-p", "duration:=0.01"], cwd=tmp_path, env=env, start_new_session=True)
    assert "finished at t = 0.01 s: complete" in result.stdout + result.stderr, result.stderr
    where = _run([sys.executable, "-c", "import mech_regulator.nodes.machine as m; print(m.__file__)"],
                 cwd=tmp_path, env=env).stdout.strip()
    assert Path(where).is_relative_to(colcon_install), f"machine_node imported {where}, not the colcon install"
