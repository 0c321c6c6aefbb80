"""Point-cloud sources behind one interface: a simulated pinhole depth camera and files (PLY/PCD/XYZ/NPZ).

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
import trimesh

from .._validation import as_int
from ..voxels import voxel_average

__all__ = ["PointCloud", "PointCloudSource", "MultiViewSource", "PinholeCamera", "SimulatedDepthCamera", "look_at",
           "CameraError", "AppliedCameraError"]


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
        if not self.sees_free_space:
            raise ValueError("behind: the point cloud has no camera origin; pass origin= to its source")
        if isinstance(depth, bool) or not isinstance(depth, (int, float)) or not (math.isfinite(depth) and depth > 0):
            raise ValueError(f"behind: depth must be a positive number [m], got {depth!r}")
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
        return pts - depth * nrm


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


def error_key(name: str) -> tuple:
    """What a simulated camera error is drawn with besides a view's seed: the scene's name, so that two objects' runs
    of one seed are off in their own directions."""
    import zlib

    return (zlib.crc32(name.encode()) % 2 ** 31,)


def view_errors(error: "CameraError", views, seed: int, key: tuple = ()) -> dict[str, dict]:
    """The error each simulated view of a world draws (:meth:`AppliedCameraError.as_record`, by view name), as its
    camera draws it: the seed alone for the paper's single fixed view, ``[seed, k]`` for view k of several, each with
    ``key`` (:func:`error_key`); empty without an error."""
    if not error.extrinsic:
        return {}
    views = tuple(views)
    seeds = [[seed]] if views == ("fixed",) else [[seed, k] for k in range(len(views))]
    return {v: error.draw([*s, *key]).as_record() for v, s in zip(views, seeds)}


#: Units a :meth:`CameraError.parse` text may give: lengths to metres, angles to radians.
_LENGTH_UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}
_ANGLE_UNITS = {"deg": math.pi / 180.0, "rad": 1.0}


@dataclass(frozen=True)
class AppliedCameraError:
    """One camera's extrinsic error as drawn: its captures are moved rigidly about the optical centre ``c`` that the
    camera reports, ``p' = c + R (p - c) + t``, while the reported origin stays ``c`` (a camera whose calibrated pose
    is off: what it sees lands where its calibration says, not where it is).

    Attributes:
        translation: `(3,)` t [m], base frame.
        rotation: `(3,)` the rotation R as a rotation vector (axis times angle) [rad], base frame.
    """

    translation: tuple
    rotation: tuple

    def matrix(self) -> np.ndarray:
        """`(3, 3)` R (:func:`rotation_matrix`)."""
        return rotation_matrix(self.rotation)

    def apply(self, points: np.ndarray, origin: np.ndarray) -> np.ndarray:
        """`(n, 3)` ``points`` [m] moved by this error about ``origin`` `(3,)` [m] (both base frame)."""
        return rigid_about(points, origin, self.rotation, self.translation)

    def as_record(self) -> dict:
        """The error for a run's record: ``translation_mm`` and ``rotation_deg`` (a rotation vector) as lists, and
        their sizes ``|t|`` [mm] and the angle [deg]."""
        t, w = np.asarray(self.translation), np.asarray(self.rotation)
        return {"translation_mm": (t * 1e3).round(4).tolist(), "rotation_deg": np.degrees(w).round(5).tolist(),
                "size_mm": round(float(np.linalg.norm(t)) * 1e3, 4),
                "angle_deg": round(math.degrees(float(np.linalg.norm(w))), 5)}


@dataclass(frozen=True)
class CameraError:
    """A simulated depth camera's errors beyond its model's own depth noise: the extrinsic (hand-eye) calibration
    error, and worse sensing than the camera model's datasheet. Each camera of each run draws a rigid error of exactly
    the extrinsic sizes, in a direction and about an axis uniform on the sphere, from its own seed (:meth:`draw`;
    :class:`AppliedCameraError` says how it moves the captures); the sensing terms scale its depth noise and lose
    pixels (:class:`SimulatedDepthCamera`).

    Attributes:
        translation: the translation's size [m] (0: none).
        rotation: the rotation's angle [rad] (0: none).
        noise: a multiple of the camera model's depth noise (1: as the model gives it; 0: none).
        dropout: the fraction of pixels lost at random, each on its own (beside the camera's own ``dropout``).
        holes: the fraction of the image lost in square blocks (:data:`HOLE_BLOCKS` across the image), drawn anew
            for each capture: the patches a real depth camera loses on dark, shiny or steep surfaces.

    Raises:
        ValueError: a negative, non-finite or implausible size (above 10 cm or 20 degrees: not a calibration error;
            a noise above 100 times the model's; a fraction outside [0, 0.95]).
    """

    translation: float = 0.0
    rotation: float = 0.0
    noise: float = 1.0
    dropout: float = 0.0
    holes: float = 0.0

    def __post_init__(self) -> None:
        for name, value, top, unit in (("translation", self.translation, 0.1, "m"),
                                       ("rotation", self.rotation, math.radians(20), "rad"),
                                       ("noise", self.noise, 100.0, "times the model's"),
                                       ("dropout", self.dropout, 0.95, "a fraction"),
                                       ("holes", self.holes, 0.95, "a fraction")):
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                    or not 0.0 <= value <= top:
                raise ValueError(f"camera error: the {name} must be in [0, {top:.3g}] ({unit}), got {value!r}")
            object.__setattr__(self, name, float(value))

    @property
    def extrinsic(self) -> bool:
        """Whether the captures are moved (a translation or a rotation)."""
        return self.translation > 0.0 or self.rotation > 0.0

    @property
    def sensing(self) -> bool:
        """Whether the sensing is worse than the camera model's (noise scaled, pixels or blocks lost)."""
        return self.noise != 1.0 or self.dropout > 0.0 or self.holes > 0.0

    def __bool__(self) -> bool:
        return self.extrinsic or self.sensing

    def fingerprint(self) -> list:
        """What a world's fingerprint hashes of this error: nothing without one, the extrinsic sizes as before the
        sensing terms existed, the sensing terms after them when set (so that older logs still resume)."""
        return ([[self.translation, self.rotation]] if self.extrinsic else []) \
            + ([[self.noise, self.dropout, self.holes]] if self.sensing else [])

    def check_bound(self, name: str = "camera_bound") -> "CameraError":
        """This error as a bound on a correction: both a translation and a rotation, no sensing terms.

        Raises:
            ValueError: either size missing, or a noise, dropout or holes given.
        """
        if self.sensing:
            raise ValueError(f"{name}: a bound is a translation and a rotation (e.g. 12mm,2deg); noise, dropout and "
                             f"holes are simulated camera errors, got {self}")
        if not self.translation or not self.rotation:
            raise ValueError(f"{name}: give both a translation and a rotation (e.g. 12mm,2deg), got {self}")
        return self

    @classmethod
    def parse(cls, text) -> "CameraError":
        """A camera error from text such as ``"6mm,1deg"``, ``"0.5cm"``, ``"1deg"``, ``"3x"``, ``"6mm,1deg,2x,20%"``
        or ``"0"`` (none), comma-separated parts in any order, each at most once: a length (m, cm, mm: the
        translation), an angle (deg, rad: the rotation), a multiple of the depth noise (``3x``), a fraction of pixels
        lost at random (``20%``) and a fraction of the image lost in blocks (``20%holes``); a :class:`CameraError` is
        returned as it is.

        Raises:
            ValueError: a part without a unit, an unknown unit, a part given twice, or a size out of range.
        """
        if isinstance(text, CameraError):
            return text
        if not isinstance(text, str):
            raise ValueError(f"camera error: expected text such as \"6mm,1deg\", got {text!r}")
        parts = [p.strip().lower() for p in text.split(",") if p.strip()]
        if parts in ([], ["0"], ["none"]):
            return cls()
        units = {**{u: ("translation", f) for u, f in _LENGTH_UNITS.items()},
                 **{u: ("rotation", f) for u, f in _ANGLE_UNITS.items()},
                 "x": ("noise", 1.0), "%": ("dropout", 0.01), "%holes": ("holes", 0.01)}
        sizes: dict[str, float] = {}
        for part in parts:
            unit = next((u for u in sorted(units, key=len, reverse=True) if part.endswith(u)), None)
            try:
                value = float(part[:len(part) - len(unit)]) if unit else None
            except ValueError:
                value = None
            if unit is None or value is None:
                raise ValueError(f"camera error: {part!r} is not a size with a unit (a length in m, cm or mm, an "
                                 "angle in deg or rad, a depth noise's multiple as 3x, pixels lost as 20% or "
                                 "20%holes: e.g. \"6mm,1deg\")")
            kind, factor = units[unit]
            if kind in sizes:
                raise ValueError(f"camera error: the {kind} twice in {text!r}")
            sizes[kind] = value * factor
        return cls(**sizes)

    def __str__(self) -> str:
        parts = [f"{self.translation * 1e3:g}mm,{math.degrees(self.rotation):g}deg"] if self.extrinsic else []
        parts += [f"{self.noise:g}x"] if self.noise != 1.0 else []
        parts += [f"{self.dropout * 100:g}%"] if self.dropout else []
        parts += [f"{self.holes * 100:g}%holes"] if self.holes else []
        return ",".join(parts) or "0mm,0deg"

    def as_record(self) -> dict:
        """The sensing terms for a run's record (the extrinsic draw is each view's: :func:`view_errors`)."""
        return {"noise": self.noise, "dropout": self.dropout, "holes": self.holes}

    def drawn(self, seed, key=()) -> AppliedCameraError | None:
        """What a camera seeded with ``seed`` (and ``key``, :func:`error_key`) applies: :meth:`draw`, or None
        without an error."""
        return self.draw([*np.atleast_1d(seed).tolist(), *np.atleast_1d(key).tolist()]) if self.extrinsic else None

    def draw(self, seed) -> AppliedCameraError:
        """The error one camera applies, drawn from ``seed`` (an int or a sequence of ints, the camera's noise seed:
        a stream of its own, so that the noise of a camera with and without an error is the same)."""
        rng = np.random.default_rng([*np.atleast_1d(np.asarray(seed, dtype=np.int64)).tolist(), 0x0CA1])
        unit = rng.standard_normal((2, 3))
        unit /= np.linalg.norm(unit, axis=1, keepdims=True)
        return AppliedCameraError(tuple(self.translation * unit[0]), tuple(self.rotation * unit[1]))


#: How many square blocks across the image a :class:`CameraError`'s ``holes`` are counted in (8 px of a half-resolution
#: Kinect: 5 cm at a metre).
HOLE_BLOCKS = 32


def lost_blocks(error: CameraError, intrinsics: "PinholeCamera", rng: np.random.Generator) -> np.ndarray | None:
    """The blocks of the image one capture loses (``error.holes`` of them, drawn from ``rng`` without replacement):
    `(rows, HOLE_BLOCKS)` bool, or None without holes (nothing drawn, so that the noise is as without them)."""
    if not error.holes:
        return None
    size = intrinsics.width / HOLE_BLOCKS
    rows = max(1, math.ceil(intrinsics.height / size))
    lost = np.zeros(rows * HOLE_BLOCKS, dtype=bool)
    lost[rng.choice(lost.size, size=round(error.holes * lost.size), replace=False)] = True
    return lost.reshape(rows, HOLE_BLOCKS)


def sensed_points(p_cam: np.ndarray, T_base_camera: np.ndarray, intrinsics: "PinholeCamera",
                  rng: np.random.Generator, *, noise_a: float, noise_b: float, dropout: float,
                  error: CameraError | None = None, lost: np.ndarray | None = None,
                  applied: "AppliedCameraError | None" = None) -> np.ndarray:
    """Noise-free points as a depth camera reports them (shared by the simulated cameras of every world).

    Args:
        p_cam: `(k, 3)` noise-free points in the camera frame (OpenCV axes) [m], each on its pixel's ray.
        T_base_camera: `(4, 4)` the camera's calibrated pose.
        intrinsics: the camera's :class:`PinholeCamera` (for the blocks ``lost`` is counted in).
        rng: the camera's noise generator (drawn from only where a term is non-zero).
        noise_a: depth noise at zero depth [m], along each ray (the pixel stays): ``noise_a + noise_b z^2``.
        noise_b: its growth with depth [1/m].
        dropout: fraction of pixels lost at random.
        error: the camera's :class:`CameraError`, whose sensing terms scale the depth noise and join the dropout
            (the pixel kept only if neither loses it); None: as the camera model gives them.
        lost: :func:`lost_blocks`, or None.
        applied: the rigid extrinsic error the points are moved by about the optical centre, or None.

    Returns:
        `(j, 3)` points [m], base frame, ``j <= k``.
    """
    if error is not None:
        noise_a, noise_b = noise_a * error.noise, noise_b * error.noise
        if error.dropout:
            dropout = 1.0 - (1.0 - dropout) * (1.0 - error.dropout)
    z = p_cam[:, 2]
    if lost is not None and len(p_cam):
        size = intrinsics.width / HOLE_BLOCKS
        u = np.clip((intrinsics.fx * p_cam[:, 0] / z + intrinsics.cx) // size, 0, lost.shape[1] - 1).astype(int)
        v = np.clip((intrinsics.fy * p_cam[:, 1] / z + intrinsics.cy) // size, 0, lost.shape[0] - 1).astype(int)
        keep = ~lost[v, u]
        p_cam, z = p_cam[keep], z[keep]
    if noise_a > 0 or noise_b > 0:
        z_noisy = z + rng.standard_normal(len(z)) * (noise_a + noise_b * z**2)
        p_cam = p_cam * (z_noisy / z)[:, None]   # along the ray: the pixel stays, its depth changes
    if dropout > 0:
        p_cam = p_cam[rng.uniform(size=len(p_cam)) >= dropout]
    R, t = T_base_camera[:3, :3], T_base_camera[:3, 3]
    points = p_cam @ R.T + t
    return points if applied is None else applied.apply(points, t)


#: How far around the mesh's bounding box [m] a simulated camera's table is seen (:attr:`SimulatedDepthCamera.support`):
#: the part of a table a capture keeps beside the object.
SUPPORT_REACH = 0.15


class SimulatedDepthCamera(PointCloudSource):
    """A depth camera ray-cast against a mesh (the outer surface of a covered object).

    Rays through every pixel centre are intersected with the mesh (``trimesh``'s ray engine: Embree via
    ``embreex`` when installed, ~20 ms for a half-resolution Kinect frame; else trimesh's rtree-based engine,
    which takes tens of seconds for the same frame); the first hit of each ray becomes a point. Depth
    noise is Gaussian along the ray with a standard deviation growing with depth,
    ``noise_a + noise_b * z^2`` (the usual time-of-flight/structured-light model), and a fraction
    ``dropout`` of valid pixels is lost at random.

    Args:
        mesh: what the camera sees [m], base frame (several objects: concatenate them first).
        intrinsics: :class:`PinholeCamera`.
        T_base_camera: `(4, 4)` camera pose (OpenCV axes, see :func:`look_at`).
        noise_a: depth noise at zero depth [m]; noise_b: its growth [1/m].
        dropout: fraction of pixels returned empty.
        seed: random seed of noise and dropout (and of the extrinsic error's direction, a stream of its own).
        engine: ray engine: "auto" (Embree when ``embreex`` is installed, else trimesh's own), "embree" or
            "triangle" (trimesh's pure-Python engine; slow, no extra needed).
        error: a :class:`CameraError` (or its text, ``"6mm,1deg"``): every capture is moved by the rigid error drawn
            from ``seed`` (:attr:`applied_error`), its reported origin left where the pose says, its depth noise
            scaled by ``error.noise``, its pixels lost by ``error.dropout`` and ``error.holes`` as well; None: none.
        error_key: integers drawn with ``seed`` for the error alone (a scene's name, so that two objects' runs of
            one seed are not off in the same direction); kept by :meth:`reseeded`.
        support: the height [m] of a horizontal plane the object stands on (a table), seen where the rays miss the
            mesh within :data:`SUPPORT_REACH` of it: kept apart in each capture (``PointCloud.support``), with the
            same depth noise, dropout and extrinsic error (drawn after the object's, so that its points are as
            without it); None: no table.
    """

    ENGINES = ("auto", "embree", "triangle")

    def __init__(self, mesh: trimesh.Trimesh, intrinsics: PinholeCamera, T_base_camera, *,
                 noise_a: float = 0.0, noise_b: float = 0.0, dropout: float = 0.0, seed: int = 0,
                 engine: str = "auto", error: "CameraError | str | None" = None, error_key=(),
                 support: float | None = None) -> None:
        T = np.asarray(T_base_camera, dtype=np.float64)
        if T.shape != (4, 4) or not np.isfinite(T).all() or not np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3),
                                                                          atol=1e-6):
            raise ValueError("T_base_camera: expected a rigid (4, 4) transform")
        if noise_a < 0 or noise_b < 0 or not 0 <= dropout < 1:
            raise ValueError("noise_a, noise_b must be >= 0 and dropout in [0, 1)")
        if engine not in self.ENGINES:
            raise ValueError(f"engine: must be one of {self.ENGINES}, got {engine!r}")
        self.engine = engine
        if support is not None and (isinstance(support, bool) or not isinstance(support, (int, float))
                                    or not math.isfinite(support)):
            raise ValueError(f"support: a table's height [m] or None, got {support!r}")
        self.support = None if support is None else float(support)
        self.mesh, self.intrinsics, self.T_base_camera = mesh, intrinsics, T
        self.noise_a, self.noise_b, self.dropout = float(noise_a), float(noise_b), float(dropout)
        self._rng = np.random.default_rng(seed)
        self.error = CameraError() if error is None else CameraError.parse(error)
        self.error_key = tuple(int(k) for k in np.atleast_1d(error_key))
        #: The rigid error this camera's captures carry (:meth:`CameraError.draw` of its seed), or None.
        self.applied_error = self.error.drawn(seed, self.error_key)

    @property
    def origin(self) -> np.ndarray:
        """`(3,)` optical centre [m], base frame."""
        return self.T_base_camera[:3, 3].copy()

    def reseeded(self, seed) -> "SimulatedDepthCamera":
        """The same camera with its noise, dropout and extrinsic error drawn from ``seed`` (an int or a sequence of
        ints)."""
        return SimulatedDepthCamera(self.mesh, self.intrinsics, self.T_base_camera, noise_a=self.noise_a,
                                    noise_b=self.noise_b, dropout=self.dropout, seed=seed, engine=self.engine,
                                    error=self.error, error_key=self.error_key, support=self.support)

    def _ray_directions(self) -> np.ndarray:
        """`(pixels, 3)` unit directions of the rays through every pixel centre, base frame."""
        rays = self.intrinsics.rays()
        return (rays / np.linalg.norm(rays, axis=1, keepdims=True)) @ self.T_base_camera[:3, :3].T

    def support_points(self, hit: np.ndarray) -> np.ndarray:
        """Noise-free points on the support plane (:attr:`support`) of the rays that hit nothing else: `(k, 3)` in
        the camera frame, within the camera's depth range and :data:`SUPPORT_REACH` of the mesh's bounding box
        (horizontally); ``hit``: `(j,)` the pixel indices :meth:`depth_points` found on the mesh."""
        dirs = self._ray_directions()
        R, t = self.T_base_camera[:3, :3], self.T_base_camera[:3, 3]
        free = np.ones(len(dirs), dtype=bool)
        free[hit] = False
        down = free & (dirs[:, 2] < -1e-9)
        s = (self.support - t[2]) / np.where(down, dirs[:, 2], -1.0)
        down &= s > 0
        p = t + s[down, None] * dirs[down]
        lo, hi = self.mesh.bounds[0][:2] - SUPPORT_REACH, self.mesh.bounds[1][:2] + SUPPORT_REACH
        near = ((p[:, :2] >= lo) & (p[:, :2] <= hi)).all(axis=1)
        p_cam = (p[near] - t) @ R
        z = p_cam[:, 2]
        return p_cam[(z >= self.intrinsics.min_depth) & (z <= self.intrinsics.max_depth)]

    def depth_points(self) -> tuple[np.ndarray, np.ndarray]:
        """Noise-free first hits: `(k, 3)` points in the camera frame and `(k,)` their pixel indices."""
        R, t = self.T_base_camera[:3, :3], self.T_base_camera[:3, 3]
        dirs = self._ray_directions()
        origins = np.broadcast_to(t, dirs.shape)
        engine = self._ray_engine()
        # trimesh's fallback engine (no embreex) holds every candidate triangle of every ray in memory: chunk it
        chunk = len(dirs) if type(engine).__module__.endswith("ray_pyembree") else 256
        parts = [engine.intersects_location(origins[i:i + chunk], dirs[i:i + chunk], multiple_hits=False)
                 for i in range(0, len(dirs), chunk)]
        # a chunk whose rays all miss comes back as a 1-D empty array: give every part its (k, 3) shape
        hits = np.concatenate([np.reshape(h, (-1, 3)) for h, _, _ in parts] + [np.zeros((0, 3))])
        ray_idx = np.concatenate([np.reshape(r, -1).astype(np.int64) + i * chunk for i, (_, r, _) in enumerate(parts)]
                                 + [np.zeros(0, np.int64)])
        p_cam = (hits - t) @ R
        z = p_cam[:, 2]
        keep = (z >= self.intrinsics.min_depth) & (z <= self.intrinsics.max_depth)
        order = np.argsort(ray_idx[keep])
        return p_cam[keep][order], ray_idx[keep][order]

    def _ray_engine(self):
        if self.engine == "auto":
            engine = self.mesh.ray
            if not type(engine).__module__.endswith("ray_pyembree"):
                _say_once_without_embree()
            return engine
        if self.engine == "embree":
            try:
                from trimesh.ray.ray_pyembree import RayMeshIntersector
            except ImportError as exc:
                from .._extras import install_hint

                raise ImportError(f"engine='embree' needs embreex: {install_hint('raycast')}") from exc
            return RayMeshIntersector(self.mesh)
        from trimesh.ray.ray_triangle import RayMeshIntersector

        return RayMeshIntersector(self.mesh)

    def capture(self) -> PointCloud:
        lost = lost_blocks(self.error, self.intrinsics, self._rng)
        p_cam, hit = self.depth_points()
        points = self._sensed(p_cam, lost)
        if self.support is None:
            return PointCloud(points, self.origin)
        return PointCloud(points, self.origin, support=self._sensed(self.support_points(hit), lost))

    def _sensed(self, p_cam: np.ndarray, lost: np.ndarray | None = None) -> np.ndarray:
        """Noise-free points `(k, 3)` in the camera frame as the camera reports them in the base frame: the lost
        blocks, depth noise, dropout and the extrinsic error applied (:func:`sensed_points`, with :attr:`error`'s
        sensing terms)."""
        return sensed_points(p_cam, self.T_base_camera, self.intrinsics, self._rng, noise_a=self.noise_a,
                             noise_b=self.noise_b, dropout=self.dropout, error=self.error, lost=lost,
                             applied=self.applied_error)


_SAID: set[str] = set()


def _say_once_without_embree() -> None:
    """Say once per process that the simulated camera runs on trimesh's Python ray engine: a run of the simulated
    worlds then spends most of its time in the camera (43 % of a 0.15 m run in one profile), where Embree takes
    milliseconds a frame."""
    if "embree" in _SAID:
        return
    _SAID.add("embree")
    import warnings

    from .._extras import install_hint

    warnings.warn("the simulated camera casts its rays with trimesh's Python engine (embreex is not installed): "
                  f"much slower than Embree; {install_hint('raycast')}", RuntimeWarning, stacklevel=4)
