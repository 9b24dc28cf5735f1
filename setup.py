from glob import glob

from setuptools import find_packages, setup

package_name = "grasp_safety_filter"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/launch", glob("launch/*.launch.py")),
        ("share/" + package_name + "/config", glob("config/*.yaml") + glob("config/*.urdf")),
    ],
    # Runtime dependencies for a pip install without ROS; under colcon they come from
    # package.xml (rosdep) and osqp from pip.
    install_requires=[
        "setuptools",
        "numpy>=1.24",
        "osqp>=1.0",
        "pin>=3.0",
        "rosbags>=0.10",
        "pyyaml>=6.0",
        "matplotlib>=3.6",
    ],
    extras_require={
        "test": ["pytest>=7", "ruff>=0.6", "flake8>=7", "pydocstyle>=6", "daqp>=0.6"],
        "bench": ["cvxpy>=1.4", "qpsolvers>=4.0", "daqp>=0.6"],
    },
    python_requires=">=3.10",
    zip_safe=True,
    maintainer="grasp_safety_filter maintainers",
    maintainer_email="maintainers@users.noreply.github.com",
    description="CBF-QP safety filter keeping an object in a robotic hand's grasp (ROS 2 Jazzy).",
    license="Apache-2.0",
    tests_require=["pytest"],
    entry_points={
        "console_scripts": [
            "grasp-model-report = grasp_safety_filter.cli:model_report_main",
        ],
    },
)
