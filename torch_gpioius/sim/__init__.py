"""Simulated worlds: 2-D polygons (Sec. V) and 3-D meshes with a depth camera and a robot (Sec. VI)."""

from .scene2d import Scene2D, paper_objects_2d, rectangle
from .scene3d import Scene3D, paper_objects_3d, sphere_scene
from .shapes3d import MeshSDF, capsule, mesh_from_sdf, offset, rounded_box, smooth_union

__all__ = ["Scene2D", "paper_objects_2d", "rectangle", "Scene3D", "paper_objects_3d", "sphere_scene", "MeshSDF",
           "capsule", "mesh_from_sdf", "offset", "rounded_box", "smooth_union"]
