"""Object sets: a seeded family of grocery-shelf primitives and the meshes of ``pybullet``'s data, by name and range.

A set is named as ``FAMILY:FIRST-LAST`` (``primitives:0-99``, ``pybullet-random:0-49``), a list of pybullet's named
meshes (``pybullet:duck,teddy``) or a folder of the user's own meshes (``folder:PATH``). Each object of a set is a
closed mesh [m] standing on the table (z = 0 at its lowest point, centred on the z axis), with a largest extent drawn
from 8-25 cm by its own seed, so that object ``i`` is the same object in every run, on every machine.

The primitives are what a grocery shelf holds beside the blobs: boxes with rounded edges, gabled cartons, cylinders
(cans, bottles), capsules and loaves, each the convex hull of a few analytic point sets (a rounded box is the hull of
spheres at a box's corners, exactly its Minkowski sum with a ball), so every mesh is closed and convex by
construction. pybullet's ``random_urdfs/NNN/NNN.obj`` are unions of overlapping closed pieces; they are loaded with
:func:`~torch_gpioius.sim.meshes.load_mesh`, which unites them.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

__all__ = ["PRIMITIVE_KINDS", "SetObject", "primitive_mesh", "parse_object_set", "object_set", "SIZE_RANGE",
           "COVERS", "set_mesh", "set_scene"]

#: The kinds of primitive, in the order object ``i`` cycles through them (``i % 5``).
PRIMITIVE_KINDS = ("rounded-box", "gabled-carton", "cylinder", "capsule", "loaf")
#: The largest extent of every object of a set [m].
SIZE_RANGE = (0.08, 0.25)
#: Seeds of a set's objects are ``_SALT + index``: sets do not share their random streams with study seeds.
_SALT = 54_000


@dataclass(frozen=True)
class SetObject:
    """One object of a set: its name (``primitives-007``), where it comes from (``primitives:7``,
    ``pybullet:random_urdfs/007/007.obj`` or a file path), and its size [m] (the largest extent it is scaled to)."""

    name: str
    source: str
    size: float
    index: int


def _size(rng: np.random.Generator) -> float:
    return float(rng.uniform(*SIZE_RANGE))


def _sphere_points(centres: np.ndarray, r: float, n: int = 2) -> np.ndarray:
    ball = trimesh.creation.icosphere(subdivisions=n, radius=r).vertices
    return (np.asarray(centres)[:, None, :] + ball[None]).reshape(-1, 3)


def _hull(points: np.ndarray) -> trimesh.Trimesh:
    mesh = trimesh.convex.convex_hull(points)
    trimesh.repair.fix_normals(mesh)
    return mesh


def primitive_mesh(index: int) -> tuple[trimesh.Trimesh, str]:
    """Object ``index`` of the primitive family: a closed convex mesh [m], standing on z = 0, centred on the z axis,
    its largest extent drawn from :data:`SIZE_RANGE`.

    Args:
        index: a non-negative integer; the kind is ``PRIMITIVE_KINDS[index % 5]``, the proportions and size are
            drawn from ``numpy.random.default_rng(54000 + index)``.

    Returns:
        ``(mesh, kind)``.

    Raises:
        ValueError: a negative or non-integer index.
    """
    if isinstance(index, bool) or not isinstance(index, (int, np.integer)) or index < 0:
        raise ValueError(f"index: must be a non-negative integer, got {index!r}")
    rng = np.random.default_rng(_SALT + int(index))
    kind = PRIMITIVE_KINDS[int(index) % len(PRIMITIVE_KINDS)]
    size = _size(rng)
    if kind == "rounded-box":
        e = np.sort(rng.uniform(0.35, 1.0, 3))[::-1] * size             # extents, largest first
        e = rng.permutation(e) if rng.uniform() < 0.5 else e[[1, 2, 0]]  # standing or lying
        r = float(rng.uniform(0.05, 0.2)) * float(e.min())
        core = (e / 2 - r) * np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
        mesh = _hull(_sphere_points(core, r))
    elif kind == "gabled-carton":
        w = float(rng.uniform(0.3, 0.6)) * size
        d = float(rng.uniform(0.6, 1.0)) * w
        roof = float(rng.uniform(0.1, 0.25)) * size
        body = size - roof
        base = np.array([[sx * w / 2, sy * d / 2, z] for sx in (-1, 1) for sy in (-1, 1) for z in (0.0, body)])
        ridge = np.array([[-w / 2, 0.0, size], [w / 2, 0.0, size]])
        mesh = _hull(np.vstack([base, ridge]))
    elif kind == "cylinder":
        r = float(rng.uniform(0.15, 0.5)) * size
        height = size if 2 * r < size else float(rng.uniform(0.4, 1.0)) * 2 * r
        sections = int(rng.integers(24, 65))
        mesh = trimesh.creation.cylinder(radius=r, height=height, sections=sections)
    elif kind == "capsule":
        r = float(rng.uniform(0.12, 0.3)) * size
        mesh = trimesh.creation.capsule(height=size - 2 * r, radius=r, count=[24, 24])
        if rng.uniform() < 0.5:                                           # lying on its side
            mesh.apply_transform(trimesh.transformations.rotation_matrix(math.pi / 2, [1, 0, 0]))
    else:                                                                 # loaf: a box with a rounded top
        length = size
        w = float(rng.uniform(0.4, 0.75)) * size
        h = float(rng.uniform(0.35, 0.7)) * size
        top = float(rng.uniform(0.25, 0.5)) * w                           # the crown's height
        a = np.linspace(0, math.pi, 17)
        arc = np.c_[np.cos(a) * w / 2, h - top + np.sin(a) * top]        # (y, z) of the crown
        ends = [np.c_[np.full(len(arc), x), arc] for x in (-length / 2, length / 2)]
        base = np.array([[x, y, 0.0] for x in (-length / 2, length / 2) for y in (-w / 2, w / 2)])
        mesh = _hull(np.vstack([base, *ends]))
    return _standing(mesh), kind


def _lying(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """``mesh`` turned onto its side: a quarter turn about the horizontal axis (x or y) that leaves it lowest, then
    standing on z = 0, centred on the z axis (a can on its side, a carton on its back); one that already lies (its
    height its smallest extent: a blob's stable pose, often) stays as it is."""
    if mesh.extents[2] <= mesh.extents[:2].min():
        return _standing(mesh)
    turns = []
    for axis in ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0)):
        turned = mesh.copy()
        turned.apply_transform(trimesh.transformations.rotation_matrix(math.pi / 2, axis))
        turns.append(turned)
    return _standing(min(turns, key=lambda m: float(m.extents[2])))


def _standing(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """``mesh`` moved to stand on z = 0, centred on the z axis."""
    lo, hi = mesh.bounds
    mesh = mesh.copy()
    mesh.apply_translation([-(lo[0] + hi[0]) / 2, -(lo[1] + hi[1]) / 2, -lo[2]])
    return mesh


#: The families a set can be drawn from, and their largest index. A ``-lying`` family is the same objects turned onto
#: their side (:func:`set_mesh`): low and wide, where a standing object is tall.
FAMILIES = {"primitives": 10_000, "pybullet-random": 999, "primitives-lying": 10_000, "pybullet-random-lying": 999}


def parse_object_set(text: str) -> list[SetObject]:
    """The objects a set's name stands for (see the module docstring).

    Args:
        text: ``primitives:A-B``, ``pybullet-random:A-B`` (one index, or a range, or a comma list of either),
            ``pybullet:NAME[,NAME...]`` (``duck``, ``teddy``, ``bunny``, ``mug``, or a path inside pybullet's data)
            or ``folder:PATH`` (every ``.stl``, ``.obj``, ``.ply`` and ``.off`` in it, sorted by name).

    Returns:
        the set's objects, in order.

    Raises:
        ValueError: an unknown family, a bad range, an empty folder (each names the part of ``text`` at fault).
    """
    if not isinstance(text, str) or ":" not in text:
        raise ValueError(f"objects: expected FAMILY:RANGE (primitives:0-99, pybullet-random:0-49, pybullet:duck,teddy "
                         f"or folder:PATH), got {text!r}")
    family, _, rest = text.partition(":")
    family = family.strip().lower()
    if family in FAMILIES:
        out = []
        base, lying = family.removesuffix("-lying"), family.endswith("-lying")
        tag = "-lying" if lying else ""
        for i in _indices(rest, FAMILIES[family], text):
            if base == "primitives":
                size = float(np.max(primitive_mesh(i)[0].extents))
                out.append(SetObject(f"primitives{tag}-{i:03d}", f"primitives{tag}:{i}", size, i))
            else:                       # the same size as the standing object's: one stream per index
                size = _size(np.random.default_rng(_SALT + 500_000 + i))
                out.append(SetObject(f"pybullet-random{tag}-{i:03d}",
                                     f"pybullet{tag}:random_urdfs/{i:03d}/{i:03d}.obj", size, i))
        return out
    if family == "pybullet":
        names = [n.strip() for n in rest.split(",") if n.strip()]
        if not names:
            raise ValueError(f"objects: {text!r} names no pybullet mesh")
        known = {"duck": "duck.obj", "teddy": "teddy2_VHACD_CHs.obj", "bunny": "bunny.obj", "mug": "objects/mug.obj"}
        from .scenefile import resolve_mesh

        for n in names:                 # each named mesh found before a study runs (a typo gave two failed runs)
            try:
                resolve_mesh("pybullet:" + known.get(n, n), Path.cwd())
            except ValueError as exc:
                raise ValueError(f"objects: {text!r}: {n!r} is no mesh in pybullet's data ({exc}); the names "
                                 f"{sorted(known)} or a path inside pybullet_data") from None
        return [SetObject(n.replace("/", "-").rsplit(".", 1)[0], "pybullet:" + known.get(n, n),
                          _size(np.random.default_rng(_SALT + 900_000 + i)), i) for i, n in enumerate(names)]
    if family == "folder":
        folder = Path(os.path.expanduser(rest.strip()))
        if not folder.is_dir():
            raise ValueError(f"objects: {text!r}: {folder} is not a folder")
        files = sorted(p for p in folder.iterdir() if p.suffix.lower() in (".stl", ".obj", ".ply", ".off"))
        if not files:
            raise ValueError(f"objects: {text!r}: {folder} holds no .stl, .obj, .ply or .off mesh")
        return [SetObject(p.stem, str(p.resolve()), _size(np.random.default_rng(_SALT + 800_000 + i)), i)
                for i, p in enumerate(files)]
    raise ValueError(f"objects: unknown family {family!r} in {text!r}; choose among "
                     f"{sorted([*FAMILIES, 'pybullet', 'folder'])}")


def _indices(rest: str, largest: int, text: str) -> list[int]:
    out: list[int] = []
    for part in rest.split(","):
        part = part.strip()
        try:
            if "-" in part:
                a, b = (int(v) for v in part.split("-", 1))
            else:
                a = b = int(part)
        except ValueError:
            raise ValueError(f"objects: {text!r}: {part!r} is not an index or a range A-B") from None
        if not 0 <= a <= b <= largest:
            raise ValueError(f"objects: {text!r}: the range {part!r} must lie in 0-{largest}, first <= last")
        out.extend(range(a, b + 1))
    return list(dict.fromkeys(out))


def object_set(text: str) -> list[SetObject]:
    """:func:`parse_object_set` (the name a study and the CLI use)."""
    return parse_object_set(text)


#: The covers a set's objects are explored under, ``name -> (cover kind, its options)``
#: (:func:`~torch_gpioius.sim.forcefield.cover_around`): tight (the body grown by 8 mm), wide (4 cm off, draped over
#: concavities narrower than 6 cm, as the real shapes' wide covers), and two whose gap varies over the body: uneven
#: (5 mm on the -y side growing to 5 cm on the +y side) and hanging (5 mm on top, falling straight to the table below
#: the body's widest part).
COVERS = {"tight": ("tight", {"gap": 0.008}), "wide": ("loose", {"gap": 0.04}),
          "uneven": ("uneven", {"gap": 0.005, "gap_far": 0.05, "thick_side": (0.0, 1.0, 0.0)}),
          "hanging": ("hanging", {"gap": 0.005})}
#: Where a set's object stands: the bottom centre of its box, on a table in front of the UR5 [m].
STAND_AT = (0.5, 0.0, 0.1)


def set_mesh(obj: SetObject) -> trimesh.Trimesh:
    """The closed mesh [m] of a set's object, in its most probable stable pose on the table (trimesh's
    ``compute_stable_poses``; a primitive stands as it was built; a ``-lying`` family's object is that turned onto its
    side), z = 0 at its lowest point, centred on the z axis, scaled so that its largest extent is ``obj.size``.

    Raises:
        ValueError: a mesh that cannot be loaded or closed (:func:`~torch_gpioius.sim.meshes.load_mesh`).
    """
    if obj.source.startswith("primitives-lying:") or obj.source.startswith("pybullet-lying:"):
        standing = SetObject(obj.name, obj.source.replace("-lying:", ":", 1), obj.size, obj.index)
        return _lying(set_mesh(standing))
    if obj.source.startswith("primitives:"):
        return primitive_mesh(obj.index)[0]
    from .meshes import load_mesh, read_mesh
    from .scenefile import resolve_mesh

    path = resolve_mesh(obj.source, Path.cwd())
    raw = read_mesh(path, obj.name)                         # its size first: pybullet's blobs are metres across
    extent = float(np.max(raw.extents))
    if not extent > 0:
        raise ValueError(f"{obj.name} ({path}): the mesh has no extent")
    mesh = load_mesh(raw, scale=obj.size / extent, name=f"{obj.name} ({path})").copy()
    poses, probabilities = mesh.compute_stable_poses(n_samples=1)
    if len(poses):
        mesh.apply_transform(poses[int(np.argmax(probabilities))])
    mesh.apply_scale(obj.size / float(np.max(mesh.extents)))      # in the pose it stands in (the repair and the
    return _standing(mesh)                                        # turn move the box a little)


def set_scene(obj: SetObject, cover: str = "tight", *, settings: str = "default", seed: int = 0, **kwargs):
    """The force-field world of one set object: the object on the table at :data:`STAND_AT` under a cover of
    :data:`COVERS`, the robot coming from above, the library's ``settings``; ``seed`` perturbs the start and the
    noise as every world's seed does (0: unperturbed). ``kwargs`` go to
    :meth:`~torch_gpioius.sim.forcefield.Scene3D.from_mesh` (``resolution`` for a coarser cover, ...).

    Raises:
        ValueError: an unknown cover, or a scene that cannot be built (names the object).
    """
    from .forcefield import Scene3D

    if cover not in COVERS:
        raise ValueError(f"cover: must be one of {sorted(COVERS)}, got {cover!r}")
    kind, options = COVERS[cover]
    try:
        scene = Scene3D.from_mesh(set_mesh(obj), kind, **options, at=STAND_AT, name=obj.name, settings=settings,
                                  **kwargs)
    except ValueError as exc:
        raise ValueError(f"{obj.name} ({obj.source}): {exc}") from None
    return scene if seed == 0 else scene.perturbed(seed)
