"""The MuJoCo world (optional extra ``mujoco``): a UR5 generated from the project's DH table with a compliant
fingertip force sensor, rigid inner objects from primitives, and cloth or foam covers on MuJoCo's contact physics."""

from .covers import COVER_KINDS, CoverMesh, cap_base, make_cover, shrink_wrap, tube_base
from .hardware import MujocoDepthCamera, MujocoForceSensor, MujocoInstability, MujocoPhysics, MujocoUR5
from .objects import OBJECTS, arm_primitives, mujoco_objects_3d, torso_primitives
from .primitives import Primitive, as_primitives, capsule_between, rounded_box_primitives, union_sdf
from .scene import MUJOCO_DEFAULTS, MujocoScene
from .ur5 import ur5_mjcf
from ...exploration.registry import register_world

register_world("mujoco", MujocoScene, objects=lambda names, smoke: mujoco_objects_3d(names, smoke=smoke),
               object_names=tuple(OBJECTS),
               description="Sec. VI on MuJoCo: a simulated UR5, cloth and foam covers the fingertip pushes aside "
                           "(objects E-H)")

__all__ = ["MujocoScene", "MUJOCO_DEFAULTS", "mujoco_objects_3d", "arm_primitives", "torso_primitives", "OBJECTS",
           "COVER_KINDS", "CoverMesh", "cap_base", "make_cover", "shrink_wrap", "tube_base", "MujocoDepthCamera",
           "MujocoForceSensor", "MujocoInstability", "MujocoPhysics", "MujocoUR5", "Primitive", "as_primitives",
           "capsule_between", "rounded_box_primitives", "union_sdf", "ur5_mjcf"]
