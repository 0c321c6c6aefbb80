"""3-D world of the paper's robot experiment (Sec. VI): a rigid inner mesh under a soft outer mesh, a depth
camera that sees the outer one, and an exploration range for the fingertip (eq. 25).

Frames: everything is in the UR5 base frame [m] (z up); the objects stand in front of the robot.
"""

from __future__ import annotations

import math

import numpy as np
import trimesh

from ..metrics import hausdorff_distance
from ..planning import RangePenalty
from ..sensors.pointcloud import PinholeCamera, SimulatedDepthCamera, look_at
from ..sensors.simulated import PenaltyContact
from .shapes3d import MeshSDF, capsule, mesh_from_sdf, offset, rounded_box, smooth_union

__all__ = ["Scene3D", "paper_objects_3d", "sphere_scene"]


def _mesh(m, name: str) -> trimesh.Trimesh:
    if not isinstance(m, trimesh.Trimesh) or len(m.faces) == 0:
        raise ValueError(f"{name}: expected a non-empty trimesh.Trimesh [m]")
    if not np.isfinite(m.vertices).all():
        raise ValueError(f"{name}: vertices contain NaN or inf")
    if not m.is_watertight:
        raise ValueError(f"{name}: the mesh must be closed (watertight)")
    return m


class Scene3D:
    """A covered object in 3-D, seen by a depth camera and touched by the UR5's fingertip.

    Args:
        inner: closed mesh of the rigid inner object [m], base frame.
        outer: closed mesh of the cover's outer surface [m] (must contain the inner one).
        start: `(3,)` fingertip start position [m], outside the outer mesh.
        direction: `(3,)` approach direction (normalised here); the tool points along it.
        bounds: `(3, 2)` exploration range [[x_min, x_max], [y_min, y_max], [z_min, z_max]] [m]: the range
            penalty C (eq. 25) keeps the planner inside it, and the metrics are evaluated inside it.
        name: label for figures and records.
        camera: point-cloud source seeing the outer mesh (default: :meth:`default_camera`).
        cover_stiffness: stiffness of the cover in the simulated force model [N/m].

    Raises:
        ValueError: open or invalid meshes, an outer mesh not containing the inner one, a start inside the outer
            mesh, an approach ray missing the inner mesh, or invalid bounds.
    """

    def __init__(self, inner: trimesh.Trimesh, outer: trimesh.Trimesh, start, direction, bounds, name: str = "",
                 camera=None, cover_stiffness: float = 5.0) -> None:
        self.inner, self.outer = _mesh(inner, "inner"), _mesh(outer, "outer")
        self.inner_sdf, self.outer_sdf = MeshSDF(self.inner), MeshSDF(self.outer)
        # containment on at most 2000 inner vertices (trimesh's ray-based contains needs GBs for large meshes)
        probe = self.inner.vertices[::max(1, len(self.inner.vertices) // 2000)]
        if not bool((self.outer_sdf(probe)[0] <= 1e-9).all()):
            raise ValueError("outer: must contain the inner mesh (a cover around the object)")
        self.start = np.asarray(start, dtype=np.float64).reshape(-1)
        d = np.asarray(direction, dtype=np.float64).reshape(-1)
        if self.start.shape != (3,) or not np.isfinite(self.start).all():
            raise ValueError(f"start: expected a finite (3,) position [m], got {start!r}")
        if d.shape != (3,) or not np.isfinite(d).all() or np.linalg.norm(d) == 0:
            raise ValueError("direction: must be a finite non-zero 3-vector")
        self.direction = d / np.linalg.norm(d)
        b = np.asarray(bounds, dtype=np.float64)
        if b.shape != (3, 2) or not np.isfinite(b).all() or not (b[:, 1] > b[:, 0]).all():
            raise ValueError(f"bounds: expected (3, 2) finite [min, max] per axis with min < max [m], got {bounds!r}")
        self.range = b
        if float(self.outer_sdf(self.start[None])[0][0]) <= 0:
            raise ValueError("start: must lie outside the outer mesh")
        if not cover_stiffness >= 0:
            raise ValueError("cover_stiffness must be >= 0 [N/m]")
        self.name = name
        self._inner_samples: dict[float, np.ndarray] = {}
        self.cover_stiffness = float(cover_stiffness)
        self.camera = camera if camera is not None else self.default_camera()
        self.first_contact()  # raises if the approach misses

    dim = 3

    # ------------------------------------------------------------------ geometry
    def first_contact(self) -> np.ndarray:
        """`(3,)` first point of the inner mesh hit from ``start`` along ``direction`` [m]."""
        hits, _, _ = self.inner.ray.intersects_location(self.start[None], self.direction[None], multiple_hits=True)
        if len(hits) == 0:
            raise ValueError("direction: the approach ray from start misses the inner mesh")
        return hits[np.argmin(np.linalg.norm(hits - self.start, axis=1))]

    def bounds(self, margin: float = 0.05) -> np.ndarray:
        """`(3, 2)` grid box for surfaces and metrics: the exploration range grown by ``margin`` [m]."""
        return self.range + np.array([-margin, margin])

    def in_range(self, points: np.ndarray) -> np.ndarray:
        """`(n,)` bool: points `(n, 3)` inside the exploration range."""
        p = np.asarray(points, dtype=np.float64)
        return ((p >= self.range[:, 0]) & (p <= self.range[:, 1])).all(axis=1)

    def inner_samples_in_range(self, spacing: float = 0.003) -> np.ndarray:
        """`(n, 3)` samples of the true inner surface inside the exploration range, about one per ``spacing``^2
        (the reference of the Hausdorff metric; computed once per spacing)."""
        from ..exploration3d import surface_samples

        if spacing not in self._inner_samples:
            pts = surface_samples(self.inner, spacing)
            self._inner_samples[spacing] = pts[self.in_range(pts)]
        return self._inner_samples[spacing]

    def range_penalty(self, beta: float = 100.0) -> RangePenalty:
        """The paper's C(x) (eq. 25, beta = 100) for this scene's exploration range."""
        return RangePenalty(self.range[:, 0], self.range[:, 1], beta=beta)

    def inner_outer_hausdorff(self, spacing: float = 0.003) -> float:
        """Hausdorff distance between the inner and outer surfaces [m] (the whole meshes).

        Both surfaces are sampled every ``spacing`` (vertices plus area-uniform samples) and compared with k-d
        trees: within about ``spacing`` of the exact value, seconds instead of minutes for 10^5 faces.
        """
        from ..exploration3d import surface_samples

        return hausdorff_distance(surface_samples(self.inner, spacing), surface_samples(self.outer, spacing))

    def contact_model(self, k_inner: float = 1000.0) -> PenaltyContact:
        """Force on a point fingertip: the rigid inner mesh and the soft cover (``cover_stiffness``)."""
        return PenaltyContact(self.inner_sdf, self.outer_sdf, k_inner=k_inner,
                              k_cover=self.cover_stiffness)

    def default_camera(self, scale: float = 0.5) -> SimulatedDepthCamera:
        """A Kinect v2 (half resolution; depth noise 1.5 mm + 1.5 mm/m^2 * z^2) looking at the centre of the
        exploration range from 1.1 m, from behind the approach (so that it sees what the robot will touch),
        30 cm to the side and 30 cm up."""
        target = self.range.mean(axis=1)
        back = -self.direction
        side = np.cross(back, [0.0, 0.0, 1.0]) if abs(back[2]) < 0.9 else np.array([0.0, -1.0, 0.0])
        eye = target + back + 0.3 * side / np.linalg.norm(side) + np.array([0.0, 0.0, 0.3])
        eye = target + 1.1 * (eye - target) / np.linalg.norm(eye - target)
        return SimulatedDepthCamera(self.outer, PinholeCamera.kinect_v2(scale), look_at(eye, target),
                                    noise_a=0.0015, noise_b=0.0015, seed=0)

    def __repr__(self) -> str:
        return (f"Scene3D({self.name!r}, inner volume={self.inner.volume * 1e6:.0f} cm^3, "
                f"outer volume={self.outer.volume * 1e6:.0f} cm^3)")


def sphere_scene(radius: float = 0.08, cover: float = 0.01, center=(0.5, 0.0, 0.25), name: str = "sphere",
                 subdivisions: int = 4) -> Scene3D:
    """A sphere under a uniform cover, approached from above; the exploration range is its upper half.

    Args:
        radius: inner radius [m]. cover: cover thickness [m]. center: `(3,)` [m], base frame.
    """
    c = np.asarray(center, dtype=np.float64)
    inner = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    outer = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius + cover)
    inner.apply_translation(c)
    outer.apply_translation(c)
    reach = radius + cover + 0.05
    bounds = np.stack([c - reach, c + reach], axis=1)
    bounds[2, 0] = c[2] - 0.3 * radius
    return Scene3D(inner, outer, start=c + [0.01, 0.005, reach + 0.05], direction=(0, 0, -1), bounds=bounds,
                   name=name)


def paper_objects_3d(resolution: float = 0.006) -> dict[str, Scene3D]:
    """Objects E-H of the robot experiment (Sec. VI, Fig. 6), built from capsules and rounded boxes [m].

    * E, arm in a tight sleeve: an upper arm (r = 5 cm) and a forearm (r = 4 cm) capsule blended at the elbow,
      lying along y at 25 cm height, bent 18 deg at the elbow; the sleeve is the arm grown by 8 mm.
    * F, arm in a loose sleeve: the same arm; the sleeve is a 9 cm tube along the upper arm and forearm axes,
      sagging 2.5 cm, blended with the arm grown by 1 cm. The arm's shape stays recognisable.
    * G, torso in a tight shirt: a chest (rounded box 18 x 30 x 36 cm), shoulders (capsule, r = 6 cm) and a neck
      (capsule, r = 4.5 cm) blended; the shirt is the torso grown by 8 mm.
    * H, torso in a loose garment: the same torso under a poncho, a rounded box 34 x 52 x 48 cm with 8 cm edge
      radius, blended with the torso grown by 1 cm (neck and shoulders shape the top, the rest hangs).

    The arm is approached from above, the torso from the front (the side facing the robot base). The
    exploration range is the upper half of the arm and the front and top of the torso, as in Fig. 6. The
    inner-outer Hausdorff distances are in docs/results-3d.md (``Scene3D.inner_outer_hausdorff``).

    Args:
        resolution: marching-cubes grid spacing of the meshes [m].
    """
    elbow = np.array([0.5, 0.02, 0.25])
    hand = elbow + 0.19 * np.array([-math.sin(math.radians(18)), math.cos(math.radians(18)), 0.0])
    shoulder = np.array([0.5, -0.21, 0.25])
    arm = smooth_union(capsule(shoulder, elbow, 0.05), capsule(elbow, hand, 0.04), k=0.03)
    sag = np.array([0.0, 0.0, -0.025])
    sleeve = smooth_union(offset(arm, 0.01), capsule(shoulder + sag, elbow + sag, 0.09),
                          capsule(elbow + sag, hand + 0.6 * sag, 0.075), k=0.04)
    arm_box = [[0.25, 0.75], [-0.40, 0.40], [0.05, 0.45]]
    arm_mesh = mesh_from_sdf(arm, arm_box, resolution)
    arm_range = [[0.36, 0.66], [-0.24, 0.24], [0.24, 0.42]]
    arm_start, down = (0.51, -0.06, 0.45), (0.0, 0.0, -1.0)

    torso = smooth_union(rounded_box((0.62, 0.0, 0.24), (0.09, 0.15, 0.18), 0.06),
                         capsule((0.62, -0.14, 0.40), (0.62, 0.14, 0.40), 0.06),
                         capsule((0.62, 0.0, 0.42), (0.62, 0.0, 0.53), 0.045), k=0.05)
    poncho = smooth_union(offset(torso, 0.01), rounded_box((0.62, 0.0, 0.25), (0.17, 0.26, 0.24), 0.08), k=0.03)
    torso_box = [[0.32, 0.92], [-0.4, 0.4], [-0.1, 0.62]]
    torso_mesh = mesh_from_sdf(torso, torso_box, resolution)
    torso_range = [[0.34, 0.62], [-0.24, 0.24], [0.10, 0.56]]
    torso_start, forward = (0.34, 0.03, 0.27), (1.0, 0.0, 0.0)

    return {
        "E": Scene3D(arm_mesh, mesh_from_sdf(offset(arm, 0.008), arm_box, resolution), arm_start, down,
                     arm_range, name="E"),
        "F": Scene3D(arm_mesh, mesh_from_sdf(sleeve, arm_box, resolution), arm_start, down, arm_range, name="F",
                     cover_stiffness=3.0),
        "G": Scene3D(torso_mesh, mesh_from_sdf(offset(torso, 0.008), torso_box, resolution), torso_start, forward,
                     torso_range, name="G"),
        "H": Scene3D(torso_mesh, mesh_from_sdf(poncho, torso_box, resolution), torso_start, forward,
                     torso_range, name="H", cover_stiffness=3.0),
    }
