"""The UR5 (CB3) as MJCF, generated from the project's own DH table and Universal Robots' published link masses and
centres of mass (``kinematics.dh``), with capsule collision geometry and a fingertip force sensor.

Generated rather than taken from ``mujoco-menagerie`` (which downloads at run time): the same DH table defines the
project's FK/IK (``kinematics.UR5``) and this model, and a test holds their fingertip poses equal.

Body tree (the URDF's): ``link_i`` sits at ``Trans(a_{i-1}, 0, d_{i-1}) Rot_x(alpha_{i-1})`` in its parent and turns
about its z axis (joint ``q_i``); the DH frame ``i`` is ``link_i`` composed with ``Trans_z(d_i) Trans_x(a_i)
Rot_x(alpha_i)``, where UR's centres of mass are given. Inertia tensors are not published: each link's is that of a
uniform cylinder of its length and a radius of the real link's size, about its centre of mass.

The fingertip: a sphere of radius ``tip_radius`` at ``tool_offset`` in the flange frame, on a body mounted on the
flange by three spring-loaded slide joints (``tip_stiffness`` per axis, the compliance of the OptoForce's silicone
dome: a rigid fingertip on a stiff arm would turn each millimetre of pressing into ~200 N); the force sensor reads
the mount's deflection (``MujocoForceSensor``), in the tool frame (the OptoForce's frame). Joints are
position-controlled servos (``kp``, ``kv``), with gravity compensation and rotor inertia (armature), as the UR's own
joint controllers hold the arm.
"""

from __future__ import annotations

import math

import numpy as np

from kinematics.dh import UR5_DH, UR5_JOINT_LIMITS, UR5_JOINT_NAMES, UR5_LINK_COMS, UR5_LINK_MASSES

__all__ = ["ur5_mjcf", "LINK_RADII", "ROBOT_GROUP"]

#: Collision radius of each link's capsule [m] (the UR5's casting diameters, about 12 cm shoulder to 8 cm wrist).
LINK_RADII = (0.06, 0.06, 0.05, 0.045, 0.045, 0.04)
#: Geom group of the robot (the camera's rays skip it).
ROBOT_GROUP = 2


def _quat_rotx(angle: float) -> str:
    return f"{math.cos(angle / 2):.17g} {math.sin(angle / 2):.17g} 0 0"


def _vec(v) -> str:
    return " ".join(f"{float(x):.17g}" for x in v)


def _link_inertial(i: int) -> str:
    """``<inertial>`` of link i (0-based) in its body frame: UR's mass and centre of mass, a cylinder's inertia."""
    row = UR5_DH[i]
    ca, sa = math.cos(row.alpha), math.sin(row.alpha)
    com = np.array(UR5_LINK_COMS[i])
    rot = np.array([[1, 0, 0], [0, ca, -sa], [0, sa, ca]])
    pos = np.array([row.a, 0.0, row.d]) + rot @ com
    m = UR5_LINK_MASSES[i]
    length = max(abs(row.a), abs(row.d), 0.08)
    r = LINK_RADII[i]
    axial, transverse = m * r * r / 2, m * (3 * r * r + length * length) / 12
    # the long axis of links 2 and 3 (a != 0) is the DH x axis; of the others, the joint axis (z)
    diag = (axial, transverse, transverse) if abs(row.a) > 0 else (transverse, transverse, axial)
    return (f'<inertial pos="{_vec(pos)}" quat="{_quat_rotx(row.alpha)}" mass="{m:.17g}" '
            f'diaginertia="{_vec(diag)}"/>')


def _link_capsule(i: int) -> str:
    """A capsule around link i's span from its joint to the next joint (in the body frame), robot geom group."""
    row = UR5_DH[i]
    ca, sa = math.cos(row.alpha), math.sin(row.alpha)
    end = np.array([row.a, 0.0, row.d])
    start = np.zeros(3)
    if np.linalg.norm(end) < 0.05:      # wrist links: a short capsule along the joint axis
        end = np.array([0.0, 0.0, 0.04])
        start = np.array([0.0, 0.0, -0.02])
    del ca, sa
    return (f'<geom type="capsule" fromto="{_vec(start)} {_vec(end)}" size="{LINK_RADII[i]}" group="{ROBOT_GROUP}" '
            f'contype="0" conaffinity="0" rgba=".6 .65 .7 1"/>')


def ur5_mjcf(*, tool_offset=(0.0, 0.0, 0.05), tip_radius: float = 0.004, tip_mass: float = 0.02,
             tip_stiffness: float = 1000.0, tip_damping: float = 8.0,
             kp: float = 50000.0, kv: float = 600.0, armature: float = 0.5, base_pos=(0.0, 0.0, 0.0)) -> str:
    """The ``<worldbody>`` fragment, actuators and sensors of a UR5 (CB3) with a fingertip force sensor.

    Args:
        tool_offset: `(3,)` fingertip centre in the flange frame [m] (as ``kinematics.UR5(tool_offset=...)``).
        tip_radius: radius of the fingertip sphere [m].
        tip_mass: mass of the fingertip body [kg] (what the sensor carries; tared away in free space).
        tip_stiffness: stiffness of the fingertip's mount along each tool axis [N/m] (1 N per mm, as the force-field
            world's inner object: the 1-5 N contact band is 4 mm wide, several controller steps).
        tip_damping: damping of the mount [N s/m].
        kp: position gain of each joint servo [N m / rad]; kv: its damping [N m s / rad].
        armature: rotor inertia reflected through each gearbox [kg m^2].
        base_pos: `(3,)` position of the robot base in the world [m] (the base frame is the world frame).

    Returns:
        ``(body_xml, actuator_xml, sensor_xml)`` strings to place in the ``<worldbody>``, ``<actuator>`` and
        ``<sensor>`` elements of an MJCF model. Names: joints ``UR5_JOINT_NAMES``, actuators ``servo_<joint>``,
        site ``ft_site``, sensor ``fingertip_force``, body ``fingertip``, geom ``fingertip``.
    """
    tool = np.asarray(tool_offset, dtype=np.float64)
    lines = [f'<body name="base_link" pos="{_vec(base_pos)}">',
             f'<geom type="cylinder" size="0.075 0.04" pos="0 0 0.04" group="{ROBOT_GROUP}" contype="0" '
             'conaffinity="0" rgba=".4 .4 .45 1"/>']
    closing = ["</body>"]
    prev = None
    for i, (name, row) in enumerate(zip(UR5_JOINT_NAMES, UR5_DH)):
        pos = (0.0, 0.0, 0.0) if prev is None else (prev.a, 0.0, prev.d)
        quat = "1 0 0 0" if prev is None else _quat_rotx(prev.alpha)
        lo, hi = UR5_JOINT_LIMITS[i]
        lines += [f'<body name="link_{i + 1}" pos="{_vec(pos)}" quat="{quat}" gravcomp="1">',
                  _link_inertial(i),
                  f'<joint name="{name}" type="hinge" axis="0 0 1" range="{lo:.17g} {hi:.17g}" limited="true" '
                  f'armature="{armature}" damping="1"/>',
                  _link_capsule(i)]
        closing.append("</body>")
        prev = row
    lines += [f'<body name="flange" pos="{_vec((prev.a, 0.0, prev.d))}" quat="{_quat_rotx(prev.alpha)}" gravcomp="1">',
              '<inertial pos="0 0 0.01" mass="0.05" diaginertia="1e-5 1e-5 1e-5"/>',
              f'<geom type="cylinder" size="0.012 {max(tool[2] - tip_radius, 0.002) / 2:.6g}" '
              f'pos="{_vec((tool[0], tool[1], max(tool[2] - tip_radius, 0.002) / 2))}" group="{ROBOT_GROUP}" '
              'contype="0" conaffinity="0" rgba=".2 .2 .2 1"/>',
              f'<body name="fingertip" pos="{_vec(tool)}" gravcomp="1">',
              f'<inertial pos="0 0 0" mass="{tip_mass}" diaginertia="1e-6 1e-6 1e-6"/>',
              *[f'<joint name="tip_{a}" type="slide" axis="{ax}" stiffness="{tip_stiffness}" damping="{tip_damping}" '
                'range="-0.012 0.012" limited="true" armature="0.01"/>'
                for a, ax in (("x", "1 0 0"), ("y", "0 1 0"), ("z", "0 0 1"))],
              '<site name="ft_site" pos="0 0 0" size="0.002"/>',
              f'<geom name="fingertip" type="sphere" size="{tip_radius}" contype="1" conaffinity="1" condim="3" '
              'friction="0.3 0.005 0.0001" solref="0.004 1" rgba=".9 .3 .1 1"/>',
              "</body>", "</body>"]
    lines += closing[::-1]
    actuators = "\n".join(f'<position name="servo_{n}" joint="{n}" kp="{kp}" kv="{kv}" ctrlrange="{lo} {hi}" '
                          f'ctrllimited="true"/>' for n, (lo, hi) in zip(UR5_JOINT_NAMES, UR5_JOINT_LIMITS))
    sensors = '<force name="fingertip_force" site="ft_site"/>'
    return "\n".join(lines), actuators, sensors
