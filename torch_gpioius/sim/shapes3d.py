"""3-D shapes for the simulated worlds: signed-distance primitives, blending, meshing, and a mesh SDF.

The paper's objects E-H (mannequin arm and torso under clothes) are composed from capsules and rounded boxes
with a smooth union (the "blend" that turns two capsules into an elbow), then meshed by marching cubes. Scenes
hold ``trimesh.Trimesh`` surfaces; the simulated force sensor reads a :class:`MeshSDF` of them, so a scene
built from any closed mesh (a scanned mannequin, a CAD model) works the same way.

Sign convention everywhere: distance < 0 inside, normals point outward.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
import torch
import trimesh
from skimage import measure

from ..core.validation import as_bounds

__all__ = ["capsule", "rounded_box", "smooth_union", "offset", "mesh_from_sdf", "MeshSDF", "SDF"]

#: A numpy signed-distance function: `(m, 3)` points [m] -> `(m,)` distances [m], negative inside.
SDF = Callable[[np.ndarray], np.ndarray]


def capsule(a, b, radius: float) -> SDF:
    """Capsule of ``radius`` [m] around the segment a-b (`(3,)` end points [m])."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    ab = b - a
    denom = float(ab @ ab)
    if radius <= 0 or denom == 0:
        raise ValueError("capsule: needs radius > 0 and distinct end points")

    def sdf(p: np.ndarray) -> np.ndarray:
        t = np.clip(((p - a) @ ab) / denom, 0.0, 1.0)
        return np.linalg.norm(p - (a + t[:, None] * ab), axis=1) - radius

    return sdf


def rounded_box(center, half_extents, radius: float) -> SDF:
    """Axis-aligned box with edges rounded by ``radius`` [m]; ``half_extents`` `(3,)` include the rounding."""
    c = np.asarray(center, dtype=np.float64)
    h = np.asarray(half_extents, dtype=np.float64) - radius
    if radius < 0 or (h <= 0).any():
        raise ValueError("rounded_box: half extents must exceed the rounding radius")

    def sdf(p: np.ndarray) -> np.ndarray:
        q = np.abs(p - c) - h
        outside = np.linalg.norm(np.maximum(q, 0.0), axis=1)
        inside = np.minimum(q.max(axis=1), 0.0)
        return outside + inside - radius

    return sdf


def smooth_union(*parts: SDF, k: float = 0.03) -> SDF:
    """Union blended over a width ``k`` [m] (polynomial smooth minimum; ``k = 0`` is the plain union)."""
    if not parts:
        raise ValueError("smooth_union: needs at least one shape")

    def sdf(p: np.ndarray) -> np.ndarray:
        d = parts[0](p)
        for f in parts[1:]:
            e = f(p)
            if k <= 0:
                d = np.minimum(d, e)
                continue
            h = np.clip(0.5 + 0.5 * (e - d) / k, 0.0, 1.0)
            d = e * (1 - h) + d * h - k * h * (1 - h)
        return d

    return sdf


def offset(shape: SDF, distance: float) -> SDF:
    """The shape grown by ``distance`` [m] (a cover of uniform thickness when applied to an object)."""
    return lambda p: shape(p) - distance


def mesh_from_sdf(sdf: SDF, bounds, resolution: float = 0.005) -> trimesh.Trimesh:
    """Triangle mesh of ``{sdf = 0}`` by marching cubes (scikit-image) on a regular grid.

    Args:
        sdf: the shape.
        bounds: `(2, 3)` box `[min corner; max corner]` [m]; must enclose the shape with at least one cell of margin.
        resolution: grid spacing [m].

    Returns:
        A closed ``trimesh.Trimesh`` [m] with outward normals.

    Raises:
        ValueError: the shape is empty or touches the bounds (the mesh would be open).
    """
    b = as_bounds(bounds, 3)
    axes = [np.arange(lo, hi + resolution / 2, resolution) for lo, hi in b.T]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    d = sdf(grid).reshape(tuple(len(a) for a in axes))
    if not (d.min() < 0 < d.max()):
        raise ValueError("mesh_from_sdf: the shape does not cross the grid (empty or larger than bounds)")
    faces_border = np.concatenate([d[[0, -1]].ravel(), d[:, [0, -1]].ravel(), d[:, :, [0, -1]].ravel()])
    if (faces_border <= 0).any():
        raise ValueError("mesh_from_sdf: the shape touches the bounds; enlarge them")
    verts, faces, _, _ = measure.marching_cubes(d, level=0.0, spacing=(resolution,) * 3,
                                                gradient_direction="descent")
    mesh = trimesh.Trimesh(vertices=verts + b[0], faces=faces, process=True)
    # marching cubes emits zero-area triangles where the surface passes through a grid node; they leave
    # edges with a single neighbour once their duplicate vertices are merged
    mesh.update_faces(mesh.nondegenerate_faces())
    mesh.remove_unreferenced_vertices()
    if not mesh.is_watertight:  # pragma: no cover - marching cubes of a bounded SDF is closed
        raise ValueError("mesh_from_sdf: the mesh is not closed")
    return mesh


class MeshSDF:
    """Signed distance to a closed triangle mesh, for the simulated force sensor (distance < 0 inside), with the
    outward normal the sensor's spring pushes along.

    The distance and the closest point come from :class:`torch_gpioius.sim.meshes.MeshDistance` (libigl's AABB tree,
    built once; signed by the pseudo-normal at the closest point, exact for closed meshes, Baerentzen & Aanaes
    2005): about 0.1 ms a point, for a sensor read every millimetre of motion. The normal is the unit offset from the
    closest point, outwards (the closest face's normal on the surface itself).

    Args:
        mesh: a closed (watertight) ``trimesh.Trimesh`` [m].

    Attributes:
        distance: the mesh's :class:`~torch_gpioius.sim.meshes.MeshDistance` (NumPy in, NumPy out; no normals), for
            callers that need the distance alone.

    Raises:
        ValueError: the mesh is not watertight (inside/outside would be undefined).
    """

    def __init__(self, mesh: trimesh.Trimesh) -> None:
        from .meshes import MeshDistance

        if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
            raise ValueError("MeshSDF: expected a non-empty trimesh.Trimesh")
        if not mesh.is_watertight:
            raise ValueError("MeshSDF: the mesh is not watertight; inside/outside is undefined")
        self.mesh = mesh
        self.distance = MeshDistance(mesh)
        self._face_normals = np.array(mesh.face_normals)

    def __call__(self, points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """`(m, 3)` points [m] -> `(m,)` signed distances [m] (negative inside), `(m, 3)` outward normals."""
        p = torch.as_tensor(points, dtype=torch.float64)
        q = p.detach().cpu().numpy().reshape(-1, 3)
        dist, closest, face = self.distance.closest(q)
        normal = self._face_normals[face].copy()
        off = np.abs(dist) > 1e-9
        normal[off] = (q[off] - closest[off]) / dist[off, None]        # outward on both sides: d < 0 inside
        return (torch.as_tensor(dist, dtype=torch.float64).reshape(p.shape[:-1]),
                torch.as_tensor(normal, dtype=torch.float64).reshape(p.shape))

