"""Scenes and runs several exploration test modules share (each costs seconds; computed once per session)."""

import pytest

import torch_gpioius as tg
from torch_gpioius.sim import Scene2D, rectangle


@pytest.fixture(scope="session")
def c_from_the_left():
    """Object C approached from the side where the cover coincides with the body: the approach records no free
    space inside the cover, so without taps the similarity stays 1 and the estimate keeps the 27 cm extension."""
    return Scene2D(rectangle(-0.15, 0.15, -0.10, 0.10), rectangle(-0.15, 0.419, -0.10, 0.10), start=(-0.30, 0.01),
                   direction=(1, 0), name="C-left")


@pytest.fixture(scope="session")
def c_left_without_recovery(c_from_the_left):
    """140 steps on C from the left with the no-progress rule off: the run stalls in the corner where body and cover
    part (from step 111 on)."""
    return tg.explore(c_from_the_left, max_steps=140, stall=None)

