"""A run's history rebuilds each step's model as the run had it: with a learned length and noise, not the header's."""

import math

import numpy as np
import pytest
import torch

import torch_gpioius as tg
from torch_gpioius.io.runs import load_run
from torch_gpioius.sim import Scene2D
from torch_gpioius.models.overrides import EstimatorOverrides


def _circle(r, n=72):
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.c_[r * np.cos(a), r * np.sin(a)]


@pytest.mark.filterwarnings("ignore::torch_gpioius.models.gpiois.FitNotConvergedWarning")
@pytest.mark.filterwarnings("ignore:explore.*no estimated inner surface")
def test_model_at_uses_the_length_and_noise_the_run_had_learned(tmp_path):
    """learn="length" holds the 2-D world's sigma^2 (0.006): the rebuilt model's mean then agrees to 1e-9. (A learned
    sigma^2 near its 1e-4 bound conditions the Gram matrix at ~1e8, and the rounding of K_t's logged copy moves the
    rebuilt mean by ~1e-7 relative.)"""
    scene = Scene2D(_circle(0.10), _circle(0.13), start=(-0.25, 0.0), direction=(1, 0))
    log = tmp_path / "run.gpioius"
    trace = tg.explore(scene, max_steps=7, settings=EstimatorOverrides(restart_every=3, learn="length"),
                       metrics_every=100, log=log)
    assert trace.model.hyper_result.kept and trace.length[-1] != trace.length[0]
    run = load_run(log)
    last = run.model_at(run.steps[-1])
    assert last.hyperparameter_state() == trace.model.hyperparameter_state()
    q = torch.tensor([[0.0, 0.0], [0.11, 0.02], [-0.2, 0.05]], dtype=torch.float64)
    torch.testing.assert_close(last.predict(q, 0)[0], trace.model.predict(q, 0)[0], rtol=1e-9, atol=1e-10)
    early = run.model_at(2)                      # before the first learning: the configured values
    assert early.kernel.length == pytest.approx(scene.defaults.lengthscale, rel=1e-12)
    assert early.noise == pytest.approx(scene.defaults.noise, rel=1e-12)
    assert math.isclose(run.params[run.steps[-1]]["length"], trace.length[-1], rel_tol=1e-15)


def _edited_log(src, dst, edit):
    """A copy of the log ``src`` at ``dst`` whose last step record's meta passes through ``edit(meta)``."""
    import struct

    from torch_gpioius.io.datasets import FORMAT_VERSION, MAGIC, _encode, read_records

    records = list(read_records(src))
    last = max(i for i, r in enumerate(records) if r.kind == "step")
    out = [MAGIC + struct.pack(">H", FORMAT_VERSION)]
    for i, r in enumerate(records):
        out.append(_encode(r.kind, edit(dict(r.meta)) if i == last else r.meta, r.arrays))
    dst.write_bytes(b"".join(out))
    return dst


@pytest.mark.parametrize("edit, match", [
    (lambda m: {**m, "step": 10**30}, r"field 'step' must be a non-negative integer below 2\^62, got '1e\+30'"),
    (lambda m: {**m, "taps": [1]}, r"field 'taps' must be a number or null, got \[1\]"),
    (lambda m: {**m, "similarity": "high"}, r"field 'similarity' must be a number or null"),
    (lambda m: {**m, "taps": 1.5}, r"field 'taps' must be a count"),
])
def test_bad_step_fields_are_named_by_every_command(tmp_path, capsys, edit, match):
    """Issue 51, item 18: a log step of 10**30 gave OverflowError in fit, replay, export and view; a list where
    step metadata holds a number gave TypeError in export and view. Each is one line naming the file and field, and
    the viewer shows a study's good runs beside the bad one."""
    import shutil

    from torch_gpioius.cli import main
    from torch_gpioius.io.datasets import DatasetError

    good = tmp_path / "study" / "logs" / "good.gpioius"
    good.parent.mkdir(parents=True)
    tg.explore(tg.sim.paper_objects_2d()["A"], max_steps=3, log=good, progress=False)
    bad = _edited_log(good, tmp_path / "study" / "logs" / "bad.gpioius", edit)
    with pytest.raises(DatasetError, match=match):
        load_run(bad)
    # every command that reads the field names it (fit and replay read no step metadata but the step number)
    every = "'step'" in match
    for argv in (["fit", str(bad)], ["replay", str(bad), "--out", str(tmp_path / "r"), "--quiet"],
                 ["export", str(bad), "--mesh", str(tmp_path / "m.svg")]):
        code = main(argv)
        err = capsys.readouterr().err
        assert code == 2 if every or argv[0] == "export" else code in (0, 2), (argv, code, err)
        assert "Traceback" not in err and (code == 0 or "bad.gpioius" in err), (argv, err)
    pytest.importorskip("viser")
    from torch_gpioius.viewer import RunViewer

    viewer = RunViewer(tmp_path / "study", port=0)
    try:
        assert [p.name for p in viewer.files] == ["good.gpioius"] and "bad.gpioius" in str(list(viewer.skipped))
    finally:
        viewer.close()
    shutil.rmtree(tmp_path / "study")
