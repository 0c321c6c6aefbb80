"""A run's history rebuilds each step's model as the run had it: with a learned length and noise, not the header's."""

import math

import numpy as np
import pytest
import torch

import torch_gpioius as tg
from torch_gpioius.io.runs import load_run
from torch_gpioius.sim import Scene2D


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
    trace = tg.explore(scene, max_steps=7, restart_every=3, learn="length", metrics_every=100, log=log)
    assert trace.model.hyper_result.kept and trace.length[-1] != trace.length[0]
    run = load_run(log)
    last = run.model_at(run.steps[-1])
    assert last.hyperparameter_state() == trace.model.hyperparameter_state()
    q = torch.tensor([[0.0, 0.0], [0.11, 0.02], [-0.2, 0.05]], dtype=torch.float64)
    torch.testing.assert_close(last.predict(q, 0)[0], trace.model.predict(q, 0)[0], rtol=1e-9, atol=1e-10)
    early = run.model_at(2)                      # before the first learning: the configured values
    assert early.kernel.length == pytest.approx(scene.defaults.theta, rel=1e-12)
    assert early.noise == pytest.approx(scene.defaults.noise, rel=1e-12)
    assert math.isclose(run.params[run.steps[-1]]["length"], trace.length[-1], rel_tol=1e-15)
