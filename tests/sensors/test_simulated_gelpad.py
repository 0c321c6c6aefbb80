"""The simulated gel pad against analytic geometry: a flat body, with a cover everywhere (the force-field world) or
a cover sheet whose place the caller gives (the MuJoCo world's cloth)."""

import numpy as np
import pytest

from torch_gpioius.exploration.patches import patch_observations
from torch_gpioius.sensors.simulated.gelpad import SimulatedGelPad

T = 5e-4            # cloth thickness [m]
FORCE = 2.0         # [N] along +z: the pad presses 1 mm (2000 N/m)


def _pad(cover=None, **kw):
    """A pad at the origin facing a body that fills z < 0 (its signed distance is z)."""
    return SimulatedGelPad(lambda p: p[:, 2], lambda: np.array([0.003, -0.002, 0.004]),
                           lambda: np.array([0.0, 0.0, FORCE]), cloth_thickness=T, cover=cover, **kw)


def _sheet(height, where=lambda o: np.ones(len(o), bool)):
    """A cover whose face is the plane z = height where ``where(origins)`` (rays run along -z)."""
    def cover(origins, axis, far):
        assert np.allclose(axis, [0.0, 0.0, -1.0])
        d = origins[:, 2] - height
        return np.where(where(origins) & (d >= 0) & (d <= far), d, np.inf)
    return cover


def _surface(pad):
    reading = pad.read()
    obs = patch_observations(reading)
    return reading, obs.x[obs.y == 0]


def test_without_a_cover_sheet_the_pad_reads_the_body_plus_the_cloth():
    reading, surf = _surface(_pad())
    assert np.abs(surf[:, 2] - T).max() < 1e-9
    assert np.nanmax(reading.depth) == pytest.approx(FORCE / 2000.0, rel=1e-9)


def test_cloth_pressed_onto_the_body_reads_as_body_plus_cloth():
    _, surf = _surface(_pad(_sheet(1e-3)))            # the face 1 mm up: within the 1.5 mm pinch
    assert np.abs(surf[:, 2] - T).max() < 1e-9


def test_cloth_held_off_the_body_reads_as_cloth():
    _, surf = _surface(_pad(_sheet(2e-3)))            # 2 mm up: beyond the pinch, the cover alone carries the force
    assert np.abs(surf[:, 2] - 2e-3).max() < 1e-9


def test_where_the_cloth_slid_away_the_pad_reads_the_bare_body():
    reading, surf = _surface(_pad(_sheet(1e-3, where=lambda o: o[:, 0] < 0.003)))
    left, right = surf[surf[:, 0] < 0.003 - 1e-3], surf[surf[:, 0] > 0.003 + 1e-3]
    assert len(left) > 10 and len(right) > 10
    assert np.abs(left[:, 2] - T).max() < 1e-9 and np.abs(right[:, 2]).max() < 1e-9
    # the bare body lies the cloth's thickness behind the deepest pixel
    assert np.nanmin(reading.depth) == pytest.approx(FORCE / 2000.0 - T, rel=1e-9)


def test_nothing_under_the_pad_is_an_error_by_name():
    pad = SimulatedGelPad(lambda p: np.full(len(p), 1.0), lambda: np.zeros(3), lambda: np.array([0.0, 0.0, FORCE]),
                          cover=_sheet(-1.0))
    with pytest.raises(RuntimeError, match="nothing lies under the pad"):
        pad.read()
    with pytest.raises(ValueError, match="pinch"):
        _pad(_sheet(0.0), pinch=-1.0)
