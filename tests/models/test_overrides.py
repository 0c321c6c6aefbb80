"""The one resolver of the estimator's loose settings (:class:`EstimatorOverrides`): one check per setting at every
door (keyword, command line, scene file, study), the same settings from every door, and a recorded run rebuilt from
its recorded settings."""

import dataclasses
import math

import numpy as np
import pytest

import torch_gpioius as tg
from torch_gpioius.core.validation import NOISE_RANGE
from torch_gpioius.cli import main
from torch_gpioius.exploration.config import ExploreConfig
from torch_gpioius.kernels import InverseMultiquadricKernel, KernelChoice, Matern52
from torch_gpioius.models.estimator import EstimatorSettings, LengthRule
from torch_gpioius.models.labels import ObservationPolicy
from torch_gpioius.models.overrides import EstimatorOverrides, parse_assignment

BASE = EstimatorSettings.default().for_extent(0.2)          # sized to a 20 cm body: 4 cm length, 2 cm voxels


def test_each_change_is_applied_as_the_settings_own_fields_say():
    """The reference is written field by field with ``dataclasses.replace``, not through the resolver."""
    changes = EstimatorOverrides(noise=0.05, voxel=0.03, learn="length", restart_every=None,
                                 labels={"ray_smoothing": None, "vision_inside": 0.01})
    got = changes.apply(BASE)
    want = dataclasses.replace(
        BASE, noise=0.05, learn="length", restart_every=None, voxel_rule=None, name="custom",
        labels=dataclasses.replace(BASE.labels, voxel=0.03, ray_smoothing=None, vision_inside=0.01))
    assert got == want and got.length_rule == BASE.length_rule and got.lengthscale == BASE.lengthscale == 0.04
    assert EstimatorOverrides().apply(BASE) is BASE and not EstimatorOverrides()


def test_a_kernel_named_alone_keeps_the_rule_at_its_length_and_a_length_or_kernel_object_replaces_it():
    named = EstimatorOverrides(kernel="imq").apply(BASE)
    assert isinstance(named.kernel, InverseMultiquadricKernel) and named.lengthscale == 0.04
    assert named.length_rule == LengthRule() and named.for_extent(0.2) == named     # sized already: unchanged
    fixed = EstimatorOverrides(kernel=KernelChoice(lengthscale=0.06)).apply(BASE)
    assert isinstance(fixed.kernel, Matern52) and fixed.lengthscale == 0.06 and fixed.length_rule is None
    given = EstimatorOverrides(kernel=InverseMultiquadricKernel(0.15)).apply(BASE)
    assert given.lengthscale == 0.15 and given.length_rule is None
    assert BASE.lengthscale == 0.04 and isinstance(BASE.kernel, Matern52)          # the base untouched


@pytest.mark.parametrize("bad, match", [
    (dict(noise=NOISE_RANGE[0] / 2), "noise"), (dict(noise=NOISE_RANGE[1] * 2), "noise"),
    (dict(noise=math.nan), "noise"), (dict(voxel=-0.01), "voxel"), (dict(voxel=2.0), "voxel"),
    (dict(learn="everything"), "learn"), (dict(restart_every=0), "restart_every"),
    (dict(kernel="rbf"), "rbf"),
    (dict(kernel=3), "kernel"), (dict(labels={"ray_smoothing": 3}), "ray_smoothing"),
    (dict(labels={"touch_inside": 0.15}), "touch_inside"), (dict(labels={"cover_offset": 1}), "cover_offset"),
    (dict(labels={"no_such_field": 1}), "unknown field 'no_such_field'"),
    (dict(labels={"camera_bound": "12mm,2deg"}), "camera_bound: must be \\(translation"),
    (dict(voxel=0.03, labels={"voxel": 0.02}), "voxel given twice"), (dict(policy="paper"), "policy"),
])
def test_a_bad_value_is_refused_when_given_naming_the_setting(bad, match):
    with pytest.raises(ValueError, match=match):
        EstimatorOverrides(**bad)


def test_the_checks_are_the_settings_own_at_every_door(tmp_path, capsys):
    """sigma^2 above its range is refused alike by the settings, the resolver, the command line's two spellings, a
    scene file's [estimator] section and a study: one check, one message."""
    from tests.sim.test_scenefile import ball_scene
    from torch_gpioius.sim.scenefile import read_scene
    from torch_gpioius.studies.study import run_sweep

    noise = NOISE_RANGE[1] * 2
    messages = []
    for make in (lambda: EstimatorSettings.default().replace(noise=noise), lambda: EstimatorOverrides(noise=noise),
                 lambda: read_scene(ball_scene(tmp_path, extra=f"[estimator]\nnoise = {noise}\n")),
                 lambda: run_sweep(world="forcefield", out=tmp_path / "s", estimator={"noise": noise})):
        with pytest.raises(ValueError) as info:
            make()
        messages.append(str(info.value))
    said = f"noise: {noise:g} is above the supported maximum {NOISE_RANGE[1]:g}"
    assert all(m.endswith(said) for m in messages), messages
    for args in (["--noise", str(noise)], ["--estimator", f"noise={noise}"]):
        with pytest.raises(SystemExit):
            main(["study", "--world", "forcefield", "--out", str(tmp_path / "c"), *args])
        assert said in capsys.readouterr().err
    assert not (tmp_path / "s").exists() and not (tmp_path / "c").exists()      # refused before anything


def test_plain_data_and_assignments_round_trip():
    changes = EstimatorOverrides.from_assignments(
        ["kernel=imq", "lengthscale=0.05", "noise=0.02", "learn=all", "restart_every=none", "labels.ray_smoothing=none",
         "labels.cover_offset=true", "labels.camera_bound=0.012,0.035"])
    assert changes.kernel == KernelChoice("imq", 0.05) and changes.restart_every is None
    assert dict(changes.labels) == {"ray_smoothing": None, "cover_offset": True,
                                    "camera_bound": (0.012, 0.035)}
    assert EstimatorOverrides.from_dict(changes.to_dict()) == changes
    whole = EstimatorOverrides(policy=ObservationPolicy(voxel=0.05), noise=0.1)
    assert EstimatorOverrides.from_dict(whole.to_dict()) == whole
    assert parse_assignment("voxel = 0") == ("voxel", 0) and parse_assignment("x=on") == ("x", True)
    for bad in ("noise", "=3", None):
        with pytest.raises(ValueError, match="KEY=VALUE"):
            parse_assignment(bad)
    with pytest.raises(ValueError, match="noise given twice"):
        EstimatorOverrides.from_assignments(["noise=0.1", "noise=0.2"])
    with pytest.raises(ValueError, match=r"unknown key\(s\) \['nosie'\].*labels.<field>"):
        EstimatorOverrides.from_dict({"nosie": 0.1})
    with pytest.raises(ValueError, match="lengthscale: 25 m is above 10 m"):
        EstimatorOverrides.from_dict({"lengthscale": 25})
    with pytest.raises(ValueError, match="lengthscale, theta"):
        EstimatorOverrides.from_dict({"theta": 0.1, "lengthscale": 0.1})


def test_merged_lets_the_later_win_and_merges_labels():
    first = EstimatorOverrides(noise=0.1, voxel=0.02, labels={"ray_smoothing": None, "vision_inside": 0.01})
    later = EstimatorOverrides(noise=0.2, labels={"vision_inside": 0.03})
    both = first.merged(later)
    assert both.noise == 0.2 and both.voxel == 0.02
    assert dict(both.labels) == {"ray_smoothing": None, "vision_inside": 0.03}


def test_explore_takes_the_changes_as_keywords_or_as_one_object_and_makes_the_same_settings():
    scene = tg.sim.paper_objects_2d()["A"]
    policy = dataclasses.replace(scene.defaults.policy, vision_free_offset=0.04)
    with pytest.warns(DeprecationWarning, match=r"ExploreConfig.from_world\(kernel=, noise=, policy=, learn=, "
                      r"restart_every=\): give settings=EstimatorOverrides"):
        loose = ExploreConfig.from_world(scene, noise=0.01, learn="length", kernel=Matern52(0.08), policy=policy,
                                         restart_every=5)
    one = ExploreConfig.from_world(scene, settings=EstimatorOverrides(
        noise=0.01, learn="length", kernel=Matern52(0.08), policy=policy, restart_every=5))
    assert loose.estimator == one.estimator
    assert one.estimator.noise == 0.01 and one.estimator.labels.vision_free_offset == 0.04
    assert one.estimator.restart_every == 5 and one.estimator.lengthscale == 0.08
    with pytest.raises(ValueError, match="no learnable length"):     # the settings' own check, after merging
        with pytest.warns(DeprecationWarning):
            ExploreConfig.from_world(scene, settings=EstimatorOverrides(learn="length"), kernel=_FixedLength(0.1))
    with pytest.raises(TypeError, match="unexpected keyword argument 'nosie'"):
        ExploreConfig.from_world(scene, nosie=0.01)
    with pytest.raises(TypeError, match="explore\\(\\) got an unexpected keyword argument 'voxel'"):
        tg.explore(scene, voxel=0.01)


class _FixedLength(InverseMultiquadricKernel):
    """A kernel without a learnable length (as a kind registered from outside may be)."""

    learnable_length = False


def test_a_study_sends_every_change_to_its_runs_in_one_object(tmp_path):
    """--estimator reaches each run's settings beside the flags of their own (which keep the folder's old identity
    keys), the folder records it, and another change is another folder."""
    from torch_gpioius.studies.study import _claim
    from torch_gpioius.studies.study_runs import _explore_kwargs
    from torch_gpioius.studies.study_plan import StudyPlan, with_loose

    def settings(estimator, **loose):
        return StudyPlan.checked(world="planar", objects=["A"], modes=["visual-tactile"], seeds=1,
                                 out=tmp_path / "s", workers=None, address=None, max_travel=None,
                                 max_steps=None, smoke=True, progress=False, threads=1, backend="local",
                                 force=False, scenes=(), touch="point", outer_tol=None,
                                 device=None, estimator=with_loose(estimator, loose))

    sweep = settings(["labels.vision_free_offset=0.04", "learn=length", "noise=0.02"])
    assert sweep.noise == 0.02 and sweep.learn == "length"               # the folder's identity keys, as before
    assert dict(sweep.estimator.labels) == {"vision_free_offset": 0.04} and sweep.estimator.learn is None
    assert settings(["labels.vision_free_offset=0.04", "learn=length"], noise=0.02) == sweep   # the old keyword
    (spec,) = sweep._specs(tmp_path / "s")
    world = tg.sim.paper_objects_2d()["A"]
    est = _explore_kwargs(spec, world)["settings"]
    assert est.noise == 0.02 and est.learn == "length" and est.labels.vision_free_offset == 0.04
    assert est.kernel.describe() == world.defaults.kernel.describe()
    _claim(sweep)
    with pytest.raises(FileExistsError):
        _claim(settings(["labels.vision_free_offset=0.03", "learn=length", "noise=0.02"]))
    with pytest.raises(ValueError, match="noise given beside the noise argument"):
        settings({"noise": 0.03}, noise=0.02)


def test_the_command_line_declares_the_estimators_flags_once_for_each_command(monkeypatch):
    """study, simulate3d, fit and import-bag take the same flags, of the same types, from one declaration."""
    import argparse

    from torch_gpioius import cli

    seen = {}
    real = cli._add_estimator_arguments

    def spy(p, default):
        seen[p.prog.split()[-1]] = default
        return real(p, default)

    monkeypatch.setattr(cli, "_add_estimator_arguments", spy)
    cli.build_parser()
    assert set(seen) == {"study", "simulate3d", "fit", "import-bag"}, seen
    args = argparse.Namespace(theta=None, kernel="imq", lengthscale=None, noise=0.1, learn=None, voxel=0.02,
                              estimator=["labels.ray_smoothing=none"])
    changes = cli._estimator_overrides(args)
    assert changes == EstimatorOverrides(kernel="imq", noise=0.1, voxel=0.02, labels={"ray_smoothing": None})
    with pytest.raises(ValueError, match="noise given by its own flag too"):
        cli._estimator_overrides(argparse.Namespace(**{**vars(args), "estimator": ["noise=0.2"]}))
    with pytest.warns(DeprecationWarning):
        theta = cli._estimator_overrides(argparse.Namespace(**{**vars(args), "kernel": None, "theta": 0.1}))
    assert theta.kernel == KernelChoice("imq", 0.1)


def test_a_scene_files_estimator_section_changes_the_worlds_own_settings(tmp_path):
    from tests.sim.test_scenefile import ball_scene
    from torch_gpioius.sim.scenefile import load_scene, read_scene

    path = ball_scene(tmp_path, extra="[estimator]\nnoise = 0.05\nlabels = { ray_smoothing = 32 }\n")
    (tmp_path / "p").mkdir()
    plain = load_scene(ball_scene(tmp_path / "p"))
    scene = load_scene(path)
    want = plain.defaults.estimator.replace(noise=0.05, labels={"ray_smoothing": 32})
    assert scene.defaults.estimator == want
    for bad, match in (("nosie = 1", "unknown key"), ("labels = { ray_smoothing = 2 }", "ray_smoothing")):
        with pytest.raises(ValueError, match=rf"{path.name}: \[estimator\]: .*{match}"):
            read_scene(ball_scene(tmp_path, extra=f"[estimator]\n{bad}\n"))


def test_a_recorded_run_is_rebuilt_from_its_recorded_settings_and_old_headers_read(tmp_path):
    from torch_gpioius.io.runs import load_run

    scene = tg.sim.paper_objects_2d()["A"]
    log = tmp_path / "run.gpioius"
    trace = tg.explore(scene, max_steps=3, log=log, settings=EstimatorOverrides(noise=0.01))
    run = load_run(log)
    assert run.settings() == ExploreConfig.from_world(scene, settings=EstimatorOverrides(noise=0.01)).estimator
    model = run.model_at(run.steps[-1])
    assert model.noise == pytest.approx(0.01, rel=1e-12)
    np.testing.assert_allclose(model.task_covariance.detach().numpy(), trace.task_covariance[-1], rtol=0, atol=0)
    old = EstimatorSettings.of_record({"theta": 0.12, "noise": 0.02})           # before the settings were recorded
    assert isinstance(old.kernel, InverseMultiquadricKernel) and old.lengthscale == 0.12 and old.noise == 0.02
    assert EstimatorSettings.of_record({}).noise == 0.006 and EstimatorSettings.of_record({}).lengthscale == 0.1
    with pytest.raises(ValueError, match="the header's noise"):
        EstimatorSettings.of_record({"noise": 1e3})


def test_every_model_comes_from_the_settings_factory():
    rng = np.random.default_rng(0)
    x, y = rng.uniform(-1, 1, (30, 2)) * 0.1, rng.integers(0, 2, 30).astype(float)
    task = np.r_[np.zeros(20, int), np.ones(10, int)]
    est = EstimatorSettings.paper_2d()
    assert type(est.make_model(x, y, task)).__name__ == "GPIOIS"
    assert type(est.make_model(x, y, task, regions=2)).__name__ == "LocalGPIOIS"
    assert type(est.make_model(x, y, np.ones(30, int))).__name__ == "GPIOIS"   # the camera's alone, before a touch
    gpis = est.make_model(x, y)
    assert type(gpis).__name__ == "GPIS" and gpis.noise == pytest.approx(0.006)
    inner = est.make_model(x, y, np.zeros(30, int), noise=0.01, kernel=Matern52(0.05))
    assert inner.noise == pytest.approx(0.01) and isinstance(inner.kernel, Matern52)
    with pytest.raises(ValueError, match="regions"):
        est.make_model(x, y, regions=2)


def test_fit_dataset_takes_changes_to_the_files_own_settings_and_its_loose_keywords_warn():
    """``fit_dataset(settings=EstimatorOverrides(...))`` changes the file's own settings (and records what it used);
    the loose ``kernel``, ``noise``, ``learn`` give the same fit with a DeprecationWarning naming the way."""
    from torch_gpioius.fitting import fit_dataset

    data = "data/example_2d.gpioius"
    one = fit_dataset(data, settings=EstimatorOverrides(kernel=InverseMultiquadricKernel(0.12), noise=0.01),
                      resolution=0.02)
    with pytest.warns(DeprecationWarning, match=r"fit_dataset\(kernel=, noise=\): give settings=EstimatorOverrides"):
        loose = fit_dataset(data, kernel=InverseMultiquadricKernel(0.12), noise=0.01, resolution=0.02)
    assert one["task_covariance"] == loose["task_covariance"] and one["mll"] == loose["mll"]
    assert one["lengthscale"] == pytest.approx(0.12) and one["noise"] == pytest.approx(0.01)
    assert one["settings"]["noise"] == 0.01 and one["settings"]["kernel"]["lengthscale"] == pytest.approx(0.12)


def test_dataset_from_files_takes_changes_to_the_default_preset_and_its_loose_keywords_warn(tmp_path):
    """``settings=EstimatorOverrides(voxel=..., noise=...)`` labels a user's files with the default preset so changed
    (the length rule still sized to the clouds); the loose ``voxel`` and ``noise`` give the same dataset, warned."""
    from torch_gpioius.io.importers import dataset_from_files

    rng = np.random.default_rng(1)
    d = rng.standard_normal((400, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    c = np.array([0.5, 0.0, 0.2])
    np.savez(tmp_path / "cloud.npz", points=c + 0.08 * d[d[:, 2] > 0])
    (tmp_path / "touch.csv").write_text("x,y,z,label\n" + "".join(f"{x},{y},{z},contact\n"
                                                                   for x, y, z in c + 0.07 * d[:8]))
    one = dataset_from_files(tmp_path / "touch.csv", tmp_path / "cloud.npz",
                             settings=EstimatorOverrides(voxel=0.03, noise=0.02))
    with pytest.warns(DeprecationWarning, match=r"dataset_from_files\(noise=, voxel=\)"):
        loose = dataset_from_files(tmp_path / "touch.csv", tmp_path / "cloud.npz", voxel=0.03, noise=0.02)
    np.testing.assert_array_equal(one.x, loose.x)
    assert one.meta["estimator"] == loose.meta["estimator"]
    est = EstimatorSettings.from_dict(one.meta["estimator"])
    assert est.labels.voxel == 0.03 and est.voxel_rule is None and est.noise == 0.02
    assert est.length_rule is not None and est.lengthscale == est.length_rule.length(0.16)   # sized to the cloud


def test_every_door_reads_its_old_loose_keywords_once_with_the_way_named():
    """The loose estimator keywords left the signatures (explore, Scene3D.from_mesh, Dataset.to_model, import_bag,
    fit_dataset, dataset_from_files): each still works for one release, through the one resolver, with one
    DeprecationWarning naming settings=EstimatorOverrides(...); a keyword none of them took is a TypeError."""
    import inspect

    import trimesh

    from torch_gpioius.io.importers import dataset_from_files
    from torch_gpioius.fitting import fit_dataset
    from torch_gpioius.io.rosbag import import_bag
    from torch_gpioius.sim.forcefield import Scene3D

    for door in (tg.explore, ExploreConfig.from_world, Scene3D.from_mesh, tg.Dataset.to_model, import_bag,
                 fit_dataset, dataset_from_files):
        named = set(inspect.signature(door).parameters)
        assert not named & {"noise", "voxel", "theta", "lengthscale", "kernel"}, door.__qualname__
    body = trimesh.creation.icosphere(subdivisions=2, radius=0.06)
    with pytest.warns(DeprecationWarning, match=r"Scene3D.from_mesh\(noise=, touch_inside=\): give settings="):
        loose = Scene3D.from_mesh(body, at=[0.5, 0.0, 0.1], noise=0.05, touch_inside=0)
    one = Scene3D.from_mesh(body, at=[0.5, 0.0, 0.1],
                            estimator=tg.EstimatorOverrides(noise=0.05, labels={"touch_inside": None}))
    assert loose.defaults.estimator == one.defaults.estimator
    assert one.defaults.estimator.noise == 0.05 and one.defaults.policy.touch_inside is None
    with pytest.raises(TypeError, match="from_mesh\\(\\) got an unexpected keyword argument 'nosie'"):
        Scene3D.from_mesh(body, at=[0.5, 0.0, 0.1], nosie=0.05)
    from pathlib import Path

    ds = tg.load_dataset(Path(__file__).resolve().parents[2] / "data" / "example_2d.gpioius")
    with pytest.warns(DeprecationWarning, match=r"Dataset.to_model\(noise=\)"):
        old = ds.to_model(noise=0.01)
    new = ds.to_model(settings=tg.EstimatorOverrides(noise=0.01))
    assert float(old.noise) == float(new.noise) == pytest.approx(0.01)
    assert type(old.covar_module) is type(new.covar_module)


def test_the_3d_simulation_takes_the_estimators_changes_as_one_object():
    """run_study_3d(estimator=...) as the study's; its voxel= of before still read (with the warning), and an
    estimator beside explore's own settings refused, each before anything is built."""
    from torch_gpioius.studies.simulate3d import run_study_3d

    with pytest.warns(DeprecationWarning, match=r"run_study_3d\(voxel=\)"):
        with pytest.raises(ValueError, match="objects: unknown"):            # read, then the objects checked
            run_study_3d(["Q"], voxel=0.01)
    with pytest.raises(ValueError, match="give either estimator or policy / settings"):
        run_study_3d(["E"], estimator={"noise": 0.05}, settings="paper")
    with pytest.raises(ValueError, match="unknown key"):
        run_study_3d(["E"], estimator={"nosie": 0.05})
