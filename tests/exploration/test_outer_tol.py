"""Explorations with the truncated outer basis (``outer_tol``): the bound in every record, logs, resume, refusals."""

import numpy as np
import pytest

import torch_gpioius as tg
from torch_gpioius.io.datasets import read_records
from torch_gpioius.sim import paper_objects_2d
from torch_gpioius.studies.study_runs import RunSpec, _explore_kwargs


def test_every_record_carries_the_bound_and_a_log_resumes_with_it(tmp_path):
    scene = paper_objects_2d()["A"]
    log = tmp_path / "run.gpioius"
    trace = tg.explore(scene, max_steps=4, outer_tol=10.0, log=log)
    engine = trace.model._inference()
    assert engine.truncated and engine.rank < len(engine.xo)          # 153 camera points, fewer modes
    kt11 = trace.task_covariance[:, 1, 1]
    assert np.all(trace.truncation > 0) and np.all(trace.truncation <= 10.0 * kt11 * (1 + 1e-12))
    np.testing.assert_allclose(trace.truncation[-1], engine.truncation(float(kt11[-1])), rtol=1e-12)
    records = list(read_records(log))
    assert records[0].meta["outer_tol"] == 10.0                       # the header
    steps = [r for r in records if r.kind == "step"]
    np.testing.assert_allclose([r.meta["truncation"] for r in steps], trace.truncation, rtol=0, atol=0)
    again = tg.explore(scene, max_steps=4, outer_tol=10.0, resume_from=log)   # finished: restored as it was
    np.testing.assert_allclose(again.truncation, trace.truncation, rtol=0, atol=0)
    with pytest.raises(ValueError, match="outer_tol"):
        tg.explore(scene, max_steps=4, outer_tol=1.0, resume_from=log)
    exact = tg.explore(scene, max_steps=4)
    assert np.all(exact.truncation == 0.0) and exact.model.outer_tol is None


@pytest.mark.parametrize(
    "kwargs",
    [
        dict(mode="tactile"),
        dict(regions=2),
        dict(touch="patch"),
        dict(outer_tol_value=-1.0),
        dict(outer_tol_value=float("nan")),
    ],
)
def test_settings_that_cannot_truncate_are_refused(kwargs):
    scene = paper_objects_2d()["A"]
    value = kwargs.pop("outer_tol_value", 1e-3)
    with pytest.raises(ValueError, match="outer_tol"):
        tg.explore(scene, max_steps=1, outer_tol=value, **kwargs)


def test_a_study_passes_it_to_its_visual_tactile_runs_only():
    world = tg.sim.paper_objects_2d()["A"]
    for mode, expected in (("visual-tactile", 1e-3), ("tactile", None), ("local", None)):
        kw = _explore_kwargs(RunSpec("planar", "A", mode, 0, "out", outer_tol=1e-3), world)
        assert kw.get("outer_tol") == expected
    from torch_gpioius.studies.study import run_sweep    # not loaded by the package itself: named, not assumed

    with pytest.raises(ValueError, match="outer_tol"):
        run_sweep(world="forcefield", objects=["E"], modes=["visual-tactile"], seeds=1,
                                   out="unused", touch="patch", outer_tol=1e-3)
