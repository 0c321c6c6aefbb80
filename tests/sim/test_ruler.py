"""The converged ruler of the 3-D worlds (sim/ruler.py): an offset sphere measured in closed form on a coarse grid,
and a fitted estimate's figures stable when the grid is halved."""

import numpy as np
import pytest
import torch

from torch_gpioius.sim.forcefield import sphere_scene


class _Sphere:
    """An "estimate" whose mean is an analytic field: |x - c| - r, zero on a sphere of radius r [m] (a stand-in model
    for the ruler: what it measures is known in closed form)."""

    def __init__(self, centre, radius):
        import torch

        self.c, self.r = torch.tensor(centre, dtype=torch.float64), radius
        self.train_inputs = (torch.zeros(1, 3, dtype=torch.float64),)
        self.dim = 3

    def predict_mean(self, x):
        return (x - self.c).norm(dim=-1) - self.r


def _ruler_figures(world, model, grid):
    from torch_gpioius.sim.ruler import METRICS_EDGE, score_surface
    from torch_gpioius.geometry.surfaces import converged_level_mesh, evaluate_grid

    field = evaluate_grid(model, world.bounds(0.05), grid, 0, variance=False)
    whole = converged_level_mesh(model, None, field=field, edge=METRICS_EDGE, keep=world.range)

    def mean(p):
        with torch.no_grad():
            return model.predict_mean(torch.as_tensor(p)).numpy()

    _, h, shape = score_surface(world, whole, None, np.zeros((0, 3)), METRICS_EDGE, mean=mean)
    return {**shape, "hausdorff": h}


def test_the_converged_ruler_measures_a_known_offset_sphere_in_closed_form_on_a_coarse_grid():
    """Issue 61: the figures came from marching cubes on a 2 cm grid, which moved a run's Chamfer distance by -15 % to
    +89 %. An estimate that is a sphere 3 mm larger than the 6 cm true one has, in closed form, a Chamfer distance,
    a Hausdorff distance and a bias of 3 mm (the truth inside it), an F-score of 1 at 5 mm and 0 at 1 mm. The converged
    ruler gives them within 1 % (the Hausdorff distance within 3 %) on its 1 cm grid and on a 5 mm one; marching cubes
    alone, on the 2 cm grid of the releases before, is off by more than the ruler's 2 % (the vertices interpolated
    linearly on the grid's edges)."""
    from torch_gpioius.sim.ruler import METRICS_EDGE, score_surface
    from torch_gpioius.geometry.surfaces import evaluate_grid, zero_level_mesh

    world = sphere_scene(radius=0.06, cover=0.01, subdivisions=6)       # facets of 1.4 mm: a sagitta of 4 um
    model = _Sphere(world.inner.bounds.mean(axis=0), 0.063)
    from torch_gpioius.sim.ruler import METRICS_GRID

    for grid in (METRICS_GRID, METRICS_GRID / 2):
        figures = _ruler_figures(world, model, grid)
        for key, want in (("chamfer", 0.003), ("bias", 0.003)):
            assert figures[key] == pytest.approx(want, rel=0.01), (grid, key, figures[key])
        # a supremum carries the worst point's chord correction (a Newton step from the closest chord point)
        assert figures["hausdorff"] == pytest.approx(0.003, rel=0.03), (grid, figures["hausdorff"])
        assert figures["fscore_5mm"] == pytest.approx(1.0, abs=1e-12) and figures["fscore_1mm"] == 0.0
    coarse = zero_level_mesh(model, None, field=evaluate_grid(model, world.bounds(0.05), 0.02, 0, variance=False))
    _, _, plain = score_surface(world, coarse, None, np.zeros((0, 3)), METRICS_EDGE)
    assert abs(plain["chamfer"] - 0.003) > 0.02 * 0.003


def test_the_figures_of_a_fitted_estimate_move_by_under_two_percent_when_the_grid_is_halved():
    """Issue 61: a real run's final estimate (a ball under a tight cover), measured on the ruler's 1 cm grid and on a
    5 mm one: every figure moves by less than 2 % of its value (or 0.02 mm and 0.01 where it is near zero)."""
    from tests.scenes import ball_scene
    from torch_gpioius.sim.ruler import METRICS_GRID, estimate_metrics_3d
    from torch_gpioius.sim.scenefile import load_scene

    import tempfile
    from pathlib import Path

    import torch_gpioius as tg

    folder = Path(tempfile.mkdtemp())
    world = load_scene(ball_scene(folder))
    trace = tg.explore(world, max_travel=0.15, metrics_every=1000)
    coarse, fine = (estimate_metrics_3d(trace.model, world, grid) for grid in (METRICS_GRID, METRICS_GRID / 2))
    assert coarse.estimate and fine.estimate
    for key in ("chamfer", "bias", "hausdorff_observed"):
        assert abs(coarse.shape[key] - fine.shape[key]) <= max(0.02 * abs(fine.shape[key]), 2e-5), key
    for key in ("fscore_1mm", "fscore_5mm", "fscore_10mm", "unseen"):
        assert abs(coarse.shape[key] - fine.shape[key]) <= max(0.02 * fine.shape[key], 0.01), key
    assert abs(coarse.hausdorff - fine.hausdorff) <= max(0.02 * fine.hausdorff, 2e-5)
    assert abs(coarse.uncertainty - fine.uncertainty) <= 0.02 * fine.uncertainty
    assert coarse.surface.metadata["ruler"]["last_step"] < 1e-4         # every grid vertex within a step of mu = 0
