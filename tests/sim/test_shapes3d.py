"""3-D shapes and scenes: SDF primitives against closed forms, the mesh SDF against trimesh, scene checks."""

import math

import numpy as np
import pytest
import torch
import trimesh

from torch_gpioius.sim import (MeshSDF, Scene3D, capsule, mesh_from_sdf, offset, paper_objects_3d, rounded_box,
                               smooth_union, sphere_scene)

RNG = np.random.default_rng(0)


def test_primitives_match_closed_forms():
    p = RNG.uniform(-0.3, 0.3, (500, 3))
    d = capsule((0, 0, -0.1), (0, 0, 0.1), 0.05)(p)
    z = np.clip(p[:, 2], -0.1, 0.1)
    np.testing.assert_allclose(d, np.linalg.norm(p - np.c_[0 * z, 0 * z, z], axis=1) - 0.05, atol=1e-15)
    # a rounded box with radius 0 is the plain box: outside distance to the box, inside minus depth
    box = rounded_box((0, 0, 0), (0.1, 0.2, 0.05), 0.0)
    q = np.array([[0.0, 0.0, 0.0], [0.3, 0.0, 0.0], [0.2, 0.3, 0.0], [0.05, 0.0, 0.0]])
    np.testing.assert_allclose(box(q), [-0.05, 0.2, math.hypot(0.1, 0.1), -0.05], atol=1e-15)
    # smooth union: the plain minimum away from the blend, below it inside the blend
    a, b = capsule((-0.2, 0, 0), (-0.1, 0, 0), 0.03), capsule((0.1, 0, 0), (0.2, 0, 0), 0.03)
    u = smooth_union(a, b, k=0.02)
    far = np.array([[-0.15, 0.0, 0.0], [0.15, 0.1, 0.0]])
    np.testing.assert_allclose(u(far), np.minimum(a(far), b(far)))
    mid = np.array([[0.0, 0.0, 0.0]])
    assert u(mid)[0] <= min(a(mid)[0], b(mid)[0])
    np.testing.assert_allclose(offset(a, 0.01)(far), a(far) - 0.01)
    with pytest.raises(ValueError):
        capsule((0, 0, 0), (0, 0, 0), 0.1)


def test_meshed_capsule_has_the_analytic_volume_and_closed_surface():
    sdf = capsule((0, -0.1, 0), (0, 0.1, 0), 0.05)
    mesh = mesh_from_sdf(sdf, [[-0.1, -0.2, -0.1], [0.1, 0.2, 0.1]], 0.004)
    assert mesh.is_watertight and mesh.volume > 0
    exact = math.pi * 0.05**2 * 0.2 + 4 / 3 * math.pi * 0.05**3
    assert mesh.volume == pytest.approx(exact, rel=0.01)
    assert np.abs(sdf(mesh.vertices)).max() < 0.004 * 0.1
    with pytest.raises(ValueError, match="touches the bounds"):
        mesh_from_sdf(sdf, [[-0.04, -0.2, -0.1], [0.04, 0.2, 0.1]], 0.004)


def test_mesh_sdf_matches_trimesh_and_the_analytic_sphere():
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=0.1)
    sdf = MeshSDF(mesh)
    p = RNG.uniform(-0.2, 0.2, (300, 3))
    p = np.concatenate([p, mesh.vertices[:20], mesh.triangles_center[:20]])   # on vertices and faces too
    d, n = sdf(torch.as_tensor(p))
    ref = -trimesh.proximity.signed_distance(mesh, p)        # trimesh: positive inside
    np.testing.assert_allclose(d.numpy(), ref, atol=1e-9)
    far = np.linalg.norm(p, axis=1) > 0.12
    np.testing.assert_allclose(n.numpy()[far], p[far] / np.linalg.norm(p[far], axis=1)[:, None], atol=0.03)
    assert np.allclose(np.linalg.norm(n.numpy(), axis=1), 1.0)
    with pytest.raises(ValueError, match="watertight"):
        MeshSDF(trimesh.Trimesh(mesh.vertices, mesh.faces[:-1]))


def test_paper_objects_are_valid_and_ordered_by_cover_looseness():
    objs = paper_objects_3d(resolution=0.01)
    dh = {k: s.inner_outer_hausdorff(spacing=0.006) for k, s in objs.items()}
    assert dh["E"] < 0.015 and dh["G"] < 0.015                   # tight: 8 mm covers
    assert dh["F"] > 0.04 and dh["H"] > 0.1                       # loose
    for s in objs.values():
        assert s.in_range(s.first_contact()[None])[0] or s.first_contact()[2] >= s.range[0, 2]
        assert float(s.inner_sdf(s.first_contact()[None])[0][0]) == pytest.approx(0.0, abs=1e-9)


def test_scene_validation():
    s = sphere_scene()
    np.testing.assert_allclose(np.linalg.norm(s.first_contact() - [0.5, 0.0, 0.25]), 0.08, atol=1e-3)
    inner, outer = s.inner, s.outer
    b = s.range
    with pytest.raises(ValueError, match="contain"):
        Scene3D(outer, inner, s.start, s.direction, b)
    with pytest.raises(ValueError, match="outside"):
        Scene3D(inner, outer, [0.5, 0.0, 0.25], s.direction, b)
    with pytest.raises(ValueError, match="misses"):
        Scene3D(inner, outer, s.start, (0, 0, 1), b)
    with pytest.raises(ValueError, match="bounds"):
        Scene3D(inner, outer, s.start, s.direction, b[::-1])          # max corner first
    with pytest.raises(ValueError, match=r"\[min, max\]-per-axis layout: pass its transpose"):
        Scene3D(inner, outer, s.start, s.direction, b.T)              # the (3, 2) layout of 0.1
    s2 = Scene3D(inner, outer, s.start, s.direction, outer.bounds)    # trimesh's mesh.bounds works as is
    np.testing.assert_array_equal(s2.range, outer.bounds)
    with pytest.raises(ValueError, match="watertight|closed"):
        Scene3D(trimesh.Trimesh(inner.vertices, inner.faces[:-1]), outer, s.start, s.direction, b)
    with pytest.raises(ValueError, match="direction"):
        Scene3D(inner, outer, s.start, (0, 0, 0), b)
