"""ament_python package that also installs with plain `pip install -e .` where ROS is absent."""
import os
from glob import glob

from setuptools import find_packages, setup

package_name = "arm_sim_ros"


def share(subdir, pattern):
    return (os.path.join("share", package_name, subdir), sorted(glob(os.path.join(subdir, pattern))))


setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test", "benchmarks"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        share("config", "*.yaml"),
        share("config/scenes", "*.yaml"),
        share("launch", "*.launch.py"),
        share("urdf", "*.urdf"),
        share("urdf", "*.xml"),
        share("rviz", "*.rviz"),
    ],
    python_requires=">=3.11",
    # Pinned: what CI and the README install. On a ROS machine rosdep supplies numpy/yaml.
    install_requires=[
        "numpy==2.4.6",
        "PyYAML==6.0.3",
        "cyclonedds==11.0.1",
        "rerun-sdk==0.41.0",
        "rosbags==0.11.9",
        "scipy==1.17.1",         # the accuracy study's reference solutions
        "matplotlib==3.11.2",    # the accuracy study's plot
        "tqdm==4.70.1",          # progress on a terminal
    ],
    extras_require={
        "test": ["pytest==9.0.3", "hypothesis==6.155.2",
                 "pytest-xdist==3.8.0",    # the suite on every core (setup.cfg: -n auto)
                 "pandas==3.1.1"],         # the sweeps guide reads its table as a reader would
        "bench": ["mujoco==4.0.0"],
        "fit": ["dask==2026.8.0", "distributed==2026.8.0"],   # arm-sim fit --scheduler
        "fast": ["numba==0.68.1"],   # compiled rhs, steps and rollouts (physics/compiled/build.py)
    },
    zip_safe=True,
    maintainer="arm_sim_ros developers",
    maintainer_email="arm-sim@example.com",
    description="Planar two-link arm simulator node for ROS 2 Jazzy",
    license="Apache-2.0",
    tests_require=["pytest"],
    entry_points={
        "console_scripts": [
            "arm-sim = arm_sim_ros.tools.cli:main",
            "arm_sim_node = arm_sim_ros.node.entry:main",   # signals handled before the imports
            "arm_sim_controllers = arm_sim_ros.tools.control.follower:main",
        ],
        # the fixtures `arm` and `arm_node` in every pytest run (arm_sim_ros/testing)
        "pytest11": ["arm_sim_ros = arm_sim_ros.testing.plugin"],
    },
)
