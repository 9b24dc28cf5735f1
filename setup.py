from glob import glob

from setuptools import find_packages, setup

package_name = 'grasp_safety_filter'

setup(
    name=package_name,
    version='0.1.0',
    # The runtime (grasp_safety_filter, hand_sim_node: what the nodes import) and, apart,
    # the benchmarks and studies in tools/, installed as grasp_tools: never imported by the
    # runtime, run by their console scripts and ``python -m grasp_tools.<module>``.
    packages=[
        *find_packages(include=['grasp_safety_filter', 'grasp_safety_filter.*']),
        *find_packages(include=['hand_sim_node', 'hand_sim_node.*']),
        'grasp_tools',
        *(f'grasp_tools.{name}' for name in find_packages('tools')),
    ],
    package_dir={'grasp_tools': 'tools'},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
        ('share/' + package_name + '/config', glob('config/*.yaml') + glob('config/*.urdf')),
        ('share/' + package_name + '/config/campaigns', glob('config/campaigns/*.yaml')),
    ],
    # Runtime dependencies for a pip install without ROS; under colcon they come from
    # package.xml (rosdep), osqp and daqp from pip.
    install_requires=[
        'setuptools',
        'numpy>=1.24',
        'osqp>=1.0',
        'daqp>=0.11',  # the qp.solver=daqp backend: a warm-started daqp.Model
        'scipy>=1.8',  # sparse matrices for OSQP
        # The model's per-tick kernels (grasp_safety_filter/model/compiled.py); tested with
        # numba 0.68.1 on numpy 2.4.
        'numba>=0.68',
        'pin>=3.0',
        'rosbags>=0.10',
        'pyyaml>=6.0',
        'matplotlib>=3.6',
        'distributed>=2024.1',  # grasp-campaign's engine: local cores or a Dask cluster
        'tqdm>=4.60',  # grasp-campaign's progress bar
    ],
    extras_require={
        'test': [
            'pytest>=7',
            'pytest-xdist>=3.5',  # make test: two tests at a time
            'ruff>=0.6',
            # The linters a colcon build runs on Jazzy (ament_flake8 with its plugins, pep257).
            'ament-lint==0.14.2',
            'ament-lint-flake8==0.14.4',
            'ament-lint-pep257==0.14.3',
            'flake8-quotes==3.4.0',
            'flake8-import-order==0.19.2',
            'flake8-docstrings==1.7.0',
            'flake8-builtins==3.1.0',
            'flake8-comprehensions==3.17.0',
            'mujoco>=3.2',  # test/test_mujoco_*.py: the MuJoCo plant against our model
        ],
        # Real ROS 2 Jazzy rclpy and the message packages from the package index: the nodes
        # run and are tested over Fast DDS without a ROS install (no AMENT_PREFIX_PATH).
        'ros': [
            'ros-jazzy-rclpy[fastrtps]',
            'ros-jazzy-builtin-interfaces',
            'ros-jazzy-diagnostic-msgs',
            'ros-jazzy-geometry-msgs',
            'ros-jazzy-nav-msgs',
            'ros-jazzy-rcl-interfaces',
            'ros-jazzy-rosgraph-msgs',
            'ros-jazzy-sensor-msgs',
            'ros-jazzy-std-msgs',
            'ros-jazzy-trajectory-msgs',
            'ros-jazzy-visualization-msgs',
        ],
        # grasp-bench's comparison: the same QPs through cvxpy (OSQP, Clarabel) and daqp.
        'bench': ['cvxpy>=1.4', 'qpsolvers>=4.0'],
        # The MuJoCo plant (hand_sim_node.mujoco_plant): soft contacts, Coulomb friction.
        # Not 4.x only: mujoco 4 needs Python >= 3.11, the package supports 3.10.
        'mujoco': ['mujoco>=3.2'],
    },
    python_requires='>=3.10',
    zip_safe=True,
    maintainer='grasp_safety_filter maintainers',
    maintainer_email='maintainers@users.noreply.github.com',
    description="CBF-QP safety filter keeping an object in a robotic hand's grasp (ROS 2 Jazzy).",
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'grasp-demo = grasp_safety_filter.console:demo',
            'grasp-analyze = grasp_safety_filter.console:analyze',
            'grasp-bench = grasp_tools.bench:bench_main',
            'grasp-bench-ros = grasp_tools.bench_ros:bench_ros_main',
            'grasp-bench-realtime = grasp_tools.bench.real_time:main',
            'grasp-record = grasp_safety_filter.console:record',
            'grasp-campaign = grasp_safety_filter.console:campaign',
            'grasp-model-report = grasp_safety_filter.model_report:main',
            'hand_sim_node = grasp_safety_filter.nodes.entry_points:hand_sim_node',
            (
                'nominal_controller_node = '
                'grasp_safety_filter.nodes.entry_points:nominal_controller_node'
            ),
            'safety_filter_node = grasp_safety_filter.nodes.entry_points:safety_filter_node',
            'grasp_markers_node = grasp_safety_filter.nodes.entry_points:grasp_markers_node',
        ],
    },
)
