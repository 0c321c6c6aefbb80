"""Do the camera's inside points help or harm under a cover that stands off the body? On finished runs' data.

Offline screen behind ``ObservationPolicy.vision_inside_gap``: each log's final inner data (contacts, free space,
the touches' inside points) is kept, the outer data are rebuilt from the scene's camera with inside points at the
depths of each variant (``none``: no camera inside points; ``2``: 2 cm, as the defaults), K_t is re-learned (fixed
starts too), and the estimate is measured as the studies do. Each line also gives the cover's gap as the touches
show it (``cover_gap`` of the contacts and the run's seen points, as the rule computes it). docs/method-notes.md
section 13 reports what it printed.

    python scripts/camera_inside_depths.py outputs/real_ff_wide/logs/*visual-tactile*.gpioius

The logs must come from a study of ``examples/scenes/real/*.toml`` (each log's name gives its scene and seed).
"""

from __future__ import annotations

import dataclasses
import sys
import warnings

import numpy as np
import torch

import torch_gpioius as tg
from torch_gpioius.exploration.observations import (Observations, cover_gap, drop_contradicted_inside,
                                                    vision_observations)

from inner_mean_offset import final_state       # scripts/ is on the path when a script runs: the same log reader

VARIANTS = {"none": (), "2": (0.02,)}


def outer_data(scene, depths) -> tuple[np.ndarray, np.ndarray]:
    """The scene camera's outer observations as a run's first step makes them, with inside points at ``depths``."""
    policy = scene.defaults.policy
    crop = scene.crop_box()
    if crop is not None and policy.crop_margin is not None:
        crop = crop + np.array([[-policy.crop_margin], [policy.crop_margin]])
    cloud = scene.camera.capture()
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


def _row(tag: str, scene, model, contacts) -> str:
    m = scene.measure(model, contacts).shape
    return f"{tag}: Ch {m['chamfer'] * 100:.2f} bias {m['bias'] * 100:+.2f} rho {model.correlation:.2f}"


def main(paths: list[str]) -> None:
    warnings.simplefilter("ignore")
    torch.set_num_threads(1)
    for path in paths:
        run, scene, model, data, contacts = final_state(path)
        inner = data.task == 0
        seen = data.x[(data.task == 1) & (data.y == 0)]
        gap = cover_gap(contacts, seen, reach=max(0.02, scene.defaults.policy.voxel or 0.0))
        out = [f"gap {gap * 100:.1f}", _row("run", scene, model, contacts)]
        for tag, depths in VARIANTS.items():
            xo, yo = outer_data(scene, depths)
            x, y = np.concatenate([data.x[inner], xo]), np.concatenate([data.y[inner], yo])
            t = np.concatenate([np.zeros(int(inner.sum()), np.int64), np.ones(len(xo), np.int64)])
            fit = tg.GPIOIS(torch.as_tensor(x), torch.as_tensor(y), torch.as_tensor(t), noise=model.noise,
                            kernel=model.covar_module).fit(multi_start=True)
            out.append(_row(tag, scene, fit, contacts))
        print(run.path.stem, " | ".join(out), flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
