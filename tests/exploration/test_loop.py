import math

import numpy as np
import pytest

import torch_gpioius as tg
from torch_gpioius.exploration import gone_around, largest_uncovered_gap
from torch_gpioius.sim import Scene2D


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
