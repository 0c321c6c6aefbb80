"""A user's files the tests write: contacts on a 6 cm sphere (with outward normals) and free space above it, and two
captures of a cover 1 cm off it, one from each side (the own-data tutorial's object at a smaller size)."""

import numpy as np

CENTRE = np.array([0.5, 0.0, 0.2])                        # [m], the robot's base frame
#: The two cameras' optical centres [m]: the first sees the half y < 0, the second y >= 0.
EYES = (CENTRE + [0.0, -1.0, 0.2], CENTRE + [0.0, 1.0, 0.2])


def _directions(rng, n, upper=False):
    d = rng.standard_normal((n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    if upper:
        d[:, 2] = np.abs(d[:, 2])
    return d


def sphere_files(folder, contacts: int = 30, cover: int = 1500, *, normal_sign: float = 1.0, repeat: int = 1,
                 seed: int = 0, name: str = "contacts.csv", radius: float = 0.06, gap: float = 0.01):
    """Write ``contacts.csv`` (``contacts`` contacts on a ball of ``radius`` [m] with normals times ``normal_sign``, 15
    free rows twice as far out; every row ``repeat`` times), ``left.ply`` and ``right.ply`` (its cover ``gap`` off)
    into ``folder``; returns ``(csv, [left, right])`` paths. ``gap``: how far the cover stands off the ball [m]."""
    import trimesh

    rng = np.random.default_rng(seed)
    touch = _directions(rng, contacts, upper=True)
    passed = CENTRE + 2 * radius * _directions(rng, 15, upper=True)
    rows = [f"{x:.6f},{y:.6f},{z:.6f},contact,{a:.4f},{b:.4f},{c:.4f}"
            for (x, y, z), (a, b, c) in zip(CENTRE + radius * touch, normal_sign * touch)]
    rows += [f"{x:.6f},{y:.6f},{z:.6f},free,,," for x, y, z in passed]
    path = folder / name
    path.write_text("x,y,z,label,nx,ny,nz\n" + "".join(f"{r}\n" * repeat for r in rows))
    shell = CENTRE + (radius + gap) * _directions(rng, cover) + rng.normal(0, 0.001, (cover, 3))
    trimesh.PointCloud(shell[shell[:, 1] < 0]).export(folder / "left.ply")
    trimesh.PointCloud(shell[shell[:, 1] >= 0]).export(folder / "right.ply")
    return path, [folder / "left.ply", folder / "right.ply"]
