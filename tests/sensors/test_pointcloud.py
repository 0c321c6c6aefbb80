"""Point-cloud sources: the simulated depth camera against analytic geometry, voxel averaging, file sources."""

import numpy as np
import pytest
import trimesh

from torch_gpioius.geometry.voxels import voxel_average
from torch_gpioius.io import FilePointCloud
from torch_gpioius.sensors import PinholeCamera, PointCloud, SimulatedDepthCamera, look_at

from tests.sensors.spheres import C, EYE, R, sphere_camera


def test_look_at_is_a_rigid_pose_pointing_at_the_target():
    T = look_at(EYE, C)
    np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-12)
    assert np.linalg.det(T[:3, :3]) == pytest.approx(1.0)
    z = T[:3, 2]
    np.testing.assert_allclose(z, (C - EYE) / np.linalg.norm(C - EYE), atol=1e-12)
    assert T[:3, 1] @ [0, 0, 1] < 0           # image y points down
    with pytest.raises(ValueError, match="parallel"):
        look_at([0, 0, 1], [0, 0, 0])


def test_sphere_seen_from_a_known_pose_gives_points_on_the_visible_sphere():
    cam = sphere_camera()
    cloud = cam.capture()
    r = np.linalg.norm(cloud.points - C, axis=1)
    # icosphere subdivision 5: chord sag below 0.1 mm for r = 10 cm
    assert np.abs(r - R).max() < 2e-4
    # only the hemisphere facing the camera, and only points whose ray meets no other part of the sphere
    assert ((cloud.points - C) @ (EYE - C) > 0).all()
    np.testing.assert_allclose(cloud.origin, EYE)
    # pixel count matches the sphere's projected solid angle: pi * atan(R / sqrt(D^2 - R^2))^2 * f^2
    D = np.linalg.norm(EYE - C)
    half_angle = np.arcsin(R / D)
    intr = cam.intrinsics
    expected = np.pi * (np.tan(half_angle) * intr.fx) ** 2
    assert len(cloud) == pytest.approx(expected, rel=0.05)


def test_depth_noise_is_along_the_ray_with_the_model_std():
    clean = sphere_camera().capture()
    noisy = sphere_camera(noise_a=0.002, noise_b=0.0, seed=3).capture()
    assert len(noisy) == len(clean)
    d_clean = np.linalg.norm(clean.points - EYE, axis=1)
    d_noisy = np.linalg.norm(noisy.points - EYE, axis=1)
    dirs_clean = (clean.points - EYE) / d_clean[:, None]
    dirs_noisy = (noisy.points - EYE) / d_noisy[:, None]
    np.testing.assert_allclose(dirs_clean, dirs_noisy, atol=1e-12)        # same pixel rays
    z = d_clean * (dirs_clean @ look_at(EYE, C)[:3, 2])
    dz = (d_noisy - d_clean) * (z / d_clean)
    assert np.std(dz) == pytest.approx(0.002, rel=0.1)
    dropped = sphere_camera(dropout=0.5, seed=1).capture()
    assert 0.4 * len(clean) < len(dropped) < 0.6 * len(clean)


@pytest.mark.parametrize("engine", ["embree", "triangle"])
def test_both_ray_engines_see_the_same_sphere_including_all_miss_chunks(engine):
    """A small image whose first and last 256-ray chunks see only background (the all-miss chunk crashed the
    trimesh engine's concatenation); both engines give points on the analytic sphere, the same pixels."""
    pytest.importorskip("embreex") if engine == "embree" else None
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=R)
    mesh.apply_translation(C)
    cam = SimulatedDepthCamera(mesh, PinholeCamera.kinect_v2(0.15), look_at(EYE, C), engine=engine)
    pts, pix = cam.depth_points()
    assert pix.min() >= 256 and pix.max() < cam.intrinsics.width * cam.intrinsics.height - 256   # misses at both ends
    world = pts @ cam.T_base_camera[:3, :3].T + cam.T_base_camera[:3, 3]
    assert np.abs(np.linalg.norm(world - C, axis=1) - R).max() < 1e-3
    other = SimulatedDepthCamera(mesh, PinholeCamera.kinect_v2(0.15), look_at(EYE, C),
                                 engine="triangle" if engine == "embree" else "auto")
    pts2, pix2 = other.depth_points()
    np.testing.assert_array_equal(pix, pix2)
    np.testing.assert_allclose(pts, pts2, atol=1e-6)   # Embree intersects in float32


def test_unknown_ray_engine_is_refused():
    with pytest.raises(ValueError, match="engine"):
        sphere_camera(engine="optix")


@pytest.mark.parametrize("engine", ["auto", "triangle"])
def test_missing_everything_gives_an_empty_cloud(engine):
    mesh = trimesh.creation.icosphere(radius=0.1)
    mesh.apply_translation([10.0, 0.0, 0.0])   # behind the camera
    cam = SimulatedDepthCamera(mesh, PinholeCamera.kinect_v2(0.1), look_at(EYE, C), engine=engine)
    assert len(cam.capture()) == 0


def test_voxel_averaging_against_a_hand_computed_grid():
    pts = np.array([[0.01, 0.01, 0.01], [0.03, 0.04, 0.02],   # voxel (0, 0, 0)
                    [0.06, 0.01, 0.01],                         # voxel (1, 0, 0)
                    [-0.01, 0.02, 0.03], [-0.03, 0.04, 0.01]])  # voxel (-1, 0, 0)
    out = voxel_average(pts, 0.05)
    want = np.array([[-0.02, 0.03, 0.02], [0.02, 0.025, 0.015], [0.06, 0.01, 0.01]])
    np.testing.assert_allclose(out, want, atol=1e-15)
    # values carried by the points are averaged over the same voxels, in the same order
    same, vals = voxel_average(pts, 0.05, np.array([[1.0], [3.0], [5.0], [7.0], [9.0]]))
    np.testing.assert_allclose(same, want, atol=1e-15)
    np.testing.assert_allclose(vals, [[8.0], [2.0], [5.0]], atol=1e-15)
    # a dense plane averages to one point per voxel, each within its voxel
    g = np.stack(np.meshgrid(np.linspace(0, 0.2, 81), np.linspace(0, 0.2, 81)), -1).reshape(-1, 2)
    plane = np.c_[g, np.full(len(g), 0.012)]
    avg = PointCloud(plane).voxel_averaged(0.05).points
    assert len(avg) == 25                       # 0 <= x, y < 0.2 (4 x 4) plus the edge at exactly 0.2 (+9)
    np.testing.assert_allclose(avg[:, 2], 0.012)
    with pytest.raises(ValueError, match="voxel size"):
        voxel_average(pts, 0.0)


def test_voxel_averaging_at_other_positions_groups_by_them_and_averages_the_points():
    points = np.array([[0.011, 0.0, 0.0], [0.019, 0.0, 0.0], [0.021, 0.0, 0.0], [0.005, 0.0, 0.0]])
    at = np.array([[0.011, 0.0, 0.0], [0.019, 0.0, 0.0], [0.019, 0.0, 0.0], [0.025, 0.0, 0.0]])  # 3rd and 4th swap
    np.testing.assert_allclose(voxel_average(points, 0.01, at=at), [[(0.011 + 0.019 + 0.021) / 3, 0, 0],
                                                                     [0.005, 0, 0]], atol=1e-15)
    cloud = PointCloud(points, np.array([0.0, 0.0, 1.0]))
    np.testing.assert_allclose(cloud.voxel_averaged(0.01, at=at).points, voxel_average(points, 0.01, at=at))
    np.testing.assert_array_equal(cloud.voxel_averaged(0.01).points, voxel_average(points, 0.01))
    with pytest.raises(ValueError, match="at"):
        cloud.voxel_averaged(0.01, at=at[:2])
    with pytest.raises(ValueError, match="at"):
        voxel_average(points, 0.01, at=at[:, :2])
    from torch_gpioius.geometry.voxels import VoxelAccumulator

    batches = VoxelAccumulator(0.01)                      # in batches, as a bag's frames arrive: the same means
    batches.add(points[:3], at=at[:3])
    batches.add(points[3:], at=at[3:])
    np.testing.assert_allclose(batches.mean(), voxel_average(points, 0.01, at=at), atol=1e-15)
    with pytest.raises(ValueError, match="at"):
        batches.add(points, at=at[:2])


def test_free_space_lies_on_the_rays_in_front_of_the_surface():
    cloud = sphere_camera().capture()
    free = cloud.free_space(0.05)
    assert len(free) == len(cloud)
    np.testing.assert_allclose(np.linalg.norm(free - cloud.points, axis=1), 0.05, atol=1e-12)
    assert (np.linalg.norm(free - C, axis=1) > R + 0.01).all()   # outside the sphere
    with pytest.raises(ValueError, match="origin"):
        PointCloud(cloud.points).free_space(0.05)


def test_normals_of_a_seen_sphere_are_radial_and_face_the_camera():
    cloud = sphere_camera().capture()
    nrm = cloud.normals()
    known = np.isfinite(nrm).all(axis=1)
    radial = (cloud.points - C) / R
    # a plane fitted to 12 neighbours on a 10 cm sphere sampled about every 2 mm: within a few degrees of the radius,
    # and every known one facing the camera (out of the sphere); the grazing rim is left unknown
    cos = np.einsum("ni,ni->n", nrm[known], radial[known])
    assert cos.min() > 0.99
    assert 0.9 < known.mean() < 1.0
    to_camera = EYE - cloud.points[~known]
    rim_cos = np.abs(np.einsum("ni,ni->n", radial[~known], to_camera)) / np.linalg.norm(to_camera, axis=1)
    assert rim_cos.max() < 0.35                                  # only the rim (75 deg off, to the plane fit's error)


def test_points_behind_the_seen_surface_lie_inside_at_the_depth():
    cloud = sphere_camera().capture()
    inside = cloud.behind(0.02)
    assert len(inside) == np.isfinite(cloud.normals()).all(axis=1).sum()
    np.testing.assert_allclose(np.linalg.norm(inside - C, axis=1), R - 0.02, atol=5e-4)
    with pytest.raises(ValueError, match="origin"):
        PointCloud(cloud.points).behind(0.02)
    with pytest.raises(ValueError, match="depth"):
        cloud.behind(-0.01)


def test_points_behind_a_merged_capture_are_voxel_averaged_per_view_and_stay_at_the_depth():
    mesh = trimesh.creation.icosphere(subdivisions=5, radius=R)
    mesh.apply_translation(C)
    a = sphere_camera().capture()
    b = SimulatedDepthCamera(mesh, PinholeCamera.kinect_v2(0.5), look_at(EYE2, C)).capture()
    merged = PointCloud.merge([a, b])
    inside = merged.behind(0.02, voxel=0.02)
    per_view = len(a.behind(0.02, voxel=0.02)) + len(b.behind(0.02, voxel=0.02))
    assert len(inside) == per_view                          # one per occupied voxel of each view
    # the voxel's mean point (up to ~0.6 mm inside a 10 cm sphere over 2 cm voxels) moved 2 cm along its mean normal
    r = np.linalg.norm(inside - C, axis=1)
    assert np.abs(r - (R - 0.02)).max() < 1.5e-3


def test_file_source_loads_and_transforms(tmp_path):
    pts = np.array([[0.0, 0.0, 1.0], [0.1, 0.0, 1.0]])
    np.savez(tmp_path / "cloud.npz", points=pts * 1000)
    T = np.eye(4)
    T[:3, 3] = [0.5, 0.0, 0.2]
    src = FilePointCloud(tmp_path / "cloud.npz", units="mm", T_base_camera=T, origin=[0, 0, 0])
    cloud = src.capture()
    np.testing.assert_allclose(cloud.points, pts + [0.5, 0.0, 0.2])
    np.testing.assert_allclose(cloud.origin, [0.5, 0.0, 0.2])
    with pytest.raises(ValueError, match="T_base_camera"):
        FilePointCloud(tmp_path / "cloud.npz", T_base_camera=np.eye(3))


def test_bad_inputs():
    with pytest.raises(ValueError, match="NaN"):
        PointCloud(np.array([[0.0, np.nan, 0.0]]))
    with pytest.raises(ValueError, match=r"\(n, 3\)"):
        PointCloud(np.zeros((4, 4)))
    with pytest.raises(ValueError, match="origin"):
        PointCloud(np.zeros((4, 2)), origin=np.zeros(3))
    with pytest.raises(ValueError, match="rigid"):
        SimulatedDepthCamera(trimesh.creation.box(), PinholeCamera.kinect_v2(), 2 * np.eye(4))
    with pytest.raises(ValueError, match="focal"):
        PinholeCamera(10, 10, 0.0, 1.0, 5, 5)


# ------------------------------------------------------------------ several views
EYE2 = np.array([0.5, 0.8, 0.9])                 # the mirror of EYE across the sphere's x-z plane


def test_a_merged_capture_puts_each_views_free_space_on_its_own_rays():
    a = sphere_camera().capture()
    mesh = trimesh.creation.icosphere(subdivisions=5, radius=R)
    mesh.apply_translation(C)
    b = SimulatedDepthCamera(mesh, PinholeCamera.kinect_v2(0.5), look_at(EYE2, C)).capture()
    merged = PointCloud.merge([a, b])
    assert merged.per_point_origins and len(merged) == len(a) + len(b)
    free = merged.free_space(0.05)
    # each free point lies on the segment from its own camera to its seen point, 5 cm in front of the sphere
    origins = np.concatenate([np.broadcast_to(EYE, a.points.shape), np.broadcast_to(EYE2, b.points.shape)])
    ray = origins - merged.points
    expected = merged.points + 0.05 * ray / np.linalg.norm(ray, axis=1, keepdims=True)
    np.testing.assert_allclose(free, expected, atol=1e-12)
    assert (np.linalg.norm(free - C, axis=1) > R + 0.01).all()
    # the merged rays to ONE origin (a single-origin cloud of both views) would pass through the sphere for the
    # second view's points: the very error per-point origins remove
    wrong = PointCloud(merged.points, EYE).free_space(0.05)
    assert (np.linalg.norm(wrong - C, axis=1) < R).sum() > 0.3 * len(b)
    # both hemispheres seen: the far side's points are the second view's
    assert ((b.points - C) @ (EYE2 - C) > 0).all()


def test_a_merged_capture_crops_averages_and_skips_free_space_per_view():
    a = PointCloud(np.array([[0.01, 0.01, 0.01], [0.02, 0.02, 0.02], [0.3, 0.0, 0.0]]), np.array([0.0, 0.0, 1.0]))
    b = PointCloud(np.array([[0.011, 0.011, 0.011], [0.4, 0.0, 0.0]]))        # a capture without camera origin
    m = PointCloud.merge([a, b])
    assert np.isnan(m.origin[3:]).all() and m.sees_free_space
    # free space only for the first view's three points
    assert len(m.free_space(0.05)) == 3
    # voxel averaging keeps the views apart: view a's two near points average, view b's near point stays itself
    avg = m.voxel_averaged(0.05)
    assert len(avg) == 4 and avg.origin.shape == (4, 3)
    near = avg.points[np.linalg.norm(avg.points, axis=1) < 0.1]
    np.testing.assert_allclose(sorted(near[:, 0]), [0.011, 0.015], atol=1e-15)
    cropped = m.cropped([0, 0, 0], [0.1, 0.1, 0.1])     # a: two points; b: one
    assert len(cropped) == 3 and cropped.origin.shape == (3, 3)
    assert len(cropped.free_space(0.05)) == 2
    with pytest.raises(ValueError, match="no point clouds"):
        PointCloud.merge([])
    with pytest.raises(ValueError, match="mix dimensions"):
        PointCloud.merge([a, PointCloud(np.zeros((1, 2)))])
    with pytest.raises(ValueError, match="per-point origins"):
        PointCloud(np.zeros((3, 3)), np.zeros((2, 3)))
    with pytest.raises(ValueError, match="all NaN"):
        PointCloud(np.zeros((1, 3)), np.array([[0.0, np.nan, 1.0]]))
    with pytest.raises(ValueError, match="free_space"):
        PointCloud.merge([b, b]).free_space(0.05)


def test_a_multi_view_source_draws_each_views_noise_from_the_seed():
    from torch_gpioius.sensors import MultiViewSource

    mesh = trimesh.creation.icosphere(subdivisions=5, radius=R)
    mesh.apply_translation(C)
    cams = [
        SimulatedDepthCamera(mesh, PinholeCamera.kinect_v2(0.25), look_at(e, C), noise_a=0.002) for e in (EYE, EYE2)
    ]
    src = MultiViewSource(cams, ("left", "right"))
    one, two, again = src.reseeded(1).capture(), src.reseeded(2).capture(), src.reseeded(1).capture()
    np.testing.assert_array_equal(one.points, again.points)
    assert one.points.shape == two.points.shape and not np.allclose(one.points, two.points)
    # the two views of one seed draw different noise (not one stream replayed on both)
    n = len(cams[0].capture())
    assert not np.allclose(np.linalg.norm(one.points[:n] - C, axis=1)[:50],
                           np.linalg.norm(one.points[n:] - C, axis=1)[:50])
    with pytest.raises(ValueError, match="at least one view"):
        MultiViewSource([])
    with pytest.raises(ValueError, match="not a PointCloudSource"):
        MultiViewSource([cams[0], "camera"])
    with pytest.raises(ValueError, match="names"):
        MultiViewSource(cams, ("one",))


def _rays_of(cloud: PointCloud, origin) -> np.ndarray:
    ray = cloud.points - origin
    return ray / np.linalg.norm(ray, axis=1, keepdims=True)


def test_smoothing_along_the_rays_leaves_a_noise_free_plane_and_step_where_they_are():
    # a tilted plane, and a square 5 cm in front of it, seen obliquely: the inverse depth is affine in the image
    # coordinates on each plane, so the fit is exact wherever most of a ray's neighbours lie on its own plane
    u, v = np.meshgrid(np.linspace(-0.15, 0.15, 80), np.linspace(-0.15, 0.15, 80))
    far = np.c_[u.ravel(), v.ravel(), 0.3 * u.ravel() + 0.1 * v.ravel()]
    eye = np.array([0.2, -0.3, 1.0])
    ray = far - eye                          # the rays through the far plane's grid, first met by the square
    normal = np.array([-0.3, -0.1, 1.0])                 # both planes': n . p = 0 (far) and 0.05 (near)
    t = (0.05 - eye @ normal) / (ray @ normal)
    hit = eye + t[:, None] * ray
    square = (np.abs(hit[:, 0]) < 0.05) & (np.abs(hit[:, 1]) < 0.05)
    cloud = PointCloud(np.where(square[:, None], hit, far), eye)
    assert 0.05 < square.mean() < 0.2
    moved = np.linalg.norm(cloud.smoothed_along_rays().points - cloud.points, axis=1)
    assert (moved < 1e-9).mean() > 0.98
    assert moved.max() < 0.05 * 1.2                      # a corner's ray at worst lands on the other plane


def test_smoothing_along_the_rays_averages_the_depth_noise_and_keeps_each_point_on_its_ray():
    noisy = sphere_camera(noise_a=0.005, noise_b=0.0, seed=4).capture()
    smooth = noisy.smoothed_along_rays(24)
    np.testing.assert_allclose(_rays_of(smooth, EYE), _rays_of(noisy, EYE), atol=1e-12)   # the same pixels' rays
    off_noisy = np.linalg.norm(noisy.points - C, axis=1) - R
    off_smooth = np.linalg.norm(smooth.points - C, axis=1) - R
    # a 24-ray fit averages independent noise by about sqrt(24 / 3) = 2.8 (three coefficients per fit); the rim,
    # where a ray grazes the sphere, is fitted worse: judged on the rays within 60 degrees of the sphere's normal
    facing = ((noisy.points - C) @ (EYE - C) / R / np.linalg.norm(EYE - C)) > 0.6
    assert np.std(off_smooth[facing]) < np.std(off_noisy[facing]) / 2.2
    # a plane fitted to a curved patch: a 2 cm patch on a 10 cm sphere sags by 0.5 mm, well under the noise
    assert abs(np.median(off_smooth[facing])) < 1e-3
    # voxel means of the noisy surface spread behind it (noise pushed into the voxels in front of and behind it);
    # those of the smoothed one stay within the curvature's sag and the remaining noise
    inside_noisy = R - np.linalg.norm(noisy.voxel_averaged(0.02).points - C, axis=1)
    inside_smooth = R - np.linalg.norm(smooth.voxel_averaged(0.02).points - C, axis=1)
    assert inside_noisy.max() > 0.006 and inside_smooth.max() < 0.004


def test_smoothing_along_the_rays_fits_each_view_of_a_merged_capture_apart():
    mesh = trimesh.creation.icosphere(subdivisions=5, radius=R)
    mesh.apply_translation(C)
    a = sphere_camera(noise_a=0.004, seed=1).capture()
    b = SimulatedDepthCamera(mesh, PinholeCamera.kinect_v2(0.5), look_at(EYE2, C), noise_a=0.004, seed=2).capture()
    unknown = PointCloud(b.points[:50].copy())                   # a view whose camera is unknown stays as it is
    merged = PointCloud.merge([a, b, unknown])
    smooth = merged.smoothed_along_rays(16)
    n_a, n_b = len(a), len(b)
    np.testing.assert_allclose(smooth.points[:n_a], a.smoothed_along_rays(16).points, atol=1e-12)
    np.testing.assert_allclose(smooth.points[n_a:n_a + n_b], b.smoothed_along_rays(16).points, atol=1e-12)
    np.testing.assert_array_equal(smooth.points[n_a + n_b:], unknown.points)
    np.testing.assert_array_equal(smooth.origin, merged.origin, strict=False)
    assert unknown.smoothed_along_rays() is unknown                 # no camera: nothing to smooth along
    for bad in (7, 2.5, True, 20_000):
        with pytest.raises(ValueError, match="neighbours"):
            a.smoothed_along_rays(bad)


def test_smoothing_along_the_rays_leaves_rays_outside_a_cameras_view_as_measured():
    # a camera inside its cloud (a user's origin mistake): rays in every direction, which no image plane holds
    rng = np.random.default_rng(0)
    d = rng.normal(size=(3000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    centre = np.array([0.5, 0.0, 0.25])
    cloud = PointCloud(centre + d * (0.1 + rng.normal(0, 0.002, (3000, 1))), centre + [0.0, 0.0, 0.01])
    smooth = cloud.smoothed_along_rays()
    moved = np.linalg.norm(smooth.points - cloud.points, axis=1)
    assert moved.max() < 0.01                       # none thrown along its ray: each at most a tenth of its depth
    np.testing.assert_allclose(_rays_of(smooth, cloud.origin), _rays_of(cloud, cloud.origin), atol=1e-12)
    axis = (cloud.points - cloud.origin).sum(axis=0)             # the view's axis: its rays' sum
    wide = _rays_of(cloud, cloud.origin) @ (axis / np.linalg.norm(axis)) <= 0.5
    assert wide.sum() > 1000 and (moved[wide] == 0).all()
