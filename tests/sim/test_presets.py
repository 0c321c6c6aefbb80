"""The settings every 3-D world borrows (sim/presets.py): a preset per body, the views, and the loose estimator
settings of scene files made one change."""

import pytest
import trimesh

from torch_gpioius.models.overrides import EstimatorOverrides
from torch_gpioius.sim.presets import (ROBOT_STUDY_DEFAULTS, VIEWS, as_views, estimator_changes, inside_labels,
                                       settings_for)


def test_the_presets_size_the_default_to_the_body_and_keep_the_papers_as_it_is():
    body = trimesh.creation.box(extents=(0.2, 0.1, 0.1))
    paper = settings_for("paper", body)
    assert paper["defaults"] is ROBOT_STUDY_DEFAULTS and as_views(paper["views"]) == ("fixed",)
    default = settings_for("default", body)
    assert default["views"] == VIEWS
    assert default["defaults"].policy.voxel == pytest.approx(0.02)           # a tenth of 20 cm
    assert default["defaults"].estimator.lengthscale == pytest.approx(0.04)  # a fifth of it
    with pytest.raises(ValueError, match="settings: must be one of"):
        settings_for("mine", body)


def test_loose_settings_become_one_change_where_a_depth_of_zero_means_none():
    changes = estimator_changes(EstimatorOverrides(noise=0.05), touch_inside=0, vision_inside=0.01, voxel=0.02)
    assert changes == EstimatorOverrides(noise=0.05, voxel=0.02,
                                         labels={"touch_inside": None, "vision_inside": 0.01})
    assert estimator_changes({"learn": "length"}, learn="all").learn == "all"          # the loose value on top
    assert not estimator_changes()
    assert inside_labels(cover_offset=False) == {"cover_offset": False}             # False is a value, not none
    with pytest.raises(ValueError, match=r"estimator: unknown \['nosie'\]"):
        estimator_changes(nosie=0.1)
    with pytest.raises(ValueError, match="touch_inside"):
        estimator_changes(touch_inside=0.5)                                        # beyond the labels' range
    with pytest.raises(ValueError, match="expected EstimatorOverrides, its dict or KEY=VALUE texts"):
        estimator_changes(0.05)
