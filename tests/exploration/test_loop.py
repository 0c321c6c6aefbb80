import math

import numpy as np
import pytest

import torch_gpioius as tg
from torch_gpioius.exploration import gone_around, largest_uncovered_gap
from torch_gpioius.sim import Scene2D
from torch_gpioius.models.overrides import EstimatorOverrides


def _polygon_circle(r, n=72, c=(0.0, 0.0)):
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.stack([c[0] + r * np.cos(a), c[1] + r * np.sin(a)], -1)


def test_gone_around_and_largest_gap():
    a = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    loop = 0.1 * np.stack([np.cos(a), np.sin(a)], -1)
    assert gone_around(loop, np.zeros(2), max_gap=0.05)
    angle, chord = largest_uncovered_gap(loop, np.zeros(2))
    assert angle == pytest.approx(2 * np.pi / 60) and chord == pytest.approx(0.2 * np.sin(np.pi / 60))
    # three sides of a square seen from its centre: a quarter turn unvisited, chord = the side
    u = np.concatenate([np.linspace([-1, 1], [-1, -1], 20), np.linspace([-1, -1], [1, -1], 20),
                        np.linspace([1, -1], [1, 1], 20)]) * 0.1
    angle, chord = largest_uncovered_gap(u, np.zeros(2))
    assert angle == pytest.approx(np.pi / 2) and chord == pytest.approx(0.2)
    assert not gone_around(u, np.zeros(2), max_gap=0.05)
    assert not gone_around(loop[:50], np.zeros(2), max_gap=0.05)   # a 60 degree gap, chord 10 cm
    assert not gone_around(loop, None, max_gap=0.05)               # no estimated interior yet


@pytest.mark.parametrize("mode", ["tactile", "visual-tactile"])
def test_circle_exploration_converges(mode):
    """A circle of radius 10 cm inside a 13 cm cover: the exploration goes around and the estimate is < 2 cm off."""
    scene = Scene2D(_polygon_circle(0.10), _polygon_circle(0.13), start=(-0.25, 0.0), direction=(1, 0),
                    name="circle")
    trace = tg.explore(scene, mode=mode, max_steps=120)
    assert trace.terminated == "once-around"
    assert trace.hausdorff[-1] < 0.02
    # 2 pi r = 0.63 m: going once around should not take much more than the perimeter
    assert 0.5 < trace.travel[-1] < 1.0
    assert np.isfinite(trace.uncertainty[-1])
    assert trace.n_steps == len(trace.travel) == len(trace.hausdorff) == len(trace.similarity)
    if mode == "visual-tactile":
        assert trace.similarity[-1] > 0.5   # nearly concentric circles: clearly similar
    else:
        assert np.isnan(trace.similarity).all()


def test_no_closed_curve_is_recorded_as_nan_not_zero():
    scene = Scene2D(_polygon_circle(0.10), _polygon_circle(0.13), start=(-0.25, 0.0), direction=(1, 0))
    trace = tg.explore(scene, mode="tactile", max_steps=0)
    assert trace.n_steps == 1
    assert math.isnan(trace.hausdorff[0]) or trace.hausdorff[0] > 0


def test_bad_mode():
    scene = Scene2D(_polygon_circle(0.10), _polygon_circle(0.13), start=(-0.25, 0.0), direction=(1, 0))
    with pytest.raises(ValueError, match="mode"):
        tg.explore(scene, mode="vision")



def test_lost_contact_falls_back_to_the_last_contact():
    """When the re-approach along the estimated normal finds nothing, the loop heads back to the last contact;
    travel and path count both re-approaches, and only a second miss ends the run."""
    import torch

    from torch_gpioius.exploration.contact import ContactResult
    from torch_gpioius.exploration import ExplorationState, Hardware
    from torch_gpioius.exploration.loop import recover

    def result(ok, points):
        p = torch.as_tensor(np.asarray(points, dtype=float))
        return ContactResult(ok, p[-1], p[:-1], p, torch.ones_like(p), float((p[1:] - p[:-1]).norm(dim=1).sum()))

    class Controller:
        """Replays approaches: the first goes 10 cm without contact; the second touches the last contact or not."""

        def __init__(self, second_hits):
            self.second_hits, self.calls, self.at = second_hits, [], None

        def approach(self, direction, max_travel=0.3):
            d = np.asarray(direction, dtype=float)
            self.calls.append((d, max_travel))
            if len(self.calls) == 1:
                self.at = here + 0.1 * d
                return result(False, [here, self.at])
            end = last if self.second_hits else self.at + max_travel * d
            return result(self.second_hits, [self.at, end])

    # a circle of radius 10 cm that the model knows; contact lost at (0.2, 0.05); the last contact at (0.1, 0)
    a = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    ring = np.stack([np.cos(a), np.sin(a)], -1)
    model = tg.GPIS(
        np.concatenate([0.1 * ring, 0.2 * ring]),
        np.r_[np.zeros(24), np.ones(24)],
        kernel=tg.kernels.InverseMultiquadricKernel(0.1),
        noise=1e-3,
    )
    here, last = np.array([0.2, 0.05]), np.array([0.1, 0.0])
    lost = result(False, [[0.15, 0.0], here])
    for second_hits in (True, False):
        s = ExplorationState(model=model, contacts=[last])
        ctl = Controller(second_hits)
        out = recover(s, Hardware(robot=None, sensor=None, camera=None, controller=ctl), lost)
        assert len(ctl.calls) == 2
        (d1, _), (d2, reach) = ctl.calls
        assert np.dot(d1, here) < 0                                  # first: inward along the estimated normal
        gap = np.linalg.norm(last - ctl.at)
        assert np.allclose(d2, (last - ctl.at) / gap, atol=1e-12)    # second: towards the last contact
        assert reach == pytest.approx(gap + 0.05)
        if second_hits:
            assert out is not None and out.in_contact and np.allclose(out.contact.numpy(), last)
            assert out.travel == pytest.approx(lost.travel + 0.1 + gap)
            assert s.travel == pytest.approx(0.1 + gap)              # the loop had counted the lost step itself
            assert len(out.path) == len(lost.path) + 4
        else:
            assert out is None
        # issue 33, item 7: each re-approach is counted with its travel (they were invisible: recoveries stayed 0)
        assert s.reapproaches == 2 and s.reapproach_travel == pytest.approx(s.travel)
    # ... and none goes past the travel budget: with 12 cm left, 10 cm along the normal, then at most 2 cm
    s = ExplorationState(model=model, contacts=[last])
    ctl = Controller(False)
    assert recover(s, Hardware(robot=None, sensor=None, camera=None, controller=ctl), lost, budget_left=0.12) is None
    assert [round(r, 12) for _, r in ctl.calls] == [0.1, 0.02] and s.travel <= 0.12 + 1e-12
    # a run whose re-approach spent the rest of its budget ends by its budget, not as a lost contact (a failure)
    from torch_gpioius.exploration.loop import lost_contact_end

    assert lost_contact_end(s, 0.12) == "travel" and lost_contact_end(s, 0.5) == "lost-contact"
    assert lost_contact_end(s, None) == "lost-contact"
    s = ExplorationState(model=model, contacts=[last])
    ctl = Controller(True)
    assert recover(s, Hardware(robot=None, sensor=None, camera=None, controller=ctl), lost, budget_left=0.0) is None
    assert ctl.calls == [] and s.reapproaches == 0


def test_the_first_reapproach_reaches_twice_the_controllers_own_search_for_lost_contact():
    """Issue 63: after a slide that lost contact, the leg along the estimate's inward normal goes at most twice the
    distance the controller has just pressed in vain (10 cm with the controller's default 5 cm; a controller
    without a config, 10 cm), so that a small body's search does not spend 10 cm on a wrong normal."""
    import torch

    from torch_gpioius.exploration.contact import ContactConfig, ContactResult
    from torch_gpioius.exploration import ExplorationState, Hardware
    from torch_gpioius.exploration.loop import reapproach_reach, recover

    class Controller:
        def __init__(self, config):
            self.calls = []
            if config is not None:
                self.config = config

        def approach(self, direction, max_travel=0.3):
            self.calls.append(max_travel)
            p = torch.zeros(2, 2, dtype=torch.float64)
            return ContactResult(False, p[-1], p[:1], p, torch.zeros_like(p), 0.0)

    model = tg.GPIS(np.array([[0.1, 0.0], [0.3, 0.0]]), np.array([0.0, 1.0]),
                    kernel=tg.kernels.InverseMultiquadricKernel(0.1), noise=1e-3)
    here = torch.tensor([[0.12, 0.0], [0.13, 0.0]], dtype=torch.float64)
    lost = ContactResult(False, here[-1], here[:1], here, torch.zeros_like(here), 0.01)
    for config, reach in ((ContactConfig(max_normal_travel=0.015), 0.03), (ContactConfig(), 0.1), (None, 0.1)):
        ctl = Controller(config)
        assert reapproach_reach(ctl) == pytest.approx(reach)
        s = ExplorationState(model=model, contacts=[np.array([0.1, 0.0])])
        assert recover(s, Hardware(robot=None, sensor=None, camera=None, controller=ctl), lost) is None
        assert ctl.calls[0] == pytest.approx(reach) and len(ctl.calls) == 2


@pytest.mark.parametrize("kwargs, field", [
    (dict(metrics_resolution=1e-5), "metrics_resolution"),     # a 25 GiB grid before the check existed
    (dict(step=1e6), "step"),                                   # MemoryError before
    (dict(step=float("nan")), "step"),
    (dict(theta=1e-170), "theta"),                              # an endless jitter loop before
    (dict(noise=-1.0), "noise"),
    (dict(max_steps=-1), "max_steps"),
    (dict(max_travel=float("inf")), "max_travel"),
    (dict(regions=0), "regions"),
    (dict(evidence="no_such_policy"), "evidence"),
    (dict(learn="everything"), "learn: must be one of"),
    (dict(learn="all", restart_every=None), "restart_every=None has none"),
    (dict(learn="length", regions=2), "regions has one per region"),
])
def test_bad_exploration_settings_are_named_before_anything_moves(kwargs, field):
    scene = Scene2D(_polygon_circle(0.10), _polygon_circle(0.13), start=(-0.25, 0.0), direction=(1, 0))
    estimator = {k: kwargs.pop(k) for k in ("noise", "learn", "restart_every") if k in kwargs}
    with pytest.raises(ValueError, match=field):
        tg.explore(scene, **kwargs, **({"settings": EstimatorOverrides(**estimator)} if estimator else {}))


def test_resume_compares_the_geometry_not_the_name(tmp_path):
    """Issue 14, item 11: a different geometry under the same name, or two unnamed scenes, must not share a log."""
    log = tmp_path / "run.gpioius"
    a = Scene2D(_polygon_circle(0.10), _polygon_circle(0.13), start=(-0.25, 0.0), direction=(1, 0), name="A")
    tg.explore(a, mode="tactile", max_steps=2, log=log)
    other = Scene2D(_polygon_circle(0.11), _polygon_circle(0.13), start=(-0.25, 0.0), direction=(1, 0), name="A")
    with pytest.raises(ValueError, match="geometry"):
        tg.explore(other, mode="tactile", max_steps=2, resume_from=log)
    log2 = tmp_path / "unnamed.gpioius"
    tg.explore(Scene2D(_polygon_circle(0.10), _polygon_circle(0.13), start=(-0.25, 0.0), direction=(1, 0)),
               mode="tactile", max_steps=2, log=log2)
    with pytest.raises(ValueError, match="geometry"):
        tg.explore(Scene2D(_polygon_circle(0.10), _polygon_circle(0.15), start=(-0.25, 0.0), direction=(1, 0)),
                   mode="tactile", max_steps=2, resume_from=log2)
    same = tg.explore(a, mode="tactile", max_steps=2, resume_from=log)     # the same world resumes
    assert same.n_steps == 3


class _LostEstimate(Scene2D):
    """A world whose estimate vanishes from ``vanish`` on (its metrics find no closed curve): the situation of a
    user's open box or a carton whose inner estimate left the range."""

    vanish = 3

    def measure(self, model, contacts, resolution=None):
        from torch_gpioius.exploration.world import Measurement

        if len(contacts) > self.vanish:
            return Measurement(estimate=False)
        return super().measure(model, contacts, resolution)


def test_a_run_that_ends_without_an_estimate_says_so(tmp_path):
    """Issue 33, item 5: a run whose final estimate had no surface said nothing (NaN in the table, an empty figure)."""
    from torch_gpioius.exploration import NoEstimateWarning
    from torch_gpioius.io.runs import load_run

    scene = _LostEstimate(_polygon_circle(0.10), _polygon_circle(0.13), start=(-0.25, 0.0), direction=(1, 0))
    log = tmp_path / "run.gpioius"
    with pytest.warns(NoEstimateWarning, match=r"ended at step 5 with no estimated inner surface .*no closed curve"):
        trace = tg.explore(scene, mode="tactile", max_steps=5, log=log, metrics_every=2)
    assert trace.has_estimate is False
    assert trace.estimate[0] == 1.0 and trace.estimate[-1] == 0.0 and math.isnan(trace.estimate[1])   # not measured
    assert math.isnan(trace.hausdorff[-1]) and trace.records()[-1]["estimate"] == 0.0
    history = load_run(log)
    assert history.params[5]["estimate"] == 0.0 and history.params[0]["estimate"] == 1.0     # the log keeps it
    fine = tg.explore(paper_objects_2d_a(), mode="tactile", max_steps=2)
    assert fine.has_estimate is True


def paper_objects_2d_a():
    from torch_gpioius.sim import paper_objects_2d

    return paper_objects_2d()["A"]


def test_each_reported_fraction_is_measured_where_the_travel_reaches_it():
    """Issue 33, item 8: metrics every 5 steps put "H at 10 %" at 0.182 m of a 0.6 m budget; the step that first
    reaches 10, 25 and 50 % of the budget is measured now."""
    from torch_gpioius.exploration.recorders import REPORT_FRACTIONS
    from torch_gpioius.sim.forcefield import sphere_scene

    budget = 0.08
    trace = tg.explore(sphere_scene(), mode="tactile", max_travel=budget, metrics_every=1000)
    measured = ~np.isnan(trace.estimate)
    for f in REPORT_FRACTIONS:
        first = int(np.flatnonzero(trace.travel >= f * budget)[0])
        assert measured[first], f"the step reaching {f:.0%} was not measured"
        assert trace.travel[first - 1] < f * budget
    assert measured.sum() == len(REPORT_FRACTIONS) + 2          # record 0, the three fractions, the last
    assert trace.travel[-1] <= budget + 0.03                     # at most one step (and its regulation) past it


@pytest.mark.filterwarnings("ignore::torch_gpioius.models.gpiois.FitNotConvergedWarning")
@pytest.mark.filterwarnings("ignore:explore.*no estimated inner surface")
def test_a_run_learns_its_length_and_noise_on_the_restart_steps():
    """learn="all": the length and sigma^2 change on restart steps only, start from the configured values each time,
    are in every record, and are what the model holds; learn="length" holds sigma^2; a kernel without a learnable
    length is refused before anything moves. (A few touches of a 2-D circle: the learned values are not judged here,
    and the short run's fits and estimate may be poor; the studies judge them.)"""
    scene = Scene2D(_polygon_circle(0.10), _polygon_circle(0.13), start=(-0.25, 0.0), direction=(1, 0))
    trace = tg.explore(scene, max_steps=7, settings=EstimatorOverrides(restart_every=3, learn="all"),
                       metrics_every=100)
    assert trace.n_steps == 8 and np.isfinite(trace.length).all() and np.isfinite(trace.noise).all()
    changed = [i for i in range(1, trace.n_steps) if trace.length[i] != trace.length[i - 1]
               or trace.noise[i] != trace.noise[i - 1]]
    assert set(changed) <= {3, 6} and changed                      # learned (and kept) on a restart step
    assert trace.length[0] == pytest.approx(scene.defaults.lengthscale, rel=1e-12)
    assert trace.length[-1] == pytest.approx(trace.model.kernel.length, rel=0, abs=0)
    assert trace.noise[-1] == trace.model.noise and trace.model.hyper_result.kept
    rows = trace.records()
    assert rows[-1]["length"] == trace.length[-1] and rows[-1]["noise"] == trace.noise[-1]
    only_length = tg.explore(scene, max_steps=4, settings=EstimatorOverrides(restart_every=3, learn="length"),
                             metrics_every=100)
    assert np.all(only_length.noise == only_length.noise[0]) and only_length.length[3] != only_length.length[0]

    class Plain(tg.kernels.Matern52):          # a kernel that does not offer its length for learning
        learnable_length = False

    with pytest.raises(ValueError, match="no learnable length"):
        tg.explore(scene, settings=EstimatorOverrides(kernel=Plain(0.1), learn="length"))
    # the loose keywords still work for a release, through the same resolver, with a warning that names the way
    with pytest.warns(DeprecationWarning, match=r"explore\(learn=, restart_every=\): give settings=EstimatorOverrides"):
        loose = tg.explore(scene, max_steps=4, restart_every=3, learn="length", metrics_every=100)
    np.testing.assert_array_equal(loose.length, only_length.length)


def test_the_measuring_schedule_measures_at_its_fractions_of_the_travel_and_the_end_only():
    """Issue 54: measuring the estimate at every step took a third of a run. ``metrics_every="schedule"`` measures
    at the first step that reaches 10, 25 and 50 % of the travel budget, and at the end (issue 61: not before
    exploring, which no table reports, since the converged ruler costs more); recomputed here from the run's own
    travel. A run without a travel budget has no schedule, and says so."""
    from torch_gpioius.exploration.recorders import REPORT_FRACTIONS

    scene = Scene2D(_polygon_circle(0.10), _polygon_circle(0.13), start=(-0.25, 0.0), direction=(1, 0))
    budget = 0.12
    trace = tg.explore(scene, max_travel=budget, metrics_every="schedule")
    travel, measured = np.asarray(trace.travel), ~np.isnan(np.asarray(trace.hausdorff))
    want = {len(travel) - 1}
    for f in REPORT_FRACTIONS:
        first = np.flatnonzero(travel >= f * budget)
        if len(first):
            want.add(int(first[0]))
    assert set(np.flatnonzero(measured).tolist()) == want and len(travel) > len(want) + 3
    with pytest.raises(ValueError, match="metrics_every='schedule': measures at fractions of a travel budget"):
        tg.explore(scene, metrics_every="schedule")
