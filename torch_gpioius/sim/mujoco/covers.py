"""Covers as MuJoCo flexes: cloth (2-D shells) and foam (3-D layers of tetrahedra) around a union of primitives.

A cover is built by *shrink-wrapping* a regular mesh onto the inner object: every vertex of a regular base mesh (a
tube around an axis polyline for limbs, a spherical cap around a centre for torsos) moves inward along its ray
until it is ``offset`` from the object (the first crossing from outside, found by bisection on the exact signed
distance). Regular base meshes give well-shaped elements (marching cubes gives slivers, which make cloth stiff and
unstable); bridging concave regions is what cloth does anyway. The base mesh's boundary (sleeve ends, the back edge
of a shirt front) is pinned, as a garment is held where it is sewn to the rest of itself.

* ``tight``: a cloth shell ``gap`` off the body (default 8 mm, the force-field world's sleeve and shirt).
* ``loose``: a cloth shell built ``slack`` off the body that settles under gravity before exploring.
* ``foam``: a soft 3-D shell of ``thickness``, ``gap`` off the body (prisms between two shrink-wrapped layers, each
  split into three tetrahedra).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .primitives import union_sdf

__all__ = ["CoverMesh", "tube_base", "cap_base", "shrink_wrap", "make_cover", "COVER_KINDS", "cover_flexcomp",
           "CLOTH_YOUNG"]

COVER_KINDS = ("tight", "loose", "foam")

#: Young's modulus of the cloth [Pa] (1 mm thick: a membrane stiffness of 10 N/m, a knit fabric's order). Stiffer
#: cloth carries the fingertip: with 5e4 Pa (the default before 0.4) a loose cover pinned at its rim acts as a
#: trampoline once the fingertip has dragged it taut, the 1 N contact threshold fires on cloth alone, and on a
#: capsule under a loose cover (r = 5 cm, 26 cm long) only 16-20 % of the contacts lay within 1 cm of the body.
#: At 1e4 Pa the cloth stretches and folds under the fingertip and resists where it is pinched against the body:
#: 98-100 % within 1 cm on 3 seeds, with the loose covers as loose as before (docs/results-3d.md, "Cloth you can
#: check"). Unpinned cloth or a 1.2 cm vertex spacing fixed it too, but an unpinned loose sleeve collapses onto the
#: arm (from 7.4 to 4.4 cm of looseness) and the finer cloth runs 3x slower.
CLOTH_YOUNG = 1e4


@dataclass
class CoverMesh:
    """A cover ready for MuJoCo: ``vertices (n, 3)`` [m], ``elements (k, dim + 1)`` (triangles counter-clockwise
    seen from outside, or tetrahedra), ``pinned (p,)`` vertex ids, ``dim`` 2 or 3, and the material."""

    vertices: np.ndarray
    elements: np.ndarray
    pinned: np.ndarray
    dim: int
    kind: str
    radius: float
    young: float
    poisson: float
    thickness: float
    damping: float
    density: float                 # kg/m^2 for cloth, kg/m^3 for foam

    @property
    def outer_faces(self) -> np.ndarray:
        """`(f, 3)` triangles of the outside surface (the cloth itself, or the outer layer of the foam)."""
        if self.dim == 2:
            return self.elements
        return self._foam_outer


def _rotation_to(z: np.ndarray) -> np.ndarray:
    z = z / np.linalg.norm(z)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], axis=1)


def tube_base(axis_points, spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A regular tube around an axis polyline: ray origins on the axis and outward directions, rings every
    ``spacing`` [m] along the axis with the same number of vertices around.

    Returns:
        ``origins (n, 3)``, ``directions (n, 3)`` (unit, perpendicular to the axis), ``faces (k, 3)`` and the
        boundary vertex ids (the first and last rings).
    """
    pts = np.asarray(axis_points, dtype=np.float64)
    seg = np.diff(pts, axis=0)
    lengths = np.linalg.norm(seg, axis=1)
    total = float(lengths.sum())
    n_rings = max(2, int(math.ceil(total / spacing)) + 1)
    s = np.linspace(0, total, n_rings)
    cum = np.r_[0.0, np.cumsum(lengths)]
    n_around = 16
    origins, dirs = [], []
    frame = _rotation_to(seg[0])
    for si in s:
        k = min(int(np.searchsorted(cum, si, side="right")) - 1, len(seg) - 1)
        t = (si - cum[k]) / lengths[k]
        centre = pts[k] + t * seg[k]
        # the ring's plane: perpendicular to the segment, bisecting at interior polyline corners
        tangent = seg[k] / lengths[k]
        if t < 1e-9 and k > 0:
            tangent = tangent + seg[k - 1] / lengths[k - 1]
        tangent /= np.linalg.norm(tangent)
        # parallel transport of the previous frame: no twist along the tube
        x = frame[:, 0] - (frame[:, 0] @ tangent) * tangent
        x /= np.linalg.norm(x)
        frame = np.stack([x, np.cross(tangent, x), tangent], axis=1)
        for j in range(n_around):
            a = 2 * math.pi * j / n_around
            origins.append(centre)
            dirs.append(math.cos(a) * frame[:, 0] + math.sin(a) * frame[:, 1])
    faces = []
    for r in range(n_rings - 1):
        for j in range(n_around):
            a, b = r * n_around + j, r * n_around + (j + 1) % n_around
            c, d = a + n_around, b + n_around
            faces += [(a, b, d), (a, d, c)]
    boundary = np.r_[np.arange(n_around), np.arange((n_rings - 1) * n_around, n_rings * n_around)]
    return np.asarray(origins), np.asarray(dirs), np.asarray(faces, dtype=np.int64), boundary


def cap_base(centre, facing, half_angle_deg: float, spacing: float, radius_hint: float) -> tuple:
    """A spherical cap of rays from ``centre`` around the direction ``facing`` (half angle in degrees), vertices
    about ``spacing`` [m] apart at ``radius_hint`` [m] from the centre (the typical distance of the wrapped surface):
    a subdivided icosphere restricted to the cap.

    Returns:
        ``origins (n, 3)``, ``directions (n, 3)``, ``faces (k, 3)``, boundary vertex ids.
    """
    import trimesh

    c = np.asarray(centre, dtype=np.float64)
    f = np.asarray(facing, dtype=np.float64)
    f /= np.linalg.norm(f)
    sub = 1
    while 1.05 * 2.0 ** -sub * radius_hint > spacing and sub < 6:   # icosphere edges ~1.05 / 2^sub on the unit sphere
        sub += 1
    ico = trimesh.creation.icosphere(subdivisions=sub)
    keep = ico.vertices @ f >= math.cos(math.radians(half_angle_deg))
    faces = ico.faces[keep[ico.faces].all(axis=1)]
    used = np.unique(faces)
    remap = -np.ones(len(ico.vertices), dtype=np.int64)
    remap[used] = np.arange(len(used))
    faces = remap[faces]
    dirs = np.asarray(ico.vertices[used])
    sub_mesh = trimesh.Trimesh(dirs, faces, process=False)
    edges = sub_mesh.edges_sorted
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    boundary = np.unique(unique[counts == 1])
    return np.repeat(c[None], len(dirs), axis=0), dirs, faces, boundary


def _sdf_of(body):
    """The signed distance function the cloth meets: of a body's collision geometry (``collision_sdf``; a mesh body's
    convex parts can span a concavity such as a mug's handle), or of a list of primitives."""
    if hasattr(body, "collision_sdf"):
        return body.collision_sdf
    return lambda p: union_sdf(body, p)


def shrink_wrap(body, origins: np.ndarray, directions: np.ndarray, offset: float,
                far: float = 2.0, faces: np.ndarray | None = None) -> np.ndarray:
    """Move from ``origin + far * direction`` inward along each ray to the first point ``offset`` [m] from the
    object (signed distance = offset, bisection to 1e-6 m).

    A ray that never comes within ``offset`` (one that leaves through a cup's opening) has no such point: every point
    along it is farther than ``offset``. With the base mesh's ``faces`` it is placed as a membrane spanning the
    opening would lie: at the harmonic mean over the mesh of its neighbours' distances along their rays, the rays that
    did come within ``offset`` held fixed. Without them, or where no ray of its part of the mesh came within
    ``offset``, it keeps the point where it is closest to the object (for rays from a centre inside an opening, the
    centre itself: several vertices on one point, the degenerate elements :func:`make_cover` refuses).

    Args:
        body: the object: a list of primitives, or a body with ``sdf(points)``
            (:mod:`~torch_gpioius.sim.mujoco.bodies`).
        origins, directions: `(n, 3)` the rays [m] (unit directions).
        offset: distance from the object [m].
        far: where the search starts along each ray [m].
        faces: `(k, 3)` the base mesh's triangles (vertex ids of the rays), to span the rays that never come within
            ``offset``.

    Returns:
        `(n, 3)` the wrapped vertices [m].
    """
    sdf = _sdf_of(body)
    o, d = np.asarray(origins, dtype=np.float64), np.asarray(directions, dtype=np.float64)
    ts = np.linspace(far, 0.0, 401)
    # one batched query (a mesh body's distance is one libigl call for all rays and depths)
    sd = (sdf((o[:, None, :] + ts[None, :, None] * d[:, None, :]).reshape(-1, 3)).reshape(len(o), len(ts))
          - offset)                                                    # (n, 401), from outside in
    inside = sd <= 0
    first = np.where(inside.any(axis=1), inside.argmax(axis=1), sd.argmin(axis=1))
    hi = ts[np.maximum(first - 1, 0)]       # outside
    lo = ts[first]                           # inside (or closest)
    hit = inside.any(axis=1)
    for _ in range(40):
        mid = 0.5 * (hi + lo)
        out = sdf(o + mid[:, None] * d) - offset > 0
        hi = np.where(hit & out, mid, hi)
        lo = np.where(hit & ~out, mid, lo)
    t = np.where(hit, hi, lo)
    if faces is not None and 0 < hit.sum() < len(hit):
        t = _span(t, hit, np.asarray(faces, dtype=np.int64))
    return o + t[:, None] * d


def _span(t: np.ndarray, fixed: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``t`` `(n,)` with the entries not ``fixed`` replaced by the harmonic interpolation of their neighbours over the
    mesh ``faces`` (each free entry the mean of its neighbours; the fixed entries the boundary values). A group of
    free entries with no fixed neighbour anywhere keeps its values.

    Written here because it is ten lines of scipy's sparse solve: the graph Laplacian restricted to the free entries
    (trimesh's smoothing moves the vertices themselves, not one number along each ray)."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components
    from scipy.sparse.linalg import spsolve

    n = len(t)
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    edges = np.unique(np.sort(edges, axis=1), axis=0)
    # each edge once in each direction (unique above), so every entry is 1
    adj = sp.coo_matrix((np.ones(2 * len(edges)), (np.r_[edges[:, 0], edges[:, 1]], np.r_[edges[:, 1], edges[:, 0]])),
                        shape=(n, n)).tocsr()
    free = ~fixed
    rows = adj[free]
    # a free group reaches the boundary values only if one of its vertices has a fixed neighbour
    _, group = connected_components(rows[:, free], directed=False)
    touches = np.asarray(rows[:, fixed].sum(axis=1)).ravel() > 0
    reached = np.isin(group, np.unique(group[touches]))
    idx = np.flatnonzero(free)[reached]
    if not len(idx):
        return t
    lap = sp.diags(np.asarray(adj[idx].sum(axis=1)).ravel()) - adj[idx][:, idx]
    rhs = adj[idx][:, fixed] @ t[fixed]
    out = t.copy()
    out[idx] = spsolve(lap.tocsc(), rhs)
    return out


def _outward(verts: np.ndarray, faces: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """Order each triangle counter-clockwise seen from outside (its normal along the rays' outward direction)."""
    t = verts[faces]
    normal = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    out = dirs[faces].sum(axis=1)
    flip = np.einsum("ij,ij->i", normal, out) < 0
    faces = faces.copy()
    faces[flip] = faces[flip][:, [0, 2, 1]]
    return faces


def _tets_from_prisms(bottom: np.ndarray, faces: np.ndarray, n: int) -> np.ndarray:
    """Split each prism (face in the inner layer, same face + n in the outer) into 3 tetrahedra consistently: each
    quad side is cut by the diagonal from its smallest global vertex id, so neighbours agree."""
    tets = []
    for a, b, c in faces:
        v = sorted([a, b, c])
        a, b, c = v
        A, B, C = a + n, b + n, c + n
        tets += [(a, b, c, A), (b, c, A, B), (c, A, B, C)]
    return np.asarray(tets, dtype=np.int64)


def _areas(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """`(k,)` the areas [m^2] of the triangles ``faces`` `(k, 3)` of ``verts`` `(n, 3)`."""
    t = verts[faces]
    return 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)


def _refuse_degenerate(verts: np.ndarray, faces: np.ndarray) -> None:
    """Refuse a wrapped cover with an element of no area (two vertices on one point, or three on a line): MuJoCo's
    elasticity divides by it, and the first step turns the whole state to NaN."""
    bad = _areas(verts, faces) < 1e-10          # m^2: 0.01 mm^2, where the elements are cm across
    if bad.any():
        where = np.unique(faces[bad])
        first = np.round(verts[where[0]], 4).tolist()
        raise ValueError(f"cover: {int(bad.sum())} of its {len(faces)} elements have no area (vertices "
                         f"{where[:6].tolist()}{' ...' if len(where) > 6 else ''} at {first} "
                         "and its neighbours coincide or lie on a line): rays of the base mesh that never come within "
                         "the cover's distance of the body and have no neighbour that does; move the base's centre "
                         "into the body")


def make_cover(prims, kind: str, base: tuple, *, gap: float = 0.008, slack: float = 0.04,
               thickness: float = 0.015, radius: float = 0.002, young: float | None = None,
               poisson: float | None = None, damping: float | None = None, density: float | None = None,
               pin: bool = True) -> CoverMesh:
    """Shrink-wrap a base mesh (:func:`tube_base` or :func:`cap_base`) onto ``prims`` as a cover of ``kind``.

    Why this many parameters: the cloth's shape (``gap``, ``slack``, ``thickness``, ``radius``) and its material
    (``young``, ``poisson``, ``damping``, ``density``, ``pin``) are MuJoCo's flex attributes one for one, each varied by
    the cover kinds and the studies.

    Args:
        prims: the inner object: a list of primitives or a body (:mod:`~torch_gpioius.sim.mujoco.bodies`).
        kind: "tight", "loose" or "foam".
        base: ``(origins, directions, faces, boundary)`` from a base-mesh function.
        gap: distance of a tight cloth or of the foam's inner layer from the body [m].
        slack: distance of a loose cloth from the body before it settles [m].
        thickness: foam thickness [m].
        radius: collision radius of the flex elements [m].
        young, poisson, damping, density: material (defaults: cloth 1e4 Pa, 0.2, 0.02, 0.15 kg/m^2 (see
            :data:`CLOTH_YOUNG`); foam 2e3 Pa,
            0.3, 0.05, 30 kg/m^3).
        pin: hold the base mesh's boundary fixed (where a garment is sewn to the rest of itself); False lets the
            whole cover slide over the body.

    Raises:
        ValueError: an unknown kind or a non-positive distance.
    """
    from ...core.validation import as_float

    if kind not in COVER_KINDS:
        raise ValueError(f"cover: must be one of {COVER_KINDS}, got {kind!r}")
    gap, slack, thickness, radius = (as_float(v, f"cover option {n}", lo=lo, hi=hi, positive=True, unit="m")
                                     for n, v, lo, hi in (("gap", gap, 0.0, 0.2), ("slack", slack, 0.0, 0.5),
                                                          ("thickness", thickness, 0.0, 0.2),
                                                          ("radius", radius, 0.0005, 0.02)))
    if young is not None:
        young = as_float(young, "cover option young", lo=1.0, hi=1e9, unit="Pa")
    if poisson is not None:
        poisson = as_float(poisson, "cover option poisson", lo=0.0, hi=0.49)
    if damping is not None:
        damping = as_float(damping, "cover option damping", lo=0.0, hi=10.0)
    if density is not None:
        density = as_float(density, "cover option density", lo=1e-3, hi=1e4, positive=True)
    origins, dirs, faces, boundary = base
    if not pin:
        boundary = np.zeros(0, dtype=np.int64)
    if kind == "foam":
        inner = shrink_wrap(prims, origins, dirs, gap, faces=faces)
        outer = shrink_wrap(prims, origins, dirs, gap + thickness, faces=faces)
        _refuse_degenerate(inner, faces)
        _refuse_degenerate(outer, faces)
        n = len(inner)
        verts = np.concatenate([inner, outer])
        elements = _tets_from_prisms(inner, faces, n)
        mesh = CoverMesh(verts, elements, np.r_[boundary, boundary + n], 3, kind, radius,
                         young or 2e3, poisson if poisson is not None else 0.3, thickness,
                         damping if damping is not None else 0.05, density or 30.0)
        mesh._foam_outer = faces + n
        return mesh
    dist = gap if kind == "tight" else slack
    verts = shrink_wrap(prims, origins, dirs, dist, faces=faces)
    _refuse_degenerate(verts, faces)
    faces = _outward(verts, faces, dirs)
    return CoverMesh(verts, faces, boundary, 2, kind, radius, young or CLOTH_YOUNG,
                     poisson if poisson is not None else 0.2, 1e-3, damping if damping is not None else 0.02,
                     density or 0.15)


def cover_mass(cover: CoverMesh) -> float:
    """Total mass [kg] from the material density and the cover's area (cloth) or volume (foam)."""
    v = cover.vertices
    if cover.dim == 2:
        return float(cover.density * _areas(v, cover.elements).sum())
    t = v[cover.elements]
    vol = np.abs(np.einsum("ij,ij->i", t[:, 1] - t[:, 0], np.cross(t[:, 2] - t[:, 0], t[:, 3] - t[:, 0]))).sum() / 6
    return float(cover.density * vol)


def cover_flexcomp(cover: CoverMesh, name: str = "cover", group: int = 1) -> str:
    """The ``<flexcomp type="direct">`` of a cover (contacts with the body and the fingertip, self-contact off)."""
    points = " ".join(f"{x:.6f}" for x in cover.vertices.reshape(-1))
    elements = " ".join(str(int(i)) for i in cover.elements.reshape(-1))
    pins = " ".join(str(int(i)) for i in np.unique(cover.pinned))
    elastic2d = ' elastic2d="both"' if cover.dim == 2 else ""
    return (f'<flexcomp name="{name}" type="direct" dim="{cover.dim}" radius="{cover.radius}" '
            f'mass="{cover_mass(cover):.6g}" group="{group}" rgba=".3 .5 .8 .8" point="{points}" element="{elements}">'
            f'<contact selfcollide="none" condim="3" friction="0.5" solref="0.004 1" solimp=".95 .99 .0001"/>'
            f'<elasticity young="{cover.young:g}" poisson="{cover.poisson:g}" thickness="{cover.thickness:g}"'
            f'{elastic2d} damping="{cover.damping:g}"/>'
            + (f'<pin id="{pins}"/>' if pins else "") + "</flexcomp>")
