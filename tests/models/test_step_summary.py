"""What an exploration step records of a model comes from the model's own ``step_summary`` (the loop used to probe
``hasattr(m, "region_correlations")``, ``getattr(m, "similarity", nan)``): each entry recomputed here from the
model's properties, for the three models."""

import math

import numpy as np
import pytest
import torch

import torch_gpioius as tg
from torch_gpioius.kernels import InverseMultiquadricKernel, Matern52


def _data(seed=0):
    rng = np.random.default_rng(seed)
    a = rng.uniform(0, 2 * np.pi, 40)
    inner = np.c_[0.1 * np.cos(a[:20]), 0.1 * np.sin(a[:20])]
    outer = np.c_[0.13 * np.cos(a[20:]), 0.13 * np.sin(a[20:])]
    x = np.r_[inner, outer, [[0.3, 0.0], [-0.3, 0.0]]]
    y = np.r_[np.zeros(40), np.ones(2)]
    t = np.r_[np.zeros(20), np.ones(20), [0, 1]].astype(int)
    return x, y, t


def test_gpiois_summary_is_its_similarity_correlation_and_task_covariance():
    x, y, t = _data()
    m = tg.GPIOIS(x, y, t, kernel=Matern52(0.1), noise=0.006).fit()
    s = m.step_summary()
    assert s["similarity"] == m.similarity and s["correlation"] == m.correlation
    np.testing.assert_array_equal(s["task_covariance"], m.task_covariance.numpy())
    assert s["truncation"] == 0.0 and s["noise"] == pytest.approx(0.006, rel=1e-12)
    assert s["length"] == pytest.approx(0.1, rel=1e-12) and s["region_correlation"] is None
    assert math.isnan(s["fit_gap"])                       # a full fit re-learned K_t: no gap to report
    assert tg.GPIOIS.FIT_OPTIONS == {"min_gain", "max_hold", "track", "scout"}


def test_gpis_summary_has_no_similarity_and_takes_batches_with_task_ids():
    x, y, t = _data()
    keep = t == 0
    m = tg.GPIS(x[keep], y[keep], kernel=InverseMultiquadricKernel(0.1), noise=0.006)
    s = m.step_summary()
    assert math.isnan(s["similarity"]) and math.isnan(s["correlation"]) and s["task_covariance"] is None
    assert s["length"] == pytest.approx(0.1, rel=1e-12) and tg.GPIS.FIT_OPTIONS == frozenset()
    n = len(m.train_targets)
    m.add_observations(np.array([[0.0, 0.2]]), [1.0], torch.zeros(1, dtype=torch.long))
    assert len(m.train_targets) == n + 1
    with pytest.raises(ValueError, match="a GPIS models the inner task alone"):
        m.add_observations(np.array([[0.0, 0.25]]), [1.0], [1])
    assert len(m.train_targets) == n + 1                   # refused: left as it was


def test_local_summary_carries_each_regions_correlation():
    x, y, t = _data()
    m = tg.LocalGPIOIS(x, y, t, regions=2, kernel=InverseMultiquadricKernel(0.1), noise=0.006).fit()
    s = m.step_summary()
    np.testing.assert_array_equal(s["region_correlation"], m.region_correlations().numpy())
    assert s["correlation"] == m.correlation and s["similarity"] == m.similarity
