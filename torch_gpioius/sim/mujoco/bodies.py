"""The hidden body of a MuJoCo scene: a union of primitives, or any closed mesh split into convex parts.

A body tells the scene four things: its exact signed distance (metrics, the cover's shrink-wrap, where a contact
lies), samples of its surface (the Hausdorff reference), the MJCF that makes it collide, and a fingerprint.

**Why convex parts.** MuJoCo collides a mesh geom as its convex hull: a mug would collide as a cup with its handle's
hole filled, a bunny as a potato, and the fingertip would stop on the hull, centimetres from the surface being
estimated. MuJoCo's alternative for non-convex shapes, a signed-distance geom, needs an SDF plugin; the ``mujoco``
wheel bundles only analytic ones (nut, torus, bowl, gear, bolt; the mesh plugin built on sdflib is not in it), so a
mesh SDF would mean compiling our own plugin. :class:`MeshBody` therefore decomposes the mesh with CoACD (Wei et al.
2022, collision-aware approximate convex decomposition; the ``coacd`` package) into parts whose union follows the
surface to within ``threshold`` (a concavity measure relative to the object's size), and the parts collide as
themselves. ``benchmarks/mesh_collision.py`` measures how far from the true surface each choice stops the fingertip.
The metrics and the cover always use the exact distance to the mesh itself, never the parts.

Decompositions take seconds to minutes; they are cached on disk by the mesh's content and the settings
(``$XDG_CACHE_HOME/torch_gpioius/coacd``, default ``~/.cache``).
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np
import trimesh

from .primitives import Primitive, as_primitives, union_sdf, union_surface_samples

__all__ = ["PrimitiveBody", "MeshBody", "as_body", "COLLISION_MODES"]

#: How a mesh body collides: "convex" (CoACD parts, the default), "hull" (MuJoCo's own convex hull of the whole mesh:
#: only right for convex objects; kept for the comparison in ``benchmarks/mesh_collision.py``).
COLLISION_MODES = ("convex", "hull")
_GEOM_CONTACT = 'condim="3" friction="0.6 0.005 0.0001" solref="0.002 1" rgba=".85 .7 .55 1"'


class PrimitiveBody:
    """A body made of MuJoCo primitives (:mod:`~torch_gpioius.sim.mujoco.primitives`), exact in collision and in
    distance."""

    kind = "primitives"

    def __init__(self, primitives) -> None:
        prims = list(primitives)
        self.primitives = prims if prims and all(isinstance(p, Primitive) for p in prims) else as_primitives(prims)

    def sdf(self, points: np.ndarray) -> np.ndarray:
        """`(n,)` signed distance [m] of `(n, 3)` points (negative inside)."""
        return union_sdf(self.primitives, points)

    #: What MuJoCo collides with is the primitives themselves.
    collision_sdf = sdf

    def surface_samples(self, spacing: float) -> np.ndarray:
        """`(n, 3)` samples of the surface [m], about one per ``spacing``^2."""
        return union_surface_samples(self.primitives, spacing)

    @property
    def centre(self) -> np.ndarray:
        return np.mean([p.pos for p in self.primitives], axis=0)

    def assets(self) -> str:
        return ""

    def geoms(self) -> str:
        return "\n".join(p.mjcf(f"inner_{i}") for i, p in enumerate(self.primitives))

    def fingerprint(self) -> list:
        return [np.array([list(p.size) + [0.0] * (3 - len(p.size)) + list(p.pos) + list(p.quat)
                          for p in self.primitives])]

    def __len__(self) -> int:
        return len(self.primitives)

    def describe(self) -> str:
        return f"{len(self.primitives)} primitives"


def _cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "torch_gpioius" / "coacd"


def convex_parts(mesh: trimesh.Trimesh, threshold: float = 0.05, max_parts: int = 32, seed: int = 0,
                 cache: bool = True) -> list[trimesh.Trimesh]:
    """A mesh as convex parts by CoACD (cached on disk, see the module docstring).

    Args:
        mesh: a closed mesh [m].
        threshold: CoACD's concavity threshold (0.01-1; smaller follows the surface more closely with more parts).
        max_parts: the most parts (CoACD merges beyond it).
        seed: CoACD's random seed (the same seed gives the same parts).
        cache: read and write the disk cache.

    Returns:
        Convex ``trimesh.Trimesh`` parts [m] whose union approximates ``mesh``.
    """
    import torch  # noqa: F401  (imported before coacd: the other order left torch.jit hanging on import)

    try:
        import coacd
    except ImportError as exc:   # pragma: no cover - depends on the environment
        from ...core.extras import install_hint

        raise ImportError(f"a mesh body in the MuJoCo world needs 'coacd': {install_hint('mujoco')}") from exc
    key = hashlib.sha256(np.ascontiguousarray(mesh.vertices, dtype=np.float64).tobytes()
                         + np.ascontiguousarray(mesh.faces, dtype=np.int64).tobytes()
                         + json.dumps([threshold, max_parts, seed, 1000, 60,
                                       getattr(coacd, "__version__", "")]).encode()
                         ).hexdigest()[:24]
    path = _cache_dir() / f"{key}.npz"
    if cache and path.exists():
        try:
            data = np.load(path)
            return [trimesh.Trimesh(data[f"v{i}"], data[f"f{i}"], process=False)
                    for i in range(int(data["count"]))]
        except (OSError, ValueError, KeyError):
            pass                                    # a damaged cache entry is recomputed and overwritten
    coacd.set_log_level("error")
    # CoACD's defaults (2000 samples per hull, 150 tree-search iterations, its own manifold preprocessing) took over
    # ten minutes on pybullet's duck; these settings take 4 s with 11 parts at threshold 0.05 (benchmarks/
    # mesh_collision.py measures the parts' fidelity). The preprocessing is off because load_mesh has already made
    # the mesh closed and manifold.
    raw = coacd.run_coacd(coacd.Mesh(np.asarray(mesh.vertices, dtype=np.float64),
                                     np.asarray(mesh.faces, dtype=np.int64)),
                          threshold=float(threshold), max_convex_hull=int(max_parts), seed=int(seed),
                          preprocess_mode="off", resolution=1000, mcts_iterations=60, mcts_nodes=10,
                          mcts_max_depth=2)
    parts = [trimesh.Trimesh(v, f, process=True) for v, f in raw]
    parts = [p.convex_hull for p in parts if len(p.faces) >= 4]
    if cache:
        # written to a temporary name and renamed, so a reader never sees half a file (the io layer's atomic_write
        # sits above this one)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f"{path.stem}.{os.getpid()}.tmp.npz")
        np.savez(tmp, count=len(parts), **{f"v{i}": p.vertices for i, p in enumerate(parts)},
                 **{f"f{i}": p.faces for i, p in enumerate(parts)})
        os.replace(tmp, path)
    return parts


class MeshBody:
    """A body given by a closed triangle mesh (:func:`torch_gpioius.sim.meshes.load_mesh` makes one from a file).

    Args:
        mesh: closed ``trimesh.Trimesh`` [m], base frame.
        collision: "convex" (CoACD parts) or "hull" (see :data:`COLLISION_MODES`).
        threshold: CoACD's concavity threshold (:func:`convex_parts`).
        max_parts: CoACD's most parts.
        name: label.

    Raises:
        ValueError: a mesh that is not closed, an unknown collision mode.
    """

    kind = "mesh"

    def __init__(self, mesh: trimesh.Trimesh, collision: str = "convex", *, threshold: float = 0.05,
                 max_parts: int = 32, name: str = "inner") -> None:
        from ..meshes import MeshDistance

        if collision not in COLLISION_MODES:
            raise ValueError(f"collision: must be one of {COLLISION_MODES}, got {collision!r}")
        self.mesh, self.collision, self.name = mesh, collision, name
        self.distance = MeshDistance(mesh)               # refuses an open mesh
        self.parts = convex_parts(mesh, threshold, max_parts) if collision == "convex" else [mesh.convex_hull]
        self.threshold, self.max_parts = float(threshold), int(max_parts)
        self._part_distances = None

    def sdf(self, points: np.ndarray) -> np.ndarray:
        """`(n,)` exact signed distance [m] to the mesh itself (not its parts) of `(n, 3)` points."""
        return self.distance(points)

    def collision_sdf(self, points: np.ndarray) -> np.ndarray:
        """`(n,)` signed distance [m] to what MuJoCo collides with: the union of the convex parts and the mesh (the
        parts can reach past the mesh, e.g. across a mug's handle; a cover must start outside both)."""
        from ..meshes import MeshDistance

        if self._part_distances is None:
            self._part_distances = [MeshDistance(p) for p in self.parts]
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        out = self.distance(p)
        for d in self._part_distances:
            out = np.minimum(out, d(p))
        return out

    def surface_samples(self, spacing: float) -> np.ndarray:
        from ...geometry.surfaces import surface_samples

        return surface_samples(self.mesh, spacing)

    @property
    def centre(self) -> np.ndarray:
        return np.asarray(self.mesh.bounds.mean(axis=0))

    def assets(self) -> str:
        out = []
        for i, p in enumerate(self.parts):
            v = " ".join(f"{x:.9g}" for x in np.asarray(p.vertices).reshape(-1))
            f = " ".join(str(int(k)) for k in np.asarray(p.faces).reshape(-1))
            out.append(f'<mesh name="inner_part_{i}" vertex="{v}" face="{f}"/>')
        return "\n".join(out)

    def geoms(self) -> str:
        return "\n".join(f'<geom name="inner_{i}" type="mesh" mesh="inner_part_{i}" group="0" {_GEOM_CONTACT}/>'
                         for i in range(len(self.parts)))

    def fingerprint(self) -> list:
        return [np.asarray(self.mesh.vertices), np.asarray(self.mesh.faces),
                np.array([COLLISION_MODES.index(self.collision), self.threshold, self.max_parts])]

    def __len__(self) -> int:
        return len(self.parts)

    def describe(self) -> str:
        return f"a mesh of {len(self.mesh.faces)} faces colliding as {len(self.parts)} convex part(s)"


def as_body(inner):
    """A :class:`PrimitiveBody` or :class:`MeshBody` from either, from primitive specs, or from a closed mesh."""
    if isinstance(inner, (PrimitiveBody, MeshBody)):
        return inner
    if isinstance(inner, trimesh.Trimesh):
        return MeshBody(inner)
    return PrimitiveBody(inner)
