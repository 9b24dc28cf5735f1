"""The simulator's plant parameters: ``plant`` and MuJoCo's ``mujoco.*``, as data.

Part of ``hand_sim_node``'s section (:data:`grasp_safety_filter.io.schemas.HAND_SIM_PARAMETERS`).
The ``mujoco.*`` defaults are MuJoCo's own (unless said) and are the defaults of
:class:`hand_sim_node.mjcf.MjcfOptions`, which reads them from here. All are read-only: the
plant is built once, at start-up.
"""

from __future__ import annotations

from grasp_safety_filter.io.parameters import ParameterSpec, ParameterType

#: Our rigid rolling-contact model (the paper's plant).
RIGID_PLANT = 'rigid'
#: MuJoCo: soft contacts with Coulomb friction (the optional ``mujoco`` package).
MUJOCO_PLANT = 'mujoco'
#: The plants ``hand_sim_node`` can simulate.
PLANTS = (RIGID_PLANT, MUJOCO_PLANT)

#: MuJoCo's friction cones.
MUJOCO_CONES = ('pyramidal', 'elliptic')
#: MuJoCo's integrators (MJCF spelling).
MUJOCO_INTEGRATORS = ('Euler', 'RK4', 'implicit', 'implicitfast')

# fmt: off
PLANT_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec(
        'plant', ParameterType.STRING, RIGID_PLANT,
        "Plant simulated: rigid (our rolling-contact model, the paper's) or mujoco (MuJoCo "
        'soft contacts from the same URDF and scenario; needs the mujoco package); same '
        'topics either way, mujoco adds contact-lost, object-dropped and slip-distance '
        'values to /diagnostics',
        choices=PLANTS, read_only=True,
    ),
    ParameterSpec(
        'mujoco.friction_coefficient', ParameterType.DOUBLE, 0.0,
        "MuJoCo's sliding friction mu of every fingertip-object contact; 0: each contact's "
        "model.friction_coefficient (the filter's) [-]",
        min_value=0.0, read_only=True,
    ),
    ParameterSpec(
        'mujoco.torsional_friction', ParameterType.DOUBLE, 0.005,
        'Torsional friction, used with condim 4 and 6 [m]',
        min_value=0.0, exclusive_min=True, read_only=True,
    ),
    ParameterSpec(
        'mujoco.rolling_friction', ParameterType.DOUBLE, 0.0001,
        'Rolling friction, used with condim 6 [m]',
        min_value=0.0, exclusive_min=True, read_only=True,
    ),
    ParameterSpec(
        'mujoco.cone', ParameterType.STRING, 'pyramidal',
        'Friction cone: pyramidal or elliptic',
        choices=MUJOCO_CONES, read_only=True,
    ),
    ParameterSpec(
        'mujoco.condim', ParameterType.INTEGER, 3,
        'Contact dimensionality: 1 (frictionless), 3 (+ tangential), 4 (+ torsional), '
        '6 (+ rolling) [-]',
        min_value=1, max_value=6, read_only=True,
    ),
    ParameterSpec(
        'mujoco.solref', ParameterType.DOUBLE_ARRAY, [0.02, 1.0],
        'Contact (timeconst, dampratio); smaller timeconst is stiffer and needs timestep <= '
        'timeconst / 2 [s, -]',
        length=2, min_value=0.0, read_only=True,
    ),
    ParameterSpec(
        'mujoco.solimp', ParameterType.DOUBLE_ARRAY, [0.9, 0.95, 0.001, 0.5, 2.0],
        'Contact impedance (dmin, dmax, width, midpoint, power) [-, -, m, -, -]',
        length=5, min_value=0.0, read_only=True,
    ),
    ParameterSpec(
        'mujoco.impratio', ParameterType.DOUBLE, 1.0,
        'Frictional to normal constraint impedance ratio; larger is stiffer friction '
        '(advised with the elliptic cone) [-]',
        min_value=0.0, exclusive_min=True, read_only=True,
    ),
    ParameterSpec(
        'mujoco.noslip_iterations', ParameterType.INTEGER, 0,
        "Iterations of MuJoCo's no-slip post-solver; 0: off (soft friction creeps under a "
        'steady tangential load) [-]',
        min_value=0, read_only=True,
    ),
    ParameterSpec(
        'mujoco.timestep', ParameterType.DOUBLE, 0.001,
        "MuJoCo's step, a whole fraction of time_step (not MuJoCo's default 0.002 s: the "
        'control period is 1 ms) [s]',
        min_value=0.0, exclusive_min=True, read_only=True,
    ),
    ParameterSpec(
        'mujoco.integrator', ParameterType.STRING, 'Euler',
        "MuJoCo's integrator: Euler (semi-implicit), RK4, implicit or implicitfast",
        choices=MUJOCO_INTEGRATORS, read_only=True,
    ),
    ParameterSpec(
        'mujoco.joint_limits', ParameterType.BOOL, True,
        "The URDF's joint limits are hard stops in MuJoCo, as on a real hand (the rigid plant "
        'has none)',
        read_only=True,
    ),
)
# fmt: on
