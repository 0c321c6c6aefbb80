import numpy as np
import pytest
import torch


def _circle(n, r, c=(0.0, 0.0)):
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.stack([c[0] + r * np.cos(a), c[1] + r * np.sin(a)], -1)


@pytest.fixture
def two_shape_data():
    """2-D inner circle (r = 0.15) touched on one side, outer circle (r = 0.2) seen all round, with free space."""
    rng = np.random.default_rng(0)
    inner_s = _circle(24, 0.15)[:10]
    inner_f = _circle(10, 0.22)[:4]
    outer_s = _circle(40, 0.20)
    outer_f = _circle(30, 0.30)
    x = np.concatenate([inner_s, inner_f, outer_s, outer_f]) + 1e-3 * rng.standard_normal((84, 2))
    y = np.concatenate([np.zeros(10), np.ones(4), np.zeros(40), np.ones(30)])
    t = np.concatenate([np.zeros(14), np.ones(70)]).astype(np.int64)
    return torch.tensor(x), torch.tensor(y), torch.tensor(t)


@pytest.fixture
def random_data():
    rng = np.random.default_rng(1)
    n = 60
    x = rng.uniform(-0.3, 0.3, (n, 2))
    y = (rng.uniform(size=n) > 0.5).astype(float)
    t = (rng.uniform(size=n) > 0.4).astype(np.int64)
    return torch.tensor(x), torch.tensor(y), torch.tensor(t)


def pytest_configure(config):
    """Under pytest-xdist (``make test`` runs two workers) each worker computes with one torch thread: two workers
    with two threads each on two cores run 2-3 times slower than one thread each (oversubscription)."""
    import os

    if os.environ.get("PYTEST_XDIST_WORKER"):
        torch.set_num_threads(1)
