"""The simulated depth camera of the force-field world and of any user's mesh: a pinhole camera that casts a ray
through every pixel at the body, with the depth noise of its model, and the errors a real one has beyond it (a
calibration that is off, pixels and blocks lost: :class:`CameraError`). Its captures are
:class:`~torch_gpioius.sensors.pointcloud.PointCloud` objects like every other source's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import trimesh

from ..pointcloud import PinholeCamera, PointCloud, PointCloudSource, rigid_about, rotation_matrix

__all__ = ["SimulatedDepthCamera", "CameraError", "AppliedCameraError", "view_errors", "error_key", "lost_blocks",
           "sensed_points", "HOLE_BLOCKS", "SUPPORT_REACH"]


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

    Why this many parameters: after the body and the camera's intrinsics and pose, each is one property of the simulated
    sensor (its depth noise model, dropout, seed, ray engine, calibration error, what it keeps apart), all keywords with
    the real camera's defaults.

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
                from ...core.extras import install_hint

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

    from ...core.extras import install_hint

    warnings.warn("the simulated camera casts its rays with trimesh's Python engine (embreex is not installed): "
                  f"much slower than Embree; {install_hint('raycast')}", RuntimeWarning, stacklevel=4)
