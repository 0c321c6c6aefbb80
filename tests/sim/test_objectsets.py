"""Object sets: the seeded primitive family (closed, standing, sized within 8-25 cm, the same on every call) and set
names by family and range."""

import numpy as np
import pytest

from torch_gpioius.sim.objectsets import PRIMITIVE_KINDS, SIZE_RANGE, parse_object_set, primitive_mesh


def test_every_primitive_is_closed_standing_and_sized():
    kinds = set()
    for i in range(20):
        mesh, kind = primitive_mesh(i)
        kinds.add(kind)
        assert mesh.is_watertight and mesh.volume > 0, (i, kind)
        lo, hi = mesh.bounds
        assert abs(lo[2]) < 1e-12 and np.allclose((lo[:2] + hi[:2]) / 2, 0.0, atol=1e-12)    # on z = 0, centred
        assert SIZE_RANGE[0] - 1e-9 <= float(np.max(mesh.extents)) <= SIZE_RANGE[1] + 1e-9, (i, mesh.extents)
    assert kinds == set(PRIMITIVE_KINDS)
    again, _ = primitive_mesh(7)
    assert np.array_equal(again.vertices, primitive_mesh(7)[0].vertices)          # seeded: the same object


def test_set_names_by_family_and_range():
    objs = parse_object_set("primitives:3-5,9")
    assert [o.name for o in objs] == ["primitives-003", "primitives-004", "primitives-005", "primitives-009"]
    blobs = parse_object_set("pybullet-random:0-2")
    assert [o.source for o in blobs][0] == "pybullet:random_urdfs/000/000.obj"
    assert all(SIZE_RANGE[0] <= o.size <= SIZE_RANGE[1] for o in blobs)
    for bad, match in (("primitives", "expected FAMILY:RANGE"), ("boxes:0-3", "unknown family"),
                       ("primitives:5-2", "first <= last"), ("primitives:a-b", "not an index"),
                       ("pybullet-random:990-1200", "must lie in 0-999")):
        with pytest.raises(ValueError, match=match):
            parse_object_set(bad)
    with pytest.raises(ValueError, match="index"):
        primitive_mesh(-1)
