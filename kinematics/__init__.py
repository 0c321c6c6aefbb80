"""UR5 (CB3) kinematics and robot backends for torch_gpioius.

``UR5``: forward kinematics and Jacobians from the published DH table in closed form (``dh.dh_forward``, torch,
batched and differentiable; ``single``, NumPy for one joint vector), inverse kinematics on the bundled URDF (written
from the same table) with pytorch-kinematics, and a differentiable damped-least-squares Cartesian step. The backends
(``SimulatedUR5``, ``RTDEUR5``) execute motions behind one interface, every command through one
``SafetyGate``. See docs/robot.md.
"""

from .backends import RobotBackend, RTDEUR5, SimulatedUR5
from .dh import UR5_DH, UR5_JOINT_LIMITS, UR5_JOINT_NAMES, UR5_VELOCITY_LIMITS, ur5_urdf
from .safety import SafetyGate, SafetyViolation
from .ur5 import UR5, UnreachablePoseError, pose_error, tool_rotation

__all__ = ["UR5", "UnreachablePoseError", "pose_error", "tool_rotation", "SafetyGate", "SafetyViolation",
           "RobotBackend", "SimulatedUR5", "RTDEUR5", "UR5_DH", "UR5_JOINT_LIMITS", "UR5_JOINT_NAMES",
           "UR5_VELOCITY_LIMITS", "ur5_urdf"]
