"""torch_gpioius.explore's log argument: an existing log is never truncated, bad paths are named before the run."""

import os

import numpy as np
import pytest

import torch_gpioius as tg
from torch_gpioius.sim import paper_objects_2d


def _a():
    return paper_objects_2d()["A"]


def test_an_existing_log_is_refused_and_left_as_it_was(tmp_path):
    log = tmp_path / "run.gpioius"
    tg.explore(_a(), mode="tactile", max_steps=3, log=log)
    before = log.read_bytes()
    with pytest.raises(FileExistsError, match=r"log: .*run\.gpioius exists.*resume_from.*overwrite=True"):
        tg.explore(_a(), mode="tactile", max_steps=1, log=log)
    assert log.read_bytes() == before                         # not truncated, not appended to
    done = tg.explore(_a(), mode="tactile", max_steps=3, resume_from=log)   # resume still reads it
    assert done.n_steps == 4


def test_overwrite_replaces_the_log(tmp_path):
    log = tmp_path / "run.gpioius"
    tg.explore(_a(), mode="tactile", max_steps=3, log=log)
    size = log.stat().st_size
    tg.explore(_a(), mode="tactile", max_steps=1, log=log, overwrite=True)
    assert log.stat().st_size < size


def test_a_link_at_the_log_path_counts_as_existing(tmp_path):
    target = tmp_path / "elsewhere.txt"
    target.write_text("keep")
    log = tmp_path / "run.gpioius"
    os.symlink(target, log)
    with pytest.raises(FileExistsError, match="log:"):
        tg.explore(_a(), mode="tactile", max_steps=1, log=log)
    assert target.read_text() == "keep"


@pytest.mark.parametrize("kind", ["missing folder", "a folder"])
def test_a_bad_log_path_is_named_before_anything_runs(tmp_path, kind):
    path = tmp_path / "missing_dir" / "x.gpioius" if kind == "missing folder" else tmp_path
    with pytest.raises(ValueError, match="log: .*(does not exist|is a folder)"):
        tg.explore(_a(), mode="tactile", max_steps=1, log=path)
    assert not (tmp_path / "missing_dir").exists()


def test_a_missing_resume_log_is_named(tmp_path):
    with pytest.raises(FileNotFoundError, match="resume_from: .*nothere.gpioius does not exist"):
        tg.explore(_a(), mode="tactile", resume_from=tmp_path / "nothere.gpioius")
    with pytest.raises(ValueError, match="resume_from: .*is a folder"):
        tg.explore(_a(), mode="tactile", resume_from=tmp_path)


def test_overwrite_replaces_a_link_at_the_log_path_and_never_writes_through_it(tmp_path):
    """Issue 51, item 4: `tg.explore(log=link, overwrite=True)` wrote the log into the link's target."""
    target = tmp_path / "elsewhere.txt"
    target.write_text("keep")
    log = tmp_path / "run.gpioius"
    os.symlink(target, log)
    tg.explore(_a(), mode="tactile", max_steps=1, log=log, overwrite=True)
    assert target.read_text() == "keep"
    assert not log.is_symlink() and log.stat().st_size > 100
    assert tg.explore(_a(), mode="tactile", max_steps=1, resume_from=log).n_steps == 2


def test_a_log_is_never_resumed_through_a_link(tmp_path):
    from torch_gpioius.io.datasets import DatasetError, LogWriter

    real = tmp_path / "real.gpioius"
    tg.explore(_a(), mode="tactile", max_steps=1, log=real)
    before = real.read_bytes()
    link = tmp_path / "link.gpioius"
    os.symlink(real, link)
    with pytest.raises(DatasetError, match="is a symbolic link"):
        LogWriter(link, resume=True)
    assert real.read_bytes() == before


def test_the_shipped_example_resumes(tmp_path):
    """Issue 51, item 28: `data/example_2d.gpioius` could not be resumed: the refusal named the policy, whose only
    difference was a newer field at its off value (`vision_free_far: None`)."""
    import shutil

    from torch_gpioius.io.runs import load_run

    log = tmp_path / "example.gpioius"
    shutil.copy("data/example_2d.gpioius", log)
    run = load_run(log)
    done = tg.explore(_a(), mode="visual-tactile", max_steps=run.meta["max_steps"], resume_from=log)
    assert done.n_steps == run.steps[-1] + 1
    np.testing.assert_array_equal(done.model.train_targets.numpy(), run.states[run.steps[-1]].y)


def test_a_field_added_since_a_log_was_written_matches_at_its_off_value():
    """Issue 51, item 28: a policy whose only difference is a newer field at its off value means the same."""
    from torch_gpioius.io.logs import _same

    old = {"voxel": None, "ramp": 0.05}
    assert _same(old, {"voxel": None, "ramp": 0.05, "vision_free_far": None, "cover_offset": False})
    assert not _same(old, {"voxel": None, "ramp": 0.05, "vision_free_far": 0.3})      # a setting that acts
    assert not _same({**old, "gone": 0.02}, old)
