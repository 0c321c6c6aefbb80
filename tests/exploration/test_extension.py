"""Extending the library from outside: every part below is defined in this file, through public contracts only,
and run with ``explore``: a toy world (a ball under a soft cover, a gantry robot, a camera), a toy force sensor, a
Matérn-3/2 kernel used through GPIOIS, a custom evidence policy, a touch model and a custom recorder. Each is
registered by name, and the names then reach scene files, the command line and studies with no package file
edited."""

import math

import numpy as np
import pytest
import torch

import torch_gpioius as tg
from torch_gpioius.testing import KernelContract, WorldContract
from torch_gpioius.exploration.contact import ContactConfig, ContactController
from torch_gpioius.exploration import (Evidence, ExplorationDefaults, Hardware, Measurement, ObservationPolicy,
                                       PointTouch, Recorder, SceneSupport, TouchModelBase, TravelBudget, World,
                                       register_evidence_policy, register_touch_model, register_world, world_entry)
from torch_gpioius.kernels import ExactKernel
from torch_gpioius.sensors import ForceReading, ForceSensor, PointCloud, PointCloudSource
from torch_gpioius.models.overrides import EstimatorOverrides

CENTRE, RADIUS, COVER = np.array([0.5, 0.0, 0.2]), 0.06, 0.08


# ------------------------------------------------------------------------------------------------ a kernel
class Matern32(ExactKernel):
    """k(r) = (1 + sqrt(3) r / l) exp(-sqrt(3) r / l): once differentiable, unlike the default kernel."""

    kind = "TestMatern32"

    def __init__(self, lengthscale=0.1, **kw):
        super().__init__(**kw)
        self.ell = float(lengthscale)

    def value(self, x1, x2):
        s = math.sqrt(3) * torch.cdist(x1, x2, compute_mode="donot_use_mm_for_euclid_dist") / self.ell
        return (1 + s) * torch.exp(-s)

    def gradient(self, x1, x2, value=None):
        s = math.sqrt(3) * torch.cdist(x1, x2, compute_mode="donot_use_mm_for_euclid_dist") / self.ell
        coef = -3.0 / self.ell ** 2 * torch.exp(-s)                  # kappa'(r) / r
        return ((x1.unsqueeze(1) - x2.unsqueeze(0)) * coef.unsqueeze(-1)).permute(2, 0, 1)

    def prior_variance(self, scale=1.0):
        return scale * 1.0

    def second_derivative_at_zero(self):
        return -3.0 / self.ell ** 2

    def describe(self):
        return {"kernel": self.kind, "lengthscale": self.ell}


tg.kernels.register_kernel(Matern32)


class TestMatern32Contract(KernelContract):
    def make(self):
        return Matern32(0.12)


# ------------------------------------------------------------------------------------------------ a world
class Gantry:
    """A Cartesian robot that moves its fingertip exactly where it is told (inside a box), with a clock."""

    def __init__(self, start, lo, hi):
        self.p = np.asarray(start, dtype=float)
        self.lo, self.hi, self.time = np.asarray(lo), np.asarray(hi), 0.0

    def move_cartesian(self, dx, speed=0.05):
        dx = np.asarray(torch.as_tensor(dx).detach(), dtype=float)
        target = self.p + dx
        if (target < self.lo).any() or (target > self.hi).any():
            raise RuntimeError(f"move to {target} leaves the workspace")
        self.p = target
        self.time += max(np.linalg.norm(dx) / speed, 1e-3)

    def read_pose(self):
        T = torch.eye(4, dtype=torch.float64)
        T[:3, 3] = torch.as_tensor(self.p)
        return T

    def tool_position(self):
        return torch.as_tensor(self.p)

    def stop(self):
        pass


class BallSensor(ForceSensor):
    """The force on the fingertip: 800 N/m into the ball, a 5 N/m field through the cover, zero outside."""

    def __init__(self, robot):
        self.robot, self.counter = robot, 0

    def read(self):
        p = self.robot.p - CENTRE
        r = float(np.linalg.norm(p))
        n = p / max(r, 1e-12)
        f = n * (800.0 * max(RADIUS - r, 0.0) + 5.0 * max(COVER - r, 0.0))
        self.counter += 1
        return ForceReading(torch.as_tensor(f), 0, self.counter, self.robot.time)

    def tare(self):
        pass


class CoverCamera(PointCloudSource):
    """A camera 1 m up that sees the front of the cover."""

    def capture(self):
        rng = np.random.default_rng(0)
        d = rng.standard_normal((600, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        d = d[d[:, 2] > -0.2]
        return PointCloud(CENTRE + COVER * d, origin=CENTRE + [0.0, 0.0, 1.0])


class BallWorld(World):
    """A ball of 6 cm under an 8 cm soft cover, touched from above."""

    dim = 3

    def __init__(self, name="ball", step=0.01):
        self.name, self.step = name, step
        self.start = CENTRE + [0.004, 0.003, 0.15]
        self.direction = np.array([0.0, 0.0, -1.0])
        self.range = np.stack([CENTRE - 0.12, CENTRE + 0.12])

    @property
    def defaults(self):
        settings = tg.EstimatorSettings(tg.kernels.InverseMultiquadricKernel(0.1), 0.006, ObservationPolicy(voxel=0.02))
        return ExplorationDefaults(step=self.step, max_steps=40, stop=(TravelBudget(0.15),), approach_travel=0.3,
                                   estimator=settings)

    def hardware(self):
        robot = Gantry(self.start, self.range[0] - 0.1, self.range[1] + 0.1)
        sensor = BallSensor(robot)
        controller = ContactController(robot, sensor, ContactConfig(speed=0.05, approach_step=0.002))
        return Hardware(robot, sensor, CoverCamera(), controller)

    def measure(self, model, contacts, resolution=None):
        mesh = tg.surfaces.zero_level_mesh(model, np.stack([CENTRE - 0.15, CENTRE + 0.15]), 0.02)
        if mesh is None:
            return Measurement()
        off = np.abs(np.linalg.norm(mesh.vertices - CENTRE, axis=1) - RADIUS)
        return Measurement(hausdorff=float(off.max()), surface=mesh)     # the estimate's side of eq. 24


class TestBallWorldContract(WorldContract):
    def make(self):
        return BallWorld()


def ball_from_scene_file(mesh, kind, *, name, where, cover, settings, preset, smoke):
    """A scene file's ball: its name, and the step its own ``[toyball]`` section gives (the mesh is the ball's)."""
    assert kind == "tight" and abs(float(np.max(mesh.extents)) - 2 * RADIUS) < 1e-3
    return BallWorld(name, step=settings.get("step", 0.01))


register_world("toyball", BallWorld, objects=lambda names, smoke: {n: BallWorld(n) for n in names},
               object_names=("ball",), description="a ball under a soft cover (a test's world)",
               scene=SceneSupport(cover_keys=frozenset({"gap"}), cover_kinds=("tight",),
                                  settings_keys=frozenset({"step"}), build=ball_from_scene_file, ur5=False))


# ------------------------------------------------------------------------------------------------ evidence, recorder
class Poke:
    """Every 3 steps: lift 3 cm along the measured normal, then come back down."""

    name = "poke"

    def due(self, state):
        return state.steps - state.last_evidence >= 3

    def gather(self, state, toucher):
        lift = toucher.lift(state.normal, step=0.005, until_force_below=0.1, extra=0.03, max_distance=0.1)
        back = toucher.approach(-state.normal, max_travel=lift.travel + 0.05)
        return Evidence([lift, back], back.contact.numpy() if back.in_contact else None,
                        back.force_normal if back.in_contact else None)

    def describe(self):
        return {"name": self.name}


register_evidence_policy("poke", Poke, modes=("visual-tactile",), description="lift 3 cm every 3 steps")


class Counting(TouchModelBase):
    """The fingertip's point contact, counting the contacts it turns into observations."""

    name = "counting"
    seen = 0

    def observations(self, result, contacts, policy, step):
        Counting.seen += 1
        return PointTouch().observations(result, contacts, policy, step)


register_touch_model("counting", Counting, description="a point contact that counts")


class Diary(Recorder):
    """Writes down the hooks it sees and the records they carry."""

    def __init__(self):
        self.calls, self.hausdorff = [], []

    def start(self, run, state):
        self.calls.append(("start", len(state.records)))

    def step(self, run, state, record):
        assert record is state.records[-1]
        self.calls.append(("step", record.step))
        self.hausdorff.append(record.hausdorff)

    def end(self, run, state):
        self.calls.append(("end", state.terminated))


# ------------------------------------------------------------------------------------------------ the tests
def test_a_world_sensor_kernel_policy_and_recorder_of_ones_own_run_through_explore(tmp_path):
    diary = Diary()
    trace = tg.explore(BallWorld(), settings=EstimatorOverrides(kernel=Matern32(0.1)), evidence=Poke(),
                       recorders=[diary], metrics_every=2,
                       log=tmp_path / "ball.gpioius")
    assert trace.terminated == "travel" and trace.travel[-1] >= 0.15
    # the recorder saw start, every step in order, and the end
    steps = [c[1] for c in diary.calls if c[0] == "step"]
    assert diary.calls[0] == ("start", 1) and diary.calls[-1] == ("end", "travel")
    assert steps == list(range(1, trace.n_steps))
    # it ran after the built-in metrics: every second step and the last carry a Hausdorff distance
    assert all(np.isfinite(h) for s, h in zip(steps, diary.hausdorff) if s % 2 == 0)
    # the policy poked, and the fingertip came back to the ball each time: contacts on its surface (the tip is a
    # point pressed to 1-5 N at 800 N/m: 1.3-6.3 mm deep)
    assert trace.taps[-1] >= 2
    depth = RADIUS - np.linalg.norm(trace.contacts - CENTRE, axis=1)
    assert (depth > 0.0).all() and (depth < 0.0075).all()
    # the model is GPIOIS with the kernel of this file, and its structured engine is exact for it
    model = trace.model
    assert isinstance(model, tg.GPIOIS) and isinstance(model.kernel, Matern32)
    assert type(model._inference()).__name__ == "StructuredExactInference"
    x, t = model.train_inputs[0], model.train_task
    dense = tg.GPIOIS(x, model.train_targets, t, kernel=Matern32(0.1), noise=0.006, inference="dense",
                      task_covariance=model.task_covariance)
    q = torch.as_tensor(CENTRE + np.array([[0.0, 0.0, 0.07], [0.05, 0.0, 0.03]]))
    for task in (0, 1):
        torch.testing.assert_close(model.predict(q, task)[0], dense.predict(q, task)[0], rtol=1e-10, atol=1e-11)
    # the log names the kernel; the run history rebuilds the model with it
    history = tg.load_run(tmp_path / "ball.gpioius")
    assert history.meta["kernel"] == {"kernel": "TestMatern32", "lengthscale": 0.1}
    assert history.meta["world"] == "toyball" and history.meta["evidence"] == "poke"
    assert isinstance(history.model_at(history.steps[-1]).kernel, Matern32)


def test_the_registered_world_is_made_by_name():
    world = world_entry("toyball").build("ball")
    assert isinstance(world, BallWorld) and world.kind == "toyball"
    with pytest.raises(ValueError, match="unknown 'nope' in the toyball world"):
        world_entry("toyball").build("nope")
    with pytest.raises(ValueError, match="already BallWorld"):
        register_world("toyball", Gantry)


def test_a_policy_or_touch_without_the_contract_is_named():
    with pytest.raises(ValueError, match="evidence: a policy needs due"):
        tg.explore(BallWorld(), evidence=object())
    with pytest.raises(ValueError, match="touch: expected a name or an object with observations"):
        tg.explore(BallWorld(), touch=object())
    with pytest.warns(DeprecationWarning, match="EstimatorOverrides"), \
            pytest.raises(TypeError, match="kernel: expected a torch_gpioius.kernels.ExactKernel"):
        tg.explore(BallWorld(), kernel="matern")          # the deprecated keyword still checks its value
    with pytest.raises(ValueError, match="'matern'"):
        tg.explore(BallWorld(), settings=EstimatorOverrides(kernel="matern"))


def test_a_kernel_registered_outside_the_package_is_used_by_name_from_a_scene_file_and_a_study(tmp_path):
    """Issue 53: a registered kernel was refused by name in a scene file ("kernel: must be one of ('imq',
    'matern52')") and by the command line's choices. Now the names come from the registry: the scene file's
    ``[forcefield] kernel`` and ``gpioius study --kernel`` take this test's TestMatern32, with no package file
    edited, and the run's model uses it."""
    import json

    from tests.scenes import ball_scene
    from torch_gpioius.cli import _estimator_overrides, build_parser
    from torch_gpioius.sim.scenefile import load_scene
    from torch_gpioius.studies.study import run_sweep

    scene = load_scene(ball_scene(tmp_path, extra='[forcefield]\nkernel = "TestMatern32"\n'))
    # a kind without a learnable length: its own, the length rule dropped
    assert isinstance(scene.defaults.kernel, Matern32) and scene.defaults.kernel.ell == 0.1
    assert scene.defaults.estimator.length_rule is None
    trace = tg.explore(scene, "tactile", max_steps=2, metrics_every=100)
    assert isinstance(trace.model.kernel, Matern32)
    # the command line: the name is checked against the registry, then reaches every run (a local backend: Ray's
    # workers would need the kernel's module importable, as any user's code run there)
    args = build_parser().parse_args(["study", "--world", "forcefield", "--kernel", "TestMatern32",
                                      "--out", str(tmp_path / "s")])
    choice = _estimator_overrides(args).kernel
    assert choice.name == "TestMatern32" and choice.lengthscale is None
    run_sweep("forcefield", scenes=[ball_scene(tmp_path)], modes=["tactile"], seeds=1, out=tmp_path / "s",
              smoke=True, backend="local", progress=False, kernel=choice)
    record = json.loads((tmp_path / "s" / "runs" / "ball_tactile_0.json").read_text())
    assert record["kernel"] == "TestMatern32" and record["estimator"]["kernel"]["kernel"] == "TestMatern32"
    with pytest.raises(SystemExit):
        build_parser().parse_args(["study", "--kernel", "NoSuchKernel"])


def test_a_touch_model_declares_its_contract_by_subclassing_the_base():
    """Issue 53: the loop asked ``getattr(touch, "bind" / "select" / "retraction_margin")``. A touch now subclasses
    TouchModelBase and the loop calls every method of the contract; an object with ``observations`` alone gets the
    defaults, and one that writes more of the contract without the base is refused by name (its methods would have
    been passed over)."""
    from torch_gpioius.exploration import touch_model

    calls = []

    class Counting(TouchModelBase):
        name = "counting"

        def observations(self, result, contacts, policy, step):
            return PointTouch().observations(result, contacts, policy, step)

        def bind(self, hardware):
            calls.append("bind")

        def select(self, model, obs):
            calls.append("select")
            return obs

    trace = tg.explore(BallWorld(), touch=Counting(), max_steps=3, metrics_every=100)
    assert calls[0] == "bind" and calls.count("select") >= 3 and trace.touch == "counting"

    class Bare:
        def observations(self, result, contacts, policy, step):
            return PointTouch().observations(result, contacts, policy, step)

    wrapped = touch_model(Bare())
    assert isinstance(wrapped, TouchModelBase) and wrapped.name == "Bare" and wrapped.fit_options() == {}
    assert tg.explore(BallWorld(), touch=Bare(), max_steps=2, metrics_every=100).touch == "Bare"

    class HalfDeclared(Bare):
        def select(self, model, obs):
            return obs

    with pytest.raises(ValueError, match="HalfDeclared has select: subclass torch_gpioius.exploration.TouchModelBase"):
        touch_model(HalfDeclared())


def test_a_world_policy_and_touch_registered_outside_the_package_run_from_a_scene_file_and_a_study(tmp_path):
    """Issue 53: the command line, scene files and studies matched world, touch and mode names by hand
    (``["forcefield", "mujoco"]``, ``("point", "patch")``, ``world not in ("forcefield", "mujoco")``). Now they read
    the registries: this file's world (with its scene-file section), touch model and evidence policy are chosen by
    name from a scene file and from ``gpioius study``, and the run records them."""
    import json

    from tests.scenes import ball_scene
    from torch_gpioius.cli import build_parser
    from torch_gpioius.exploration import world_names
    from torch_gpioius.sim.scenefile import load_scene, scene_worlds
    from torch_gpioius.studies.study import run_sweep, sweep_modes

    assert "toyball" in scene_worlds() and "toyball" in world_names(simulated=True)
    assert "visual-tactile+poke" in sweep_modes() and "tactile+poke" not in sweep_modes()
    path = ball_scene(tmp_path, extra="[toyball]\nstep = 0.008\n")
    path.write_text('world = "toyball"\n' + path.read_text())
    world = load_scene(path)
    assert isinstance(world, BallWorld) and world.name == "ball" and world.defaults.step == 0.008
    with pytest.raises(ValueError, match=r"\[toyball\]: unknown key\(s\) \['stride'\]"):
        load_scene(ball_scene(tmp_path, name="bad", extra="[toyball]\nstride = 0.01\n"), world="toyball")
    args = build_parser().parse_args(["study", "--world", "toyball", "--scenes", str(path), "--modes",
                                      "visual-tactile+poke", "--touch", "counting", "--out", str(tmp_path / "s")])
    assert (args.world, args.touch) == ("toyball", "counting")
    before = Counting.seen
    run_sweep(args.world, scenes=[path], modes=args.modes.split(","), touch=args.touch, seeds=1, out=tmp_path / "s",
              smoke=True, backend="local", progress=False, max_steps=7)
    record = json.loads((tmp_path / "s" / "runs" / "ball_visual-tactile+poke_0.json").read_text())
    assert (record["world"], record["mode"], record["touch"]) == ("toyball", "visual-tactile+poke", "counting")
    assert record["taps"] >= 1 and Counting.seen > before
    for argv in (["study", "--world", "robot"], ["study", "--touch", "nope"], ["simulate3d", "--world", "planar"]):
        with pytest.raises(SystemExit):
            build_parser().parse_args(argv)
