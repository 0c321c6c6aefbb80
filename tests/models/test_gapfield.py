"""The cover's gap over the body (:class:`torch_gpioius.models.gapfield.GapField`) and the outer task's prior mean
that stands for it place by place, held against the dense NumPy reference (tests/reference.py)."""

import itertools

import numpy as np
import pytest
import torch

import torch_gpioius as tg
from tests import reference as ref
from torch_gpioius.kernels import InverseMultiquadricKernel as IMQ
from torch_gpioius.models.gapfield import GAP_LENGTHS, GAP_NOISES, GAP_SCALES, GapField

KT = np.array([[0.8, 0.5], [0.5, 1.3]])


def _gaps(n=25, seed=3, d=2):
    """Gaps measured at ``n`` places over a 60 cm square: 5 mm on one side growing to 5 cm on the other, noisy."""
    rng = np.random.default_rng(seed)
    points = rng.uniform(-0.3, 0.3, (n, d))
    gaps = np.clip(0.005 + 0.045 * (points[:, 1] + 0.3) / 0.6 + rng.normal(0, 0.003, n), 0.0, 0.1)
    return points, gaps


def test_the_field_is_the_regressions_closed_form_and_its_grid_choice_the_best_likelihood():
    points, gaps = _gaps()
    field = GapField.fit(points, gaps)
    best = max(itertools.product(GAP_LENGTHS, GAP_SCALES, GAP_NOISES),
               key=lambda p: ref.gap_field_mll(points, gaps, *p, np.median(gaps)))
    assert (field.length, field.scale, field.noise) == best
    assert field.prior == np.median(gaps)
    assert abs(field.log_marginal_likelihood() - ref.gap_field_mll(points, gaps, *best, np.median(gaps))) < 1e-9
    xq = np.random.default_rng(4).uniform(-0.35, 0.35, (40, 2))
    expected = np.clip(ref.gap_field(points, gaps, *best, np.median(gaps), xq), 0.0, 0.1)
    np.testing.assert_allclose(field.gap(xq).numpy(), expected, atol=1e-12, rtol=0)
    np.testing.assert_allclose(field.mean(xq).numpy(), 1 - expected / 0.05, atol=1e-10, rtol=0)
    # it follows the gap across the square: thin on one side, thick on the other, within a few millimetres
    side = np.array([[0.0, -0.25], [0.0, 0.25]])
    np.testing.assert_allclose(field.gap(side).numpy(), [0.005 + 0.045 * 0.05 / 0.6, 0.005 + 0.045 * 0.55 / 0.6],
                               atol=0.004)


def test_far_from_every_touch_the_field_is_the_median_and_it_is_clipped_to_the_gaps_range():
    points, gaps = _gaps()
    field = GapField(points, gaps, length=0.04, scale=0.01, noise=0.004)
    assert abs(float(field.gap(np.array([[5.0, 5.0]]))) - np.median(gaps)) < 1e-12
    steep = GapField(np.array([[0.0, 0.0], [0.01, 0.0]]), np.array([0.0, 0.1]), length=0.005, scale=0.2,
                     noise=1e-4, prior=0.05)
    g = steep.gap(np.array([[-0.005, 0.0], [0.015, 0.0]])).numpy()
    assert g.min() >= 0.0 and g.max() <= 0.1


def test_a_field_round_trips_through_its_record_and_bad_input_is_named():
    points, gaps = _gaps(d=3)
    field = GapField.fit(points, gaps, ramp=0.04)
    back = GapField.from_dict(field.as_dict())
    assert back == field and back.ramp == 0.04
    xq = np.random.default_rng(2).uniform(-0.3, 0.3, (10, 3))
    assert torch.equal(back.gap(xq), field.gap(xq))
    with pytest.raises(ValueError, match="gap field"):
        GapField.from_dict({"points": [[0.0, 0.0]]})
    with pytest.raises(ValueError, match="gaps"):
        GapField(points, gaps[:-1], 0.04, 0.01, 0.004)
    with pytest.raises(ValueError, match="gaps"):
        GapField(points, np.r_[gaps[:-1], np.nan], 0.04, 0.01, 0.004)
    with pytest.raises(ValueError, match="gaps"):
        GapField(points, np.r_[gaps[:-1], 0.2], 0.04, 0.01, 0.004)
    with pytest.raises(ValueError, match="length"):
        GapField(points, gaps, -0.04, 0.01, 0.004)
    with pytest.raises(ValueError, match="points"):
        GapField(np.zeros((0, 3)), np.zeros(0), 0.04, 0.01, 0.004)


def _model(data, **kw):
    x, y, t = data
    return tg.GPIOIS(x, y, t, kernel=IMQ(0.1), noise=0.006, task_covariance=torch.tensor(KT), **kw)


@pytest.mark.parametrize("inference", ["dense", "structured", "batched"])
def test_an_outer_mean_from_a_gap_field_is_the_dense_reference_with_a_mean_per_place(random_data, inference):
    """With the outer mean ``1 - g(x) / ramp`` every engine's posterior of both tasks, the closed-form mean gradient
    (against central differences), the GPyTorch idiom's posterior and the MLL equal the dense reference with each
    observation's own prior mean; an appended outer point enters with the field's mean where it lies; a constant
    mean set afterwards gives the constant-mean model again."""
    x, y, t = (v.numpy() for v in random_data)
    points, gaps = _gaps()
    field = GapField.fit(points, gaps)
    m = _model(random_data, inference=inference).set_outer_mean(field)
    assert m.outer_field is field and m.outer_mean == pytest.approx(1 - np.median(gaps) / 0.05)

    def means(xs, ts):
        return np.where(ts == 1, field.mean(xs).numpy(), 1.0)

    xq = np.random.default_rng(7).uniform(-0.4, 0.4, (15, 2))
    for task in (0, 1):
        tq = np.full(len(xq), task)
        rm, rv = ref.posterior_with_means(x, y, t, KT, 0.1, 0.006, xq, task, means(x, t), means(xq, tq))
        closed = ref.assert_model_predicts(m, xq, task, rm, rv)
        if closed is not None:
            h = 1e-5                                    # central differences: error ~h^2 * f''' ~ 1e-8
            for axis in range(2):
                e = np.zeros(2)
                e[axis] = h
                up = ref.posterior_with_means(x, y, t, KT, 0.1, 0.006, xq + e, task, means(x, t), means(xq + e, tq))
                down = ref.posterior_with_means(x, y, t, KT, 0.1, 0.006, xq - e, task, means(x, t),
                                                means(xq - e, tq))
                np.testing.assert_allclose(closed[2][:, axis].numpy(), (up[0] - down[0]) / (2 * h), atol=1e-5,
                                           rtol=0)
    ref_mll = ref.mll_with_means(x, y, t, KT, 0.1, 0.006, means(x, t))
    assert abs(float(m.log_marginal_likelihood()) - ref_mll) < 1e-9 * len(x)
    xn, yn, tn = np.array([[0.05, -0.1], [0.2, 0.2]]), np.array([0.0, 1.0]), np.array([1, 0])
    m.add_observations(xn, yn, tn)
    xa, ya, ta = np.r_[x, xn], np.r_[y, yn], np.r_[t, tn]
    rm, _ = ref.posterior_with_means(xa, ya, ta, KT, 0.1, 0.006, xq, 0, means(xa, ta), np.ones(len(xq)))
    np.testing.assert_allclose(m.predict(torch.tensor(xq), 0)[0].numpy(), rm, atol=1e-8, rtol=0)
    m.set_outer_mean(0.6)
    assert m.outer_field is None and m.outer_mean == 0.6
    rm, _ = ref.posterior(xa, ya, ta, KT, 0.1, 0.006, xq, 0, m=(1.0, 0.6))
    np.testing.assert_allclose(m.predict(torch.tensor(xq), 0)[0].numpy(), rm, atol=1e-8, rtol=0)


def test_a_checkpoint_keeps_the_gap_field(random_data, tmp_path):
    from torch_gpioius.io import checkpoints

    points, gaps = _gaps()
    q = torch.tensor([[0.1, 0.0], [-0.2, 0.1]], dtype=torch.float64)
    for carry in (0.0, 0.3):                        # carried through the transfer (cover_carry) or not
        m = _model(random_data).set_outer_mean(GapField.fit(points, gaps).carried(carry))
        back = checkpoints.load_checkpoint(checkpoints.save_checkpoint(m, tmp_path / "m.pt"))
        assert back.outer_field == m.outer_field and back.outer_field.carry == carry
        for task in (0, 1):
            torch.testing.assert_close(back.predict(q, task)[0], m.predict(q, task)[0], rtol=0, atol=1e-12)


def test_a_field_the_outer_mean_cannot_take_is_refused_and_changes_nothing(random_data):
    points, gaps = _gaps()
    m = _model(random_data).set_outer_mean(0.5)
    q = torch.tensor([[0.1, 0.0]], dtype=torch.float64)
    before = m.predict(q, 1)[0]
    tiny_ramp = GapField(points, gaps, 0.04, 0.01, 0.004, ramp=0.005)     # 10 cm deep = 20 label units
    with pytest.raises(ValueError, match="outer_mean"):
        m.set_outer_mean(tiny_ramp)
    assert m.outer_field is None and m.outer_mean == 0.5 and torch.equal(m.predict(q, 1)[0], before)
