"""How close `gpioius fit` on a user's own files comes to the body: real-like files written for hidden bodies, fitted
from the command line with the default settings, the estimate measured against the body.

For each body (a 22 cm bottle, objects of the seeded primitive family, pybullet's meshes), placed on the table at
(0.5, 0, 0.1) m under a tight cover 8 mm off:

* three captures of the cover (the force-field world's fixed, mirrored and wrist cameras: a Kinect's depth noise of
  1.5 mm and more, a D405's 0.5 mm), cropped to the body's box grown by 15 cm, one PLY each with its camera origin;
* about 60 contacts on the body along two sliding paths (a ring around it at mid-height, and an arc over its top
  in the x-z plane), each with 1 mm of noise and its outward normal (as a force sensor measures it, within 5 deg),
  and the free space of each path's approach, as a contacts CSV with ``nx,ny,nz``.

Then ``gpioius fit contacts.csv --cloud ... --camera-origin ... --mesh est.ply`` (the default settings), the same
contacts alone, and the clouds with ``--settings paper``, and the simple baselines the first fit writes from the same
observations (``--out``: vision alone, vision shrunk by the gap the first five or all contacts measure); the
estimate within the studies' range (the body's box grown by 3 cm, from a quarter of its height up) against the body:
Chamfer distance, F-score at 1 cm, median signed bias (negative: inside), Hausdorff, and the estimate's box against
the body's (a phantom dome shows as a box far larger than the body).

    python scripts/own_data_check.py                        # the bottle and primitives 100-104
    python scripts/own_data_check.py --bodies bottle pybullet:duck primitives:120-124 --out outputs/own_data
    python scripts/own_data_check.py --bodies pybullet:duck --arm learned "--learn length"   # a further arm
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
import trimesh

AT = np.array([0.5, 0.0, 0.1])
#: The simple baselines `gpioius fit --out` writes beside the estimate (torch_gpioius.baselines), scored as arms.
BASELINE_ARMS = ("vision", "vision-shrunk-5", "vision-shrunk-all")


def bottle() -> trimesh.Trimesh:
    """A 22 cm bottle: a 7 cm body of 15 cm, a shoulder and a 2.6 cm neck (a union remeshed by the loader)."""
    body = trimesh.creation.cylinder(radius=0.035, height=0.15, sections=48)
    body.apply_translation([0, 0, 0.075])
    shoulder = trimesh.creation.cone(radius=0.035, height=0.05, sections=48)
    shoulder.apply_translation([0, 0, 0.15])
    neck = trimesh.creation.cylinder(radius=0.013, height=0.05, sections=32)
    neck.apply_translation([0, 0, 0.195])
    return trimesh.util.concatenate([body, shoulder, neck])


def bodies(names: list[str]) -> list[tuple[str, trimesh.Trimesh]]:
    from torch_gpioius.sim.objectsets import parse_object_set, primitive_mesh

    out = []
    for name in names:
        if name == "bottle":
            out.append(("bottle", bottle()))
            continue
        for obj in parse_object_set(name):
            if obj.source.startswith("primitives:"):
                out.append((obj.name, primitive_mesh(obj.index)[0]))
            else:
                from torch_gpioius.sim.meshes import load_mesh
                from torch_gpioius.sim.scenefile import resolve_mesh

                mesh = load_mesh(resolve_mesh(obj.source, Path(".")))
                out.append((obj.name, mesh.apply_scale(obj.size / float(np.max(mesh.extents)))))
    return out


def _ring_and_arc(body: trimesh.Trimesh, n: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """`n` points on the body along a ring at mid-height and an arc over the top (x-z plane through the centre),
    with their outward normals."""
    lo, hi = body.bounds
    centre = (lo + hi) / 2
    pts = []
    ring = body.section(plane_origin=centre, plane_normal=[0, 0, 1])
    arc = body.section(plane_origin=centre, plane_normal=[0, 1, 0])
    for section, count, keep in ((ring, n // 2, None), (arc, n - n // 2, centre[2])):
        if section is None:
            continue
        path = np.concatenate([e.discrete(section.vertices) for e in section.entities])
        if keep is not None:                                    # the arc's upper half: reachable from above
            path = path[path[:, 2] >= keep]
        seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
        s = np.r_[0, np.cumsum(seg)]
        at = np.linspace(0, s[-1], count, endpoint=False)
        pts.append(np.stack([np.interp(at, s, path[:, k]) for k in range(3)], axis=1))
    pts = np.concatenate(pts)
    closest, _, face = trimesh.proximity.closest_point(body, pts)
    normals = body.face_normals[face]
    return closest, normals


def write_files(body: trimesh.Trimesh, folder: Path, seed: int = 0, n_contacts: int = 60) -> list[str]:
    """The real-like files of ``body`` (see the module docstring) in ``folder``; returns the fit's cloud arguments."""
    from torch_gpioius.sim.forcefield import Scene3D

    rng = np.random.default_rng(seed)
    folder.mkdir(parents=True, exist_ok=True)
    scene = Scene3D.from_mesh(body, cover="tight", gap=0.008, at=AT, seed=seed)
    inner = scene.inner
    cloud = scene.hardware().camera.capture()
    lo, hi = inner.bounds[0] - 0.15, inner.bounds[1] + 0.15
    cloud = cloud.cropped(lo, hi)
    views = cloud.view_ids()
    argv = []
    for k in dict.fromkeys(views.tolist()):
        pts = cloud.points[views == k]
        trimesh.PointCloud(pts).export(folder / f"capture{k}.ply")
        origin = cloud.origin[views == k][0] if cloud.per_point_origins else cloud.origin
        argv += ["--cloud", str(folder / f"capture{k}.ply"), "--camera-origin", " ".join(f"{v:.6f}" for v in origin)]
    contacts, normals = _ring_and_arc(inner, n_contacts, rng)
    contacts = contacts + rng.normal(0, 0.001, contacts.shape)
    tilt = normals + rng.normal(0, math.radians(5) / math.sqrt(3), normals.shape)
    tilt /= np.linalg.norm(tilt, axis=1, keepdims=True)
    rows = ["x,y,z,label,nx,ny,nz"]
    for start in (contacts[0], contacts[n_contacts // 2]):        # each path's approach from 10 cm out
        n = normals[0] if start is contacts[0] else normals[n_contacts // 2]
        for d in (0.1, 0.08, 0.06, 0.04, 0.02):
            rows.append(",".join(f"{v:.6f}" for v in start + d * n) + ",free,,,")
    rows += [",".join(f"{v:.6f}" for v in p) + ",contact," + ",".join(f"{v:.6f}" for v in n)
             for p, n in zip(contacts, tilt)]
    (folder / "contacts.csv").write_text("\n".join(rows) + "\n")
    inner.export(folder / "truth.stl")
    return argv


def measure(estimate_path: Path, truth: trimesh.Trimesh, spacing: float = 0.003) -> dict:
    """The estimate against the body within the studies' range: the body's box grown by 3 cm, from a quarter of its
    height up (a camera above the table and a fingertip reach that part; the underside stands on the table)."""
    from torch_gpioius.geometry.metrics import surface_agreement
    from torch_gpioius.sim.meshes import MeshDistance

    est = trimesh.load(estimate_path, process=False)
    lo, hi = truth.bounds[0] - 0.03, truth.bounds[1] + 0.03
    lo[2] = truth.bounds[0, 2] + 0.25 * (truth.bounds[1, 2] - truth.bounds[0, 2])
    n_est = max(2000, int(est.area / spacing ** 2))
    n_true = max(2000, int(truth.area / spacing ** 2))
    a = est.sample(n_est, seed=0) if hasattr(est, "sample") else np.zeros((0, 3))
    a = a[((a >= lo) & (a <= hi)).all(axis=1)]
    b = truth.sample(n_true, seed=0)
    b = b[((b >= lo) & (b <= hi)).all(axis=1)]
    if len(a):
        # the estimate is clipped by its grid's box, so open: inside and outside by its generalized winding number
        import igl

        unsigned = MeshDistance(est, signed=False)(b)
        winding = igl.fast_winding_number(np.asarray(est.vertices, dtype=np.float64),
                                          np.asarray(est.faces, dtype=np.int64), b)
        signed = np.where(np.abs(winding) > 0.5, -unsigned, unsigned)          # negative: truth inside the estimate
    else:
        signed = np.full(len(b), np.nan)
    out = surface_agreement(MeshDistance(truth, signed=False)(a), np.abs(signed), -signed)
    out["hausdorff"] = (
        float(max(MeshDistance(truth, signed=False)(a).max(), np.abs(signed).max())) if len(a) else math.nan
    )
    out["box"] = (a.max(axis=0) - a.min(axis=0)).round(3).tolist() if len(a) else [math.nan] * 3
    return out


def main() -> None:
    from torch_gpioius.cli import main as gpioius

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bodies", nargs="+", default=["bottle", "primitives:100-104"])
    parser.add_argument("--out", type=Path, default=Path("outputs/own_data"))
    parser.add_argument("--resolution", type=float, default=0.005)
    parser.add_argument("--arm", nargs=2, action="append", default=[], metavar=("NAME", "ARGS"),
                        help="a further arm: the clouds and these fit arguments, e.g. --arm learned '--learn length'")
    args = parser.parse_args()
    arms = [("with clouds", []), ("contacts alone", None), ("paper, with clouds", ["--settings", "paper"])]
    arms += [(name, extra.split()) for name, extra in args.arm]
    rows = []
    for name, body in bodies(args.bodies):
        folder = args.out / name
        clouds = write_files(body, folder)
        truth = trimesh.load(folder / "truth.stl")
        csv = str(folder / "contacts.csv")
        result = {"body": name, "extent": (truth.bounds[1] - truth.bounds[0]).round(3).tolist()}
        for arm, extra in arms:
            extra = [] if extra is None else clouds + extra
            mesh = folder / f"estimate_{arm.replace(' ', '_').replace(',', '')}.ply"
            fit_out = ["--out", str(folder / "fit")] if arm == "with clouds" else []     # its baselines too
            code = gpioius(["fit", csv, *extra, "--mesh", str(mesh), "--resolution", str(args.resolution),
                            "--force", *fit_out])
            result[arm] = measure(mesh, truth) if code == 0 and mesh.exists() else {"failed": code}
        for name in BASELINE_ARMS:                         # the simple baselines of the fit with clouds
            mesh = folder / "fit" / "baselines" / f"{name}.ply"
            result[name] = measure(mesh, truth) if mesh.exists() else {"failed": "no estimate"}
        rows.append(result)
        print(json.dumps(result), flush=True)
    (args.out / "summary.json").write_text(json.dumps(rows, indent=1))
    print("| body | extent [cm] | arm | Chamfer [cm] | F 1 cm | bias [mm] | Hausdorff [cm] | estimate's box [cm] |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        for arm in [a for a, _ in arms] + list(BASELINE_ARMS):
            m = r[arm]
            if "failed" in m:
                print(f"| {r['body']} | | {arm} | failed ({m['failed']}) | | | | |")
                continue
            print(f"| {r['body']} | {' x '.join(f'{100 * e:.0f}' for e in r['extent'])} | {arm} | "
                  f"{100 * m['chamfer']:.2f} | {m['fscore_10mm']:.2f} | {1000 * m['bias']:.1f} | "
                  f"{100 * m['hausdorff']:.1f} | {' x '.join(f'{100 * e:.0f}' for e in m['box'])} |")


if __name__ == "__main__":
    main()
