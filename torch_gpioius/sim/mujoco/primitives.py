"""Rigid inner objects as unions of MuJoCo primitives, with their exact signed distance and surface samples.

MuJoCo collides meshes as their convex hulls, so a non-convex body (an arm bent at the elbow, a torso with
shoulders) is a union of capsules, boxes, spheres, ellipsoids and cylinders. Each primitive is a dict in MuJoCo's
conventions: ``{"type", "size", "pos", "quat"}`` (SI units, base frame, quaternion w-x-y-z), ``size`` as MuJoCo
reads it (sphere ``[r]``, capsule / cylinder ``[r, half-length]`` along the local z axis, box and ellipsoid
half-extents ``[x, y, z]``). The metrics use the exact signed distance of the union (negative inside), not a mesh.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Primitive", "as_primitives", "union_sdf", "union_surface_samples", "rounded_box_primitives",
           "capsule_between"]

_SIZES = {"sphere": 1, "capsule": 2, "cylinder": 2, "box": 3, "ellipsoid": 3}


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


@dataclass(frozen=True)
class Primitive:
    """One validated primitive: ``type``, ``size`` `(k,)`, ``pos`` `(3,)` [m], ``quat`` `(4,)` w-x-y-z (unit)."""

    type: str
    size: tuple
    pos: tuple
    quat: tuple = (1.0, 0.0, 0.0, 0.0)

    @property
    def rotation(self) -> np.ndarray:
        """`(3, 3)` ``R_base_primitive``."""
        return _quat_matrix(np.asarray(self.quat))

    def local(self, p: np.ndarray) -> np.ndarray:
        """`(n, 3)` base-frame points in the primitive's frame."""
        return (np.asarray(p, dtype=np.float64) - np.asarray(self.pos)) @ self.rotation

    def sdf(self, p: np.ndarray) -> np.ndarray:
        """`(n,)` exact signed distance [m] from base-frame points `(n, 3)` (negative inside)."""
        q = self.local(p)
        s = np.asarray(self.size)
        if self.type == "sphere":
            return np.linalg.norm(q, axis=1) - s[0]
        if self.type == "capsule":
            z = np.clip(q[:, 2], -s[1], s[1])
            return np.linalg.norm(q - np.c_[np.zeros_like(z), np.zeros_like(z), z], axis=1) - s[0]
        if self.type == "cylinder":
            d = np.c_[np.hypot(q[:, 0], q[:, 1]) - s[0], np.abs(q[:, 2]) - s[1]]
            return np.minimum(d.max(axis=1), 0.0) + np.linalg.norm(np.maximum(d, 0.0), axis=1)
        if self.type == "box":
            d = np.abs(q) - s
            return np.minimum(d.max(axis=1), 0.0) + np.linalg.norm(np.maximum(d, 0.0), axis=1)
        return _ellipsoid_sdf(q, s)

    def surface_samples(self, spacing: float, rng: np.random.Generator) -> np.ndarray:
        """`(n, 3)` points on the primitive's surface [m, base frame], about one per ``spacing``^2, area-uniform."""
        s = np.asarray(self.size)
        if self.type == "sphere":
            area = 4 * math.pi * s[0] ** 2
            v = rng.standard_normal((max(50, int(area / spacing ** 2)), 3))
            q = s[0] * v / np.linalg.norm(v, axis=1, keepdims=True)
        elif self.type in ("capsule", "cylinder"):
            r, h = s
            side = 2 * math.pi * r * 2 * h
            ends = 4 * math.pi * r * r if self.type == "capsule" else 2 * math.pi * r * r
            n_side, n_end = max(50, int(side / spacing ** 2)), max(20, int(ends / spacing ** 2))
            a = rng.uniform(0, 2 * math.pi, n_side)
            pts = [np.c_[r * np.cos(a), r * np.sin(a), rng.uniform(-h, h, n_side)]]
            if self.type == "capsule":
                v = rng.standard_normal((n_end, 3))
                v = r * v / np.linalg.norm(v, axis=1, keepdims=True)
                v[:, 2] += np.where(v[:, 2] >= 0, h, -h)
                pts.append(v)
            else:
                rr, aa = r * np.sqrt(rng.uniform(0, 1, n_end)), rng.uniform(0, 2 * math.pi, n_end)
                pts.append(np.c_[rr * np.cos(aa), rr * np.sin(aa), np.where(rng.uniform(size=n_end) < 0.5, -h, h)])
            q = np.concatenate(pts)
        elif self.type == "box":
            faces = []
            for axis in range(3):
                u, v = [k for k in range(3) if k != axis]
                area = 4 * s[u] * s[v]
                n = max(20, int(area / spacing ** 2))
                for sign in (-1.0, 1.0):
                    f = np.zeros((n, 3))
                    f[:, axis] = sign * s[axis]
                    f[:, u] = rng.uniform(-s[u], s[u], n)
                    f[:, v] = rng.uniform(-s[v], s[v], n)
                    faces.append(f)
            q = np.concatenate(faces)
        else:   # ellipsoid: radial projection of a dense sphere sample (not area-uniform; dense enough for metrics)
            area = 4 * math.pi * (np.prod(s) ** (2 / 3))
            v = rng.standard_normal((max(200, int(4 * area / spacing ** 2)), 3))
            v /= np.linalg.norm(v, axis=1, keepdims=True)
            q = v * s
        return q @ self.rotation.T + np.asarray(self.pos)

    def mjcf(self, name: str, group: int = 0, rgba: str = ".85 .7 .55 1") -> str:
        """The ``<geom>`` of this primitive (static: in the world body)."""
        size = " ".join(f"{v:.17g}" for v in self.size)
        pos = " ".join(f"{v:.17g}" for v in self.pos)
        quat = " ".join(f"{v:.17g}" for v in self.quat)
        return (f'<geom name="{name}" type="{self.type}" size="{size}" pos="{pos}" quat="{quat}" group="{group}" '
                f'condim="3" friction="0.6 0.005 0.0001" solref="0.002 1" rgba="{rgba}"/>')


def _ellipsoid_sdf(q: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Exact distance to an ellipsoid (half-axes ``s``) by the closest-point root of Eberly's method (bisection on
    the Lagrange multiplier), signed by the implicit function; q in the ellipsoid's frame."""
    q = np.asarray(q, dtype=np.float64)
    a = np.asarray(s, dtype=np.float64)
    inside = ((q / a) ** 2).sum(1) < 1
    y = np.abs(q)
    # closest point x_i = a_i^2 y_i / (a_i^2 + t); solve sum (a_i y_i / (a_i^2 + t))^2 = 1 for t > -min a^2
    lo = np.full(len(q), -np.min(a) ** 2 + 1e-18)
    hi = np.full(len(q), np.max(a) * np.linalg.norm(y, axis=1) + 1e-12)
    for _ in range(200):
        t = 0.5 * (lo + hi)
        g = ((a * y / (a * a + t[:, None])) ** 2).sum(1) - 1
        lo = np.where(g > 0, t, lo)
        hi = np.where(g > 0, hi, t)
    t = 0.5 * (lo + hi)
    x = a * a * y / (a * a + t[:, None])
    d = np.linalg.norm(y - x, axis=1)
    return np.where(inside, -d, d)


def as_primitives(specs) -> list[Primitive]:
    """Validate ``{"type", "size", "pos", "quat"}`` dicts (MuJoCo conventions) into :class:`Primitive` objects.

    Raises:
        ValueError: an unknown type, a size with the wrong count or a non-positive / non-finite entry, a bad position
            or quaternion; the message names the primitive's index.
    """
    if isinstance(specs, dict) or not hasattr(specs, "__iter__"):
        raise ValueError("inner: expected a list of primitives {'type', 'size', 'pos', 'quat'}")
    out = []
    for i, spec in enumerate(specs):
        if not isinstance(spec, dict):
            raise ValueError(f"inner[{i}]: expected a dict with 'type', 'size', 'pos' (and 'quat'), got {spec!r}")
        kind = spec.get("type")
        if kind not in _SIZES:
            raise ValueError(f"inner[{i}]: type must be one of {sorted(_SIZES)}, got {kind!r}")
        try:
            size = np.asarray(spec.get("size"), dtype=np.float64).reshape(-1)
            pos = np.asarray(spec.get("pos", (0.0, 0.0, 0.0)), dtype=np.float64).reshape(-1)
            quat = np.asarray(spec.get("quat", (1.0, 0.0, 0.0, 0.0)), dtype=np.float64).reshape(-1)
        except (TypeError, ValueError):
            raise ValueError(f"inner[{i}]: size, pos and quat must be numbers") from None
        if size.shape != (_SIZES[kind],) or not np.isfinite(size).all() or (size < 1e-3).any() or (size > 2).any():
            raise ValueError(f"inner[{i}]: a {kind} needs {_SIZES[kind]} size value(s) between 1 mm and 2 m, got "
                             f"{spec.get('size')!r}")
        if pos.shape != (3,) or not np.isfinite(pos).all() or (np.abs(pos) > 10).any():
            raise ValueError(f"inner[{i}]: pos must be a finite (3,) position within 10 m of the base [m], got "
                             f"{spec.get('pos')!r}")
        if quat.shape != (4,) or not np.isfinite(quat).all() or np.linalg.norm(quat) < 1e-9:
            raise ValueError(f"inner[{i}]: quat must be a non-zero (4,) quaternion w-x-y-z, got {spec.get('quat')!r}")
        quat = quat / np.linalg.norm(quat)
        out.append(Primitive(kind, tuple(size), tuple(pos), tuple(quat)))
    if not out:
        raise ValueError("inner: at least one primitive is needed")
    return out


def union_sdf(primitives: list[Primitive], p: np.ndarray) -> np.ndarray:
    """`(n,)` signed distance to the union [m]: exact outside and on the surface (the minimum of exact distances);
    inside, a lower bound of the depth."""
    p = np.asarray(p, dtype=np.float64).reshape(-1, 3)
    return np.min([prim.sdf(p) for prim in primitives], axis=0)


def union_surface_samples(primitives: list[Primitive], spacing: float, seed: int = 0) -> np.ndarray:
    """`(n, 3)` samples of the union's surface: each primitive's surface points not inside any other primitive."""
    rng = np.random.default_rng(seed)
    pts = np.concatenate([p.surface_samples(spacing, rng) for p in primitives])
    return pts[union_sdf(primitives, pts) > -1e-9]


def capsule_between(a, b, radius: float) -> dict:
    """A capsule primitive spec around the segment a-b (`(3,)` each) [m]."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    axis = b - a
    length = float(np.linalg.norm(axis))
    if length == 0:
        raise ValueError("capsule_between: the end points coincide")
    z = axis / length
    # quaternion rotating (0, 0, 1) onto z
    w = 1.0 + z[2]
    if w < 1e-12:
        quat = (0.0, 1.0, 0.0, 0.0)
    else:
        q = np.array([w, -z[1], z[0], 0.0])
        quat = tuple(q / np.linalg.norm(q))
    return {"type": "capsule", "size": (radius, length / 2), "pos": tuple((a + b) / 2), "quat": quat}


def rounded_box_primitives(center, half_extents, radius: float) -> list[dict]:
    """An axis-aligned box with rounded edges (``half_extents`` include the rounding) as 3 boxes and 12 capsules:
    the Minkowski sum of the inner box and a sphere of ``radius``, exactly."""
    c = np.asarray(center, dtype=np.float64)
    h = np.asarray(half_extents, dtype=np.float64) - radius
    if radius <= 0 or (h <= 0).any():
        raise ValueError("rounded_box_primitives: half extents must exceed the rounding radius > 0")
    out = []
    for axis in range(3):
        size = h.copy()
        size[axis] += radius
        out.append({"type": "box", "size": tuple(size), "pos": tuple(c)})
    for axis in range(3):
        u, v = [k for k in range(3) if k != axis]
        for su in (-1, 1):
            for sv in (-1, 1):
                a, b = c.copy(), c.copy()
                a[u] += su * h[u]
                b[u] += su * h[u]
                a[v] += sv * h[v]
                b[v] += sv * h[v]
                a[axis] -= h[axis]
                b[axis] += h[axis]
                out.append(capsule_between(a, b, radius))
    return out
