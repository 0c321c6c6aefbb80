"""A user's own object as the hidden body: load a mesh file, check it, repair what can be repaired (and say by how
much the repair moved the surface), refuse what cannot, and measure exact signed distances to it.

Real scans are rarely closed: a bottle STL from a scanner has holes where the scanner could not see and
non-manifold edges where patches meet. Inside and outside, and therefore the signed distance every world needs, are
undefined on such a mesh. :func:`load_mesh` handles it in these stages:

1. **Clean**: merge duplicate vertices, drop degenerate and duplicate faces and unreferenced vertices (losslessly).
2. **Hole filling** when every edge is manifold: each hole is closed by a fan of new triangles around the
   centroid of its rim; the rest of the surface is untouched.
3. **Exact union** of a closed mesh made of overlapping closed pieces (pybullet's convex decompositions, procedural
   objects): a mesh boolean (manifold3d, the ``shapes`` extra) removes the faces inside another piece and keeps the
   outer surface where it was (:func:`exact_union`).
4. **Watertight remesh** otherwise (or without manifold3d): the generalized winding number of the input (libigl;
   Jacobson et al. 2013) is evaluated on a grid and its 1/2 level set is meshed by marching cubes. The winding number
   is defined for open and non-manifold meshes and is ~1 inside and ~0 outside wherever the input nearly encloses a
   volume, so the remesh is closed by construction; its error is about the grid spacing.

Every repair is reported as a :class:`MeshRepairWarning` naming the defects found, how far the input's surface lies
from the repaired one, and how far the new surface reaches from the input (a filled hole's patch reaches about the
hole's radius: it is invented geometry, so it is stated, and its plausibility is the user's call); a repair that
moves the input's surface by more than ``max_repair_distance``, or an input that encloses no volume at all (an open
sheet), is refused with a ``ValueError`` that names the defect. A broken mesh is never explored silently.

Distances use :class:`MeshDistance`: exact point-to-triangle distance from libigl's AABB tree, signed by the
angle-weighted pseudo-normal at the closest point (exact for closed meshes; Baerentzen & Aanaes 2005). libigl is
used rather than trimesh's proximity queries because those cost milliseconds per point and a cover is shrink-wrapped
with ~10^5 queries.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh

__all__ = ["load_mesh", "read_mesh", "inspect_mesh", "repair_mesh", "MeshReport", "MeshRepairWarning", "MeshDistance",
           "MESH_SUFFIXES", "as_pose", "overlapping_components", "exact_union"]

#: Most faces a watertight remesh keeps (finer ones are decimated).
MAX_REMESH_FACES = 20_000
#: File types :func:`load_mesh` reads (by trimesh).
MESH_SUFFIXES = (".stl", ".obj", ".ply", ".glb", ".gltf", ".off")
#: Largest and smallest object extent accepted [m]: a bigger one is almost always in millimetres, a smaller one in
#: metres of a different object (both are refused with the likely cause).
MAX_EXTENT, MIN_EXTENT = 5.0, 0.005


class MeshRepairWarning(UserWarning):
    """A mesh was repaired before use; the message names the defects and the repair's distance from the input."""


@dataclass
class MeshReport:
    """What :func:`inspect_mesh` found.

    Attributes:
        faces, vertices: counts after cleaning.
        boundary_edges: edges with one face (the rims of holes).
        holes: closed loops of boundary edges.
        nonmanifold_edges: edges shared by three or more faces.
        inconsistent_winding: whether neighbouring faces disagree on their orientation.
        removed: faces dropped by cleaning (degenerate or duplicate).
        components: connected pieces.
        overlapping_vertices: vertices of one closed piece inside another (:func:`overlapping_components`).
    """

    faces: int = 0
    vertices: int = 0
    boundary_edges: int = 0
    holes: int = 0
    nonmanifold_edges: int = 0
    inconsistent_winding: bool = False
    removed: int = 0
    components: int = 0
    overlapping_vertices: int = 0
    notes: list[str] = field(default_factory=list)

    @property
    def closed(self) -> bool:
        """Watertight, manifold and consistently wound: inside and outside are defined."""
        return self.boundary_edges == 0 and self.nonmanifold_edges == 0 and not self.inconsistent_winding

    def defects(self) -> str:
        """The defects in words ("" for a closed mesh)."""
        out = []
        if self.holes or self.boundary_edges:
            out.append(f"{self.holes} hole(s) ({self.boundary_edges} boundary edges)")
        if self.nonmanifold_edges:
            out.append(f"{self.nonmanifold_edges} non-manifold edge(s)")
        if self.inconsistent_winding:
            out.append("inconsistent face winding")
        if self.overlapping_vertices:
            out.append(f"{self.components} overlapping closed pieces ({self.overlapping_vertices} vertices inside "
                       "another piece)")
        return ", ".join(out)


def _edge_use(mesh: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray]:
    edges, counts = np.unique(mesh.edges_sorted, axis=0, return_counts=True)
    return edges, counts


def inspect_mesh(mesh: trimesh.Trimesh) -> MeshReport:
    """The defects of a (cleaned) mesh that make inside and outside undefined."""
    edges, counts = _edge_use(mesh)
    boundary = edges[counts == 1]
    holes = 0
    if len(boundary):
        holes = len(trimesh.graph.connected_components(boundary, min_len=1))
    manifold = not (counts > 2).any()
    return MeshReport(faces=len(mesh.faces), vertices=len(mesh.vertices), boundary_edges=int(len(boundary)),
                      holes=int(holes), nonmanifold_edges=int((counts > 2).sum()),
                      inconsistent_winding=bool(manifold and not mesh.is_winding_consistent),
                      components=int(len(trimesh.graph.connected_components(mesh.edges, min_len=1))))


def _clean(mesh: trimesh.Trimesh) -> tuple[trimesh.Trimesh, int]:
    m = trimesh.Trimesh(np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces), process=False)
    n0 = len(m.faces)
    m.merge_vertices()
    m.update_faces(m.nondegenerate_faces(height=1e-12))
    m.update_faces(m.unique_faces())
    m.remove_unreferenced_vertices()
    return m, n0 - len(m.faces)


def _sample(mesh: trimesh.Trimesh, n: int = 20000) -> np.ndarray:
    pts, _ = trimesh.sample.sample_surface(mesh, n, seed=0)
    return np.concatenate([np.asarray(mesh.vertices), pts])


def _distance_between(a: trimesh.Trimesh, b: trimesh.Trimesh, outer_only: bool = False,
                      exclude=None, skip_interior: bool = False) -> tuple[float, float]:
    """How far a repair ``a`` is from its input ``b`` [m]: ``(moved, patched)``, the largest distance of the input's
    surface from the repair (how far existing surface moved) and of the repair's surface from the input (how far new
    patches reach from what was there: about a hole's radius for a filled hole), from dense samples to the other's
    triangles. ``outer_only``: of ``b``, only the samples outside its other pieces count (a union's internal faces
    are gone by design); ``exclude``: a distance to pieces the repair dropped, whose samples of ``b`` do not count;
    ``skip_interior``: samples of ``b`` on its own interior faces (a partition across a bottle's neck, both sides
    inside) do not count either: the winding-number remesh removes them by design, and counting them refused scans
    whose outside did not move at all."""
    patched = MeshDistance(b, signed=False)(_sample(a))
    if outer_only or skip_interior:
        pb, face = trimesh.sample.sample_surface(b, 20000, seed=0)
        normals = np.asarray(b.face_normals)[face]
        keep = np.ones(len(pb), dtype=bool)
        if outer_only:
            keep &= _outside_other_pieces(b, pb, normals)
        if skip_interior:
            keep &= ~_interior_faces(b, pb, normals)
        pb = pb[keep]
    else:
        pb = _sample(b)
    if exclude is not None:
        pb = pb[np.abs(exclude(pb)) > 1e-9]
    moved = MeshDistance(a, signed=False)(pb)
    return float(np.abs(moved).max()), float(np.abs(patched).max())


def _fill_holes(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """Close every hole of a manifold mesh by a fan of triangles around the centroid of its rim (what libigl's
    topological hole filling does; trimesh's ``fill_holes`` closes only triangular and quadrilateral holes, and
    libigl's Python bindings do not expose it), then orient all faces consistently."""
    import igl

    V, F = np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)
    new_v, new_f = [V], [F]
    n = len(V)
    for loop in igl.boundary_loop_all(F):
        loop = np.asarray(loop, dtype=np.int64)
        if len(loop) < 3:
            continue
        new_v.append(V[loop].mean(axis=0)[None])
        # the rim runs along its faces' edges (a -> b); the fan uses each rim edge reversed (b -> a)
        new_f.append(np.c_[np.roll(loop, -1), loop, np.full(len(loop), n)])
        n += 1
    m = trimesh.Trimesh(np.concatenate(new_v), np.concatenate(new_f), process=False)
    trimesh.repair.fix_winding(m)
    with np.errstate(invalid="ignore", divide="ignore"):     # a flat sheet, filled, has zero volume (refused later)
        trimesh.repair.fix_normals(m)
    return m


def exact_union(mesh: trimesh.Trimesh) -> trimesh.Trimesh | None:
    """The union of a closed mesh's overlapping closed pieces by an exact mesh boolean (manifold3d, trimesh's
    ``manifold`` engine), or None where it cannot be had: manifold3d not installed (``pip install
    'torch_gpioius[shapes]'``; the caller then remeshes the union by its winding number), or a result that is not
    closed or encloses less than the largest piece (a boolean that failed quietly).

    The union removes the faces that lie inside another piece and keeps every other face where it was: its surface is
    the input's outer surface (to manifold3d's single precision, ~1e-7 of the size), where the remesh moves it by up
    to a grid cell (9.2 mm on pybullet's ``random_urdfs/990``: 85 pieces)."""
    try:
        import manifold3d  # noqa: F401  (trimesh's "manifold" engine)
    except ImportError:
        return None
    parts = mesh.split(only_watertight=False)
    try:
        united = trimesh.boolean.union(parts, engine="manifold")
    except (ValueError, RuntimeError):
        return None
    if not isinstance(united, trimesh.Trimesh) or len(united.faces) == 0 or not inspect_mesh(united).closed:
        return None
    with np.errstate(invalid="ignore", divide="ignore"):
        if not united.volume >= (1 - 1e-9) * max(abs(p.volume) for p in parts):
            return None
    if united.volume < 0:
        united.invert()
    return united


def overlapping_components(mesh: trimesh.Trimesh) -> int:
    """How many vertices of a closed mesh lie inside another of its components (0 for one component).

    Closed pieces that overlap (a model made of convex hulls, like pybullet's teddy) are each closed, so the mesh
    passes every edge test; but the union's inside is where the generalized winding number is at least 1/2, and a
    surface vertex of one piece inside another has a winding number near 1.5 there. Such a mesh has internal faces,
    and the distance to its nearest face is not the distance to the body's surface."""
    if int(len(trimesh.graph.connected_components(mesh.edges, min_len=1))) < 2:
        return 0
    return int((~_outside_other_pieces(mesh, np.asarray(mesh.vertices), np.asarray(mesh.vertex_normals))).sum())


def _outside_other_pieces(mesh: trimesh.Trimesh, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """`(n,)` bool: surface points `(n, 3)` that no other piece of ``mesh`` encloses. Each is moved a little outward
    along its normal `(n, 3)` first, where the generalized winding number is ~0 outside every piece and ~1 inside
    another (on the surface itself it is ill-conditioned)."""
    import igl

    eps = 1e-3 * float(mesh.extents.max())
    q = np.asarray(points, dtype=np.float64) + eps * np.asarray(normals, dtype=np.float64)
    w = igl.fast_winding_number(np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64), q)
    return np.abs(w) < 0.5


def _interior_faces(mesh: trimesh.Trimesh, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """`(n,)` bool: surface points `(n, 3)` of ``mesh`` with its inside on both sides (an internal partition). A point
    of the outer surface has a side where the generalized winding number is ~0 (outside); across a partition it
    jumps between ~1/2 and ~3/2, never near 0. Tested a little off the surface on both sides along ``normals``."""
    import igl

    eps = 1e-3 * float(mesh.extents.max())
    V, F = np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)
    p, n = np.asarray(points, dtype=np.float64), np.asarray(normals, dtype=np.float64)
    w_out = np.abs(igl.fast_winding_number(V, F, p + eps * n))
    w_in = np.abs(igl.fast_winding_number(V, F, p - eps * n))
    return np.minimum(w_out, w_in) > 0.25


#: The most nodes a sampled grid may have (a cover's, a repair's remesh): at about 80 bytes a node, 2 GB.
MAX_GRID_NODES = 25_000_000


def check_grid(lo, hi, h: float, name: str, what: str) -> None:
    """Refuse a grid of spacing ``h`` [m] over the box ``lo``..``hi`` [m] with more than :data:`MAX_GRID_NODES` nodes,
    before it is allocated, naming the setting ``name`` and the spacing it would take (a scene's
    ``object.resolution = 2e-4`` allocated 4.5 GB, then died with a raw ``_ArrayMemoryError``).

    Raises:
        ValueError: naming ``name``, the nodes, the memory and the smallest spacing that fits.
    """
    extent = np.maximum(np.asarray(hi, dtype=float) - np.asarray(lo, dtype=float), 0.0)
    nodes = float(np.prod(np.floor(extent / h) + 1))
    if nodes > MAX_GRID_NODES:
        smallest = float(np.cbrt(np.prod(extent) / MAX_GRID_NODES)) * 1.05
        raise ValueError(f"{name}: {h * 1e3:.3g} mm over {what} of {' x '.join(f'{e:.3g}' for e in extent)} m needs "
                         f"{nodes:.3g} grid nodes (about {nodes * 80 / 1e9:.2g} GB); at most {MAX_GRID_NODES:.3g}: "
                         f"use {smallest * 1e3:.2g} mm or more")


#: At most this many non-manifold edges are split locally (:func:`split_nonmanifold`); more go to the remesh.
MAX_LOCAL_SPLITS = 20


def split_nonmanifold(mesh: trimesh.Trimesh) -> tuple[trimesh.Trimesh, int]:
    """The mesh with each vertex of a non-manifold edge (one that more than two faces share) given one copy per piece
    of surface that meets there: pieces that only touched along an edge (two closed parts of a procedural object, a
    stray fin on a scan) become separate pieces with the same surface. A piece is a set of faces joined through
    manifold edges (the whole mesh's, not only those around the vertex: a wall torn by a hole next to the edge stays
    one piece). Written here because trimesh and libigl repair non-manifold meshes only by remeshing them, which moves
    the whole surface.

    Returns:
        ``(mesh, vertices split)``: a new mesh (the input untouched), and how many vertex copies were made.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    faces = np.asarray(mesh.faces, dtype=np.int64).copy()
    edges = np.sort(faces[:, [[0, 1], [1, 2], [2, 0]]], axis=2)               # (f, 3, 2): each face's edges
    keys, inverse, counts = np.unique(edges.reshape(-1, 2), axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    bad = counts > 2
    if not bad.any():
        return mesh.copy(), 0
    # the pieces: faces joined through manifold edges (the two faces of each edge that has exactly two)
    owner = np.repeat(np.arange(len(faces)), 3)
    manifold = counts[inverse] == 2
    order = np.argsort(inverse[manifold], kind="stable")
    pairs = owner[manifold][order].reshape(-1, 2)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(faces),) * 2)
    _, piece = connected_components(graph, directed=False)
    vertices = [np.asarray(mesh.vertices, dtype=np.float64)]
    extra, split = len(mesh.vertices), 0
    for v in np.unique(keys[bad]):
        fan = np.flatnonzero((faces == v).any(axis=1))
        groups = piece[fan]
        if len(np.unique(groups)) == 1:
            # one piece meeting itself there (two parts welded at a few coincident vertices): its faces around v
            # grouped by the manifold edges through v instead
            groups = _fans(fan, faces, v)
        for g in np.unique(groups)[1:]:                     # the first keeps v; each other gets a copy
            rows = fan[groups == g]
            faces[rows] = np.where(faces[rows] == v, extra, faces[rows])
            vertices.append(np.asarray(mesh.vertices[v], dtype=np.float64)[None])
            extra += 1
            split += 1
    return trimesh.Trimesh(np.concatenate(vertices), faces, process=False), split


def _fans(fan: np.ndarray, faces: np.ndarray, v: int) -> np.ndarray:
    """A label per face of ``fan`` (the faces around vertex ``v``): faces that share an edge through ``v`` used by
    exactly two of them carry one label."""
    label = np.arange(len(fan))
    others = [set(faces[f][faces[f] != v].tolist()) for f in fan]
    for _ in range(len(fan)):                         # labels spread along the fan until they settle
        changed = False
        for w in set().union(*others):
            users = [i for i, o in enumerate(others) if w in o]
            if len(users) == 2 and label[users[0]] != label[users[1]]:
                low = min(label[users[0]], label[users[1]])
                label[label == max(label[users[0]], label[users[1]])] = low
                changed = True
        if not changed:
            break
    return label


def repair_mesh(mesh: trimesh.Trimesh, resolution: float | None = None,
                remesh: bool = False) -> tuple[trimesh.Trimesh, str, float, float]:
    """Close a mesh (see the module docstring): hole filling where every edge is manifold, else a watertight remesh
    of its generalized winding number.

    Args:
        mesh: the cleaned input [m].
        resolution: grid spacing of the remesh [m] (default: 1 % of the largest extent).
        remesh: remesh even where hole filling would do (overlapping closed pieces are united so).

    Returns:
        ``(closed mesh, method, moved, patched)``: how far the input's surface lies from the repair, and how far the
        repair's new surface reaches from the input [m] (about the radius of the largest filled hole).

    Raises:
        ValueError: the input encloses no volume (an open sheet: the winding number never reaches 1/2).
    """
    report = inspect_mesh(mesh)
    import igl

    if report.nonmanifold_edges == 0 and not remesh:
        m = _fill_holes(mesh)
        # pieces that enclose no volume once filled (a stray sheet or triangle of a scan) are dropped and reported
        parts = m.split(only_watertight=False) if report.components > 1 else [m]
        with np.errstate(invalid="ignore", divide="ignore"):
            flat = [abs(p.volume) <= 1e-6 * float(np.prod(np.maximum(p.extents, 1e-9))) for p in parts]
        kept = [p for p, f in zip(parts, flat) if not f]
        if any(flat) and kept:
            m = trimesh.util.concatenate(kept)
        with np.errstate(invalid="ignore", divide="ignore"):        # a flat result has zero volume
            ok = bool(kept) and inspect_mesh(m).closed and m.volume > 1e-12
        # closed pieces that now overlap (a mug's handle filled where it enters the body, a procedural blob's
        # pieces) are united exactly where manifold3d can (the outer surface kept: the remesh moved two of pybullet's
        # blobs, each with one hole of 3-4 edges, by 9-14 mm), else by the remesh
        overlap = ok and overlapping_components(m) > 0
        united = exact_union(m) if overlap else None
        remesh = overlap and united is None
        if ok and not remesh:
            what = "hole filling" + (" and an exact union of the overlapping pieces (manifold3d)" if united else "")
            m = m if united is None else united
            keep = None
            if any(flat):
                dropped = [p for p, f in zip(parts, flat) if f]
                what += f" (dropped {len(dropped)} flat piece(s) that enclose no volume)"
                keep = MeshDistance(trimesh.util.concatenate(dropped), signed=False)
            return (m, what, *_distance_between(m, mesh, outer_only=united is not None, exclude=keep))
    from skimage import measure

    lo, hi = mesh.bounds
    h = float(resolution) if resolution is not None else 0.01 * float((hi - lo).max())
    # a grid offset by an irrational fraction of a cell: a face lying on grid nodes (a box on a grid of its own
    # spacing) would give marching cubes zero-area triangles and an open result
    lo, hi = lo - (3 + 1 / math.pi) * h, hi + 3 * h
    check_grid(lo, hi + h, h, "resolution", "the repair's grid")
    axes = [np.arange(a, b + h / 2, h) for a, b in zip(lo, hi)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    w = igl.fast_winding_number(np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64),
                                grid).reshape(tuple(len(a) for a in axes))
    w = np.abs(w)                                   # a mesh wound inside out has winding number -1 inside
    if not (w.max() > 0.5):
        raise ValueError(f"encloses no volume ({report.defects() or 'an open surface'}; its generalized "
                         "winding number never reaches 1/2): an open sheet cannot be a body")
    verts, faces, _, _ = measure.marching_cubes(w, level=0.5, spacing=(h,) * 3, gradient_direction="ascent")
    m = trimesh.Trimesh(verts + lo, faces, process=True)
    m.update_faces(m.nondegenerate_faces())
    m.remove_unreferenced_vertices()
    trimesh.repair.fix_normals(m)
    if not inspect_mesh(m).closed:     # pragma: no cover - marching cubes inside a padded grid is closed
        raise ValueError("the watertight remesh is not closed")
    what = "union by winding-number remesh" if remesh else "winding-number remesh"
    if len(m.faces) > MAX_REMESH_FACES:
        # marching cubes at 1 % of the extent gives ~10^5 faces; quadric-error decimation (libigl's qslim) keeps the
        # shape to a fraction of a cell with a fifth of them (the distances reported below include its error)
        U, G = igl.qslim(np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int32),
                         MAX_REMESH_FACES)[:2]
        small = trimesh.Trimesh(U, G, process=True)
        trimesh.repair.fix_normals(small)
        # kept only if it is as clean as the remesh: closed, and no piece pushed into another (load_mesh of the
        # result must find nothing to repair)
        if inspect_mesh(small).closed and small.volume > 0 and overlapping_components(small) == 0:
            m, what = small, what + f" (decimated to {len(small.faces)} faces)"
    # what the repair does to the outside: interior partitions of the input, which the remesh drops, do not count
    return (m, f"{what} at {h * 1e3:.1f} mm", *_distance_between(m, mesh, outer_only=remesh, skip_interior=True))


def _numbers(value, name: str) -> np.ndarray:
    """``value`` as a flat float array, or ValueError naming ``name`` (a string where numbers belong)."""
    try:
        return np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected numbers, got {value!r}") from None


def as_pose(pose) -> np.ndarray | None:
    """A `(4, 4)` homogeneous transform [m] from a matrix, or from ``{"position": (3,), "quat": (4,) w-x-y-z}`` /
    ``{"position", "rpy_deg": (3,)}`` (roll, pitch, yaw about fixed x, y, z in degrees); None stays None.

    Raises:
        ValueError: a malformed pose (names the field).
    """
    if pose is None:
        return None
    if isinstance(pose, dict):
        unknown = set(pose) - {"position", "quat", "rpy_deg"}
        if unknown:
            raise ValueError(f"pose: unknown field(s) {sorted(unknown)}; use position and quat or rpy_deg")
        if "quat" in pose and "rpy_deg" in pose:
            raise ValueError("pose: give quat or rpy_deg, not both")
        T = np.eye(4)
        p = _numbers(pose.get("position", (0.0, 0.0, 0.0)), "pose.position")
        if p.shape != (3,) or not np.isfinite(p).all():
            raise ValueError(f"pose.position: expected a finite (3,) position [m], got {pose.get('position')!r}")
        T[:3, 3] = p
        if "quat" in pose:
            q = _numbers(pose["quat"], "pose.quat")
            if q.shape != (4,) or not np.isfinite(q).all() or np.linalg.norm(q) < 1e-9:
                raise ValueError(f"pose.quat: expected a non-zero (4,) quaternion w-x-y-z, got {pose['quat']!r}")
            T[:3, :3] = trimesh.transformations.quaternion_matrix(q / np.linalg.norm(q))[:3, :3]
        elif "rpy_deg" in pose:
            r = _numbers(pose["rpy_deg"], "pose.rpy_deg")
            if r.shape != (3,) or not np.isfinite(r).all():
                raise ValueError(f"pose.rpy_deg: expected 3 finite angles [deg], got {pose['rpy_deg']!r}")
            T[:3, :3] = trimesh.transformations.euler_matrix(*np.radians(r), axes="sxyz")[:3, :3]
        return T
    try:
        T = np.asarray(pose, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"pose: expected a (4, 4) transform or {{position, quat | rpy_deg}}, got {pose!r}") from None
    if T.shape != (4, 4) or not np.isfinite(T).all():
        raise ValueError(f"pose: expected a finite (4, 4) transform, got shape {T.shape}")
    R = T[:3, :3]
    if not (np.allclose(R @ R.T, np.eye(3), atol=1e-6) and np.linalg.det(R) > 0) or not np.allclose(T[3], [0, 0, 0, 1]):
        raise ValueError("pose: the (4, 4) transform must be rigid (a rotation and a translation)")
    return T


def read_mesh(path, name: str = "inner") -> trimesh.Trimesh:
    """The triangles of a mesh file as they are (several bodies merged; nothing checked, repaired or scaled: that is
    :func:`load_mesh`'s), for a caller that needs the file's own size first.

    Raises:
        ValueError: an unknown file type, no such file, or a file that does not read as a mesh (names the file).
    """
    path = Path(path)
    label = f"{name} ({path})"
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise ValueError(f"{label}: unknown mesh file type {path.suffix!r}; use one of {MESH_SUFFIXES}")
    if not path.is_file():
        raise ValueError(f"{label}: no such file")
    try:
        mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:                     # trimesh raises many types for a corrupt file
        raise ValueError(f"{label}: not a readable {path.suffix.lower()[1:].upper()} mesh "
                         f"({type(exc).__name__}: {exc})") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise ValueError(f"{label}: not a {path.suffix.lower()[1:].upper()} mesh: no triangle could be read "
                         "from it (a corrupt or empty file, or another format under this name)")
    return mesh


def load_mesh(source, *, scale: float = 1.0, pose=None, repair: bool = True, resolution: float | None = None,
              max_repair_distance: float | None = None, name: str = "inner") -> trimesh.Trimesh:
    """A user's object as a closed mesh in metres, in the robot's base frame.

    Args:
        source: a ``trimesh.Trimesh`` or a path to an STL, OBJ, PLY, GLB/glTF or OFF file (several bodies in one
            file are merged).
        scale: factor to metres (0.001 for a file in millimetres).
        pose: where the object stands: a `(4, 4)` transform or ``{"position", "quat" | "rpy_deg"}``
            (:func:`as_pose`); applied after ``scale``.
        repair: close holes and non-manifold parts (see the module docstring); False refuses a mesh that is not
            closed.
        resolution: grid spacing of a watertight remesh [m] (default 1 % of the largest extent).
        max_repair_distance: refuse a repair that moves the input's surface further than this [m] (default: 2 % of
            the bounding-box diagonal, at least 2 mm). New surface over a hole is not limited (it is reported).
        name: what error messages call the mesh.

    Returns:
        A closed, consistently wound ``trimesh.Trimesh`` with outward normals [m]. A repaired mesh comes with a
        :class:`MeshRepairWarning`.

    Raises:
        ValueError: an unreadable file, an unknown file type, no faces, non-finite vertices, an extent that cannot
            be metres (the message suggests ``scale``), a defect that ``repair=False`` does not fix, an open sheet, or
            a repair that moved the surface too far; each names the problem.
    """
    if isinstance(source, trimesh.Trimesh):
        mesh, label = source, name
    else:
        label = f"{name} ({Path(source)})"
        mesh = read_mesh(source, name)
    if len(mesh.faces) == 0 or len(mesh.vertices) == 0:
        raise ValueError(f"{label}: the mesh has no faces")
    if not isinstance(repair, bool):           # repair = "false" in a scene file used to repair
        raise ValueError(f"repair: must be true or false, got {repair!r}")
    if resolution is not None:
        from ..core.validation import as_length

        resolution = as_length(resolution, "resolution", hi=1.0)
    if not np.isfinite(np.asarray(mesh.vertices)).all():
        raise ValueError(f"{label}: vertices contain NaN or inf")
    if isinstance(scale, bool) or not (isinstance(scale, (int, float)) and math.isfinite(scale) and scale > 0):
        raise ValueError(f"scale: must be a positive number (0.001 for millimetres), got {scale!r}")
    T = as_pose(pose)
    mesh, removed = _clean(mesh)
    if len(mesh.faces) == 0:
        raise ValueError(f"{label}: every face is degenerate")
    mesh.apply_scale(float(scale))
    extent = float(mesh.extents.max())
    if extent > MAX_EXTENT:
        raise ValueError(f"{label}: {extent:.3g} m across; the file is probably in millimetres (pass scale=0.001) "
                         f"or centimetres (scale=0.01); at most {MAX_EXTENT} m is accepted")
    if extent < MIN_EXTENT:
        raise ValueError(f"{label}: {extent * 1e3:.3g} mm across; the file is probably in other units (pass scale) "
                         f"or not the object; at least {MIN_EXTENT * 1e3:.0f} mm is accepted")
    if T is not None:
        mesh.apply_transform(T)
    report = inspect_mesh(mesh)
    if repair and 0 < report.nonmanifold_edges <= MAX_LOCAL_SPLITS:
        # a few edges where closed pieces touch: each piece given its own copy of the vertices there, the surface
        # where it was (the remesh otherwise moved a procedural object's surface by 15-29 mm for one such edge)
        split, count = split_nonmanifold(mesh)
        after = inspect_mesh(split)
        if after.nonmanifold_edges == 0:
            warnings.warn(f"{label}: {report.nonmanifold_edges} non-manifold edge(s) split locally ({count} "
                          "vertices given a copy per piece of surface that meets there); the surface is the "
                          "input's", MeshRepairWarning, stacklevel=2)
            mesh, report = split, after
    overlaps = overlapping_components(mesh) if report.closed else 0
    if overlaps:
        report.overlapping_vertices = overlaps
    if report.closed and overlaps and repair:
        united = exact_union(mesh)
        if united is not None:                   # the pieces' union, exactly: the outer surface is unchanged
            warnings.warn(f"{label}: united {report.components} overlapping closed pieces exactly (manifold3d's "
                          f"boolean union, {overlaps} vertices were inside another piece); the outer surface is the "
                          "input's", MeshRepairWarning, stacklevel=2)
            return united
    if not report.closed or overlaps:
        if not repair:
            raise ValueError(f"{label}: not closed: {report.defects()}; inside and outside are undefined "
                             "(repair=True closes it and reports the change)")
        limit = (max(0.02 * float(np.linalg.norm(mesh.extents)), 0.002) if max_repair_distance is None
                 else float(max_repair_distance))
        try:
            fixed, method, moved, patched = repair_mesh(mesh, resolution, remesh=bool(overlaps))
        except ValueError as exc:
            raise ValueError(f"{label}: {exc}") from None
        if moved > limit:
            raise ValueError(f"{label}: not closed ({report.defects()}); the repair ({method}) moves the surface by "
                             f"{moved * 1e3:.1f} mm, more than the {limit * 1e3:.1f} mm allowed "
                             "(max_repair_distance); close the mesh in a mesh editor")
        warnings.warn(f"{label}: repaired {report.defects()} by {method}; the input's surface lies within "
                      f"{moved * 1e3:.2f} mm of the repaired one, and the new surface reaches up to "
                      f"{patched * 1e3:.1f} mm from the input (check that the holes were small or flat)",
                      MeshRepairWarning, stacklevel=2)
        mesh = fixed
    elif mesh.volume < 0:
        mesh.invert()                                # wound inside out: normals inward
    return mesh


class MeshDistance:
    """Exact signed distance to a closed triangle mesh, vectorised (negative inside).

    The unsigned distance and closest point come from libigl's AABB tree (built once); the sign from the
    pseudo-normal of the closest feature: the face normal inside a triangle, the sum of the two face normals on an
    edge, the angle-weighted vertex normal at a vertex; where the offset is not along that normal (off a face's
    interior on a mesh with slivers), from libigl's generalized winding number.

    Args:
        mesh: a closed ``trimesh.Trimesh`` [m] (any mesh with ``signed=False``).
        signed: False gives the unsigned distance of any mesh (closed or not).
    """

    def __init__(self, mesh: trimesh.Trimesh, signed: bool = True) -> None:
        import igl

        if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
            raise ValueError("MeshDistance: expected a non-empty trimesh.Trimesh")
        if signed and not inspect_mesh(mesh).closed:
            raise ValueError(f"MeshDistance: the mesh is not closed ({inspect_mesh(mesh).defects()}); inside and "
                             "outside are undefined (load_mesh repairs it)")
        self.mesh, self.signed = mesh, signed
        self._V = np.ascontiguousarray(mesh.vertices, dtype=np.float64)
        self._F = np.ascontiguousarray(mesh.faces, dtype=np.int64)
        self._tree = igl.AABB()
        self._tree.init(self._V, self._F)
        self._winding = None            # libigl's winding-number tree, built at the first ambiguous point
        if signed:
            self._face_n = np.asarray(mesh.face_normals)
            self._vertex_n = np.asarray(mesh.vertex_normals)         # trimesh weights them by the face angles
            edge_n = np.zeros((len(mesh.edges_unique), 3))
            np.add.at(edge_n, mesh.faces_unique_edges.ravel(), np.repeat(self._face_n, 3, axis=0))
            # faces_unique_edges lists the edges (0, 1), (1, 2), (2, 0): opposite vertices 2, 0, 1
            self._edge_n = edge_n[mesh.faces_unique_edges][:, [1, 2, 0]]   # (f, 3): the edge opposite vertex k

    def closest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(signed distance (n,), closest points (n, 3), face ids (n,))`` of `(n, 3)` points [m]."""
        p = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        if len(p) == 0:
            return np.zeros(0), np.zeros((0, 3)), np.zeros(0, np.int64)
        d2, face, c = self._tree.squared_distance(self._V, self._F, p)
        d = np.sqrt(np.maximum(d2, 0.0))
        if not self.signed:
            return d, c, face
        bary = trimesh.triangles.points_to_barycentric(self._V[self._F[face]], c)
        zero = bary < 1e-9
        n = self._face_n[face].copy()
        on_edge = zero.sum(1) == 1
        if on_edge.any():
            n[on_edge] = self._edge_n[face[on_edge], zero[on_edge].argmax(1)]
        at_vertex = zero.sum(1) >= 2
        if at_vertex.any():
            n[at_vertex] = self._vertex_n[self._F[face[at_vertex], bary[at_vertex].argmax(1)]]
        along = np.einsum("ij,ij->i", p - c, n)
        sign = np.where(along >= 0, 1.0, -1.0)
        # off a face's interior the pseudo-normal decides the side only on a clean mesh: a sliver's normal (a
        # remesh's or a decimation's) or an almost-closest second feature flips it (a teddy's cover came out open,
        # its grid's corners "inside"); where the offset is not along the normal, the generalized winding number
        # decides instead
        ambiguous = (np.abs(along) < 0.999 * d) & (d > 0)
        if ambiguous.any():
            sign[ambiguous] = np.where(np.abs(self.winding_number(p[ambiguous])) > 0.5, -1.0, 1.0)
        return sign * d, c, face

    def winding_number(self, points: np.ndarray) -> np.ndarray:
        """`(n,)` libigl's fast generalized winding number of `(n, 3)` points [m] (about 1 inside, 0 outside), its
        tree built once per mesh (rebuilding it cost 50-90 ms a call on a 20,000-face mesh, for a few points)."""
        if self._winding is None:
            import igl

            self._winding = igl.FastWindingNumberBVH()
            self._winding.init(self._V, self._F)
        return self._winding.winding_number(np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3)))

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """`(n,)` signed distance [m] of `(n, 3)` points [m] (unsigned with ``signed=False``)."""
        return self.closest(points)[0]
