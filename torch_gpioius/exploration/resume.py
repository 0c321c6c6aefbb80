"""Resume an exploration from its crash-safe log: the model, the loop state and the world's hardware state."""

from __future__ import annotations

import math
import os
import warnings

import numpy as np
import torch

from ..io.datasets import DatasetError, TornLogWarning, read_records, replay, step_number
from ..models.gpiois import GPIOIS
from ..models.gpis import GPIS

__all__ = ["restore_run"]


def _same(have, want) -> bool:
    if isinstance(want, float) and isinstance(have, (int, float)) and not isinstance(have, bool):
        return math.isclose(have, want, rel_tol=1e-12, abs_tol=0.0)
    if isinstance(want, dict) and isinstance(have, dict):
        return set(want) == set(have) and all(_same(have[k], want[k]) for k in want)
    if isinstance(want, (list, tuple)) and isinstance(have, (list, tuple)):
        return len(want) == len(have) and all(_same(a, b) for a, b in zip(have, want))
    return have == want


def restore_run(path: str | os.PathLike, params: dict, world, hw):
    """Rebuild the loop state after the last complete step of a log written by :func:`torch_gpioius.explore`.

    The log's header must carry the same parameters and the same world (its geometry fingerprint, not just its
    name); the hardware is put back into the state logged with the last step (the robot's joints and clock,
    the sensor's noise generator), so the resumed run continues exactly where the killed one stopped.

    Raises:
        ValueError: the log was written by a different run (names the parameter).
        DatasetError: the log is unreadable or holds no complete step.
    """
    from .loop import _State

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", TornLogWarning)
        records = list(read_records(path))
        states = [ds for rec, ds in replay(path) if rec.kind in ("step", "tap")]
    if not records or records[0].kind != "header":
        raise DatasetError(f"{path}: no header record; not an exploration log")
    header = records[0].meta
    for key, want in params.items():
        have = header.get(key)
        if not _same(have, want):
            what = "world geometry" if key == "scene_fingerprint" else key
            raise ValueError(f"{path}: cannot resume: the log was written with {key}={have!r}, this call asks "
                             f"{key}={want!r} (different {what})")
    steps = [r for r in records[1:] if r.kind == "step"]
    if not steps:
        raise DatasetError(f"{path}: the log has no complete step to resume from")
    end = [r for r in records[1:] if r.kind == "end"]
    s = _State(model=None)
    keys = {"h": "h", "ht": "ht", "u": "u", "s": "s", "rho": "rho", "travel": "travel", "time": "time",
            "sim": "sim_time", "taps": "taps"}
    for i, r in enumerate(steps):
        where = f"{path}: step record {i}"
        if step_number(r.meta, where) != i:
            raise DatasetError(f"{where}: steps out of order (found step {r.meta['step']})")
        s.contacts.append(np.asarray(r.arrays["contact"], dtype=np.float64))
        s.path.extend(list(np.asarray(r.arrays["path"], dtype=np.float64)))
        for key, field in keys.items():
            v = r.meta.get(field, math.nan)
            s.rec[key].append(int(v) if key == "taps" else float(v if v is not None else math.nan))
        ci = r.meta.get("ci", [math.nan, math.nan])
        s.rec["ci"].append(tuple(float(math.nan if v is None else v) for v in ci))
        s.rec["kt"].append(np.asarray(r.arrays["kt"], dtype=np.float64))
    last, data = steps[-1], states[-1]    # the training set after the last step or tap (everything replayed)
    taps = [r for r in records[1:] if r.kind == "tap"]
    theta, noise = header["theta"], header["noise"]
    if header["mode"] == "visual-tactile" and header.get("regions"):
        from ..models.local import LocalGPIOIS

        model = LocalGPIOIS(data.x, data.y, data.task, regions=int(header["regions"]), theta=theta, noise=noise)
        model.params.copy_(torch.as_tensor(last.arrays["local_params"]))
        model._engine = None
        for r in steps:
            s.rec["regions"].append(np.full(model.regions, math.nan))
    elif header["mode"] == "visual-tactile":
        model = GPIOIS(data.x, data.y, data.task, theta=theta, noise=noise,
                       task_covariance=torch.as_tensor(last.arrays["kt"]))
    else:
        model = GPIS(data.x, data.y, theta=theta, noise=noise)
    s.model = model
    s.travel = float(last.meta["travel"])
    s.retracted = int(last.meta.get("retracted", 0))
    s.taps = int(last.meta.get("taps", 0))
    s.steps = step_number(last.meta, f"{path}: last step")
    for name in ("previous", "normal"):
        v = np.asarray(last.arrays.get(name, np.full(world.dim, np.nan)), dtype=np.float64)
        setattr(s, name, None if np.isnan(v).any() else torch.as_tensor(v))
    s.terminated = end[-1].meta["terminated"] if end else None
    after = taps[-1] if taps and taps[-1].meta.get("step") == s.steps else last
    if after is not last:                        # the last step ended with a tap: its travel, contact and state
        s.travel = float(after.meta["travel"])
        s.taps = int(after.meta["taps"])
        s.contacts[-1] = np.asarray(after.arrays["contact"], dtype=np.float64)
        s.normal = torch.as_tensor(np.asarray(after.arrays["normal"], dtype=np.float64))
        s.last_tap = s.steps
    state = {k[len("world_"):]: v for k, v in after.arrays.items() if k.startswith("world_")}
    world.restore(hw, state)
    return s
