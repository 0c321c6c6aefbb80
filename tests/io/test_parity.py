"""The guard that a user's files and a simulated run never drift apart (issue 52, item 4): a simulated run's final
observations, written as a user would have them (a contacts CSV with each contact's outward normal, and one PLY per
capture with its camera origin), given to ``gpioius fit`` with default settings, give the run's own final model: the
same training data, the same K_t, the same estimate."""

import numpy as np
import pytest
import torch
import trimesh

import torch_gpioius as tg
from torch_gpioius.cli import main


def _body():
    """A 12 cm ellipsoid: the default settings' rules give 2 cm voxels and a 4 cm length for it and for its cover's
    cloud alike."""
    body = trimesh.creation.icosphere(subdivisions=3, radius=0.05)
    body.apply_scale([1.2, 1.0, 0.9])
    return body


def _scene(world: str, folder):
    """The body under a tight cover in ``world``, from a scene file with the default settings."""
    if world == "mujoco":
        pytest.importorskip("mujoco")
    from torch_gpioius.sim.scenefile import load_scene

    _body().export(folder / "body.stl")
    (folder / "body.toml").write_text('name = "body"\n[object]\nmesh = "body.stl"\nat = [0.5, 0.0, 0.1]\n'
                                       '[cover]\nkind = "tight"\ngap = 0.008\n')
    return load_scene(folder / "body.toml", world=world, settings="default", smoke=True)


def _write_ply(path, points):
    """An ASCII PLY of `(n, 3)` points with every digit (a float32 binary PLY would round them at 1e-8)."""
    lines = ["ply", "format ascii 1.0", f"element vertex {len(points)}", "property double x", "property double y",
             "property double z", "end_header"]
    lines += [" ".join(repr(float(v)) for v in p) for p in points]
    path.write_text("\n".join(lines) + "\n")


def _user_files(tmp_path, world, model, log):
    """The run's final data as a user has it: the contacts and free space the fingertip recorded, in order with
    their steps (each contact with the outward normal its inside point was placed along), and every capture of the
    camera, cropped as the run cropped it, one PLY each with its camera's origin."""
    x = model.train_inputs[0].numpy()
    y = model.train_targets.numpy()
    task = model.train_task.numpy()
    logged = tg.load_dataset(log)
    step_of = {tuple(p): int(k) for p, k in zip(logged.x, logged.step)}
    inner = np.flatnonzero(task == 0)
    depth = world.defaults.policy.touch_inside
    rows = ["x,y,z,label,step,nx,ny,nz"]
    repeats = world.defaults.policy.contact_repeats
    for j, i in enumerate(inner):
        if y[i] < 0:
            continue                                            # placed by the fit from the contact's normal
        if y[i] == 0 and j and y[inner[j - 1]] == 0 and (x[inner[j - 1]] == x[i]).all():
            continue                                            # the model's repetition of a contact (the fit's too)
        normal = ["", "", ""]
        nxt = inner[j + repeats] if y[i] == 0 and j + repeats < len(inner) else (
            inner[j + 1] if j + 1 < len(inner) else None)
        if y[i] == 0 and nxt is not None and y[nxt] < 0:       # a touch records its contact, then the point behind
            normal = [repr(float(v)) for v in (x[i] - x[nxt]) / depth]
        label = "contact" if y[i] == 0 else "free"
        rows.append(",".join([*(repr(float(v)) for v in x[i]), label, str(step_of[tuple(x[i])]), *normal]))
    (tmp_path / "contacts.csv").write_text("\n".join(rows) + "\n")
    cloud = world.hardware().camera.capture()                   # the run saw this cloud (one noise per scene)
    policy = world.defaults.policy
    crop = world.crop_box() + np.array([[-policy.crop_margin], [policy.crop_margin]])
    cloud = cloud.cropped(crop[0], crop[1])
    views = cloud.view_ids()
    argv = []
    for k in dict.fromkeys(views.tolist()):                     # the captures in the order the camera gave them
        path = tmp_path / f"capture{k}.ply"
        _write_ply(path, cloud.points[views == k])
        origin = cloud.origin[views == k][0] if cloud.per_point_origins else cloud.origin
        argv += ["--cloud", str(path), "--camera-origin", " ".join(repr(float(v)) for v in origin)]
    return argv


@pytest.mark.parametrize("world", ["forcefield", "mujoco"])
def test_fit_on_a_runs_files_gives_the_runs_own_model(tmp_path, world, capsys):
    scene = _scene(world, tmp_path)
    log = tmp_path / "run.gpioius"
    trace = tg.explore(scene, max_travel=0.06, metrics_every=100, progress=False, log=log)
    run = trace.model
    assert run.kernel.describe()["kernel"] == "Matern52"        # the default settings ran
    argv = _user_files(tmp_path, scene, run, log)
    out = tmp_path / "fit"
    assert main(["fit", str(tmp_path / "contacts.csv"), *argv, "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "settings default: Matern52(lengthscale=0.04, outputscale=1) (a fifth of the object, 4 cm-10 cm)" in printed
    fit = tg.load_checkpoint(out / "model.pt")
    # the same data: every observation of the run, and nothing else, with its label and task
    a = np.c_[run.train_inputs[0].numpy(), run.train_targets.numpy(), run.train_task.numpy()]
    b = np.c_[fit.train_inputs[0].numpy(), fit.train_targets.numpy(), fit.train_task.numpy()]
    a, b = a[np.lexsort(a.T[::-1])], b[np.lexsort(b.T[::-1])]
    assert a.shape == b.shape, (a.shape, b.shape)
    np.testing.assert_allclose(b, a, rtol=0, atol=1e-12)
    assert fit.kernel.describe() == run.kernel.describe() and fit.noise == run.noise
    # the same estimate: K_t at the likelihood's optimum, the correlation and the mean
    assert abs(fit.correlation - run.correlation) < 1e-9
    # two fits of K_t (the run's warm-started, the file's from fixed starts) stop within ~1e-10 of the optimum, whose
    # likelihood is flat along the correlation at its bound (curvature ~1e-8); the mean amplifies that about tenfold
    torch.testing.assert_close(fit.task_covariance, run.task_covariance, rtol=0, atol=1e-9)
    q = torch.as_tensor(run.train_inputs[0][:200].numpy() * 0.98 + np.array([0.01, 0.0, 0.002]))
    torch.testing.assert_close(fit.predict(q, 0)[0], run.predict(q, 0)[0], rtol=0, atol=1e-8)
    # at the same K_t the two paths are one computation: the same mean to rounding
    fit.task_covariance = run.task_covariance
    torch.testing.assert_close(fit.predict(q, 0)[0], run.predict(q, 0)[0], rtol=0, atol=1e-12)
