"""Active visuo-tactile exploration in 3-D on the simulated UR5 (Sec. VI): camera once, approach, then plan on
the GPIOIS, slide under force control, observe, re-learn, until 1.5 m of fingertip travel.

Reached through :func:`torch_gpioius.explore` with a :class:`torch_gpioius.sim.Scene3D`; the robot, the force
sensor and the camera are real objects of this library (``kinematics.SimulatedUR5`` behind its safety gate,
``torch_gpioius.sensors.SimulatedForceSensor``, ``torch_gpioius.sensors.SimulatedDepthCamera``), so the same
loop drives ``kinematics.RTDEUR5`` with an ``OptoForceDAQ`` and a recorded point cloud.
"""

from __future__ import annotations

import dataclasses
import os
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
import trimesh
from tqdm.auto import tqdm

from .contact import ContactController, ContactFault
from .datasets import LogWriter
from .gpiois import GPIOIS, INNER, OUTER
from .gpis import GPIS
from .metrics import hausdorff_distance, uncertainty_measure
from .planning import plan_direction
from .surfaces import evaluate_grid, zero_level_mesh

__all__ = ["Robot3D", "simulated_robot", "surface_samples", "clip_mesh", "thin_points", "explore_3d",
           "estimate_metrics_3d"]


@dataclass
class Robot3D:
    """The hardware of one 3-D exploration: robot backend, force sensor and contact controller."""

    robot: Any
    sensor: Any
    controller: ContactController


def tool_rotation(direction) -> torch.Tensor:
    """`(3, 3)` ``R_base_tool`` whose z axis (the fingertip's pointing direction) is ``direction``."""
    z = torch.as_tensor(direction, dtype=torch.float64)
    z = z / z.norm()
    helper = torch.tensor([1.0, 0.0, 0.0] if abs(float(z[0])) < 0.9 else [0.0, 1.0, 0.0], dtype=torch.float64)
    x = torch.linalg.cross(helper, z)
    x = x / x.norm()
    return torch.stack([x, torch.linalg.cross(z, x), z], dim=1)


def simulated_robot(scene, *, tool_length: float = 0.05, noise_std: float = 0.02, seed: int = 0,
                    q_home=(0.0, -1.2, 1.5, -1.9, -1.57, 0.0), margin: float = 0.1) -> Robot3D:
    """A simulated UR5 with a fingertip force sensor, placed at ``scene.start`` pointing along the approach.

    Args:
        scene: a ``Scene3D``.
        tool_length: fingertip offset from the flange along the tool z axis [m].
        noise_std: force-sensor noise per axis [N] (the OptoForce OMD-20 is specified to about 0.01-0.03 N).
        seed: sensor noise seed.
        q_home: `(6,)` initial guess for the inverse kinematics of the start pose [rad].
        margin: the safety gate's workspace box is the exploration range and the start grown by this [m];
            the planner's range penalty keeps it well inside.
    """
    from kinematics import UR5, SafetyGate, SimulatedUR5
    from .sensors.simulated import SimulatedForceSensor

    ur5 = UR5(tool_offset=(0.0, 0.0, tool_length))
    T = torch.eye(4, dtype=torch.float64)
    T[:3, :3] = tool_rotation(scene.direction)
    T[:3, 3] = torch.as_tensor(scene.start, dtype=torch.float64)
    q0 = ur5.inverse_kinematics(T, q_init=torch.as_tensor(q_home, dtype=torch.float64))
    lo = np.minimum(scene.range[:, 0], scene.start) - margin
    hi = np.maximum(scene.range[:, 1], scene.start) + margin
    robot = SimulatedUR5(ur5, q0, SafetyGate(ur5, lo.tolist(), hi.tolist()))
    sensor = SimulatedForceSensor(scene.contact_model(), robot.read_pose, clock=lambda: robot.time,
                                  noise_std=noise_std, seed=seed)
    return Robot3D(robot, sensor, ContactController(robot, sensor))


def thin_points(points: np.ndarray, spacing: float, avoid: np.ndarray, margin: float) -> np.ndarray:
    """Greedy subset of ``points`` `(n, 3)` with neighbours at least ``spacing`` apart and every point at least
    ``margin`` from each of ``avoid`` `(k, 3)` [m] (free space is kept away from contacts, see 2-D trap 2)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    avoid = np.asarray(avoid, dtype=np.float64).reshape(-1, 3)
    if len(avoid):
        pts = pts[np.linalg.norm(pts[:, None] - avoid[None], axis=-1).min(axis=1) >= margin]
    kept: list[np.ndarray] = []
    for p in pts:
        if all(np.linalg.norm(p - q) >= spacing for q in kept):
            kept.append(p)
    return np.asarray(kept).reshape(-1, 3)


def surface_samples(mesh: trimesh.Trimesh, spacing: float, seed: int = 0) -> np.ndarray:
    """`(n, 3)` points on a mesh: its vertices plus area-uniform samples, about one per ``spacing``^2 [m]."""
    if mesh is None or len(mesh.faces) == 0:
        return np.zeros((0, 3))
    count = int(min(max(mesh.area / spacing**2, 100), 400_000))
    pts, _ = trimesh.sample.sample_surface(mesh, count, seed=seed)
    return np.concatenate([np.asarray(mesh.vertices), pts])


def clip_mesh(mesh: trimesh.Trimesh | None, lower, upper) -> trimesh.Trimesh | None:
    """The faces of ``mesh`` whose centres lie in the box ``lower <= c <= upper`` [m]; None if none do."""
    if mesh is None:
        return None
    c = mesh.triangles_center
    keep = ((c >= np.asarray(lower)) & (c <= np.asarray(upper))).all(axis=1)
    if not keep.any():
        return None
    return mesh.submesh([np.flatnonzero(keep)], append=True)


def estimate_metrics_3d(model, scene, resolution: float = 0.02, spacing: float = 0.003) -> dict:
    """Uncertainty (eq. 23) and Hausdorff distance (eq. 24) of the estimated inner surface, in the range.

    The estimate {mu_in = 0} is meshed by marching cubes on a grid over the exploration range grown by 5 cm,
    then both it and the true inner mesh are restricted to the exploration range (the robot can neither
    touch nor be judged on what lies outside it, e.g. under the arm). The Hausdorff distance is computed
    between dense surface samples (``spacing``) with k-d trees, so it is within about ``spacing`` of the
    exact surface-to-surface value.

    Args:
        model: 3-D ``GPIOIS`` or ``GPIS``.
        scene: the ``Scene3D``.
        resolution: marching-cubes grid spacing [m].
        spacing: sampling spacing of the surfaces [m].

    Returns:
        ``{"hausdorff": [m], "uncertainty": relative V, "mesh": estimated trimesh in range or None}``; NaN
        metrics when the estimate has no surface in the range.
    """
    truth = scene.inner_samples_in_range(spacing)
    field = evaluate_grid(model, scene.bounds(0.05), resolution, INNER)
    mesh = clip_mesh(zero_level_mesh(model, None, field=field), scene.range[:, 0], scene.range[:, 1])
    if mesh is None:
        return {"hausdorff": float("nan"), "uncertainty": float("nan"), "mesh": None}
    est = surface_samples(mesh, spacing)
    est = est[scene.in_range(est)]
    return {"hausdorff": hausdorff_distance(est, truth) if len(est) else float("nan"),
            "uncertainty": uncertainty_measure(model, mesh, INNER), "mesh": mesh}


def _camera_observations(camera, voxel: float, free_offset: float | None, scene) -> tuple[np.ndarray, np.ndarray]:
    """Outer-task observations from one capture: voxel-averaged surface (y = 0) and free space (y = 1)."""
    cloud = camera.capture()
    box = scene.bounds(0.15)
    cloud = cloud.cropped(box[:, 0], box[:, 1])   # the table, walls and people a real camera sees are not the object
    if len(cloud) == 0:
        raise ValueError("the camera sees nothing of the object near the exploration range")
    seen = cloud.voxel_averaged(voxel).points
    x, y = [seen], [np.zeros(len(seen))]
    if free_offset is not None and cloud.origin is not None:
        from .importers import voxel_average

        free = voxel_average(cloud.free_space(free_offset), voxel)
        x.append(free)
        y.append(np.ones(len(free)))
    return np.concatenate(x), np.concatenate(y)


def explore_3d(scene, mode: str = "visual-tactile", step: float = 0.01, theta: float = 0.15, noise: float = 0.08,
               max_travel: float = 1.5, max_steps: int = 400, penalty=None, policy=None, voxel: float = 0.05,
               metrics_resolution: float = 0.02, metrics_every: int = 1, progress: bool = False,
               log: str | os.PathLike | None = None, robot: Robot3D | None = None, camera=None):
    """Run one exploration of a 3-D scene on a (simulated) UR5; see :func:`torch_gpioius.explore`.

    Protocol (Sec. VI-A): visual-tactile mode captures one point cloud of the outer surface before exploring
    and averages it into ``voxel`` cubes (paper: 5 cm), giving outer surface points (y = 0) and the free space
    the camera's rays crossed ``policy.vision_free_offset`` in front of them (y = 1). The fingertip approaches
    along ``scene.direction`` until ``|F| >= 1 N``; the exploration starts there. Each step plans d* (eq. 19,
    L = V_in + C with the range penalty of eq. 25) at the contact, executes it with the contact controller
    (tangential sub-steps of 2 mm, regulation along the *measured* force direction: retreat above 5 N, press
    below 1 N), records the end contact (y = 0) and the free space the fingertip crossed (|F| < 1 N, y = 1,
    thinned to ``policy.free_space_spacing`` and kept ``policy.free_space_margin`` from contacts), and
    re-learns K_t. It stops when the fingertip has travelled ``max_travel`` since the first contact, after
    ``max_steps``, when contact is lost, or when the robot refuses a command (safety gate, force fault).

    Returns:
        ``Trace`` with 3-D ``path`` and ``contacts``, plus ``sim_time`` (robot clock per record [s]) and
        ``final_mesh`` (the last estimated surface in the range).
    """
    from .exploration import MODES, ObservationPolicy, Trace, retract_free_space

    if mode not in MODES:
        raise ValueError(f"mode: must be one of {MODES}, got {mode!r}")
    if not (step > 0 and max_travel > 0 and max_steps >= 0 and metrics_every >= 1):
        raise ValueError("step and max_travel must be > 0, max_steps >= 0 and metrics_every >= 1")
    policy = policy or ObservationPolicy()
    penalty = penalty if penalty is not None else scene.range_penalty()
    hw = robot if robot is not None else simulated_robot(scene)
    ctl = hw.controller
    camera = camera if camera is not None else scene.camera

    x_out = y_out = None
    if mode == "visual-tactile":
        x_out, y_out = _camera_observations(camera, voxel, policy.vision_free_offset, scene)

    first = ctl.approach(torch.as_tensor(scene.direction), max_travel=2.0)
    if not first.in_contact:
        raise RuntimeError(f"approach from {scene.start.tolist()} along {scene.direction.tolist()} found no contact")
    contact = first.contact.numpy()
    contacts = [contact]
    path = [p for p in first.path.numpy()]
    free = thin_points(first.free_space.numpy(), policy.free_space_spacing, contact[None], policy.free_space_margin)
    x_in = np.concatenate([contact[None], free])
    y_in = np.r_[0.0, np.ones(len(free))]
    if mode == "visual-tactile":
        model = GPIOIS(np.concatenate([x_in, x_out]), np.concatenate([y_in, y_out]),
                       np.r_[np.full(len(x_in), INNER), np.full(len(x_out), OUTER)], theta=theta, noise=noise)
    else:
        model = GPIS(x_in, y_in, theta=theta, noise=noise)

    rec = {"h": [], "u": [], "s": [], "travel": [], "time": [], "kt": [], "sim": []}
    last_mesh = None

    def measure() -> tuple[float, float]:
        nonlocal last_mesh
        m = estimate_metrics_3d(model, scene, metrics_resolution)
        last_mesh = m["mesh"]
        return m["hausdorff"], m["uncertainty"]

    def record(k: int, travel: float, dt: float, final: bool = False) -> None:
        h, u = measure() if k % metrics_every == 0 or final else (float("nan"), float("nan"))
        rec["h"].append(h)
        rec["u"].append(u)
        rec["s"].append(model.similarity if mode == "visual-tactile" else float("nan"))
        rec["kt"].append(model.task_covariance.numpy() if mode == "visual-tactile" else np.full((2, 2), np.nan))
        rec["travel"].append(travel)
        rec["time"].append(dt)
        rec["sim"].append(float(getattr(hw.robot, "time", float("nan"))))

    params = {"scene": scene.name, "mode": mode, "step_length": step, "theta": theta, "noise": noise,
              "max_travel": max_travel, "max_steps": max_steps, "voxel": voxel,
              "metrics_resolution": metrics_resolution, "policy": dataclasses.asdict(policy),
              "penalty": type(penalty).__name__}
    writer = None

    def log_step(k: int, x_new, y_new, task_new, removed, res) -> None:
        if writer is None:
            return
        writer.append("step", {"step": k, "travel": travel, "h": rec["h"][-1], "u": rec["u"][-1],
                               "s": rec["s"][-1], "time": rec["time"][-1], "sim_time": rec["sim"][-1]},
                      {"x": np.asarray(x_new), "y": np.asarray(y_new), "task": np.asarray(task_new, dtype=np.int64),
                       "removed": np.asarray(removed, dtype=np.int64), "contact": contacts[-1],
                       "kt": rec["kt"][-1], "positions": res.path.numpy(), "forces": res.forces.numpy(),
                       "timestamps": np.full(len(res.path), rec["sim"][-1])})

    travel = 0.0
    t0 = time.perf_counter()
    model.fit()
    record(0, 0.0, time.perf_counter() - t0)
    if log is not None:
        writer = LogWriter(log, {"dim": 3, "frame": "base", "source": "torch_gpioius.explore", **params})
        task0 = model.train_inputs[1].reshape(-1).numpy() if mode == "visual-tactile" else np.zeros(len(x_in))
        log_step(0, model.train_inputs[0].numpy(), model.train_targets.numpy(), task0, [], first)

    previous, normal = None, first.force_normal
    terminated = None
    bar = tqdm(total=round(max_travel * 100), desc=f"{scene.name or 'scene'} {mode} [cm]", disable=not progress,
               leave=False)
    k = 0
    while terminated is None:
        if k >= max_steps:
            terminated = "max_steps"
            break
        k += 1
        t0 = time.perf_counter()
        x = contacts[-1]
        plan = plan_direction(model, torch.as_tensor(x), step=step, penalty=penalty, previous=previous)
        previous = plan.direction
        t_plan = time.perf_counter() - t0
        try:
            res = ctl.slide(plan.direction, normal)
        except (ContactFault, RuntimeError) as exc:   # SafetyViolation and RobotError are RuntimeErrors
            terminated = f"refused: {exc}"
            break
        travel += res.travel
        path.extend(res.path.numpy())
        if not res.in_contact:
            terminated = "lost-contact"
            break
        normal = res.force_normal
        t1 = time.perf_counter()
        settled = res.contact.numpy()
        contacts.append(settled)
        new_free = thin_points(res.free_space.numpy(), policy.free_space_spacing, np.asarray(contacts),
                               policy.free_space_margin)
        new_x = np.concatenate([settled[None], new_free])
        new_y = np.r_[0.0, np.ones(len(new_free))]
        removed = retract_free_space(model, settled, policy.free_space_margin)
        if mode == "visual-tactile":
            model.add_observations(new_x, new_y, INNER)
            model.fit(multi_start=False)
        else:
            model.add_observations(new_x, new_y)
            model.fit()
        dt = t_plan + time.perf_counter() - t1    # planning + ingest + re-learn; robot motion excluded
        done = travel >= max_travel
        record(k, travel, dt, final=done)
        log_step(k, new_x, new_y, np.zeros(len(new_x), np.int64), removed, res)
        bar.update(min(round(travel * 100), bar.total) - bar.n)
        if done:
            terminated = "travel"
    bar.close()
    if np.isnan(rec["h"][-1]) and len(rec["h"]) > 1:
        rec["h"][-1], rec["u"][-1] = measure()   # always measure the final estimate
    if writer is not None:
        writer.append("end", {"terminated": terminated, "steps": len(rec["h"]) - 1}, {})
        writer.close()
    return Trace(mode=mode, scene_name=scene.name, hausdorff=np.asarray(rec["h"]), uncertainty=np.asarray(rec["u"]),
                 similarity=np.asarray(rec["s"]), travel=np.asarray(rec["travel"]), path=np.asarray(path),
                 contacts=np.asarray(contacts), model=model, step_time=np.asarray(rec["time"]),
                 terminated=terminated, task_covariance=np.asarray(rec["kt"]), sim_time=np.asarray(rec["sim"]),
                 final_mesh=last_mesh)
