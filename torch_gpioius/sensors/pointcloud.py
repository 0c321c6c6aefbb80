"""Point clouds and their sources behind one interface (a camera, files: PLY/PCD/XYZ/NPZ; the simulated camera is
:mod:`torch_gpioius.sensors.simulated.camera`), the pinhole camera model and the rigid motions of a calibration.

Whatever the source, a capture is a :class:`PointCloud` in the robot base frame [m] with the camera's
optical centre, so that the exploration can record both the seen surface (y = 0) and the free space the
camera's rays crossed in front of it (y = 1), then average both into voxels as the paper does (5 cm, Sec. VI-A).
"""

from __future__ import annotations

import abc
import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..core.moved import renamed
from ..core.validation import as_int
from ..geometry.voxels import voxel_average

__all__ = ["PointCloud", "PointCloudSource", "MultiViewSource", "PinholeCamera", "look_at", "skew", "rotation_matrix",
           "rigid_about"]

#: The simulated camera and its errors were here in 0.3: they live with the other simulated sensors now.
__getattr__ = renamed(__name__, {name: ("torch_gpioius.sensors.simulated.camera", name,
                                        "simulated sensors live in one place")
                                 for name in ("SimulatedDepthCamera", "CameraError", "AppliedCameraError",
                                              "view_errors", "error_key", "lost_blocks", "sensed_points",
                                              "HOLE_BLOCKS", "SUPPORT_REACH")})


@dataclass
class PointCloud:
    """Points seen by one camera, or by several (a merged capture, :meth:`merge`).

    Attributes:
        points: `(n, 3)` surface points [m], base frame.
        origin: the optical centre [m], base frame: `(3,)` for one camera, `(n, 3)` per point for a merged capture
            (each point's own camera; a row of NaN where that capture's camera is unknown), or None if unknown (no
            free space then).
        support: `(k, 3)` points the camera saw on the plane the object stands on (the table) around it [m], base
            frame, kept apart from ``points`` (they are not the object): what a capture's pose can be checked
            against (:func:`~torch_gpioius.sensors.extrinsics.correct_captures`' ``support``); None: not kept.
            A merged capture keeps none.
    """

    points: np.ndarray
    origin: np.ndarray | None = None
    support: np.ndarray | None = None

    def __post_init__(self) -> None:
        p = np.asarray(self.points, dtype=np.float64)
        if p.ndim != 2 or p.shape[1] not in (2, 3):
            raise ValueError(f"points: expected (n, 3) (or (n, 2) in a 2-D world) [m], got shape {p.shape}")
        if not np.isfinite(p).all():
            raise ValueError("points: contain NaN or inf")
        self.points = p
        if self.origin is not None:
            o = np.asarray(self.origin, dtype=np.float64)
            if o.ndim == 2:
                if o.shape != p.shape:
                    raise ValueError(f"origin: per-point origins must have the points' shape {p.shape}, got {o.shape}")
                finite = np.isfinite(o)
                if not (finite.all(axis=1) | np.isnan(o).all(axis=1)).all():
                    raise ValueError("origin: each per-point origin must be a finite position [m] or all NaN (unknown)")
            else:
                o = o.reshape(-1)
                if o.shape != (p.shape[1],) or not np.isfinite(o).all():
                    raise ValueError(f"origin: expected a finite ({p.shape[1]},) position [m], got {self.origin!r}")
            self.origin = o
        if self.support is not None:
            sp = np.asarray(self.support, dtype=np.float64).reshape(-1, p.shape[1])
            if not np.isfinite(sp).all():
                raise ValueError("support: contains NaN or inf")
            self.support = sp

    @classmethod
    def merge(cls, clouds) -> "PointCloud":
        """One capture from several views: the points of every cloud, each keeping its own camera's origin.

        Args:
            clouds: :class:`PointCloud` objects (at least one) of the same dimension, base frame.

        Returns:
            A cloud with per-point origins (rows of NaN for the points of a cloud without origin); the cloud itself
            when there is one.

        Raises:
            ValueError: no clouds, or clouds of different dimensions.
        """
        clouds = list(clouds)
        if not clouds:
            raise ValueError("merge: no point clouds")
        if len(clouds) == 1:
            return clouds[0]
        dims = {c.points.shape[1] for c in clouds}
        if len(dims) != 1:
            raise ValueError(f"merge: the clouds mix dimensions {sorted(dims)}")
        origins = [np.full_like(c.points, np.nan) if c.origin is None else
                   np.broadcast_to(c.origin, c.points.shape).astype(np.float64) for c in clouds]
        return cls(np.concatenate([c.points for c in clouds]), np.concatenate(origins))

    def __len__(self) -> int:
        return len(self.points)

    @property
    def sees_free_space(self) -> bool:
        """Whether :meth:`free_space` can say where the view was free (it needs the camera's ``origin``)."""
        return self.origin is not None and bool(np.isfinite(self.origin).any())

    @property
    def per_point_origins(self) -> bool:
        """Whether the cloud merges views (``origin`` is `(n, 3)`, one camera per point)."""
        return self.origin is not None and self.origin.ndim == 2

    def view_ids(self) -> np.ndarray:
        """`(n,)` int64: which view of a merged capture each point came from (points with one camera origin share
        an id; an unknown origin is a view of its own); all 0 for a single view."""
        if not self.per_point_origins:
            return np.zeros(len(self), dtype=np.int64)
        return np.unique(np.nan_to_num(self.origin, nan=np.inf), axis=0, return_inverse=True)[1].reshape(-1)

    def voxel_averaged(self, voxel: float, at: np.ndarray | None = None) -> "PointCloud":
        """One mean point per occupied voxel of edge ``voxel`` [m] (paper: 0.05 m), per view of a merged capture.

        Args:
            voxel: the voxels' edge [m].
            at: `(n, d)` positions [m] that choose each point's voxel in its place (the cloud smoothed along its rays,
                :meth:`smoothed_along_rays`, so that depth noise does not carry a point into the voxel behind its
                surface); the means are of the measured points. None: the points themselves.
        """
        if len(self) == 0:
            return self
        if at is not None and np.shape(at) != self.points.shape:
            raise ValueError(f"voxel_averaged: at must have the points' shape {self.points.shape}, got "
                             f"{np.shape(at)}")
        if not self.per_point_origins:
            return dataclasses.replace(self, points=voxel_average(self.points, voxel, at=at))
        inverse = self.view_ids()
        at = None if at is None else np.asarray(at, dtype=np.float64)
        parts = [voxel_average(self.points[inverse == k], voxel, at=None if at is None else at[inverse == k])
                 for k in range(inverse.max() + 1)]
        origins = [np.broadcast_to(self.origin[inverse == k][0], part.shape) for k, part in enumerate(parts)]
        return dataclasses.replace(self, points=np.concatenate(parts), origin=np.concatenate(origins))

    def smoothed_along_rays(self, neighbours: int = 24) -> "PointCloud":
        """The cloud with each point's depth along its own ray replaced by a robust local fit: the same rays, the
        depth noise averaged over the ``neighbours`` nearest rays of its view.

        A depth camera's noise lies along its rays (the pixel stays, the depth is off), so averaging it there keeps
        each point on its ray and its neighbourhood in the image. Averaging in 3-D voxels instead spreads a noisy
        surface over the voxels in front of and behind it: with the Kinect's noise tripled (10 mm at 1.1 m) a tenth of
        the voxel means of a tight cover lay 11 mm or more inside it, where they contradict the points placed behind
        the contacts. For each point, the inverse depth of its nearest rays (nearest in the view's image plane, a
        gnomonic projection about the view's axis) is fitted by a plane in the image coordinates (exact on a plane
        surface), twice refitted without the rays more than 2.5 robust standard deviations off, starting from those
        about the median (a neighbourhood across an occluding edge keeps its majority's surface), and the point is
        moved to the fit's depth on its own ray. Written here because the field's smoothers (PCL's and Open3D's moving
        least squares, bilateral depth filters) move points along
        surface normals or need the depth image, which a merged, cropped capture no longer has.

        Args:
            neighbours: rays per fit (at least ``2 d + 2`` for a ``d``-dimensional cloud; a view with fewer points
                fits them all).

        Returns:
            A new cloud (origins and support as they were); the cloud itself without known camera origins. Points
            whose camera is unknown (a merged capture's NaN rows), views with fewer points than a fit needs, rays more
            than 60 degrees off their view's axis (:data:`RAY_FIT_CONE`: a camera inside its cloud, say) and points
            whose fit would move them by more than a tenth of their depth (:data:`RAY_FIT_MOVE`) stay where they
            are.

        Raises:
            ValueError: ``neighbours`` not an integer in [2 d + 2, 10000].
        """
        dim = self.points.shape[1]
        neighbours = as_int(neighbours, "smoothed_along_rays: neighbours", 2 * dim + 2, 10_000)
        if not self.sees_free_space or len(self) == 0:
            return self
        origin = np.broadcast_to(self.origin, self.points.shape)
        known = np.isfinite(origin).all(axis=1)
        views = self.view_ids()
        out = self.points.copy()
        for view in np.unique(views[known]):
            mine = np.flatnonzero(known & (views == view))
            if len(mine) >= dim + 1:
                out[mine] = _ray_fit(self.points[mine], origin[mine[0]], neighbours)
        return dataclasses.replace(self, points=out)

    def cropped(self, lower, upper) -> "PointCloud":
        """The points inside the box ``lower <= p <= upper`` (`(d,)` each) [m]."""
        lo, hi = np.asarray(lower, dtype=np.float64), np.asarray(upper, dtype=np.float64)
        keep = ((self.points >= lo) & (self.points <= hi)).all(axis=1)
        origin = self.origin[keep] if self.per_point_origins else self.origin
        return dataclasses.replace(self, points=self.points[keep], origin=origin)

    def free_space(self, offset: float) -> np.ndarray:
        """`(n, 3)` free-space points: each seen point moved ``offset`` [m] back along its ray to its camera.

        The ray from the camera to a seen point crossed nothing before it, so a point ``offset`` in front of
        the surface is free (outer task, y = 1). Points closer than ``offset`` to the camera give none; so do the
        points of a merged capture whose camera is unknown.

        Raises:
            ValueError: the cloud has no ``origin``.
        """
        if not self.sees_free_space:
            raise ValueError("free_space: the point cloud has no camera origin; pass origin= to its source")
        ray = self.origin - self.points
        length = np.linalg.norm(ray, axis=1)
        keep = np.isfinite(length) & (length > offset)
        return self.points[keep] + ray[keep] * (offset / length[keep])[:, None]

    def normals(self, neighbours: int = 12) -> np.ndarray:
        """`(n, 3)` unit surface normals at the seen points, pointing towards each point's camera (out of the object).

        Each is the direction of least spread of the point's ``neighbours`` nearest seen points (a local plane fit).
        Written here rather than taken from Open3D's ``estimate_normals``: the same dozen lines would bring a
        several-hundred-megabyte dependency. NaN rows where fewer than 3 neighbours exist, the camera is unknown or
        the ray grazes the surface (more than 75 deg off the normal: which side faces the camera is then unclear).

        Raises:
            ValueError: the cloud has no ``origin``.
        """
        from scipy.spatial import cKDTree

        if not self.sees_free_space:
            raise ValueError("normals: the point cloud has no camera origin; pass origin= to its source")
        out = np.full(self.points.shape, np.nan)
        k = min(int(neighbours), len(self))
        if k < 3:
            return out
        _, idx = cKDTree(self.points).query(self.points, k=k)
        nb = self.points[idx] - self.points[idx].mean(axis=1, keepdims=True)
        _, vec = np.linalg.eigh(np.einsum("nki,nkj->nij", nb, nb))
        nrm = vec[:, :, 0]                                              # the eigenvector of the smallest eigenvalue
        to_camera = self.origin - self.points
        cos = np.einsum("ni,ni->n", nrm, to_camera) / np.linalg.norm(to_camera, axis=1)
        nrm = np.where((cos < 0)[:, None], -nrm, nrm)
        # where the ray grazes the plane (over 75 deg off its normal) the side facing the camera is ambiguous
        known = np.isfinite(cos) & (np.abs(cos) >= self.GRAZING_COS)
        out[known] = nrm[known]
        return out

    #: |cos| of the largest angle between a ray and the surface normal at which :meth:`normals` still orients it.
    GRAZING_COS = math.cos(math.radians(75.0))

    def behind(self, depth: float, voxel: float | None = None) -> np.ndarray:
        """`(n, 3)` points ``depth`` [m] behind the seen points, along the inward surface normal (:meth:`normals`).

        The camera's ray ended on the object's surface, so a point just behind it lies inside the object when the
        object is thicker than ``depth`` there (an assumption, not a measurement: keep ``depth`` below the thinnest
        part that matters). Along the normal, not the ray, so that the point is ``depth`` deep also where the ray
        grazes the surface. Points without a normal (unknown camera, too few neighbours, a grazing ray) give none.

        Args:
            depth: [m], positive.
            voxel: with an edge [m], one point per voxel of the seen points (per view, as :meth:`voxel_averaged`):
                ``depth`` behind the voxel's mean point along its mean normal, so that it stays ``depth`` deep
                (averaging the deepened points instead cuts corners on thin parts); None: one per seen point.

        Raises:
            ValueError: the cloud has no ``origin``; ``depth`` not a positive number.
        """
        if isinstance(depth, bool) or not isinstance(depth, (int, float)) or not (math.isfinite(depth) and depth > 0):
            raise ValueError(f"behind: depth must be a positive number [m], got {depth!r}")
        pts, nrm = self.with_normals(voxel)
        return pts - depth * nrm

    def with_normals(self, voxel: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``(points, normals)``, each `(n, 3)`: the seen points that have a normal (:meth:`normals`) and their unit
        outward normals, or with ``voxel`` [m] one mean point and mean normal per voxel of them (per view; voxels
        whose normals disagree are left out): the lines :meth:`behind` places its points on, at any depth.

        Raises:
            ValueError: the cloud has no ``origin``.
        """
        if not self.sees_free_space:
            raise ValueError("behind: the point cloud has no camera origin; pass origin= to its source")
        nrm = self.normals()
        keep = np.isfinite(nrm).all(axis=1)
        pts, nrm = self.points[keep], nrm[keep]
        if voxel and len(pts):
            views = self.view_ids()[keep]
            parts = [voxel_average(pts[views == k], voxel, nrm[views == k]) for k in np.unique(views)]
            pts, nrm = np.concatenate([p for p, _ in parts]), np.concatenate([n for _, n in parts])
            length = np.linalg.norm(nrm, axis=1)
            ok = length > 0.5                                   # normals that agree within the voxel
            pts, nrm = pts[ok], nrm[ok] / length[ok, None]
        return pts, nrm


#: Rays further off a local fit than this many robust standard deviations (1.4826 median absolute residuals) are
#: left out of the refit (:meth:`PointCloud.smoothed_along_rays`): an occluding edge's far surface, a flying pixel.
RAY_FIT_CUT = 2.5


#: The cosine of the widest angle from a view's axis at which :meth:`PointCloud.smoothed_along_rays` smooths a ray
#: (60 degrees; depth cameras see 30-45 degrees off their axis).
RAY_FIT_CONE = 0.5

#: The farthest a ray's fit may move its point, as a fraction of its depth (:meth:`PointCloud.smoothed_along_rays`).
RAY_FIT_MOVE = 0.1


def _ray_fit(points: np.ndarray, origin: np.ndarray, neighbours: int, refits: int = 2) -> np.ndarray:
    """`(n, d)` the ``points`` `(n, d)` [m] of one view moved along their rays from ``origin`` `(d,)` to a robust
    local fit of depth (:meth:`PointCloud.smoothed_along_rays`).

    The fit is of the inverse depth along the view's axis, affine in the gnomonic image coordinates: exact on a plane
    (a plane's points ``o + s w``, ``w`` a ray scaled to unit axial length, have ``1 / s`` affine in ``w``)."""
    from scipy.spatial import cKDTree

    ray = points - origin
    length = np.linalg.norm(ray, axis=1)
    axis = ray.sum(axis=0)
    out = points.copy()
    if not np.linalg.norm(axis) > 0:
        return out
    axis /= np.linalg.norm(axis)
    axial = ray @ axis                                       # depth along the view's axis [m]
    # rays within RAY_FIT_CONE of the axis: a camera's field of view (a wider one, or a camera inside its cloud,
    # has rays the image plane cannot hold; those stay as measured)
    ahead = (length > 0) & (axial > RAY_FIT_CONE * length)
    if ahead.sum() < len(axis) + 1:
        return out
    ray, axial = ray[ahead], axial[ahead]
    scaled = ray / axial[:, None]                            # each ray at unit axial depth
    # an orthonormal basis of the image plane (perpendicular to the axis): the gnomonic image coordinates
    basis = np.linalg.svd(np.eye(len(axis)) - np.outer(axis, axis))[0][:, :len(axis) - 1]
    image = scaled @ basis
    k = min(neighbours, len(image))
    _, near = cKDTree(image).query(image, k=k)
    offsets = image[near] - image[:, None, :]               # (n, k, d - 1): the neighbours about each ray
    design = np.concatenate([np.ones(near.shape + (1,)), offsets], axis=2)    # 1/s ~ c0 + g . offset
    inverse = (1.0 / axial)[near]
    weight = _inliers(inverse - np.median(inverse, axis=1, keepdims=True), inverse)   # started about the median
    ridge = 1e-12 * np.eye(design.shape[2])
    for _ in range(refits + 1):
        weighted = design * weight[..., None]
        coef = np.linalg.solve(np.einsum("nki,nkj->nij", weighted, design) + ridge,
                               np.einsum("nki,nk->ni", weighted, inverse)[..., None])[..., 0]
        weight = _inliers(inverse - np.einsum("nki,ni->nk", design, coef), inverse)
    fitted = coef[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        moved = axial * np.abs(1.0 / fitted / axial - 1.0)  # how far the fit moves the point along its ray [m]
    # a fit through or behind the camera, or one that moves its point by more than a tenth of its depth (no
    # surface of its own in the patch), keeps the measured point
    ok = np.isfinite(moved) & (fitted > 0) & (moved <= RAY_FIT_MOVE * axial)
    out[np.flatnonzero(ahead)[ok]] = origin + scaled[ok] / fitted[ok, None]
    return out


def _inliers(residual: np.ndarray, inverse: np.ndarray) -> np.ndarray:
    """`(n, k)` 0/1 weights: the residuals `(n, k)` within :data:`RAY_FIT_CUT` robust standard deviations of each
    row's, with a floor of a millionth of the inverse depth `(n, k)` (on a noise-free plane every ray fits; the rest
    is rounding)."""
    residual = np.abs(residual)
    spread = 1.4826 * np.median(residual, axis=1, keepdims=True)
    return (residual <= np.maximum(RAY_FIT_CUT * spread, 1e-6 * inverse[:, :1])).astype(np.float64)


class PointCloudSource(abc.ABC):
    """Anything that yields a :class:`PointCloud` in the base frame: a depth camera, a file, a ROS topic."""

    @abc.abstractmethod
    def capture(self) -> PointCloud:
        """One point cloud [m], base frame."""

    def reseeded(self, seed) -> "PointCloudSource":
        """The same source with its noise drawn from ``seed`` (an int, or a sequence of ints as NumPy's seed
        sequences take; a seeded world's perturbation); a source without noise of its own (a file, a live camera)
        returns itself."""
        return self


class MultiViewSource(PointCloudSource):
    """Several point-cloud sources captured together: one :class:`PointCloud` with each point's own camera origin
    (:meth:`PointCloud.merge`), so that each view's free space lies along its own rays.

    Args:
        sources: the views (at least one), each a :class:`PointCloudSource`.
        names: optional name of each view (for reports), e.g. ``("fixed", "mirrored", "wrist")``.

    Raises:
        ValueError: no sources, a source that is not a :class:`PointCloudSource`, or names of another length.
    """

    def __init__(self, sources, names=None) -> None:
        sources = list(sources)
        if not sources:
            raise ValueError("MultiViewSource: needs at least one view")
        for i, src in enumerate(sources):
            if not isinstance(src, PointCloudSource):
                raise ValueError(f"MultiViewSource: view {i} is a {type(src).__name__}, not a PointCloudSource")
        names = tuple(f"view {i}" for i in range(len(sources))) if names is None else tuple(str(n) for n in names)
        if len(names) != len(sources):
            raise ValueError(f"MultiViewSource: {len(names)} names for {len(sources)} views")
        self.sources, self.names = sources, names

    def __len__(self) -> int:
        return len(self.sources)

    def capture(self) -> PointCloud:
        return PointCloud.merge([src.capture() for src in self.sources])

    def reseeded(self, seed) -> "MultiViewSource":
        # each view its own stream: view k of seed s draws from [s, k], never the same noise as another view
        return MultiViewSource([src.reseeded([int(seed), k]) for k, src in enumerate(self.sources)], self.names)


def look_at(eye, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """`(4, 4)` ``T_base_camera`` of a camera at ``eye`` looking at ``target`` (both `(3,)` [m], base frame).

    Camera frame as in OpenCV: z along the optical axis, x to the right of the image, y down.
    """
    eye, target, up = (np.asarray(v, dtype=np.float64) for v in (eye, target, up))
    z = target - eye
    if np.linalg.norm(z) == 0:
        raise ValueError("look_at: eye and target coincide")
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9:
        raise ValueError("look_at: the viewing direction is parallel to 'up'")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, :3] = np.stack([x, y, z], axis=1)
    T[:3, 3] = eye
    return T


@dataclass(frozen=True)
class PinholeCamera:
    """Pinhole intrinsics of a depth camera (pixels), and its depth range [m].

    Attributes:
        width, height: image size [px].
        fx, fy: focal lengths [px]; cx, cy: principal point [px].
        min_depth, max_depth: depth range [m]; hits outside it are not returned.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    min_depth: float = 0.5
    max_depth: float = 4.5

    def __post_init__(self) -> None:
        if self.width < 1 or self.height < 1 or not (self.fx > 0 and self.fy > 0):
            raise ValueError("PinholeCamera: needs a positive image size and focal lengths")
        if not 0 <= self.min_depth < self.max_depth:
            raise ValueError("PinholeCamera: needs 0 <= min_depth < max_depth")

    @classmethod
    def kinect_v2(cls, scale: float = 1.0) -> "PinholeCamera":
        """The Kinect v2 depth camera (512 x 424 px, 70.6 x 60 deg field of view), optionally subsampled.

        Args:
            scale: image scale (0.25 gives 128 x 106 px with the same field of view).
        """
        w, h = max(1, round(512 * scale)), max(1, round(424 * scale))
        return cls(w, h, 365.5 * w / 512, 365.5 * h / 424, w / 2, h / 2)

    @classmethod
    def realsense_d405(cls, scale: float = 1.0) -> "PinholeCamera":
        """A short-range stereo depth camera for the wrist (Intel RealSense D405: 1280 x 720 px, 87 x 58 deg, depth
        from 7 cm; its datasheet's best range ends near 50 cm, here 1 m), optionally subsampled."""
        w, h = max(1, round(1280 * scale)), max(1, round(720 * scale))
        fx = (w / 2) / np.tan(np.radians(87.0) / 2)
        fy = (h / 2) / np.tan(np.radians(58.0) / 2)
        return cls(w, h, fx, fy, w / 2, h / 2, min_depth=0.07, max_depth=1.0)

    def rays(self) -> np.ndarray:
        """`(height * width, 3)` ray directions in the camera frame (z = 1), row-major over pixel centres."""
        u, v = np.meshgrid(np.arange(self.width) + 0.5, np.arange(self.height) + 0.5)
        return np.stack([(u.ravel() - self.cx) / self.fx, (v.ravel() - self.cy) / self.fy,
                         np.ones(u.size)], axis=1)


def skew(v) -> np.ndarray:
    """`(3, 3)` the cross-product matrix of `(3,)` ``v``: ``skew(v) @ u == cross(v, u)``."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def rotation_matrix(rotvec) -> np.ndarray:
    """`(3, 3)` the rotation of the rotation vector `(3,)` ``rotvec`` (axis times angle [rad]; Rodrigues' formula)."""
    w = np.asarray(rotvec, dtype=np.float64)
    angle = float(np.linalg.norm(w))
    if angle == 0.0:
        return np.eye(3)
    K = skew(w / angle)
    return np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * K @ K


def rigid_about(points, origin, rotvec, translation) -> np.ndarray:
    """`(n, 3)` ``points`` [m] moved rigidly about ``origin`` `(3,)` [m]: ``origin + R (p - origin) + translation``,
    R the rotation of ``rotvec`` [rad] (a camera's calibration error, or its correction)."""
    c = np.asarray(origin, dtype=np.float64)
    return (c + (np.asarray(points, dtype=np.float64) - c) @ rotation_matrix(rotvec).T
            + np.asarray(translation, dtype=np.float64))

