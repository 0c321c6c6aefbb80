"""The force-field world's support plane: nothing passes the table the object stands on (issue 33, item 7)."""

import numpy as np
import pytest
import torch

from torch_gpioius.exploration.contact import ContactConfig, ContactController
from torch_gpioius.sim.forcefield import Scene3D, sphere_scene
from torch_gpioius.testing import WorldContract


def _beside_and_down(scene):
    """Move the fingertip 20 cm to the side of the sphere, then approach straight down for 50 cm."""
    hw = scene.hardware()
    for _ in range(2):
        hw.controller.lift(torch.tensor([-1.0, 0.0, 0.0]), step=0.002, extra=0.1, max_distance=0.1)
    return hw, hw.controller.approach(torch.tensor([0.0, 0.0, -1.0]), max_travel=0.5)


def test_the_fingertip_stops_on_the_table_the_sphere_stands_on():
    scene = sphere_scene()
    table = 0.25 - 0.08
    assert scene.support == pytest.approx(table, abs=1e-3)         # the icosphere's lowest vertex
    hw, down = _beside_and_down(scene)
    assert not down.in_contact                                     # no force: the table is no contact
    z = down.path[:, 2].numpy()
    assert z.min() >= scene.support - 1e-9 and z.min() == pytest.approx(scene.support, abs=1e-9)
    assert float(hw.robot.tool_position()[2]) >= scene.support - 1e-9


def test_without_a_table_the_same_move_passes_under_the_object_until_the_gate_stops_it():
    s = sphere_scene()
    bare = Scene3D(s.inner, s.outer, s.start, s.direction, s.range, support=None)
    from kinematics import SafetyViolation

    with pytest.raises(SafetyViolation, match="workspace"):
        _beside_and_down(bare)


def test_bad_supports_are_refused():
    s = sphere_scene()
    for bad in (s.support + 0.01, "table", float("nan"), True):
        with pytest.raises(ValueError, match="support"):
            Scene3D(s.inner, s.outer, s.start, s.direction, s.range, support=bad)
    with pytest.raises(ValueError, match="ContactConfig.floor"):
        ContactConfig(floor=float("inf"))
    low = Scene3D(s.inner, s.outer, s.start, s.direction, s.range, support=s.support - 0.02)
    assert low.fingerprint() != s.fingerprint()


def test_the_floor_keeps_a_round_fingertip_above_the_table():
    class Robot:
        def __init__(self):
            self.p = torch.tensor([0.0, 0.0, 0.1], dtype=torch.float64)

        def read_pose(self):
            T = torch.eye(4, dtype=torch.float64)
            T[:3, 3] = self.p
            return T

        def move_cartesian(self, dx, speed):
            self.p = self.p + dx

    ctl = ContactController(Robot(), sensor=None, config=ContactConfig(floor=0.05, tip_radius=0.01))
    assert torch.allclose(ctl._above_floor(torch.tensor([0.01, 0.0, -0.1], dtype=torch.float64)),
                          torch.tensor([0.01, 0.0, -0.04], dtype=torch.float64))
    up = torch.tensor([0.0, 0.02, 0.01], dtype=torch.float64)
    assert torch.equal(ctl._above_floor(up), up)



# ------------------------------------------------------------------ views
def _views_scene(views):
    s = sphere_scene()
    return Scene3D(s.inner, s.outer, s.start, s.direction, s.range, name="sphere", views=views)


def test_more_views_see_more_of_the_cover_and_each_point_lies_on_it():
    from torch_gpioius.sensors import MultiViewSource
    from torch_gpioius.sim.meshes import MeshDistance

    one, three = _views_scene("paper"), _views_scene(3)
    assert one.views == ("fixed",) and three.views == ("fixed", "mirrored", "wrist")
    assert isinstance(three.camera, MultiViewSource) and three.camera.names == three.views
    a, b = one.camera.capture(), three.camera.capture()
    assert not a.per_point_origins and b.per_point_origins
    outer = MeshDistance(three.outer, signed=False)
    # the seen points lie on the cover, to the depth noise (the Kinect's sigma is 3.5-4.5 mm at 1.1-1.4 m)
    off = np.abs(np.asarray(outer(b.points)))
    assert np.median(off) < 0.004 and np.quantile(off, 0.99) < 0.015
    # the share of the cover's upper half within 1 cm of a seen point: the mirrored and wrist views add the far side
    # and the top that the fixed camera misses
    from scipy.spatial import cKDTree

    c = np.array([0.5, 0.0, 0.25])
    np.random.seed(0)
    samples = three.outer.sample(20000)
    upper = samples[samples[:, 2] > c[2]]
    seen = lambda cloud: float((cKDTree(cloud.points).query(upper)[0] < 0.01).mean())  # noqa: E731
    assert seen(a) < 0.87 and seen(b) > 0.93        # measured: 0.83 and 0.96
    # the wrist view looks along the approach from 35 cm before the first contact
    wrist = three.wrist_camera()
    np.testing.assert_allclose(wrist.origin, three.first_contact() - 0.35 * three.direction, atol=1e-12)


def test_a_seeded_scene_reseeds_every_view_and_keeps_the_views():
    s = _views_scene(2)
    p1, p2 = s.perturbed(1), s.perturbed(2)
    assert p1.views == ("fixed", "mirrored")
    c1, c1b, c2 = p1.camera.capture(), s.perturbed(1).camera.capture(), p2.camera.capture()
    np.testing.assert_array_equal(c1.points, c1b.points)
    # another seed moves the approach and redraws the noise (the capture differs)
    assert c1.points.shape != c2.points.shape or not np.allclose(c1.points, c2.points)
    # the tripods stay where they stood for the unperturbed approach, the wrist follows the perturbed one, whether or
    # not the camera was built before the scene was perturbed
    fixed = [v.origin for v in _views_scene(3).camera.sources]
    cached = _views_scene(3)
    cached.camera                                                   # built (and cached) before the perturbation
    for base in (_views_scene(3), cached):
        moved = base.perturbed(2)
        np.testing.assert_allclose([v.origin for v in moved.camera.sources[:2]], fixed[:2], atol=0)
        np.testing.assert_allclose(moved.camera.sources[2].origin, moved.first_contact() - 0.35 * moved.direction,
                                   atol=1e-12)
        assert np.linalg.norm(moved.direction - base.direction) > 1e-3
    plain = sphere_scene()
    np.testing.assert_allclose(plain.perturbed(2).camera.origin, plain.camera.origin, atol=0)
    # a user's camera of another kind is reseeded too (it was kept with the same noise on every seed)
    from torch_gpioius.sensors import MultiViewSource

    given = MultiViewSource([s.default_camera(), s.default_camera(side=-1.0)])
    t = Scene3D(s.inner, s.outer, s.start, s.direction, s.range, camera=given)
    assert not np.allclose(t.perturbed(1).camera.capture().points[:100], t.perturbed(2).camera.capture().points[:100])
    # the fingerprint tells views apart, and the paper's single view hashes as before
    assert s.fingerprint() != _views_scene(1).fingerprint()
    assert _views_scene(1).fingerprint() == sphere_scene().fingerprint()


@pytest.mark.parametrize("bad", [0, 4, "top", ("fixed", "fixed"), (), 1.5, None])
def test_unknown_views_are_refused(bad):
    with pytest.raises(ValueError, match="views"):
        _views_scene(bad)


def test_the_default_kernel_makes_no_phantom_surface_away_from_the_body():
    """Object E seen by the three default views with one touch: the zero set of the inner estimate in the range
    (grown by 5 cm) lies within 5 cm of the body everywhere with the default Matérn-5/2, and no more than a few
    percent of it beyond 4 cm, where the range's lower face cuts the body's flanks (measured: 1.5 % beyond 4 cm, 4.2 cm
    at most; with the camera's voxels chosen by the measured depths 0 % and 3.8 cm); the paper's inverse multiquadric
    on the same data leaves ten times that share further out (16.8 %, up to 7.3 cm; 10.4 % and 5.4 cm): pieces of
    surface where there is none, from its heavy tails (k ~ 1/r)."""
    from torch_gpioius.exploration.observations import vision_observations
    from torch_gpioius.exploration.registry import make_world
    from torch_gpioius.kernels import Matern52
    from torch_gpioius.sim.forcefield import object_defaults
    from torch_gpioius.sim.meshes import MeshDistance
    from torch_gpioius.geometry.surfaces import evaluate_grid, zero_level_mesh
    import torch_gpioius as tg

    e = make_world("forcefield", "E", 0)
    s = Scene3D(e.inner, e.outer, e.start, e.direction, e.range, views=3)
    defaults = object_defaults(s.inner)
    assert isinstance(defaults.kernel, Matern52) and defaults.kernel.ell == 0.1
    crop = np.stack([s.range[0] - 0.15, s.range[1] + 0.15])
    xo, yo = vision_observations(s.camera.capture(), defaults.policy, crop)
    x, y = np.r_[s.first_contact()[None], xo], np.r_[0.0, yo]
    task = np.r_[0, np.ones(len(xo), dtype=int)]
    body = MeshDistance(s.inner, signed=False)
    box = np.stack([s.range[0] - 0.05, s.range[1] + 0.05])
    far, furthest = {}, {}
    for name, kw in (
        ("default", dict(kernel=defaults.kernel)),
        ("imq", dict(kernel=tg.kernels.InverseMultiquadricKernel(0.15))),
    ):
        model = tg.GPIOIS(x, y, task, noise=defaults.noise, **kw).fit()
        mesh = zero_level_mesh(model, None, field=evaluate_grid(model, box, 0.01, 0, variance=False))
        distance = np.asarray(body(mesh.vertices))
        far[name], furthest[name] = float((distance > 0.04).mean()), float(distance.max())
    assert far["default"] < 0.05 and furthest["default"] < 0.05
    # the check can fail: the heavy-tailed kernel does make phantoms here
    assert far["imq"] > 3 * far["default"] + 0.05 and furthest["imq"] > 0.06


def test_every_hardware_of_a_scene_sees_the_same_noisy_cloud():
    """The camera's noise starts from the scene's seed for each hardware, as the force sensor's does: one camera shared
    by every hardware of a scene carried its noise from one run to the next, so a second exploration of the same
    seed-0 world in one process saw another cloud and ended 1-4 cm away."""
    from torch_gpioius.exploration.registry import make_world

    world = make_world("forcefield", "E", 0, smoke=True)
    first, second = world.hardware(), world.hardware()
    a = first.camera.capture().points
    assert np.array_equal(a, second.camera.capture().points)
    again = first.camera.capture().points                 # the noise is real: the next capture draws anew
    assert a.shape != again.shape or not np.array_equal(a, again)


def test_a_scene_takes_a_users_settings_and_back():
    """``with_settings``: the same bodies, approach and range; the defaults and views of the setting, kept by a seed's
    perturbation; and the studies build E-H that way."""

    from torch_gpioius.kernels import Matern52
    from torch_gpioius.sim.forcefield import ROBOT_STUDY_DEFAULTS, VIEWS, object_defaults
    from torch_gpioius.studies.study import make_world

    paper = sphere_scene(radius=0.08, cover=0.01)
    mine = paper.with_settings("default")
    assert mine.views == VIEWS and paper.views != mine.views
    assert mine.inner is paper.inner and mine.outer is paper.outer
    np.testing.assert_array_equal(mine.start, paper.start)
    np.testing.assert_array_equal(mine.range, paper.range)
    assert mine.defaults.policy == object_defaults(paper.inner).policy
    assert isinstance(mine.defaults.kernel, Matern52) and mine.defaults.policy.touch_inside == 0.02
    back = mine.with_settings("paper")
    assert back.defaults == ROBOT_STUDY_DEFAULTS and back.views == paper.views
    seeded = mine.perturbed(2)
    assert seeded.views == VIEWS and seeded.defaults is mine.defaults
    assert len(seeded.camera.capture().points) > len(paper.perturbed(2).camera.capture().points)
    with pytest.raises(ValueError, match="settings"):
        paper.with_settings("mine")
    own = Scene3D(paper.inner, paper.outer, paper.start, paper.direction, paper.range, camera=paper.camera)
    with pytest.raises(ValueError, match="camera of its own"):
        own.with_settings("default")
    # a study of E under the user's defaults: the object's geometry and seed, the defaults' settings
    e = make_world("forcefield", "E", 1, settings="default")
    e_paper = make_world("forcefield", "E", 1)
    np.testing.assert_array_equal(e.start, e_paper.start)
    assert e.seed == e_paper.seed == 1 and e.views == VIEWS
    assert e.defaults.estimator_changed(kernel=Matern52()) != e_paper.defaults.estimator_changed(kernel=Matern52())
    # with_views: the same scene and settings under other views; a seed's tripods stay where they stood
    alone = seeded.with_views(1)
    assert alone.views == ("fixed",) and alone.defaults is seeded.defaults and alone.seed == 2
    np.testing.assert_array_equal(alone.start, seeded.start)
    np.testing.assert_allclose(alone.cameras(("fixed",)).T_base_camera,
                               seeded.cameras(VIEWS).sources[0].T_base_camera)
    assert len(alone.camera.capture().points) < len(seeded.camera.capture().points)
    e_one = make_world("forcefield", "E", 1, settings="default", views=("fixed", "wrist"))
    assert e_one.views == ("fixed", "wrist") and e_one.defaults.kernel.describe() == e.defaults.kernel.describe()
    assert e_one.defaults.estimator_changed(kernel=Matern52()) == e.defaults.estimator_changed(kernel=Matern52())
    with pytest.raises(ValueError, match="views"):
        paper.with_views(("fixed", "fixed"))
    with pytest.raises(ValueError, match="camera of its own"):
        own.with_views(1)


def _standing_at(mesh, at):
    lo, hi = mesh.bounds
    mesh.apply_translation(np.asarray(at) - [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])
    return mesh


def gabled_carton(fin: float = 0.0, width: float = 0.066, height: float = 0.24, roof: float = 0.03):
    """A milk carton standing at (0.5, 0, 0) [m]: a square box with a gabled top, and on its ridge a sealed fin
    ``fin`` thick [m] and 1 cm tall (none when 0), united exactly (manifold3d)."""
    import trimesh

    body = height - roof - (0.01 if fin else 0.0)
    corners = [[x, y, z] for x in (-width / 2, width / 2) for y in (-width / 2, width / 2) for z in (0.0, body)]
    mesh = trimesh.convex.convex_hull(np.array(corners + [[x, 0.0, body + roof] for x in (-width / 2, width / 2)]))
    if fin:
        pytest.importorskip("manifold3d")
        plate = trimesh.creation.box([width, fin, 0.012])
        plate.apply_translation([0.0, 0.0, body + roof + 0.004])
        mesh = trimesh.boolean.union([mesh, plate], engine="manifold")
    mesh.apply_translation([0.5, 0.0, 0.0])
    return mesh


@pytest.mark.parametrize("body, kind, gap", [
    ("cylinder", "tight", 0.008),          # radius 0.04993, height 0.14943, 43 sections at (0.5034, 0.0043, 0.1681)
    ("box", "tight", 0.008),               # 0.13 x 0.085 x 0.16 at (0.5, 0, 0.1)
    ("carton", "loose", 0.01),             # 6.6 x 6.6 x 24 cm under loose covers of 1 and 4 cm
    ("carton", "loose", 0.04),
    ("gabled", "loose", 0.01),             # the same carton with a gabled top (issue 60, item 20)
    ("gabled", "loose", 0.04),
    ("finned", "loose", 0.01),             # ... and a sealed fin 1 mm thick on its ridge
    ("finned", "loose", 0.04),
    ("finned", "tight", 0.008),
])
def test_covers_close_on_the_simple_bodies_that_failed(body, kind, gap):
    """Issue 51, item 19: "the cover mesh is not closed" on a cylinder, a box and a carton; a level set through
    grid nodes gave marching cubes zero-area triangles. Issue 60, item 20: a gabled carton 24 cm tall under a loose
    cover: on its 3 mm grid the 3 cm bridge is ten cells, the distance transform's values meet the level exactly, and
    no shifted grid helped. Each closes now on its first grid, with a volume between the body's and the box grown by
    the gap."""
    import warnings

    import trimesh

    from torch_gpioius.sim.forcefield import cover_around

    if body in ("gabled", "finned"):
        mesh = gabled_carton(fin=0.001 if body == "finned" else 0.0)
    elif body == "cylinder":
        mesh = trimesh.creation.cylinder(radius=0.04993, height=0.14943, sections=43)
        mesh.apply_translation([0.5034, 0.0043, 0.1681])
    elif body == "box":
        mesh = _standing_at(trimesh.creation.box([0.13, 0.085, 0.16]), [0.5, 0.0, 0.1])
    else:
        mesh = _standing_at(trimesh.creation.box([0.066, 0.066, 0.24]), [0.5, 0.0, 0.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")                    # closed on the first grid, nothing filled
        cover = cover_around(mesh, kind, gap=gap)
    assert cover.is_watertight and cover.volume > mesh.volume
    assert cover.volume <= np.prod(mesh.extents + 2 * gap + 0.01)


def test_covers_close_on_random_primitives():
    """Issue 51, item 19: a sweep of 61 random primitives hit one cover that did not close. A sample of the seeded
    family (every kind, under a tight and a loose cover; `scripts/cover_sweep.py` runs hundreds) closes on every
    one, each a bounded distance off its body."""
    from torch_gpioius.sim.forcefield import cover_around
    from torch_gpioius.sim.meshes import MeshDistance
    from torch_gpioius.sim.objectsets import primitive_mesh

    rng = np.random.default_rng(51)
    for i in rng.choice(1000, 10, replace=False):
        mesh, kind = primitive_mesh(int(i))
        mesh.apply_translation([0.5, 0.0, 0.1] + rng.uniform(-0.01, 0.01, 3))
        for cover_kind, gap in (("tight", 0.008), ("loose", 0.01)):
            cover = cover_around(mesh, cover_kind, gap=gap, resolution=0.004)
            assert cover.is_watertight, (i, kind, cover_kind)
            d = MeshDistance(mesh)(cover.vertices[:: max(1, len(cover.vertices) // 500)])
            assert d.min() > gap - 0.004 and (cover_kind == "loose" or d.max() < gap + 0.004), (i, kind)


def test_a_grid_too_fine_is_refused_before_it_is_allocated():
    """Issue 51, item 16: `object.resolution = 2e-4` took 4.5 GB, then died with a raw _ArrayMemoryError."""
    import trimesh

    from torch_gpioius.sim.forcefield import cover_around
    from torch_gpioius.sim.meshes import repair_mesh

    box = trimesh.creation.box([0.13, 0.085, 0.16])
    with pytest.raises(ValueError, match=r"resolution: 0.2 mm over the cover's grid .* grid nodes .*GB.*use .* mm"):
        cover_around(box, "tight", resolution=2e-4)
    with pytest.raises(ValueError, match=r"resolution: 0.2 mm over the repair's grid"):
        repair_mesh(box, 2e-4, remesh=True)


def test_the_cover_of_a_remeshed_teddy_closes_and_its_far_corners_lie_outside():
    """A teddy (pybullet's convex pieces, united and decimated by the loader) scaled to 14.2 cm: the pseudo-normal
    sign of the body's distance flipped at slivers, so the corners of the cover's grid read "inside" and the cover
    came out open on every shifted grid. The winding number decides where the offset is off a face's normal."""
    pytest.importorskip("pybullet_data")
    from pathlib import Path

    from torch_gpioius.sim.forcefield import cover_around, place
    from torch_gpioius.sim.meshes import MeshDistance, load_mesh
    from torch_gpioius.sim.scenefile import resolve_mesh

    body = load_mesh(resolve_mesh("pybullet:teddy2_VHACD_CHs.obj", Path(".")))
    body.apply_scale(0.1419 / float(np.max(body.extents)))
    body = place(body, [0.5, 0.0, 0.1])
    lo, hi = body.bounds[0] - 0.03, body.bounds[1] + 0.03
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    assert (MeshDistance(body)(corners) > 0).all()
    cover = cover_around(body, "tight", gap=0.008)
    assert cover.is_watertight and cover.volume > body.volume


class TestForceFieldWorldContract(WorldContract):
    """The force-field world keeps the contract users' worlds are tested against (torch_gpioius.testing)."""

    def make(self):
        from torch_gpioius.exploration import make_world

        return make_world("forcefield", "E", smoke=True)


def test_a_few_holes_of_less_than_a_cell_are_filled_and_a_real_hole_is_not():
    """The cover's last resort before a finer grid: a few degenerate triangles' holes are filled; a hole larger than
    two cells is a defect and stays open."""
    import trimesh

    from torch_gpioius.sim.forcefield import _fill_small_holes

    sphere = trimesh.creation.icosphere(4, 0.05)
    h = float(sphere.edges_unique_length.max())
    small = sphere.copy()
    small.update_faces(np.arange(len(small.faces)) != 7)
    assert not small.is_watertight and _fill_small_holes(small, h) and small.is_watertight
    big = sphere.copy()
    big.update_faces(np.linalg.norm(big.triangles_center - [0, 0, 0.05], axis=1) > 0.02)
    assert not _fill_small_holes(big, h) and not big.is_watertight


def _ball_on_table(radius=0.05):
    import trimesh

    ball = trimesh.creation.icosphere(subdivisions=4, radius=radius)
    ball.apply_translation([0.5, 0.0, radius])
    return ball, np.array([0.5, 0.0, radius])


def test_an_uneven_cover_grows_from_its_thin_side_to_its_thick_side():
    """Issue 62: the uneven cover is the level set {d = g(x)} with g linear in y over the body, 5 mm on its -y
    extreme to 5 cm on its +y one. On a ball d = |x - c| - R in closed form: every vertex's d equals its own g within
    the marching cubes' error, and the thin and thick sides stand off by the two gaps."""
    from torch_gpioius.sim.forcefield import cover_around

    radius, h = 0.05, 0.002
    ball, centre = _ball_on_table(radius)
    cover = cover_around(ball, "uneven", gap=0.005, gap_far=0.05, resolution=h)
    assert cover.is_watertight and len(cover.split(only_watertight=False)) == 1
    v = cover.vertices
    d = np.linalg.norm(v - centre, axis=1) - radius        # the icosphere's facets lie within 0.1 mm of the ball
    g = 0.005 + 0.045 * np.clip((v[:, 1] - centre[1] + radius) / (2 * radius), 0.0, 1.0)
    assert np.abs(d - g).max() < h / 2
    assert abs(v[:, 1].min() - (centre[1] - radius - 0.005)) < h / 2
    assert abs(v[:, 1].max() - (centre[1] + radius + 0.05)) < h / 2
    # the thick side turned to +x
    turned = cover_around(ball, "uneven", gap=0.005, gap_far=0.05, resolution=h, thick_side=(1.0, 0.0, 0.3))
    assert abs(turned.vertices[:, 0].max() - (centre[0] + radius + 0.05)) < h / 2


def test_a_hanging_cover_lies_on_the_top_and_falls_straight_to_the_table():
    """Issue 62: a ball on the table under a hanging cover: above its equator the cover is the ball grown by the
    gap; below it, a vertical cylinder of that radius down to the table (the gap below the body's lowest point),
    so the gap grows from 5 mm at the equator to the radius at the table."""
    from torch_gpioius.sim.forcefield import cover_around

    radius, gap, h = 0.05, 0.005, 0.002
    ball, centre = _ball_on_table(radius)
    cover = cover_around(ball, "hanging", gap=gap, resolution=h)
    # one closed layer: no bubbles where the loose cover's level met a node exactly (they were, before the set
    # the cover hangs from was taken as marching cubes takes it)
    assert cover.is_watertight and len(cover.split(only_watertight=False)) == 1
    v = cover.vertices - centre
    top = v[:, 2] > 2 * h
    side = (v[:, 2] < -h) & (v[:, 2] > -radius + 2 * h)
    assert top.sum() > 100 and side.sum() > 100
    # the top: the loose cover (a ball needs no bridge: within a spacing of the level set, as the closing's distance
    # transform is); the hanging side: from the grid's distance transform
    assert np.abs(np.linalg.norm(v[top], axis=1) - (radius + gap)).max() < h
    off = np.linalg.norm(v[side, :2], axis=1) - (radius + gap)
    assert np.abs(off).max() < 1.25 * h and np.median(np.abs(off)) < h / 2
    assert abs(cover.bounds[0, 2] - (ball.bounds[0, 2] - gap)) < h


def test_uneven_covers_that_cannot_be_built_are_refused():
    from torch_gpioius.sim.forcefield import cover_around

    ball, _ = _ball_on_table(0.05)
    with pytest.raises(ValueError, match="kind: must be one of"):
        cover_around(ball, "draped")
    with pytest.raises(ValueError, match="gap_far: the thick side's gap"):
        cover_around(ball, "uneven", gap=0.02, gap_far=0.01)
    # 14.5 cm more over a 10 cm body would fold the layer: it grows at half a metre a metre instead, and says so
    with pytest.warns(RuntimeWarning, match="grows at most 0.5 m a metre.* reaches 5.5 cm, not 15 cm"):
        steep = cover_around(ball, "uneven", gap=0.005, gap_far=0.15, resolution=0.002)
    assert abs(steep.vertices[:, 1].max() - (0.05 + 0.055)) < 0.001
    with pytest.raises(ValueError, match="thick_side: must be a finite 3-vector with a horizontal part"):
        cover_around(ball, "uneven", thick_side=(0.0, 0.0, 1.0))


@pytest.mark.parametrize("cover, index, widest", [("uneven", 7, 0.03), ("hanging", 3, 0.012)])
def test_a_set_object_under_a_varying_cover_builds_a_scene_whose_gap_varies(cover, index, widest):
    """The object sets' uneven and hanging covers build a scene (cover, approach, range) whose cover-body gap spans
    from about 5 mm to centimetres: 5 cm on the uneven cover's thick side (a cylinder), and where a standing
    capsule's rounded bottom curves in under the cloth hanging from its widest part."""
    import warnings

    from torch_gpioius.sim.meshes import MeshDistance
    from torch_gpioius.sim.objectsets import object_set, set_scene

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = set_scene(object_set(f"primitives:{index}")[0], cover)
    gaps = MeshDistance(scene.inner)(scene.outer.vertices)
    assert scene.outer.is_watertight
    assert np.quantile(gaps, 0.02) < 0.008 and gaps.max() > widest


def test_a_scene_with_a_camera_error_moves_every_views_capture_by_its_own_draw_and_says_so():
    """Issue 63, item 1: each simulated view of each run (its seed) draws an extrinsic error of the asked sizes; the
    captures carry it, the scene says what each view applied, the error survives a seed's perturbation, changes the
    scene's fingerprint, and a scene with a user's camera refuses it."""
    from torch_gpioius.sensors.simulated.camera import CameraError

    s = sphere_scene().with_views(["fixed", "mirrored", "wrist"])
    off = s.with_camera_error("6mm,1deg")
    assert s.camera_errors() == {} and off.camera_error == CameraError.parse("6mm,1deg")
    errors = off.camera_errors()
    assert set(errors) == {"fixed", "mirrored", "wrist"}
    assert all(e["size_mm"] == pytest.approx(6.0) and e["angle_deg"] == pytest.approx(1.0) for e in errors.values())
    assert len({tuple(e["translation_mm"]) for e in errors.values()}) == 3          # each view its own draw
    # each view's capture is the plain one (the same noise) moved by that view's error about its optical centre
    from torch_gpioius.sensors.simulated.camera import AppliedCameraError

    for name, plain, moved in zip(s.views, s.cameras(s.views).sources, off.cameras(off.views).sources):
        a, b, e = plain.capture(), moved.capture(), errors[name]
        back = AppliedCameraError(tuple(np.asarray(e["translation_mm"]) / 1e3), tuple(np.radians(e["rotation_deg"])))
        np.testing.assert_allclose(b.points, back.apply(a.points, a.origin), atol=1e-6)   # the record's rounding
        np.testing.assert_array_equal(a.origin, b.origin)
    seeded = off.perturbed(2)
    assert seeded.camera_error == off.camera_error and seeded.camera_errors() != errors
    assert off.fingerprint() != s.fingerprint() and s.with_camera_error("0").fingerprint() == s.fingerprint()
    own = Scene3D(s.inner, s.outer, s.start, s.direction, s.range, camera=s.default_camera())
    with pytest.raises(ValueError, match="camera of its own"):
        own.with_camera_error("6mm,1deg")
    with pytest.raises(ValueError, match="not a size with a unit"):
        s.with_camera_error("6")
    # worse sensing alone moves nothing, records no view's draw, and changes the fingerprint beside the extrinsic one
    noisy = s.with_camera_error("3x,20%holes")
    assert noisy.camera_errors() == {} and noisy.camera_error.sensing
    assert len({noisy.fingerprint(), off.fingerprint(), s.fingerprint(),
                s.with_camera_error("6mm,1deg,3x,20%holes").fingerprint()}) == 4


def test_a_body_too_thin_to_be_felt_from_any_side_is_refused_with_its_thickness():
    """Issue 63: six of pybullet's procedural objects 200-299 are pieces of sheets 1-3 mm thick; each was refused
    as "the approach ray only grazes the inner mesh", as if another approach could feel it. A sheet 2 mm thick is
    refused as too thin (nowhere more than 1 mm inside), a slab 2 cm thick is approached."""
    import trimesh

    from torch_gpioius.sim.forcefield import approach_from_above

    sheet = trimesh.creation.box((0.12, 0.10, 0.002))
    sheet.apply_translation([0.5, 0.0, 0.101])
    with pytest.raises(ValueError, match=r"nowhere more than 1\.0 mm inside its surface .* 1 pieces"):
        approach_from_above(sheet, sheet)
    slab = trimesh.creation.box((0.12, 0.10, 0.02))
    slab.apply_translation([0.5, 0.0, 0.11])
    start, direction, _ = approach_from_above(slab, slab)
    assert direction.tolist() == [0.0, 0.0, -1.0] and abs(start[0] - 0.5) < 0.02


def test_a_body_under_a_thin_roof_is_approached_from_the_side():
    """Issue 63 (every object reached): a 6 cm box under a 1 mm sheet wider than it (pybullet's blob 127: every ray
    from above passes a fin 0.4 mm deep first) is approached horizontally, at the box's height, from outside the
    cover, the first passage through the body deep enough to feel; the range reaches to 1 cm short of the start along
    the approach and holds the first contact; a body approached from above keeps its approach and range."""
    import trimesh

    from torch_gpioius.sim.forcefield import Scene3D, approach_from_above, first_passage
    from torch_gpioius.sim.meshes import MeshDistance

    box = trimesh.creation.box((0.06, 0.06, 0.06))
    box.apply_translation([0.5, 0.0, 0.03])
    roof = trimesh.creation.box((0.12, 0.12, 0.001))
    roof.apply_translation([0.5, 0.0, 0.07])
    body = trimesh.util.concatenate([box, roof])
    start, direction, bounds = approach_from_above(body, body)
    assert abs(direction[2]) == 0.0 and np.abs(direction).max() == 1.0
    assert 0.0 < start[2] < 0.06 and (body.bounds[0] - 0.01 > start).any() | (start > body.bounds[1] + 0.01).any()
    passage = first_passage(body, MeshDistance(body), start, direction)
    assert passage is not None and passage[1] >= Scene3D.MIN_APPROACH_DEPTH
    axis = int(np.argmax(np.abs(direction)))
    reach = bounds[1, axis] if direction[axis] < 0 else bounds[0, axis]
    assert reach == pytest.approx(start[axis] + 0.01 * direction[axis])
    hit = start + passage[0] * direction                       # the first contact: on the box's near face
    assert abs(abs(hit[axis] - 0.5) - 0.03) < 1e-9 and ((bounds[0] <= hit) & (hit <= bounds[1])).all()
    slab = trimesh.creation.box((0.12, 0.10, 0.02))
    slab.apply_translation([0.5, 0.0, 0.11])
    s_start, s_dir, s_bounds = approach_from_above(slab, slab)
    assert s_dir.tolist() == [0.0, 0.0, -1.0] and s_bounds[1, 2] == pytest.approx(max(0.12 + 0.03, s_start[2] - 0.01))


def test_a_thick_piece_where_neither_grid_looks_is_approached_at_the_thick_piece():
    """Every object reached: a 1 mm plate with a 1 cm cube on its corner (pybullet's blob 338: its thick piece lies
    beyond the middle 80 % the grids from above and from the sides aim at; refused as "the approach only grazes") is
    approached along an axis through the cube, from outside the cover, deep enough to feel; the range holds the first
    contact."""
    import trimesh

    from torch_gpioius.sim.forcefield import Scene3D, approach_from_above, first_passage
    from torch_gpioius.sim.meshes import MeshDistance

    plate = trimesh.creation.box((0.12, 0.12, 0.001))
    plate.apply_translation([0.5, 0.0, 0.0005])
    cube = trimesh.creation.box((0.01, 0.01, 0.01))
    cube.apply_translation([0.555, 0.055, 0.0055])
    body = trimesh.boolean.union([plate, cube])
    start, direction, bounds = approach_from_above(body, body)
    passage = first_passage(body, MeshDistance(body), start, direction)
    assert passage is not None and passage[1] >= Scene3D.MIN_APPROACH_DEPTH
    hit = start + passage[0] * direction                       # the first contact: on the cube
    assert hit[0] >= 0.55 - 1e-9 and hit[1] >= 0.05 - 1e-9 and ((bounds[0] <= hit) & (hit <= bounds[1])).all()
    assert np.abs(direction).max() == 1.0 and direction[2] <= 0.0


def test_a_slide_off_an_edge_gives_up_after_a_tenth_of_the_seen_body_not_five_centimetres():
    """Issue 63 (every object reached): a slide that runs off an edge presses inward along the old normal, past the
    surface it left, and finds nothing however far it presses. The force-field world's controller searches a tenth of
    the cover's largest extent (1-5 cm), not the controller's 5 cm: on a 20 cm box under an 8 mm cover the slide off
    its top edge ends out of contact having pressed 2.2 cm below the top, where the 5 cm controller presses 5 cm."""
    import trimesh

    from torch_gpioius.sim.forcefield import LOST_CONTACT_SEARCH, cover_around, lost_contact_search

    box = trimesh.creation.box((0.20, 0.20, 0.10))
    box.apply_translation([0.5, 0.0, 0.05])
    outer = cover_around(box, "tight", gap=0.008)
    scene = Scene3D(box, outer, start=(0.5, 0.0, 0.2), direction=(0.0, 0.0, -1.0),
                    bounds=[[0.2, -0.3, 0.0], [0.8, 0.3, 0.3]], support="base")
    search = lost_contact_search(outer)
    fraction, lo, hi = LOST_CONTACT_SEARCH
    assert search == pytest.approx(fraction * float(np.max(outer.extents)), abs=1e-4) and lo < search < hi
    assert search == pytest.approx(0.0216, abs=5e-4)                 # the cover 20 + 2 x 0.8 cm across
    pressed = {}
    for name, config in (("world", None), ("five", ContactConfig(floor=scene.support))):
        hw = scene.hardware()
        if config is not None:
            hw.controller = ContactController(hw.robot, hw.sensor, config)
        assert hw.controller.config.max_normal_travel == (search if config is None else 0.05)
        first = hw.controller.approach(torch.tensor([0.0, 0.0, -1.0]), max_travel=0.3)
        assert first.in_contact
        top = float(first.path[-1, 2])
        for _ in range(6):                                           # 3 cm slides towards the edge, 10 cm away
            r = hw.controller.slide(torch.tensor([0.03, 0.0, 0.0]), torch.tensor([0.0, 0.0, 1.0]))
            if not r.in_contact:
                break
        assert not r.in_contact and float(r.path[-1, 0]) > 0.59      # lost at the edge
        pressed[name] = top - float(r.path[:, 2].min())
    step = ContactConfig().normal_step
    assert pressed["world"] == pytest.approx(search, abs=2 * step)
    assert pressed["five"] == pytest.approx(0.05, abs=2 * step)
    assert lost_contact_search(trimesh.creation.box((0.04, 0.04, 0.04))) == lo          # a small body: 1 cm
    assert lost_contact_search(trimesh.creation.box((0.9, 0.5, 0.5))) == hi             # a torso: the 5 cm
