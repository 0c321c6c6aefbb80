"""The estimator's settings object: presets, its dict (what logs, datasets, checkpoints and scene files store) and
back, partial dicts on a preset, the voxel and length rules, and the models it makes, against values written out
here."""

import json

import numpy as np
import pytest

import torch_gpioius as tg
from torch_gpioius.kernels import InverseMultiquadricKernel, KernelChoice, Matern52
from torch_gpioius.models.estimator import PRESETS, EstimatorSettings, LengthRule, VoxelRule


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_every_preset_survives_its_dict_through_json_and_makes_the_same_model(name):
    settings = EstimatorSettings.preset(name)
    again = EstimatorSettings.from_dict(json.loads(json.dumps(settings.to_dict())))
    assert again == settings and again.name == name
    assert again.kernel.describe() == settings.kernel.describe() and again.kernel is not settings.kernel
    rng = np.random.default_rng(0)
    x = rng.uniform(-0.1, 0.1, (30, 3))
    y = (np.linalg.norm(x, axis=1) > 0.08).astype(float)
    task = np.r_[np.zeros(15, int), np.ones(15, int)]
    q = rng.uniform(-0.1, 0.1, (5, 3))
    a = settings.make_model(x, y, task)
    b = again.make_model(x, y, task)
    np.testing.assert_allclose(a.predict(q, task=0)[0].numpy(), b.predict(q, task=0)[0].numpy(), rtol=0, atol=1e-12)


def test_the_presets_hold_what_they_name():
    paper, paper_2d, default = (EstimatorSettings.preset(n) for n in ("paper", "paper-2d", "default"))
    assert isinstance(paper.kernel, InverseMultiquadricKernel) and paper.lengthscale == pytest.approx(0.15)
    assert paper.noise == 0.08 and paper.labels.voxel == 0.05 and paper.labels.touch_inside is None
    assert paper_2d.lengthscale == pytest.approx(0.1) and paper_2d.noise == 0.006
    assert isinstance(default.kernel, Matern52) and default.lengthscale == pytest.approx(0.1)
    assert default.labels.touch_inside == 0.02 and default.labels.vision_inside == 0.02
    assert default.labels.vision_inside_gap == 0.03 and default.voxel_rule == VoxelRule(0.1, 0.02, 0.05)
    assert default.length_rule == LengthRule(0.2, 0.04, 0.10) and paper.length_rule is None


def test_a_partial_dict_changes_its_keys_on_the_preset_and_is_named_custom():
    base = EstimatorSettings.preset("default")
    mine = EstimatorSettings.from_dict({"preset": "default", "noise": 0.02, "labels": {"voxel": 0.03}})
    assert mine.name == "custom" and mine.noise == 0.02 and mine.labels.voxel == 0.03
    assert mine.labels.touch_inside == base.labels.touch_inside and mine.kernel.describe() == base.kernel.describe()
    assert EstimatorSettings.from_dict({"preset": "paper"}) == EstimatorSettings.preset("paper")
    longer = EstimatorSettings.from_dict({"preset": "paper", "lengthscale": 0.2})
    assert isinstance(longer.kernel, InverseMultiquadricKernel) and longer.lengthscale == pytest.approx(0.2)
    assert longer.name == "custom" and EstimatorSettings.preset("paper").lengthscale == pytest.approx(0.15)
    named = EstimatorSettings.from_dict({"preset": "paper", "kernel": "matern52", "lengthscale": 0.07})
    assert isinstance(named.kernel, Matern52) and named.lengthscale == pytest.approx(0.07)


@pytest.mark.parametrize("data, match", [
    ({"preset": "default", "nois": 0.1}, r"unknown key\(s\) \['nois'\]"),
    ({"preset": "default", "labels": {"voxl": 0.1}}, r"labels: unknown field\(s\) \['voxl'\]"),
    ({"preset": "fast"}, "settings: must be one of"),
    ({"noise": 0.1}, "without a preset, give kernel and noise"),
    ({"preset": "default", "kernel": "rbf"}, "kernel: unknown 'rbf'"),
    ({"preset": "default", "lengthscale": -0.1}, "lengthscale"),
    ({"lengthscale": 0.1}, "give the kernel"),
    ("default", "expected a table of settings"),
    ({"preset": "default", "labels": {"camera_bound": [0.2, 0.01]}}, r"camera_bound: must be \(translation in"),
    ({"preset": "default", "labels": {"camera_bound": [0.01]}}, "camera_bound"),
    ({"preset": "default", "labels": {"camera_bound": [0.01, True]}}, "camera_bound"),
])
def test_bad_settings_are_refused_by_name(data, match):
    with pytest.raises(ValueError, match=match):
        EstimatorSettings.from_dict(data)


def test_the_voxel_rule_sizes_the_voxels_to_the_object_and_a_fixed_voxel_drops_it():
    default = EstimatorSettings.preset("default")
    # a tenth of the largest extent, within 2-5 cm, to 0.1 mm
    for extent, voxel in ((0.30, 0.03), (1.0, 0.05), (0.1, 0.02), (0.2345, 0.0234)):
        assert default.for_extent(extent).labels.voxel == pytest.approx(voxel, abs=1e-12)
    fixed = default.with_voxel(0.01)
    assert fixed.voxel_rule is None and fixed.labels.voxel == 0.01 and fixed.for_extent(0.3).labels.voxel == 0.01
    assert default.with_voxel(0).labels.voxel is None


def test_the_length_rule_sizes_the_kernel_to_the_object_and_a_kernel_given_drops_it():
    default = EstimatorSettings.preset("default")
    # a fifth of the largest extent, within 4-10 cm, to 0.1 mm; the voxels follow their own rule beside it
    for extent, length in ((0.15, 0.04), (0.30, 0.06), (0.7, 0.10), (0.2345, 0.0469)):
        sized = default.for_extent(extent)
        assert sized.lengthscale == pytest.approx(length, abs=1e-12) and isinstance(sized.kernel, Matern52)
        assert sized.length_rule == default.length_rule and sized.for_extent(extent) is sized
        assert EstimatorSettings.from_dict(json.loads(json.dumps(sized.to_dict()))) == sized
    assert default.lengthscale == pytest.approx(0.1)      # the object's size unknown: the rule's longest
    assert "a fifth of the object, 4 cm-10 cm" in default.summary()
    # a kernel given carries the length asked for
    mine = default.replace(kernel=Matern52(0.07))
    assert mine.length_rule is None and mine.for_extent(0.3).lengthscale == pytest.approx(0.07)
    named = default.with_kernel(KernelChoice("imq"))                  # a kind alone keeps the rule
    assert isinstance(named.kernel, InverseMultiquadricKernel) and named.length_rule == default.length_rule
    assert named.for_extent(0.3).lengthscale == pytest.approx(0.06) and default.with_kernel(KernelChoice()) is default
    assert default.with_kernel(KernelChoice(lengthscale=0.05)).for_extent(0.3).lengthscale == pytest.approx(0.05)
    asked = EstimatorSettings.from_dict({"preset": "default", "lengthscale": 0.07})
    assert asked.length_rule is None and asked.for_extent(0.15).lengthscale == pytest.approx(0.07)
    # a rule of one's own, and none
    own = EstimatorSettings.from_dict({"preset": "default", "length_rule": {"fraction": 0.25, "lo": 0.03, "hi": 0.12}})
    assert own.name == "custom" and own.for_extent(0.2).lengthscale == pytest.approx(0.05)
    assert EstimatorSettings.from_dict({"preset": "default", "length_rule": None}).for_extent(0.15).lengthscale == 0.1
    for bad, match in (({"fraction": 0}, "length_rule.fraction"), ({"lo": 0.2, "hi": 0.1}, "must not exceed"),
                       ({"fraction": 0.2, "step": 1}, "expected fraction, lo and hi")):
        with pytest.raises(ValueError, match=match):
            EstimatorSettings.from_dict({"preset": "default", "length_rule": bad})
    with pytest.raises(ValueError, match="extent"):
        default.for_extent(float("nan"))


def test_of_takes_settings_or_a_presets_name_and_names_anything_else():
    paper = EstimatorSettings.preset("paper")
    assert EstimatorSettings.of(paper) is paper and EstimatorSettings.of("paper") == paper
    with pytest.raises(ValueError, match="expected EstimatorSettings or a preset's name, got dict"):
        EstimatorSettings.of({"preset": "paper"})


def test_make_model_gives_gpiois_on_both_tasks_gpis_on_touch_alone_each_with_its_own_kernel():
    settings = EstimatorSettings.preset("default")
    rng = np.random.default_rng(1)
    x = rng.uniform(-0.1, 0.1, (20, 3))
    y = (np.linalg.norm(x, axis=1) > 0.08).astype(float)
    both = settings.make_model(x, y, np.r_[np.zeros(10, int), np.ones(10, int)])
    touch = settings.make_model(x, y, np.zeros(20, int))
    assert isinstance(both, tg.GPIOIS) and isinstance(touch, tg.GPIS)
    assert both.kernel is not settings.kernel and both.noise == pytest.approx(settings.noise)
    both.kernel.length = 0.3
    assert settings.lengthscale == pytest.approx(0.1)


def test_a_camera_bound_survives_its_dict_through_json():
    """Issue 63, item 2: ``ObservationPolicy.camera_bound`` (a pair, a list once through JSON) reads back equal."""
    settings = EstimatorSettings.preset("default").replace(labels={"camera_bound": (0.012, 0.035)})
    again = EstimatorSettings.from_dict(json.loads(json.dumps(settings.to_dict())))
    assert again == settings and again.labels.camera_bound == (0.012, 0.035)


def test_the_gap_presets_are_the_3d_worlds_gap_settings():
    """The estimator's presets "gap" and "gapfield" (for a user's files: ``gpioius fit --settings gap``) label as the
    3-D worlds' settings of those names do, sized to a body alike."""
    import dataclasses

    import trimesh

    from torch_gpioius.sim.forcefield import gap_defaults, gap_field_defaults

    body = trimesh.creation.box(extents=[0.2, 0.1, 0.15])
    for preset, world in (("gap", gap_defaults), ("gapfield", gap_field_defaults)):
        mine = EstimatorSettings.preset(preset).for_extent(0.2)
        theirs = world(body).estimator
        assert mine.name == preset and mine.labels == theirs.labels
        assert dataclasses.replace(mine, name="custom") == theirs
    assert EstimatorSettings.gap_field().labels.cover_gap_field and not EstimatorSettings.gap().labels.cover_gap_field
