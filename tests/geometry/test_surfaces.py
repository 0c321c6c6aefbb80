import numpy as np
import pytest
import torch
import trimesh

import torch_gpioius as tg
from torch_gpioius import surfaces


def test_circle_recovered_from_samples():
    a = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    ring = np.stack([np.cos(a), np.sin(a)], -1) + np.array([0.05, -0.02])
    x = np.concatenate([0.2 * (ring - [0.05, -0.02]) + [0.05, -0.02], 0.3 * (ring - [0.05, -0.02]) + [0.05, -0.02]])
    y = np.r_[np.zeros(40), np.ones(40)]
    model = tg.GPIS(torch.tensor(x), torch.tensor(y))
    curves = surfaces.zero_level_curves(model, [[-0.4, -0.45], [0.5, 0.45]], resolution=0.005)
    closed = surfaces.closed_curves(curves)
    assert len(closed) == 1
    r = np.linalg.norm(closed[0] - [0.05, -0.02], axis=1)
    assert np.abs(r - 0.2).max() < 0.002


def test_sphere_recovered_from_samples():
    sphere = trimesh.creation.icosphere(subdivisions=2, radius=0.2)
    p = np.asarray(sphere.vertices)
    x = np.concatenate([p, 1.5 * p])
    y = np.r_[np.zeros(len(p)), np.ones(len(p))]
    model = tg.GPIS(torch.tensor(x), torch.tensor(y))
    mesh = surfaces.zero_level_mesh(model, [[-0.35] * 3, [0.35] * 3], resolution=0.02)
    assert mesh is not None and mesh.is_watertight
    r = np.linalg.norm(mesh.vertices, axis=1)
    assert np.abs(r - 0.2).max() < 0.002
    # outward normals: face normals point away from the centre
    assert (np.einsum("ij,ij->i", mesh.face_normals, mesh.triangles_center) > 0).mean() > 0.99


def test_no_level_set_and_bad_bounds():
    model = tg.GPIS(torch.tensor([[5.0, 5.0]]), torch.tensor([1.0]))
    assert surfaces.zero_level_curves(model, [[-1, -1], [1, 1]], 0.1) == []
    with pytest.raises(ValueError, match="bounds"):
        surfaces.zero_level_curves(model, [[1, -1], [-1, 1]], 0.1)
    with pytest.raises(ValueError, match="3-D"):
        surfaces.zero_level_mesh(model, [[-1] * 3, [1] * 3], 0.1)
    with pytest.raises(ValueError, match="grid nodes"):           # 25 GiB asked for by explore(1e-5) in 0.1
        surfaces.evaluate_grid(model, [[-1, -1], [1, 1]], 1e-5)
    with pytest.raises(ValueError, match="resolution"):
        surfaces.evaluate_grid(model, [[-1, -1], [1, 1]], float("nan"))


def test_touched_pieces_keep_the_object_and_drop_an_untouched_blob():
    """A circle the contacts lie on and a small blob 1.5 cm beside one contact: only the circle is touched."""
    a = np.linspace(0, 2 * np.pi, 200)
    circle = np.stack([0.1 * np.cos(a), 0.1 * np.sin(a)], -1)
    blob = np.stack([0.115 + 0.004 * np.cos(a), 0.004 * np.sin(a)], -1)
    contacts = circle[::10][:15]                   # one side of the circle, 15 contacts
    kept = surfaces.touched_pieces([circle, blob], contacts)
    assert len(kept) == 1 and kept[0] is circle
    assert surfaces.touched_pieces([circle, blob], contacts, radius=0.02, min_fraction=0.0)[1] is blob
    # 3-D: two spheres as one mesh; contacts on the first only
    s1 = trimesh.creation.icosphere(subdivisions=2, radius=0.1)
    s2 = trimesh.creation.icosphere(subdivisions=2, radius=0.02)
    s2.apply_translation([0.3, 0, 0])
    both = trimesh.util.concatenate([s1, s2])
    kept3 = surfaces.touched_pieces(both, np.asarray(s1.vertices[:30]))
    assert kept3 is not None and abs(kept3.volume - s1.volume) < 1e-9
