"""LocalGPIOIS: one region is GPIOIS exactly; the structured engine equals the dense one; the dense engine equals an
independent NumPy Gram matrix; derivatives against Richardson differences; exploration with regions resumes."""

import math

import numpy as np
import pytest
import torch

import torch_gpioius as tg
from tests import reference as ref
from torch_gpioius.inference.local import region_weights


def local_reference_gram(x, task, p, centres, tau, theta, noise):
    """The local model's Gram matrix written from its definition (module docstring), in NumPy."""
    d2 = ((x[:, None, :] - centres[None]) ** 2).sum(-1)
    w = np.exp(-d2 / (2 * tau * tau))
    w /= w.sum(1, keepdims=True)
    beta = w @ p[2:]
    lam = np.where(task == 0, beta, 1.0)
    eta = (task == 0).astype(float)
    k = ref.imq(x, x, theta)
    return k * (p[1] * np.outer(lam, lam) + p[0] * np.outer(eta, eta)) + noise * np.eye(len(x))


def reference_mll(x, y, task, p, centres, tau, theta=0.1, noise=0.006):
    g = local_reference_gram(x, task, p, centres, tau, theta, noise)
    r = y - 1.0
    sign, logdet = np.linalg.slogdet(g)
    return -0.5 * logdet - 0.5 * r @ np.linalg.solve(g, r) - 0.5 * len(x) * np.log(2 * np.pi)


P = torch.tensor([0.05, 0.3, 0.8, 0.2, -0.5, 1.2], dtype=torch.float64)


def test_one_region_is_gpiois_exactly(two_shape_data):
    g = tg.GPIOIS(*two_shape_data, inference="dense").fit()
    for inference in ("dense", "structured"):
        local = tg.LocalGPIOIS(*two_shape_data, regions=1, inference=inference).fit()
        torch.testing.assert_close(local.region_task_covariances()[0], g.task_covariance, atol=1e-6, rtol=1e-5)
        same = tg.GPIOIS(*two_shape_data, inference="dense", task_covariance=local.region_task_covariances()[0])
        q = torch.rand(7, 2, dtype=torch.float64) - 0.5
        for task in (0, 1):
            for a, b in zip(local.predict(q, task), same.predict(q, task)):
                torch.testing.assert_close(a, b, atol=1e-12, rtol=1e-12)
        assert float(local.log_marginal_likelihood()) == pytest.approx(float(same.log_marginal_likelihood()),
                                                                       abs=1e-9)


def test_dense_engine_equals_the_definition(two_shape_data):
    x, y, t = (d.numpy() for d in two_shape_data)
    m = tg.LocalGPIOIS(*two_shape_data, regions=4, inference="dense")
    m.params.copy_(P)
    want = reference_mll(x, y, t, P.numpy(), m.centres.numpy(), m.tau)
    assert float(m.log_marginal_likelihood()) == pytest.approx(want, abs=1e-9)


def test_structured_engine_equals_the_dense_one_also_after_appends_and_removals(two_shape_data):
    x, y, t = two_shape_data
    dense = tg.LocalGPIOIS(x, y, t, regions=4, inference="dense")
    fast = tg.LocalGPIOIS(x, y, t, regions=4, inference="structured", centres=dense.centres, tau=dense.tau)
    q = torch.rand(9, 2, dtype=torch.float64) - 0.5
    for model in (dense, fast):
        model.params.copy_(P)
        model.add_observations(torch.tensor([[0.16, 0.02], [0.25, -0.1]]), torch.tensor([0.0, 1.0]), 0)
        model.remove_observations([2])
    fd, gd, hd = dense._inference().mll_derivatives(P)
    fs, gs, hs = fast._inference().mll_derivatives(P)
    assert abs(fd - fs) < 1e-9 * max(1, abs(fd))
    torch.testing.assert_close(gs, gd, atol=1e-9 * float(gd.abs().max()), rtol=0)
    torch.testing.assert_close(hs, hd, atol=1e-9 * float(hd.abs().max()), rtol=0)
    for task in (0, 1):
        for a, b in zip(fast.predict(q, task), dense.predict(q, task)):
            torch.testing.assert_close(a, b, atol=1e-9, rtol=0)


def test_gradient_and_hessian_match_richardson_differences(two_shape_data):
    x, y, t = (d.numpy() for d in two_shape_data)
    m = tg.LocalGPIOIS(*two_shape_data, regions=4, inference="structured")
    centres, tau = m.centres.numpy(), m.tau
    f, g, h = m._inference().mll_derivatives(P)
    fd, err = ref.richardson_derivative(lambda p: reference_mll(x, y, t, p, centres, tau), P.numpy(), 1e-3)
    ref.assert_close_to_reference(g.numpy(), fd, err, what="local MLL gradient")
    hfd, herr = ref.richardson_derivative(lambda p: m._inference().mll_derivatives(torch.tensor(p))[1].numpy(),
                                          P.numpy(), 1e-3)
    ref.assert_close_to_reference(h.numpy(), hfd, herr, what="local MLL Hessian")


def test_fit_and_region_correlations(two_shape_data):
    m = tg.LocalGPIOIS(*two_shape_data, regions=3).fit()
    assert m.fit_result.converged
    rho = m.region_correlations()
    assert rho.shape == (3,) and bool(((rho >= -1) & (rho <= 1)).all())
    start = tg.LocalGPIOIS(*two_shape_data, regions=3)
    assert float(m.log_marginal_likelihood()) >= float(start.log_marginal_likelihood())
    w = region_weights(torch.tensor([[0.0, 0.0]], dtype=torch.float64), m.centres, m.tau)
    assert float(w.sum()) == pytest.approx(1.0)
    assert -1 <= float(m.correlation_at([[0.2, 0.0]])[0]) <= 1


@pytest.mark.parametrize("kwargs, match", [(dict(regions=0), "regions"), (dict(regions=2.5), "regions"),
                                           (dict(regions=2, centres=[[0, 0]]), "centres"),
                                           (dict(regions=2, tau=-1.0), "tau")])
def test_bad_arguments(two_shape_data, kwargs, match):
    with pytest.raises(ValueError, match=match):
        tg.LocalGPIOIS(*two_shape_data, **kwargs)


def test_exploration_with_regions_records_them_and_resumes(tmp_path):
    scene = tg.sim.paper_objects_2d()["C"]
    log = tmp_path / "c.gpioius"
    full = tg.explore(scene, regions=4, max_steps=14, log=log)
    assert full.region_correlation.shape == (15, 4)
    assert np.isfinite(full.region_correlation[-1]).all()
    assert "correlation_region_3" in full.records()[-1]
    # cut the log after step 9 and resume: the same end
    from torch_gpioius.io.datasets import read_records
    recs = list(read_records(log))
    end = [r.end for r in recs if r.kind == "step" and r.meta["step"] == 9][0]
    log.write_bytes(log.read_bytes()[:end])
    resumed = tg.explore(scene, regions=4, max_steps=14, resume_from=log)
    np.testing.assert_allclose(resumed.contacts, full.contacts, atol=1e-9)
    assert math.isclose(resumed.correlation[-1], full.correlation[-1], abs_tol=1e-7)


def test_coincident_outer_points_name_the_regions_not_tau():
    """The caller never passed tau; coincident outer points made k-means stack centres and tau 0 ("tau: must be
    a positive length"), an error about an argument nobody gave."""
    x = np.concatenate([np.tile([[0.1, 0.2]], (10, 1)), [[0.0, 0.0], [0.05, 0.0]]])
    y = np.concatenate([np.zeros(10), [0.0, 1.0]])
    task = np.concatenate([np.ones(10), [0, 0]]).astype(np.int64)
    with pytest.raises(ValueError, match=r"regions: 4 regions need at least 4 distinct outer surface points, got 1 "
                                         r"distinct among 10"):
        tg.LocalGPIOIS(x, y, task, regions=4)
