"""The MuJoCo world (optional extra ``mujoco``): a UR5 generated from the project's DH table with a compliant
fingertip force sensor, rigid inner objects from primitives, and cloth or foam covers on MuJoCo's contact physics."""

from .covers import COVER_KINDS, CoverMesh, cap_base, make_cover, shrink_wrap, tube_base
from .hardware import MujocoDepthCamera, MujocoForceSensor, MujocoInstability, MujocoPhysics, MujocoUR5
from .objects import OBJECTS, arm_primitives, mujoco_objects_3d, torso_primitives
from .primitives import Primitive, as_primitives, capsule_between, rounded_box_primitives, union_sdf
from .scene import MUJOCO_DEFAULTS, MujocoScene
from .ur5 import ur5_mjcf
from ...exploration.registry import SceneSupport, register_world
from ...sensors.registry import register_sensor

register_sensor("mujoco_force", MujocoForceSensor, measures="force", hardware=False,
                description="the fingertip's contact force in MuJoCo's physics")
register_sensor("mujoco_depth_camera", MujocoDepthCamera, measures="cloud", hardware=False,
                description="a depth camera rendered by MuJoCo")


def _scene_from_file(mesh, kind: str, *, name: str, where: dict, cover: dict, settings: dict, preset: str | None,
                     smoke: bool) -> MujocoScene:
    """A scene file's world (:mod:`torch_gpioius.sim.scenefile`): :meth:`MujocoScene.from_mesh` with the file's
    values, approached from above where the file gives no approach; ``preset`` brings that preset's defaults and
    views for this body, the file's inside depths then apply on top; ``smoke`` coarsens the cover to 4 cm."""
    import numpy as np

    from ..forcefield import approach_from_above
    from ..presets import INSIDE_SETTINGS, settings_for, with_inside_depths

    where, settings = dict(where), dict(settings)
    if "start" not in where or "bounds" not in where:
        s, d, b = approach_from_above(mesh, mesh, clearance=0.12)     # above a cover of up to 4 cm
        where.setdefault("start", s)
        where.setdefault("direction", d)
        where.setdefault("bounds", b + np.array([[-0.03], [0.03]]) * np.array([1, 1, 0]))
    if smoke:
        settings["spacing"] = max(settings.get("spacing", 0.025), 0.04)
    if preset is not None:                          # the preset's defaults and views for this body
        settings.update(settings_for(preset, mesh, MUJOCO_DEFAULTS))
    depths = {k: settings.pop(k) for k in INSIDE_SETTINGS if k in settings}
    if depths:                                      # the inside points' depths on the world's (or preset's) policy
        settings["defaults"] = with_inside_depths(settings.get("defaults", MUJOCO_DEFAULTS), **depths)
    return MujocoScene.from_mesh(mesh, kind, name=name, **where, **cover, **settings)


#: What a scene file's ``[cover]`` and ``[mujoco]`` sections may hold in this world.
SCENE_SUPPORT = SceneSupport(
    cover_keys=frozenset({"gap", "slack", "young", "poisson", "thickness", "pin", "damping", "density", "radius"}),
    cover_kinds=COVER_KINDS,
    settings_keys=frozenset({"spacing", "base", "half_angle", "facing", "centre", "collision", "threshold",
                             "max_parts", "sensor_noise", "timestep", "settle_time", "camera_scale", "touch_inside",
                             "vision_inside", "vision_inside_gap", "cover_offset"}),
    build=_scene_from_file)

register_world("mujoco", MujocoScene, objects=lambda names, smoke: mujoco_objects_3d(names, smoke=smoke),
               object_names=tuple(OBJECTS), dimension=3, scene=SCENE_SUPPORT, presets=True,
               description="Sec. VI on MuJoCo: a simulated UR5, cloth and foam covers the fingertip pushes aside "
                           "(objects E-H)")

__all__ = ["MujocoScene", "MUJOCO_DEFAULTS", "mujoco_objects_3d", "arm_primitives", "torso_primitives", "OBJECTS",
           "COVER_KINDS", "CoverMesh", "cap_base", "make_cover", "shrink_wrap", "tube_base", "MujocoDepthCamera",
           "MujocoForceSensor", "MujocoInstability", "MujocoPhysics", "MujocoUR5", "Primitive", "as_primitives",
           "capsule_between", "rounded_box_primitives", "union_sdf", "ur5_mjcf"]
