"""Would the camera's inside points at more than one depth follow a cover that stands off the body? On finished runs.

Offline screen: each log's final inner data (contacts, free space, the touches' inside points) is kept, the outer
data are rebuilt from the scene's camera with inside points at the depths given, K_t is re-learned (fixed starts
too), and the estimate is measured as the studies do. ``none`` has no camera inside points.

    python scripts/camera_inside_depths.py outputs/real_ff_wide/logs/duck-wide_visual-tactile_0.gpioius ...
"""

from __future__ import annotations

import sys
import warnings

import numpy as np
import torch

import torch_gpioius as tg
from torch_gpioius.exploration.observations import (Observations, drop_contradicted_inside, vision_observations)
from torch_gpioius.io.runs import load_run
from torch_gpioius.sim.scenefile import load_scene

VARIANTS = {"none": (), "2": (0.02,)}


def outer_data(scene, depths):
    policy = scene.defaults.policy
    crop = scene.crop_box()
    if crop is not None and policy.crop_margin is not None:
        crop = crop + np.array([[-policy.crop_margin], [policy.crop_margin]])
    cloud = scene.camera.capture()
    import dataclasses
    x, y = vision_observations(cloud, dataclasses.replace(policy, vision_inside=None), crop)
    if crop is not None:
        cloud = cloud.cropped(crop[0], crop[1])
    xs, ys = [x], [y]
    for d in depths:
        pts = cloud.behind(d, policy.voxel)
        xs.append(pts)
        ys.append(np.full(len(pts), policy.inside_label(d)))
    obs = drop_contradicted_inside(Observations(np.concatenate(xs), np.concatenate(ys),
                                                np.ones(sum(map(len, ys)), np.int64)), policy)
    return obs.x, obs.y


def main(paths):
    warnings.simplefilter("ignore")
    torch.set_num_threads(1)
    for path in paths:
        run = load_run(path)
        name, _, seed = run.path.stem.rsplit("_", 2)
        scene = load_scene(f"examples/scenes/real/{name}.toml", seed=int(seed))
        last = run.steps[-1]
        model, data = run.model_at(last), run.states[last]
        inner = data.task == 0
        contacts = data.x[inner & (data.y == 0)]
        m = scene.measure(model, contacts).shape
        from scipy.spatial import cKDTree
        gap = cKDTree(scene.camera.capture().points).query(contacts)[0]
        seen = data.x[(data.task == 1) & (data.y == 0)]
        vgap = cKDTree(seen).query(contacts)[0]
        out = [f"voxel gap {np.median(vgap) * 100:.1f}", f"gap {np.median(gap) * 100:.1f} ({np.percentile(gap, 25) * 100:.1f}-{np.percentile(gap, 75) * 100:.1f})",
               f"run: Ch {m['chamfer'] * 100:.2f} bias {m['bias'] * 100:+.2f} rho {model.correlation:.2f}"]
        for tag, depths in VARIANTS.items():
            xo, yo = outer_data(scene, depths)
            if "checked" in tag:          # the touches' data contradict camera inside points in a cover's gap
                obs = drop_contradicted_inside(Observations(xo, yo, np.ones(len(xo), np.int64)),
                                               scene.defaults.policy, data.x[inner], data.y[inner])
                xo, yo = obs.x, obs.y
            x = np.concatenate([data.x[inner], xo])
            y = np.concatenate([data.y[inner], yo])
            t = np.concatenate([np.zeros(int(inner.sum()), np.int64), np.ones(len(xo), np.int64)])
            fit = tg.GPIOIS(torch.as_tensor(x), torch.as_tensor(y), torch.as_tensor(t), noise=model.noise,
                            kernel=model.covar_module)
            fit.fit(multi_start=True)
            m = scene.measure(fit, contacts).shape
            out.append(f"{tag}: Ch {m['chamfer'] * 100:.2f} bias {m['bias'] * 100:+.2f} rho {fit.correlation:.2f}")
        print(run.path.stem, " | ".join(out), flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
