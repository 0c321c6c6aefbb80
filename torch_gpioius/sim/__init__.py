"""Simulated worlds behind the exploration loop's interfaces, each registered by name
(:mod:`torch_gpioius.exploration.registry`): ``planar``, the 2-D polygon world (Sec. V); ``forcefield``, Sec. VI in
3-D with a kinematic UR5, a static force-field cover and a ray-cast depth camera; and ``mujoco``, a UR5 with a
fingertip force sensor on MuJoCo's contact physics with cloth and foam covers (the optional extra ``mujoco``)."""

from ..core.validation import as_bounds
from .forcefield import (
    ROBOT_STUDY_DEFAULTS,
    Scene3D,
    estimate_metrics_3d,
    paper_objects_3d,
    simulated_ur5,
    sphere_scene,
)
from .plane import (PlanarCamera, PlanarContact, PlanarForceSensor, PlanarGate, PlanarRobot, PlanarView, Scene2D,
                    paper_objects_2d, rectangle)
from .shapes3d import MeshSDF, capsule, mesh_from_sdf, offset, rounded_box, smooth_union

__all__ = ["as_bounds", "Scene2D", "paper_objects_2d", "rectangle", "PlanarCamera", "PlanarContact",
           "PlanarForceSensor", "PlanarGate", "PlanarRobot", "PlanarView", "Scene3D", "paper_objects_3d",
           "sphere_scene", "simulated_ur5", "estimate_metrics_3d", "ROBOT_STUDY_DEFAULTS", "MeshSDF", "capsule",
           "mesh_from_sdf", "offset", "rounded_box", "smooth_union", "MujocoScene"]


def __getattr__(name):
    # MuJoCo is an optional extra: `import torch_gpioius.sim` works without it; using the world names the extra.
    if name == "MujocoScene":
        from .mujoco import MujocoScene

        return MujocoScene
    if name == "mujoco_objects_3d":
        from .mujoco import mujoco_objects_3d

        return mujoco_objects_3d
    raise AttributeError(f"module 'torch_gpioius.sim' has no attribute {name!r}")
