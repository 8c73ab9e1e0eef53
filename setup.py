"""mech_regulator: an ament_python ROS 2 package that also installs with plain pip."""

from glob import glob

from setuptools import find_packages, setup

package_name = "mech_regulator"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{package_name}"]),
        (f"share/{package_name}", ["package.xml"]),
        (f"share/{package_name}/config/scenes", glob("config/scenes/*.yaml")),
        (f"share/{package_name}/config/params", glob("config/params/*.yaml") + glob("config/params/*.xml")),
        (f"share/{package_name}/config/schema", glob("config/schema/*.json")),
        (f"share/{package_name}/launch", glob("launch/*.launch.py")),
        (f"lib/{package_name}", ["examples/pid_governor.py"]),  # `ros2 run mech_regulator pid_governor.py`
    ],
    python_requires=">=3.10",
    install_requires=[
        "numpy>=1.26",
        "scipy>=1.11",
        "pyyaml>=6.0",
        "pydantic>=2.6",
        "rerun-sdk>=0.41,<0.42",
        "matplotlib>=3.8",
        "tqdm>=4.66",
        "numba>=0.60",
        "sympy>=1.12",
        "mcap-ros2-support>=0.5",  # and with it mcap, the MCAP library
    ],
    extras_require={
        # ruff and mypy: the checks of .ci/run, pinned to a minor version (a newer one may find more)
        "test": ["pytest>=8", "pytest-xdist>=3.5", "jsonschema>=4", "ruff>=0.17,<0.18", "mypy>=2.4,<2.5"],
        "colcon": ["colcon-common-extensions", "catkin-pkg", "ros-ament-package", "setuptools<80"],
        "distributed": ["dask[distributed]>=2024.1"],
        "bench": ["mujoco>=3.1", "psutil>=5.9"],
        "ros": [
            "ros-kilted-rclpy",
            "ros-kilted-rmw-fastrtps-cpp",
            "ros-kilted-std-msgs",
            "ros-kilted-std-srvs",
            "ros-sensor-msgs",
            "ros-geometry-msgs",
            "ros-rosgraph-msgs",
            "ros-diagnostic-msgs",
        ],
    },
    zip_safe=True,
    maintainer="mech_regulator developers",
    maintainer_email="mech-regulator@example.org",
    description="Real motion of machines and the regulation of their speed (theory of machines)",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "mech-regulator = mech_regulator.cli:entry",
            "machine_node = mech_regulator.nodes.machine:main",
            "governor_node = mech_regulator.nodes.governor:main",
            "scenario_node = mech_regulator.nodes.scenario:main",
            "recorder_node = mech_regulator.nodes.recorder:main",
        ],
    },
)
