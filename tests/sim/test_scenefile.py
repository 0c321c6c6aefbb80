"""Your own object: covers built around any mesh against their definition (offset, closing), the default approach,
scene files and every way they can be wrong, and a short exploration of a scanned bottle."""

import warnings

import numpy as np
import pytest
import trimesh

import torch_gpioius as tg
from torch_gpioius.sim.forcefield import Scene3D, approach_from_above, cover_around, place
from torch_gpioius.sim.meshes import MeshDistance, MeshRepairWarning
from torch_gpioius.sim.scenefile import load_scene, read_scene

from tests.scenes import ball_scene

PROFILE = np.array([[0, 0], [30, 0], [30, 100], [26, 115], [12, 135], [12, 160], [0, 160]], dtype=float)


def bottle() -> trimesh.Trimesh:
    m = trimesh.creation.revolve(PROFILE, sections=48)
    m.apply_scale(0.001)
    return place(m, (0.5, 0.0, 0.1))


def test_a_tight_cover_is_the_offset_surface():
    body = bottle()
    outer = cover_around(body, "tight", gap=0.008, resolution=0.003)
    d = MeshDistance(body)(outer.vertices)
    # marching cubes of the exact distance: vertices on the level set to within the grid's interpolation error
    assert np.abs(d - 0.008).max() < 0.003 * 0.5
    assert outer.is_watertight and outer.volume > body.volume


def test_a_loose_cover_bridges_a_gap_narrower_than_twice_its_radius():
    a, b = trimesh.creation.icosphere(3, 0.04), trimesh.creation.icosphere(3, 0.04)
    a.apply_translation((0.5, -0.05, 0.2))
    b.apply_translation((0.5, 0.05, 0.2))
    body = trimesh.util.concatenate([a, b])                       # 2 cm apart at the closest
    tight = cover_around(body, "tight", gap=0.005, resolution=0.003)
    loose = cover_around(body, "loose", gap=0.005, bridge=0.03, resolution=0.003)
    mid = np.array([[0.5, 0.0, 0.2 + 0.02]])                      # between the spheres, above their centres
    assert MeshDistance(tight)(mid)[0] > 0 and MeshDistance(loose)(mid)[0] < 0
    # the closing contains the tight cover, and away from the gap keeps to it (within the grid error)
    assert (MeshDistance(loose)(tight.vertices) <= 0.003).all()
    far = np.array([[0.5, -0.05 - 0.045 - 0.001, 0.2]])             # outside the far side of a sphere
    assert MeshDistance(loose)(far)[0] > 0
    with pytest.raises(ValueError, match="kind"):
        cover_around(body, "foam")
    with pytest.raises(ValueError, match="gap"):
        cover_around(body, "tight", gap=-0.01)


def test_the_default_approach_hits_the_body_from_above():
    mug = trimesh.creation.annulus(0.03, 0.04, 0.1)                # a ring from above: its centre is a hole
    mug = place(mug, (0.5, 0.0, 0.1))
    start, direction, bounds = approach_from_above(mug, mug)
    np.testing.assert_allclose(direction, [0, 0, -1])
    assert mug.ray.intersects_any(start[None], direction[None])[0]
    assert (bounds[0] < mug.bounds[1]).all() and bounds[1, 2] >= start[2] - 0.01


def test_the_default_approach_passes_a_thin_lip_by_for_a_ray_that_is_felt():
    """A thin fin (2 mm) standing above the middle of a box: the ray through the centre passes along the fin without
    ever being 3 mm inside it, so the approach takes the nearest ray whose first passage is deep enough (the box's
    top), and the scene's first contact is felt."""
    from torch_gpioius.sim.forcefield import first_passage
    from torch_gpioius.sim.meshes import MeshDistance

    box = trimesh.creation.box((0.12, 0.10, 0.06))
    fin = trimesh.creation.box((0.002, 0.08, 0.03))
    fin.apply_translation((0.0, 0.0, 0.03 + 0.005 + 0.015))
    body = place(trimesh.util.concatenate([box, fin]), (0.5, 0.0, 0.1))
    assert body.is_watertight
    distance = MeshDistance(body)
    centre = np.r_[body.bounds.mean(axis=0)[:2], body.bounds[1, 2] + 0.1]
    down = np.array([0.0, 0.0, -1.0])
    assert first_passage(body, distance, centre, down)[1] < Scene3D.MIN_APPROACH_DEPTH     # the centre grazes
    start, direction, bounds = approach_from_above(body, body)
    t, depth = first_passage(body, distance, start, direction)
    assert depth >= Scene3D.MIN_APPROACH_DEPTH and abs(start[0] - centre[0]) > 0.001
    assert first_passage(body, distance, centre + [0, 0, 1.0], down) is not None
    assert first_passage(body, distance, centre + [1.0, 0, 0], down) is None              # beside the body: a miss
    assert first_passage(body, distance, centre, 3 * down) == first_passage(body, distance, centre, down)
    for bad in ([0.0, 0.0, 0.0], [0.0, np.nan, -1.0], [0.0, -1.0]):
        with pytest.raises(ValueError, match="first_passage"):
            first_passage(body, distance, centre, bad)


def _write(tmp_path, text: str, name: str = "scene.toml"):
    (tmp_path / "bottle.stl").write_bytes(trimesh.creation.revolve(PROFILE, sections=48).export(file_type="stl"))
    path = tmp_path / name
    path.write_text(text)
    return path


GOOD = """
name = "bottle"
[object]
mesh = "bottle.stl"
scale = 0.001
at = [0.5, 0.0, 0.1]
[cover]
kind = "tight"
gap = 0.008
"""


def test_a_scene_file_builds_the_forcefield_world_and_a_short_run_touches_the_body(tmp_path):
    path = _write(tmp_path, GOOD)
    world = load_scene(path)
    assert isinstance(world, Scene3D) and world.name == "bottle"
    np.testing.assert_allclose(world.inner.bounds[0], [0.47, -0.03, 0.1], atol=1e-9)
    trace = tg.explore(world, max_travel=0.05, metrics_every=100)
    assert trace.terminated == "travel"
    on = trace.contacts_on_body()
    assert on["on_body"] == 1.0 and on["within"] == 1.0
    assert np.abs(world.true_distance(trace.contacts)).max() < 0.01
    other = load_scene(path, seed=3)
    assert np.abs(other.start - world.start).max() > 1e-4


@pytest.mark.parametrize("text, match", [
    ("this is = = not toml", "not a valid TOML"),
    (GOOD + "colour = 'red'\n", "unknown key"),
    (GOOD.replace("[cover]\nkind = \"tight\"", "[cover]\nkind = \"silk\""), "kind"),
    (GOOD.replace("gap = 0.008", "gap = 0.008\ngapp = 0.01"), "unknown key"),
    (GOOD.replace('mesh = "bottle.stl"', 'mesh = "missing.stl"'), "no such file"),
    (GOOD.replace("at = [0.5, 0.0, 0.1]", "at = [0.5, 0.0]"), "object.at"),
    (GOOD + "[range]\nmin = [0.6, 0, 0]\nmax = [0.4, 1, 1]\n", "min must be below max"),
    (GOOD + "[approach]\nstart = [0.5, 0, 0.4]\n", "both start and direction"),
    (GOOD.replace('name = "bottle"', 'name = "a b"'), "name"),
    (GOOD.replace("scale = 0.001", "scale = 1.0"), "millimetres"),
    (GOOD.replace("gap = 0.008", "slack = 0.03"), "do not apply in the forcefield world"),
    (GOOD + "[approach]\nstart = [0.5, 0, 0.4]\ndirection = [0, 0, 1]\n", "misses"),
    (GOOD + "[forcefield]\nspacing = 0.02\n", "allowed"),
    # issue 33, item 10: a string for a flag still repaired, and a zero or negative grid was accepted
    (GOOD.replace("scale = 0.001", "scale = 0.001\nrepair = \"false\""), "repair: must be true or false"),
    (GOOD.replace("scale = 0.001", "scale = 0.001\nresolution = 0"), "resolution: must be positive"),
    (GOOD.replace("scale = 0.001", "scale = 0.001\nresolution = -1"), "resolution: must be positive"),
    # issue 35, item 3: out of reach (or placed in mm) failed later in the IK, naming neither the file nor the key
    (GOOD.replace("at = [0.5, 0.0, 0.1]", "at = [500, 0.0, 100]"), r"object.at .*out of the UR5's reach"),
    (GOOD.replace("at = [0.5, 0.0, 0.1]", "at = [1.5, 0.0, 0.1]"), r"object.at .*out of the UR5's reach"),
    (GOOD + "[approach]\nstart = [0.5, 0, 1.9]\ndirection = [0, 0, -1]\n", r"approach.start: .*out of the UR5's reach"),
    # issue 34, item 6: the exploration's settings in the file, each checked
    (GOOD + "[forcefield]\nsettings = \"fast\"\n", "settings: must be one of"),
    (GOOD + "[forcefield]\nviews = [\"top\"]\n", "views"),
    (GOOD + "[forcefield]\nkernel = \"rbf\"\n", "kernel: unknown 'rbf'; choose among"),
    (GOOD + "[forcefield]\ntheta = -0.1\n", "theta"),
    (GOOD + "[forcefield]\nnoise = 0\n", "noise"),
    (GOOD + "[forcefield]\nvoxel = 2.0\n", "voxel"),
    (GOOD + "[forcefield]\ntouch_inside = 0.5\n", "touch_inside"),
    (GOOD + "[forcefield]\nvision_inside = -0.01\n", "vision_inside"),
    (GOOD + "[forcefield]\nvision_inside_gap = 0.2\n", "vision_inside_gap"),
    (GOOD + "[forcefield]\ncover_offset = 1\n", "cover_offset: must be true or false"),
    (GOOD + "[forcefield]\nlearn = \"everything\"\n", "learn: must be one of"),
])
def test_bad_scene_files_are_refused_by_name(tmp_path, text, match):
    path = _write(tmp_path, text)
    with pytest.raises(ValueError, match=match) as err:
        load_scene(path)
    assert "scene.toml" in str(err.value)


def test_a_scene_files_settings_reach_the_exploration(tmp_path):
    """The default settings for a user's object (three views, voxels a tenth of the body, a second free-space point,
    the Matérn-5/2 of a fifth of the body), the paper's in one word, and each setting by its own key (issue 34,
    item 6)."""
    from torch_gpioius.kernels import Matern52

    world = load_scene(_write(tmp_path, GOOD))
    d = world.defaults
    assert world.views == ("fixed", "mirrored", "wrist")
    assert d.policy.voxel == 0.02 and d.policy.vision_free_far == 0.1          # the bottle: 16 cm -> 2 cm (floor)
    assert isinstance(d.kernel, Matern52) and d.kernel.ell == 0.04 and d.noise == 0.08   # 16 cm -> 4 cm (floor)
    assert d.policy.touch_inside == 0.02 and d.policy.vision_inside == 0.02               # inside points
    assert d.policy.vision_inside_gap == 0.03                       # retracted behind a cover standing 3 cm off
    # one gap, while the touches' gaps agree: the outer mean and the camera's inside points continued down to it
    assert d.policy.cover_offset and d.policy.vision_inside_deep and d.policy.cover_even == 0.25
    off = load_scene(_write(tmp_path, GOOD + "[forcefield]\ncover_offset = false\n")).defaults
    assert not off.policy.cover_offset and off.policy.vision_inside_gap == 0.03
    plain = load_scene(_write(tmp_path, GOOD + "[forcefield]\ntouch_inside = 0\nvision_inside = 0.01\n"
                                               "vision_inside_gap = 0\ncover_offset = false\n")).defaults
    assert plain.policy.touch_inside is None and plain.policy.vision_inside == 0.01
    assert plain.policy.vision_inside_gap is None and not plain.policy.cover_offset
    paper = load_scene(_write(tmp_path, GOOD + "[forcefield]\nsettings = \"paper\"\n"))
    assert (
        paper.views == ("fixed",)
        and paper.defaults.policy.voxel == 0.05
        and paper.defaults.kernel.kind == "InverseMultiquadric"
    )
    assert paper.defaults.policy.vision_free_far is None and paper.defaults.lengthscale == 0.15
    assert paper.defaults.policy.touch_inside is None and paper.defaults.policy.vision_inside is None
    assert paper.defaults.policy.vision_inside_gap is None and not paper.defaults.policy.cover_offset
    # the call's settings win over the file's
    assert load_scene(_write(tmp_path, GOOD), settings="paper").views == ("fixed",)
    own = load_scene(_write(tmp_path, GOOD + "[forcefield]\nviews = 2\nkernel = \"imq\"\ntheta = 0.12\nnoise = 0.02\n"
                                           "voxel = 0.03\n"))
    assert own.views == ("fixed", "mirrored") and own.defaults.kernel.kind == "InverseMultiquadric"
    assert own.defaults.lengthscale == 0.12
    assert own.defaults.noise == 0.02 and own.defaults.policy.voxel == 0.03
    assert load_scene(_write(tmp_path, GOOD + "[forcefield]\ntheta = 0.07\n")).defaults.kernel.ell == 0.07
    assert load_scene(_write(tmp_path, GOOD + "[forcefield]\nlengthscale = 0.07\n")).defaults.kernel.ell == 0.07
    with pytest.raises(ValueError, match="lengthscale, theta: the same length under two names"):
        load_scene(_write(tmp_path, GOOD + "[forcefield]\nlengthscale = 0.07\ntheta = 0.07\n"))
    assert d.learn == "task"                                                             # the paper's learning
    assert load_scene(_write(tmp_path, GOOD + "[forcefield]\nlearn = \"length\"\n")).defaults.learn == "length"
    # and into a run: the model is built with them
    trace = tg.explore(own, max_steps=1, metrics_every=100)
    assert trace.model.theta == pytest.approx(0.12, rel=1e-12) and trace.model.noise == pytest.approx(0.02, rel=1e-12)


def test_a_scene_file_names_its_repairs(tmp_path):
    scan = trimesh.creation.revolve(PROFILE, sections=48)
    z = scan.triangles_center[:, 2]
    trimesh.Trimesh(scan.vertices, scan.faces[z > 1e-6]).export(tmp_path / "scan.stl")
    path = tmp_path / "scan.toml"
    path.write_text(GOOD.replace("bottle.stl", "scan.stl"))
    with pytest.warns(MeshRepairWarning, match="1 hole"):
        read_scene(path) and load_scene(path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MeshRepairWarning)
        path.write_text(
            GOOD.replace("bottle.stl", "scan.stl").replace("scale = 0.001", "scale = 0.001\nrepair = false")
        )
        with pytest.raises(ValueError, match="not closed"):
            load_scene(path)


def test_one_file_builds_both_worlds_with_each_worlds_own_cover_options(tmp_path):
    pytest.importorskip("mujoco")
    from torch_gpioius.sim.mujoco import MujocoScene

    text = GOOD.replace('kind = "tight"\ngap = 0.008', 'kind = "loose"\ngap = 0.01') + \
        "[forcefield]\nbridge = 0.02\ncover_stiffness = 4.0\n[mujoco]\nslack = 0.03\nspacing = 0.03\n"
    path = _write(tmp_path, text)
    ff = load_scene(path)
    assert isinstance(ff, Scene3D) and ff.cover_stiffness == 4.0
    mj = load_scene(path, world="mujoco")
    assert isinstance(mj, MujocoScene) and mj.cover.kind == "loose"
    # the cloth was built `slack` off the bottle (before it settled): its vertices 3 cm from the body
    assert np.median(mj.body.sdf(mj.cover.vertices)) == pytest.approx(0.03, abs=0.005)
    with pytest.raises(ValueError, match=r"own section, \[forcefield\]"):
        load_scene(_write(tmp_path, text.replace("gap = 0.01", "gap = 0.01\nbridge = 0.02"), "b.toml"),
                   world="mujoco")
    # a study's settings reach the MuJoCo world too: its own defaults with the user's changes, and three views
    from torch_gpioius.kernels import Matern52
    from torch_gpioius.sim.forcefield import VIEWS

    mine = load_scene(path, world="mujoco", settings="default")
    assert mine.views == VIEWS and isinstance(mine.defaults.kernel, Matern52) and mj.views == ("fixed",)
    assert mine.defaults.approach_travel == mj.defaults.approach_travel
    np.testing.assert_array_equal(mine.cover.vertices, mj.cover.vertices)
    # the inside points' depths in the MuJoCo section, on top of the settings (a loose cloth: none behind the cloth)
    assert mine.defaults.policy.vision_inside == 0.02
    loose = load_scene(_write(tmp_path, text.replace("spacing = 0.03\n", "spacing = 0.03\nvision_inside = 0\n"),
                              "c.toml"), world="mujoco", settings="default")
    assert loose.defaults.policy.vision_inside is None and loose.defaults.policy.touch_inside == 0.02
    assert mine.defaults.policy.vision_inside_gap == 0.03 and mj.defaults.policy.vision_inside_gap is None
    assert mine.defaults.policy.cover_offset and not mj.defaults.policy.cover_offset
    with pytest.raises(ValueError, match="vision_inside"):
        load_scene(_write(tmp_path, text.replace("spacing = 0.03\n", "spacing = 0.03\nvision_inside = 0.5\n"),
                          "d.toml"), world="mujoco")


def test_the_shipped_scene_files_parse_and_name_meshes_that_exist():
    from pathlib import Path

    from torch_gpioius.sim.scenefile import resolve_mesh

    files = sorted((Path(__file__).resolve().parents[2] / "examples" / "scenes").rglob("*.toml"))
    assert len(files) >= 9
    names = [read_scene(f).name for f in files]
    assert len(set(names) - {"bunny"}) == len(files) - 1          # the tutorial's bunny and eight study scenes
    try:
        import pybullet_data  # noqa: F401
    except ImportError:
        return
    for f in files:
        assert resolve_mesh(read_scene(f).object["mesh"], f.parent).is_file()


@pytest.mark.parametrize("shape", ["carton", "bottle"])
def test_a_standing_carton_and_bottle_get_closed_covers_at_the_default_grid(shape):
    """Issue 35, item 2: "the cover mesh is not closed" for a standing carton or bottle at the default grid. The
    user's meshes were not available; these stand in for them (a 7 x 7 x 19 cm carton with a gable, a 24 cm bottle
    with a neck), tight and loose, each checked for a closed cover at the stated distance from the body."""
    if shape == "carton":
        body = trimesh.convex.convex_hull(np.r_[trimesh.creation.box((0.07, 0.07, 0.19)).vertices,
                                               [[0.035, 0.0, 0.115], [-0.035, 0.0, 0.115]]])
    else:
        body = trimesh.creation.revolve(np.array([[0, 0], [0.035, 0], [0.035, 0.15], [0.012, 0.2], [0.012, 0.24],
                                                  [0, 0.24]]), sections=64)
    body = place(body, (0.5, 0.0, 0.1))
    for kind in ("tight", "loose"):
        outer = cover_around(body, kind, gap=0.008)
        assert outer.is_watertight and outer.volume > body.volume
        d = MeshDistance(body)(outer.vertices)
        assert d.min() > 0.004 and np.median(d) == pytest.approx(0.008, abs=0.002)


@pytest.mark.parametrize("extra, match", [
    ("[forcefield]\nvoxel = 1e-6\n", r"\[forcefield\] voxel: must be 0 .* or an edge in \[0.0001, 1\] m, got 1e-06"),
    ("[forcefield]\ncover_stiffness = inf\n", r"forcefield.cover_stiffness: must be a finite number, got inf"),
    ("[forcefield]\ncover_stiffness = -5.0\n", r"\[forcefield\] cover_stiffness: must be in \(0, 1e\+07\]"),
    ("[mujoco]\nvision_inside = nan\n", r"mujoco.vision_inside: must be a finite number"),
    ("[forcefield]\ncover_offset = 1\n", r"\[forcefield\] cover_offset: must be true or false"),
    ("[forcefield]\ncamera_error = \"6\"\n", r"\[forcefield\] camera_error: '6' is not a size with a unit"),
    ("[forcefield]\ncamera_error = \"30deg\"\n", r"\[forcefield\] camera_error: the rotation must be in"),
])
def test_scene_values_are_checked_when_the_file_is_read(tmp_path, extra, match):
    """Issue 51, item 26: `voxel = 1e-6` passed the parser, then failed with "voxel size must be a number in
    [0.0001, 10] m"; `cover_stiffness = inf` was accepted, then stopped the robot. Each is named by file and key
    when the file is read."""
    path = ball_scene(tmp_path, extra=extra)
    with pytest.raises(ValueError, match=match) as info:
        read_scene(path)
    assert str(path) in str(info.value)


def test_a_pose_a_deep_file_and_an_unknown_cover_key_are_named(tmp_path):
    """Issue 51, item 26: `pose = "up"` gave "could not convert string to float"; a deeply nested TOML "maximum
    recursion depth exceeded"; an unknown [cover] key's list of allowed keys mixed both worlds' options."""
    path = ball_scene(tmp_path)
    text = path.read_text()
    path.write_text(text.replace('mesh = "ball.stl"', 'mesh = "ball.stl"\npose = "up"'))
    with pytest.raises(ValueError, match=r"object.pose: expected a \(4, 4\) transform .* got 'up'"):
        read_scene(path)
    path.write_text(text.replace('mesh = "ball.stl"', 'mesh = "ball.stl"\npose = { rpy_deg = ["a", 0, 0] }'))
    with pytest.raises(ValueError, match=r"object.pose: rpy_deg: expected numbers"):
        read_scene(path)
    path.write_text("a = " + "[" * 100_000 + "]" * 100_000 + "\n")
    with pytest.raises(ValueError, match="nested too deeply"):
        read_scene(path)
    path.write_text(text.replace("gap = 0.008", "gap = 0.008\nslak = 0.03"))
    with pytest.raises(ValueError, match=r"unknown key\(s\) \['slak'\]; \[cover\] takes \['gap', 'kind'\] in every "
                                         r"world, and a world's own options \(forcefield: \['bridge'"):
        read_scene(path)


def test_a_scene_file_builds_an_uneven_cover_with_its_thick_side(tmp_path):
    """Issue 62: a scene file's ``[cover] kind = "uneven"`` with its far gap and thick side builds the force-field
    world's uneven cover (5 mm on the thin side, 3 cm on the thick one); a far gap out of range is named when the file
    is read."""
    path = ball_scene(tmp_path)
    text = path.read_text()
    path.write_text(text.replace('kind = "tight"\ngap = 0.008', 'kind = "uneven"\ngap = 0.005\ngap_far = 0.03\n'
                                 'thick_side = [1, 0, 0]'))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_scene(path, world="forcefield")
    gaps = MeshDistance(scene.inner)(scene.outer.vertices)
    x = scene.outer.vertices[:, 0]
    thin, thick = gaps[x < np.quantile(x, 0.01)], gaps[x > np.quantile(x, 0.99)]
    assert np.median(thin) == pytest.approx(0.005, abs=0.0015) and np.median(thick) == pytest.approx(0.03, abs=0.003)
    path.write_text(text.replace('kind = "tight"\ngap = 0.008', 'kind = "uneven"\ngap_far = 0.5'))
    with pytest.raises(ValueError, match=r"gap_far: must be in \(0, 0.2\]"):
        read_scene(path)


def test_a_scene_files_camera_error_reaches_its_cameras(tmp_path):
    """Issue 63, item 1: ``camera_error`` in ``[forcefield]`` gives the scene's simulated views that error."""
    scene = load_scene(ball_scene(tmp_path, extra='[forcefield]\ncamera_error = "3mm,0.5deg"\nviews = 2\n'))
    errors = scene.camera_errors()
    assert str(scene.camera_error) == "3mm,0.5deg" and len(errors) == 2
    assert all(e["size_mm"] == pytest.approx(3.0) and e["angle_deg"] == pytest.approx(0.5) for e in errors.values())


def test_a_scene_files_inside_depths_and_noise_take_the_ranges_the_worlds_build_with(tmp_path):
    """Issue 64: ``touch_inside = 0.15`` passed reading (0-0.2 m) and failed at build (0-0.1 m); sigma^2 was checked
    against three ranges. One range each, at every door: read and build refuse alike, naming the file's key."""
    from torch_gpioius.core.validation import INSIDE_DEPTH_MAX, NOISE_RANGE
    from torch_gpioius.models.estimator import EstimatorSettings
    from torch_gpioius.sim.forcefield import ROBOT_STUDY_DEFAULTS, with_inside_depths

    for key in ("touch_inside", "vision_inside", "vision_inside_gap"):
        path = ball_scene(tmp_path, extra=f"[forcefield]\n{key} = {INSIDE_DEPTH_MAX * 1.5}\n")
        with pytest.raises(ValueError, match=rf"\[forcefield\] {key}: must be in \(0, 0.1\] m or none"):
            read_scene(path)
        with pytest.raises(ValueError, match=key):
            with_inside_depths(ROBOT_STUDY_DEFAULTS, **{key: INSIDE_DEPTH_MAX * 1.5})
        with_inside_depths(ROBOT_STUDY_DEFAULTS, **{key: INSIDE_DEPTH_MAX})              # the top is allowed
    for noise in (NOISE_RANGE[0] / 2, NOISE_RANGE[1] * 2):
        with pytest.raises(ValueError, match="noise"):
            read_scene(ball_scene(tmp_path, extra=f"[forcefield]\nnoise = {noise}\n"))
        with pytest.raises(ValueError, match="noise"):
            EstimatorSettings.preset("default").replace(noise=noise)
    read_scene(ball_scene(tmp_path, extra=f"[forcefield]\nnoise = {NOISE_RANGE[1]}\n"))
