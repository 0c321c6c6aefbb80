"""Objects E-H of the robot experiment rebuilt in MuJoCo with the dimensions of ``paper_objects_3d()``.

The inner objects are unions of primitives (MuJoCo collides meshes as convex hulls); the force-field world's smooth
blends at the elbow and shoulders become plain unions (a sphere fills the elbow). The covers are cloth:

* E, arm in a tight sleeve: a cloth tube 8 mm off the arm, pinned at the shoulder and the wrist;
* F, arm in a loose sleeve: a cloth tube built 3.5 cm off the arm (a 8.5 / 7.5 cm radius sleeve), pinned at both
  ends, that sags onto the arm under gravity;
* G, torso in a tight shirt: a cloth cap 8 mm off the front and top of the torso, pinned along its back edge;
* H, torso in a loose garment: a cloth cap built 7 cm off the torso (a poncho) that settles under gravity.

Start positions, approach directions and exploration ranges are those of ``paper_objects_3d()``.
"""

from __future__ import annotations

import math

import numpy as np

from .primitives import capsule_between, rounded_box_primitives
from .scene import MujocoScene

__all__ = ["mujoco_objects_3d", "arm_primitives", "torso_primitives", "OBJECTS"]

OBJECTS = ("E", "F", "G", "H")
_ELBOW = np.array([0.5, 0.02, 0.25])
_SHOULDER = np.array([0.5, -0.21, 0.25])
_HAND = _ELBOW + 0.19 * np.array([-math.sin(math.radians(18)), math.cos(math.radians(18)), 0.0])
ARM_RANGE = [[0.36, -0.24, 0.24], [0.66, 0.24, 0.42]]
TORSO_RANGE = [[0.34, -0.24, 0.10], [0.62, 0.24, 0.56]]


def arm_primitives() -> list[dict]:
    """The arm of E and F: upper arm (r = 5 cm) and forearm (r = 4 cm) capsules bent 18 deg, a sphere at the elbow."""
    return [capsule_between(_SHOULDER, _ELBOW, 0.05), capsule_between(_ELBOW, _HAND, 0.04),
            {"type": "sphere", "size": (0.05,), "pos": tuple(_ELBOW)}]


def torso_primitives() -> list[dict]:
    """The torso of G and H: chest (rounded box 18 x 30 x 36 cm, 6 cm edges), shoulders and neck capsules."""
    return (rounded_box_primitives((0.62, 0.0, 0.24), (0.09, 0.15, 0.18), 0.06)
            + [capsule_between((0.62, -0.14, 0.40), (0.62, 0.14, 0.40), 0.06),
               capsule_between((0.62, 0.0, 0.42), (0.62, 0.0, 0.53), 0.045)])


def mujoco_objects_3d(objects=OBJECTS, *, smoke: bool = False, seed: int = 0, **scene_kw) -> dict[str, MujocoScene]:
    """Objects E-H (a subset with ``objects``) as :class:`MujocoScene` worlds.

    Args:
        objects: names among E-H.
        smoke: coarser cloth (4 cm spacing) and a quarter-resolution camera, for CI.
        seed: sensor and camera noise seed.
        **scene_kw: forwarded to :meth:`MujocoScene.from_primitives`.
    """
    unknown = [o for o in objects if o not in OBJECTS]
    if unknown:
        raise ValueError(f"objects: unknown {unknown}; choose among {list(OBJECTS)}")
    spacing = 0.04 if smoke else 0.025
    kw = dict(seed=seed, camera_scale=0.25 if smoke else 0.5, **scene_kw)
    arm_axis = [_SHOULDER - [0.0, 0.03, 0.0], _ELBOW, _HAND + 0.03 * (_HAND - _ELBOW) / np.linalg.norm(_HAND - _ELBOW)]
    arm = dict(start=(0.51, -0.06, 0.45), direction=(0.0, 0.0, -1.0), bounds=ARM_RANGE, axis=arm_axis, base="tube",
               spacing=spacing)
    torso = dict(start=(0.34, 0.03, 0.27), direction=(1.0, 0.0, 0.0), bounds=TORSO_RANGE, base="cap",
                 centre=(0.62, 0.0, 0.30), facing=(-1.0, 0.0, 0.35), half_angle=95.0, spacing=spacing)
    make = {
        "E": lambda: MujocoScene.from_primitives(arm_primitives(), "tight", name="E", gap=0.008, **arm, **kw),
        "F": lambda: MujocoScene.from_primitives(arm_primitives(), "loose", name="F", slack=0.035, **arm, **kw),
        "G": lambda: MujocoScene.from_primitives(torso_primitives(), "tight", name="G", gap=0.008, **torso, **kw),
        "H": lambda: MujocoScene.from_primitives(torso_primitives(), "loose", name="H", slack=0.07, **torso, **kw),
    }
    return {name: make[name]() for name in objects}
