"""The region figure of the local model: drawn from a real local run, refused for a run without regions."""

import numpy as np
import pytest

import torch_gpioius as tg
from torch_gpioius.studies.figures import figure_regions


def test_region_figure_of_a_local_run(tmp_path):
    tr = tg.explore(tg.sim.paper_objects_2d()["C"], mode="visual-tactile", regions=3, max_steps=12, progress=False)
    assert np.asarray(tr.region_correlation).shape == (tr.n_steps, 3)
    figure_regions(tr, tmp_path / "regions.png", "C")
    assert (tmp_path / "regions.png").stat().st_size > 10_000
    plain = tg.explore(tg.sim.paper_objects_2d()["C"], mode="visual-tactile", max_steps=3, progress=False)
    with pytest.raises(ValueError, match="no similarity per region"):
        figure_regions(plain, tmp_path / "x.png")
