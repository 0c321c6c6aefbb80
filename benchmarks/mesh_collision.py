"""How a mesh body collides in the MuJoCo world: CoACD convex parts against MuJoCo's convex hull of the whole mesh.

MuJoCo collides meshes as their convex hulls, and its wheel's SDF plugin holds only analytic shapes (no mesh SDF), so
a concave object (a bunny's ears, a mug's handle) needs a convex decomposition. For each of pybullet's meshes this
script measures, for both collision modes in one run:

* the time to decompose (uncached) and the number of parts;
* the fidelity of the collision surface: how far the body's surface lies inside or outside the parts' union (points
  of the mesh not covered by any part are where the fingertip would pass into the object; part surface far outside
  the mesh is where it would stop short), from 20 000 surface samples;
* the real-time factor of the settled scene (a loose cloth over the object, the arm still), simulated seconds per
  wall second.

    python benchmarks/mesh_collision.py               # about 2 minutes on 2 cores (needs the shapes extra)
    python benchmarks/mesh_collision.py --shapes bunny
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
import warnings

import numpy as np
import trimesh

SHAPES = {"bunny": ("bunny.obj", 0.1, {"rpy_deg": [90, 0, 0]}), "duck": ("duck.obj", 0.1, {"rpy_deg": [90, 0, 0]}),
          "teddy": ("teddy2_VHACD_CHs.obj", 0.25, {"rpy_deg": [90, 0, 0]}), "mug": ("objects/mug.obj", 1.0, None)}


def coverage(mesh: trimesh.Trimesh, parts: list[trimesh.Trimesh]) -> tuple[float, float]:
    """``(uncovered, outside)`` [m]: the largest distance of a mesh surface point outside every part, and the largest
    distance of a part's surface outside the mesh."""
    from torch_gpioius.sim.meshes import MeshDistance

    pts, _ = trimesh.sample.sample_surface(mesh, 20000, seed=0)
    # distance outside a convex part: the largest signed distance to its face planes (0 inside)
    outside = np.full(len(pts), np.inf)
    for p in parts:
        planes = (pts @ p.face_normals.T) - np.einsum("ij,ij->i", p.face_normals, p.triangles[:, 0])[None]
        outside = np.minimum(outside, np.maximum(planes.max(axis=1), 0.0))
    d = MeshDistance(mesh)
    # part surface outside the body (faces between parts lie inside it and do not count)
    far = max(float(np.maximum(d(trimesh.sample.sample_surface(p, 2000, seed=0)[0]), 0.0).max()) for p in parts)
    return float(outside.max()), far


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shapes", default=",".join(SHAPES))
    args = parser.parse_args()
    import pybullet_data
    import torch

    from torch_gpioius.sim.forcefield import approach_from_above, place
    from torch_gpioius.sim.meshes import load_mesh
    from torch_gpioius.sim.mujoco import MujocoScene
    from torch_gpioius.sim.mujoco.bodies import MeshBody

    torch.set_num_threads(1)
    os.environ["XDG_CACHE_HOME"] = tempfile.mkdtemp()          # decompose afresh
    print(f"{'shape':6} {'mode':6} {'parts':>5} {'decompose s':>11} {'uncovered mm':>12} {'outside mm':>10} "
          f"{'rtf':>5}")
    for name in args.shapes.split(","):
        f, scale, pose = SHAPES[name]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            mesh = place(load_mesh(os.path.join(pybullet_data.getDataPath(), f), scale=scale, pose=pose),
                         (0.5, 0.0, 0.1))
        start, direction, bounds = approach_from_above(mesh, mesh, clearance=0.12)
        for mode in ("convex", "hull"):
            t0 = time.perf_counter()
            body = MeshBody(mesh, mode)
            t_parts = time.perf_counter() - t0
            uncovered, outside = coverage(mesh, body.parts)
            scene = MujocoScene.from_mesh(mesh, "loose", start=start, direction=direction, bounds=bounds,
                                          collision=mode, name=name)
            rtf = scene.real_time_factor(2.0)
            print(f"{name:6} {mode:6} {len(body.parts):5d} {t_parts:11.1f} {uncovered * 1e3:12.1f} "
                  f"{outside * 1e3:10.1f} {rtf:5.2f}", flush=True)


if __name__ == "__main__":
    main()
