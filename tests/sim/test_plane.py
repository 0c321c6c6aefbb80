import numpy as np
import pytest
import shapely
from shapely.geometry import Polygon

from torch_gpioius.sim import Scene2D, paper_objects_2d, rectangle
from torch_gpioius.testing import WorldContract

TABLE_I_CM = {"A": 6.4, "B": 12.0, "C": 26.9, "D": 37.5}


@pytest.mark.parametrize("name", sorted(TABLE_I_CM))
def test_table_i_hausdorff(name):
    scene = paper_objects_2d()[name]
    ours = 100 * scene.inner_outer_hausdorff()
    assert abs(ours - TABLE_I_CM[name]) <= 0.1
    # independent reference: shapely's densified discrete Hausdorff
    theirs = 100 * shapely.hausdorff_distance(Polygon(scene.inner_boundary).exterior,
                                              Polygon(scene.outer_boundary).exterior, densify=0.001)
    assert abs(theirs - TABLE_I_CM[name]) <= 0.1


def test_first_contact_and_settle():
    scene = Scene2D(rectangle(-0.1, 0.1, -0.1, 0.1), rectangle(-0.2, 0.2, -0.2, 0.2), start=(-0.3, 0.05),
                    direction=(1, 0))
    np.testing.assert_allclose(scene.first_contact(), [-0.1, 0.05], atol=1e-12)
    np.testing.assert_allclose(scene.settle(np.array([-0.09, 0.0])), [-0.1, 0.0], atol=1e-12)   # pushed out
    np.testing.assert_allclose(scene.settle(np.array([-0.12, 0.0])), [-0.1, 0.0], atol=1e-12)   # pressed on


def test_bad_scenes():
    with pytest.raises(ValueError, match="contain"):
        Scene2D(rectangle(-0.3, 0.3, -0.1, 0.1), rectangle(-0.2, 0.2, -0.2, 0.2), (-1, 0), (1, 0))
    with pytest.raises(ValueError, match="misses"):
        Scene2D(rectangle(-0.1, 0.1, -0.1, 0.1), rectangle(-0.2, 0.2, -0.2, 0.2), (-0.3, 0.5), (1, 0))
    with pytest.raises(ValueError, match="outside"):
        Scene2D(rectangle(-0.1, 0.1, -0.1, 0.1), rectangle(-0.2, 0.2, -0.2, 0.2), (-0.15, 0.0), (1, 0))
    with pytest.raises(ValueError, match="vertices"):
        Scene2D([[0, 0], [1, 1]], rectangle(-0.2, 0.2, -0.2, 0.2), (-0.3, 0.0), (1, 0))


class TestPlanarWorldContract(WorldContract):
    """The 2-D world keeps the contract users' worlds are tested against (torch_gpioius.testing)."""

    def make(self):
        from torch_gpioius.exploration import make_world

        return make_world("planar", "A")
