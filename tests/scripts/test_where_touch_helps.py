"""scripts/where_touch_helps.py: per band of distance from the touches, the body's share and each estimate's distance
from it; checked on concentric spheres, whose distances are known in closed form."""

import numpy as np
import pytest
import trimesh

from tests.scriptfiles import load_script


def _sphere(radius: float) -> trimesh.Trimesh:
    return trimesh.creation.icosphere(subdivisions=5, radius=radius)


def test_bands_of_concentric_spheres_measure_their_radii_apart_and_the_sign():
    """A body of 10 cm, a fusion 3 mm larger and a shrunk surface 2 mm smaller: every band measures 3 and 2 mm, the
    signed means +3 and -2 mm (the icosphere's chords, under 0.1 mm at this subdivision, within the tolerance); the
    shares follow the touches' reach and sum to one."""
    from torch_gpioius.sim.meshes import MeshDistance

    script = load_script("where_touch_helps")
    body_mesh = _sphere(0.10)
    rng = np.random.default_rng(0)
    v = rng.standard_normal((4000, 3))
    body = 0.10 * v / np.linalg.norm(v, axis=1, keepdims=True)
    contacts = np.array([[0.0, 0.0, 0.10]])                    # one touch at the top
    bands = script.band_errors(body, contacts, {"fusion": _sphere(0.103), "shrunk": _sphere(0.098)},
                               MeshDistance(body_mesh))
    assert sum(bands["share"]) == pytest.approx(1.0)
    # the share of a cap within chord c of the pole is c^2 / (4 r^2) of the sphere
    cap = [min(c, 0.2) ** 2 / (4 * 0.10 ** 2) for c in script.BANDS[1:]]
    expected = np.diff([0.0, *cap])
    np.testing.assert_allclose(bands["share"], expected, atol=0.02)
    for name, gap in (("fusion", 0.003), ("shrunk", -0.002)):
        for (mean, signed), share in zip(bands[name], bands["share"]):
            if share > 0:
                assert mean == pytest.approx(abs(gap), abs=2e-4)
                assert signed == pytest.approx(gap, abs=2e-4)
    # the whole body: share-weighted means; the blend takes the fusion near the touch and the shrunk surface beyond
    assert script.one_sided(bands, "fusion") == pytest.approx(0.003, abs=2e-4)
    assert script.one_sided(bands, "shrunk", near=2) == pytest.approx(
        0.003 * sum(bands["share"][:2]) + 0.002 * sum(bands["share"][2:]), abs=2e-4)


def test_a_missing_surface_reads_nan_in_every_band():
    from torch_gpioius.sim.meshes import MeshDistance

    script = load_script("where_touch_helps")
    body = np.array([[0.1, 0.0, 0.0], [0.0, 0.1, 0.0]])
    bands = script.band_errors(body, body[:1], {"fusion": _sphere(0.1), "shrunk": None}, MeshDistance(_sphere(0.1)))
    assert all(np.isnan(m) and np.isnan(s) for m, s in bands["shrunk"])
