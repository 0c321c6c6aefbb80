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


def test_a_set_object_stands_on_the_table_at_its_size_under_its_cover():
    """Issue 54: each object of a set is scaled to its seeded size, stands in its most probable stable pose (the
    lowest point on z = 0 before it is placed), and is explored under a tight (8 mm) or wide (4 cm) cover; pybullet's
    blobs, metres across in their files, load at their size."""
    import warnings

    from torch_gpioius.sim.objectsets import COVERS, STAND_AT, object_set, set_mesh, set_scene

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")                   # the blob's repair says what it did
        for obj in object_set("primitives:7") + object_set("pybullet-random:3"):
            mesh = set_mesh(obj)
            assert mesh.is_watertight and abs(float(np.max(mesh.extents)) - obj.size) < 1e-9 * obj.size
            assert abs(float(mesh.bounds[0, 2])) < 1e-12
            np.testing.assert_allclose((mesh.bounds[0, :2] + mesh.bounds[1, :2]) / 2, 0.0, atol=1e-12)
        scene = set_scene(object_set("primitives:7")[0], "wide")
    assert scene.name == "primitives-007" and COVERS["wide"] == ("loose", {"gap": 0.04})
    assert abs(float(scene.inner.bounds[0, 2]) - STAND_AT[2]) < 1e-9
    with pytest.raises(ValueError, match="cover: must be one of"):
        set_scene(object_set("primitives:7")[0], "snug")


def test_a_corrupt_file_in_a_users_folder_is_named_not_a_crash(tmp_path):
    """A folder set's file is read once (its size first, then checked and repaired at that size); a corrupt one is a
    ValueError naming the object and the file (a study's failed row), never a parser's own exception."""
    from torch_gpioius.sim.objectsets import object_set, set_scene

    (tmp_path / "broken.stl").write_text("solid nothing\nthis is not a mesh\n")
    (obj,) = object_set(f"folder:{tmp_path}")
    with pytest.raises(ValueError, match=r"broken .*broken\.stl"):
        set_scene(obj)


def test_a_lying_family_is_the_same_objects_turned_onto_their_side():
    """Issue 63, item 3: ``primitives-lying`` and ``pybullet-random-lying`` are the standing sets' objects turned by a
    quarter turn onto their side (the same size and volume), each now as low as its smallest extent; one that already
    lay (a blob's stable pose) is left as it was. Their scenes build (the approach from above finds them)."""
    from torch_gpioius.sim.objectsets import set_mesh, set_scene

    upright = parse_object_set("primitives:0-4") + parse_object_set("pybullet-random:0-1")
    turned = parse_object_set("primitives-lying:0-4") + parse_object_set("pybullet-random-lying:0-1")
    for standing, lying in zip(upright, turned):
        family, _, index = standing.name.rpartition("-")
        assert lying.name == f"{family}-lying-{index}"
        assert lying.size == standing.size and lying.index == standing.index
        a, b = set_mesh(standing), set_mesh(lying)
        assert b.volume == pytest.approx(a.volume, rel=1e-9)
        np.testing.assert_allclose(np.sort(b.extents), np.sort(a.extents), rtol=1e-9, atol=1e-12)
        assert b.extents[2] == pytest.approx(b.extents.min(), abs=1e-12) and b.bounds[0, 2] == pytest.approx(0.0)
    assert parse_object_set("pybullet-random-lying:3")[0].name == "pybullet-random-lying-003"
    tall = parse_object_set("primitives-lying:2")[0]                  # a cylinder 23 cm tall, now on its side
    assert set_mesh(tall).extents[2] < 0.1
    scene = set_scene(tall, "tight")
    assert scene.direction.tolist() == [0.0, 0.0, -1.0] and scene.range[0, 2] < 0.1 + 0.03
