"""The sphere the simulated camera's tests look at: radius ``R`` about ``C``, seen from ``EYE`` by a half-resolution
Kinect (the closed forms they check against are a sphere's)."""

import numpy as np
import trimesh

from torch_gpioius.sensors import PinholeCamera, SimulatedDepthCamera, look_at

C, R = np.array([0.5, 0.0, 0.25]), 0.1
EYE = np.array([0.5, -0.8, 0.9])


def sphere_camera(**kw) -> SimulatedDepthCamera:
    """A simulated camera at ``EYE`` looking at the sphere (``kw``: the camera's own keywords)."""
    mesh = trimesh.creation.icosphere(subdivisions=5, radius=R)
    mesh.apply_translation(C)
    return SimulatedDepthCamera(mesh, PinholeCamera.kinect_v2(0.5), look_at(EYE, C), **kw)
