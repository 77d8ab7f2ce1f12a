"""Packaging for both worlds: colcon/ament_python (ROS install) and pip (venv with ROS wheels from PyPI).

colcon ignores ``install_requires``; ROS and system dependencies are declared in package.xml.
pip-world dependencies live in extras: ``pip install .[wheels,test]`` (or ``-e``), see scripts/setup_env.sh.
Never list ``ros-*`` wheels in ``install_requires``: they would shadow an apt ROS install.
"""

import re
from glob import glob
from pathlib import Path

from setuptools import find_packages, setup

PACKAGE = "bldc_actuator"
HERE = Path(__file__).resolve().parent
VERSION = re.search(
    r'^__version__\s*=\s*"([^"]+)"', (HERE / PACKAGE / "__init__.py").read_text(), re.M
).group(1)

# Physics, offline simulation, recordings and plots: everything but ROS itself.
SIM = [
    "numpy>=1.24",
    "scipy>=1.10",
    "PyYAML>=6.0",
    "mcap>=1.2",
    "mcap-ros2-support>=0.5",
    "matplotlib>=3.6",
    # compiles the physics kernel (bldc_actuator/kernel.py); without it the same source runs as plain Python
    "numba>=0.60",
    # bldc-actuator fleet: Dask (local cluster or a scheduler), Parquet tables, progress bar
    "dask[distributed]>=2023.1",
    "pyarrow>=12",
    "tqdm>=4.60",
]
# rclpy and the message packages as PyPI wheels (ROS 2 Kilted builds); for a venv without a ROS install.
ROS_WHEELS = [
    "ros-rclpy>=9.1",
    "ros-rmw-fastrtps-cpp>=9.3",
    "ros-std-msgs>=5.5",
    "ros-sensor-msgs>=5.5",
    "ros-diagnostic-msgs>=5.5",
    "ros-rosgraph-msgs>=2.3",
]
# bldc_actuator.mujoco (CoupledSim, export-mujoco): MuJoCo bodies driven by the actuator model; 4.0 has <dcmotor>
MUJOCO = ["mujoco>=4.0"]
TEST = MUJOCO + [
    "pytest>=7.0",
    "pytest-timeout>=2.1",
    "pytest-xdist>=3.0",
    "rosbags>=0.11",
    "colcon-common-extensions>=0.3",
    "PyYAML>=6.0",
]

setup(
    name=PACKAGE,
    version=VERSION,
    packages=find_packages(exclude=["test", "test.*", "benchmarks", "benchmarks.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", sorted(glob("config/*.yaml")) + sorted(glob("config/*.xml"))),
        (f"share/{PACKAGE}/config/foxglove", sorted(glob("config/foxglove/*.json"))),
        (f"share/{PACKAGE}/config/input_profiles", sorted(glob("config/input_profiles/*.yaml"))),
    ],
    install_requires=["setuptools"],
    extras_require={"sim": SIM, "wheels": SIM + ROS_WHEELS, "mujoco": MUJOCO, "test": TEST},
    python_requires=">=3.10",
    zip_safe=True,
    maintainer="bldc_actuator maintainers",
    maintainer_email="maintainers@users.noreply.h-seed-3f52e93b.example",
    description="Virtual BLDC/PMSM actuator: q-axis model, ROS 2 node, simulator and diagnosis tool.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "bldc-actuator = bldc_actuator.cli:main",
            "actuator_node = bldc_actuator.node:main",
        ],
    },
)
