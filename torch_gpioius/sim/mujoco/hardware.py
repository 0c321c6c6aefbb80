"""The MuJoCo world's hardware behind the loop's interfaces: a UR5 backend whose position-controlled joints are
driven through the same ``SafetyGate`` and ``UR5.cartesian_step`` as every backend, the fingertip force sensor
(MuJoCo's ``force`` sensor in the tool frame, with the OptoForce's noise model), and a depth camera that ray-casts
the settled cover with ``mujoco.mj_multiRay``.
"""

from __future__ import annotations

import json
import math

import numpy as np
import torch

from kinematics import RobotBackend, SafetyGate, UR5
from kinematics.backends import RobotError
from kinematics.dh import UR5_JOINT_NAMES

from ...sensors.base import ForceReading, ForceSensor
from ...sensors.pointcloud import PinholeCamera, PointCloud, PointCloudSource

__all__ = ["MujocoPhysics", "MujocoInstability", "MujocoUR5", "MujocoForceSensor", "MujocoDepthCamera"]


def mujoco_has_joint(model, name: str) -> bool:
    try:
        model.joint(name)
    except KeyError:
        return False
    return True


class MujocoInstability(RuntimeError):
    """The physics blew up (NaN, or runaway kinetic energy); the run stops rather than record nonsense."""


class MujocoPhysics:
    """An ``mjModel``/``mjData`` pair stepped with blow-up checks.

    Args:
        model: the compiled ``mujoco.MjModel``.
        max_kinetic_energy: kinetic energy [J] above which the simulation counts as blown up (the arm moving at its
            speed limit and a cloth in free fall stay far below 1 J).
    """

    def __init__(self, model, max_kinetic_energy: float = 5.0) -> None:
        import mujoco

        self.mj = mujoco
        self.model = model
        self.data = mujoco.MjData(model)
        self.max_kinetic_energy = float(max_kinetic_energy)

    @property
    def time(self) -> float:
        return float(self.data.time)

    #: Physics steps between two blow-up checks: a blow-up is reported within this many steps of its start (500
    #: primitives once blew up at the first step and were reported after a whole settle, 41 s later).
    CHECK_EVERY = 25

    def step(self, n: int = 1) -> None:
        """``n`` physics steps, checked for NaN / runaway energy every :attr:`CHECK_EVERY` steps and at the end.

        Raises:
            MujocoInstability: naming the time and what went wrong.
        """
        n = int(n)
        done = 0
        while done < n:
            k = min(self.CHECK_EVERY, n - done)
            bad = self._bad_warnings()
            for _ in range(k):
                self.mj.mj_step(self.model, self.data)
            done += k
            self._check(bad)

    def _check(self, bad_before: int) -> None:
        d = self.data
        # MuJoCo resets the state when it meets NaN or huge values and only counts a warning: a reset mid-run would
        # teleport the arm and the cloth, so any new such warning is an error here. (The scenes switch the reset
        # off, so the NaN stays and is caught below: a reset also re-zeroes the counters, and after a first reset a
        # second one left the count where it was, unseen; a tight cloth in a mug's handle was reset at every step
        # and the arm never moved.)
        if self._bad_warnings() > bad_before or not (np.isfinite(d.qpos).all() and np.isfinite(d.qvel).all()):
            raise MujocoInstability(f"MuJoCo simulation blew up at t = {d.time:.3f} s (NaN, inf or huge values in the "
                                    "state); reduce the timestep or stiffen the cover's damping")
        energy = self.kinetic_energy()
        if energy > self.max_kinetic_energy:
            raise MujocoInstability(f"MuJoCo simulation blew up at t = {d.time:.3f} s (kinetic energy "
                                    f"{energy:.3g} J > {self.max_kinetic_energy:g} J)")

    def _bad_warnings(self) -> int:
        w = self.mj.mjtWarning
        return int(sum(self.data.warning[k].number for k in (w.mjWARN_BADQACC, w.mjWARN_BADQVEL, w.mjWARN_BADQPOS)))

    def kinetic_energy(self) -> float:
        """``0.5 qvel^T M qvel`` [J] of the current state."""
        m, d = self.model, self.data
        mv = np.zeros(m.nv)
        self.mj.mj_mulM(m, d, mv, d.qvel)
        return float(0.5 * d.qvel @ mv)

    def get_state(self) -> np.ndarray:
        """The full integration state (``mjSTATE_INTEGRATION``: physics and controls) as a float64 array."""
        spec = self.mj.mjtState.mjSTATE_INTEGRATION
        state = np.empty(self.mj.mj_stateSize(self.model, spec))
        self.mj.mj_getState(self.model, self.data, state, spec)
        return state

    def set_state(self, state: np.ndarray) -> None:
        spec = self.mj.mjtState.mjSTATE_INTEGRATION
        self.mj.mj_setState(self.model, self.data, np.asarray(state, dtype=np.float64), spec)
        self.mj.mj_forward(self.model, self.data)


class MujocoUR5(RobotBackend):
    """A UR5 simulated by MuJoCo: every command passes the ``SafetyGate`` (``RobotBackend``), then the joint
    servos' setpoints move linearly in joint space at the commanded speed (as the UR's moveJ), and the physics runs
    until the move is done plus ``settle`` seconds; the joints it reports are the simulated ones (a fingertip
    pressed on an object deflects the arm as the real servos yield).

    Args:
        physics: the :class:`MujocoPhysics`.
        ur5: kinematic model (its tool offset is the fingertip centre).
        gate: safety gate.
        settle: after each move the physics runs until the joints are at rest (every joint speed below
            ``rest_speed`` [rad/s]), at least ``settle[0]`` and at most ``settle[1]`` seconds: the next reading is
            then quasi-static, as a real force-guided controller waits for it.
        rest_speed: joint speed below which the arm counts as at rest [rad/s].
    """

    def __init__(self, physics: MujocoPhysics, ur5: UR5, gate: SafetyGate | None = None, *,
                 settle: tuple[float, float] = (0.008, 0.2), rest_speed: float = 6e-3, **kwargs) -> None:
        super().__init__(ur5, gate, **kwargs)
        self.physics = physics
        m = physics.model
        self._qadr = np.array([m.jnt_qposadr[m.joint(n).id] for n in UR5_JOINT_NAMES])
        self._act = np.array([m.actuator(f"servo_{n}").id for n in UR5_JOINT_NAMES])
        self.settle = (float(settle[0]), float(settle[1]))
        self.rest_speed = float(rest_speed)
        m = physics.model
        self._dadr = np.array([m.jnt_dofadr[m.joint(n).id] for n in UR5_JOINT_NAMES])
        # the compliant fingertip's mount joints: the reading is quasi-static only once they are at rest too
        self._tip_dadr = np.array([m.jnt_dofadr[m.joint(n).id] for n in ("tip_x", "tip_y", "tip_z")
                                   if mujoco_has_joint(m, n)], dtype=int)
        self.stopped = False
        self._target = self._read_q()
        #: (simulated time [s], commanded joints (6,) [rad], leading joint speed [rad/s]) of every command sent
        self.log: list[tuple[float, np.ndarray, float]] = []

    def _read_q(self) -> np.ndarray:
        return self.physics.data.qpos[self._qadr].copy()

    @property
    def time(self) -> float:
        """Simulated time [s]."""
        return self.physics.time

    def read_joints(self) -> torch.Tensor:
        return torch.as_tensor(self._read_q(), dtype=self.ur5.dtype)

    def place(self, q) -> None:
        """Put the arm at joints ``q`` `(6,)` [rad] at rest (scene setup only, before anything touches)."""
        q = np.asarray(self.ur5._q(q).cpu().numpy(), dtype=np.float64)
        d = self.physics.data
        d.qpos[self._qadr] = q
        d.qvel[:] = 0.0
        d.ctrl[self._act] = q
        self._target = q.copy()
        self.physics.mj.mj_forward(self.physics.model, d)

    def _send_joint_move(self, q: torch.Tensor, speed: float) -> None:
        target = np.asarray(q.detach().cpu().numpy(), dtype=np.float64)
        start = self._target.copy()
        self.log.append((self.physics.time, target.copy(), float(speed)))
        dt = self.physics.model.opt.timestep
        duration = float(np.abs(target - start).max()) / float(speed)
        n = max(1, int(math.ceil(duration / dt)))
        d = self.physics.data
        before = self._read_q()
        for k in range(1, n + 1):
            d.ctrl[self._act] = start + (target - start) * (k / n)
            self.physics.step(1)
        self._target = target
        self._rest(dt)
        asked = float(np.abs(target - before).max())
        if asked > 1e-4 and float(np.abs(self._read_q() - before).max()) < 0.01 * asked:
            # the servos did not move the arm at all (seen once: a scene whose joints stayed frozen while their
            # targets moved); a silent no-op would look like a fingertip resting in free space
            self.stop()
            raise RobotError(f"the arm did not follow a {asked:.4f} rad joint move (its joints stayed where they "
                             "were); the simulation is stuck")

    def _rest(self, dt: float) -> None:
        """Run the physics until the arm is at rest (see ``settle``)."""
        lo, hi = (max(1, int(round(t / dt))) for t in self.settle)
        self.physics.step(lo)
        qvel = self.physics.data.qvel
        for _ in range(hi - lo):
            if np.abs(qvel[self._dadr]).max() < self.rest_speed and (
                    not len(self._tip_dadr) or np.abs(qvel[self._tip_dadr]).max() < self.rest_speed * 0.5):
                break
            self.physics.step(1)

    def stop(self) -> None:
        """Hold the current joints."""
        q = self._read_q()
        self.physics.data.ctrl[self._act] = q
        self._target = q
        self.stopped = True

    def get_state(self) -> dict[str, np.ndarray]:
        return {"physics": self.physics.get_state(), "target": self._target.copy()}

    def set_state(self, state: dict) -> None:
        self.physics.set_state(state["physics"])
        self._target = np.asarray(state["target"], dtype=np.float64).copy()


class MujocoForceSensor(ForceSensor):
    """The fingertip's 3-axis force sensor: the deflection of the compliant fingertip's mount, times its stiffness,
    in the tool frame (the OptoForce's frame), with the OMD-20's noise (Gaussian per axis, seeded).

    An OptoForce measures the deformation of its silicone dome; here the dome is the spring-loaded mount of
    :func:`~torch_gpioius.sim.mujoco.ur5.ur5_mjcf`, so ``F = k x`` is the force the surroundings exert on the
    fingertip (pointing away from a touched surface). MuJoCo's own ``force`` sensor is not used: it leaves out the
    force of flex (cloth) contacts, which is most of what this world is about. A deflection beyond 95 % of the
    mount's travel sets the Fx/Fy/Fz overload bit, as the real DAQ flags a saturated axis.

    Args:
        physics: the :class:`MujocoPhysics`.
        noise_std: noise per axis [N].
        seed: noise seed.
    """

    def __init__(self, physics: MujocoPhysics, noise_std: float = 0.02, seed: int = 0) -> None:
        self.physics = physics
        m = physics.model
        joints = [m.joint(n) for n in ("tip_x", "tip_y", "tip_z")]
        self._qadr = np.array([m.jnt_qposadr[j.id] for j in joints])
        self._k = np.array([m.jnt_stiffness[j.id] for j in joints], dtype=np.float64)
        self._travel = np.array([m.jnt_range[j.id][1] for j in joints], dtype=np.float64)
        self.noise_std = float(noise_std)
        self._rng = np.random.default_rng(seed)
        self._offset = np.zeros(3)
        self._counter = 0
        self._last_status = 0

    def _raw(self) -> np.ndarray:
        return self._k * np.asarray(self.physics.data.qpos[self._qadr], dtype=np.float64)

    def read(self) -> ForceReading:
        x = np.asarray(self.physics.data.qpos[self._qadr], dtype=np.float64)
        status = 0
        for i, bit in enumerate((9, 8, 7)):                    # Fx, Fy, Fz overload flags of the DAQ status word
            if abs(x[i]) >= 0.95 * self._travel[i]:
                status |= 1 << bit
        f = self._raw() - self._offset
        if self.noise_std > 0:
            f = f + self._rng.normal(0.0, self.noise_std, 3)
        self._counter = (self._counter + 1) & 0xFFFF
        self._last_status = status
        return ForceReading(torch.as_tensor(f), status, self._counter, self.physics.time)

    def true_force(self) -> np.ndarray:
        """`(3,)` the tared force without noise [N], tool frame (for simulated instruments that respond to the load
        itself, such as the gel pad; reading it draws no noise and leaves the sensor's state alone)."""
        return self._raw() - self._offset

    def tare(self) -> None:
        """Zero at the current load (the fingertip free of contact)."""
        self._offset = self._raw().copy()

    def get_state(self) -> dict[str, np.ndarray]:
        # the generator's state holds 128-bit integers: stored as its JSON text, in bytes
        rng = np.frombuffer(json.dumps(self._rng.bit_generator.state).encode(), dtype=np.uint8)
        return {"offset": self._offset.copy(), "counter": np.array([self._counter]), "rng": rng.copy()}

    def set_state(self, state: dict) -> None:
        self._offset = np.asarray(state["offset"], dtype=np.float64).copy()
        self._counter = int(np.asarray(state["counter"]).reshape(-1)[0])
        self._rng.bit_generator.state = json.loads(np.asarray(state["rng"], dtype=np.uint8).tobytes().decode())


class MujocoDepthCamera(PointCloudSource):
    """A pinhole depth camera ray-cast in the MuJoCo scene (``mj_multiRay``): it sees the inner object and the
    settled cover (flexes included), never the robot (geom groups 0 and 1 only). Depth noise ``noise_a + noise_b
    z^2`` along the ray, seeded, as :class:`torch_gpioius.sensors.SimulatedDepthCamera`.

    Args:
        physics: the :class:`MujocoPhysics`.
        intrinsics: :class:`torch_gpioius.sensors.PinholeCamera`.
        T_base_camera: `(4, 4)` camera pose (OpenCV axes).
        noise_a, noise_b: depth noise [m], [1/m].
        seed: noise seed (and the extrinsic error's direction, a stream of its own).
        error, error_key: a simulated camera error (calibration; depth noise's multiple, pixels and blocks lost) and
            what its extrinsic part is drawn with besides the seed, as
            :class:`torch_gpioius.sensors.SimulatedDepthCamera`'s.
    """

    def __init__(self, physics: MujocoPhysics, intrinsics: PinholeCamera, T_base_camera, *, noise_a: float = 0.0,
                 noise_b: float = 0.0, seed: int = 0, error=None, error_key=()) -> None:
        from ...sensors.simulated.camera import CameraError

        self.physics, self.intrinsics = physics, intrinsics
        self.T_base_camera = np.asarray(T_base_camera, dtype=np.float64)
        self.noise_a, self.noise_b = float(noise_a), float(noise_b)
        self._rng = np.random.default_rng(seed)
        self.error = CameraError() if error is None else CameraError.parse(error)
        #: The rigid error this camera's captures carry, or None.
        self.applied_error = self.error.drawn(seed, error_key)

    def capture(self) -> PointCloud:
        from ...sensors.simulated.camera import lost_blocks, sensed_points

        lost = lost_blocks(self.error, self.intrinsics, self._rng)
        mj = self.physics.mj
        m, d = self.physics.model, self.physics.data
        rays = self.intrinsics.rays()
        R, t = self.T_base_camera[:3, :3], self.T_base_camera[:3, 3]
        dirs = rays / np.linalg.norm(rays, axis=1, keepdims=True)
        world = np.ascontiguousarray((dirs @ R.T).reshape(-1))
        n = len(dirs)
        geomid = np.zeros(n, dtype=np.int32)
        dist = np.zeros(n)
        groups = np.array([1, 1, 0, 0, 0, 0], dtype=np.uint8)       # the object and the cover; not the robot
        mj.mj_multiRay(m, d, t.copy(), world, groups, 1, -1, geomid, dist, None, n, self.intrinsics.max_depth * 2)
        # mj_multiRay skips flexes: the cover's faces are cast one ray at a time with mj_rayFlex (~10 us per ray)
        vid = np.zeros(1, np.int32)
        origin = t.copy()
        for f in range(m.nflex):
            for i in range(n):
                df = mj.mj_rayFlex(m, d, 0, False, False, True, False, f, origin, world[3 * i:3 * i + 3].copy(), vid,
                                   None)
                if df >= 0 and (dist[i] < 0 or df < dist[i]):
                    dist[i] = df
        hit = dist >= 0
        z = dist[hit] * (dirs[hit] @ np.array([0.0, 0.0, 1.0]))
        keep = (z >= self.intrinsics.min_depth) & (z <= self.intrinsics.max_depth)
        p_cam = dirs[hit][keep] * dist[hit][keep][:, None]
        points = sensed_points(p_cam, self.T_base_camera, self.intrinsics, self._rng, noise_a=self.noise_a,
                               noise_b=self.noise_b, dropout=0.0, error=self.error, lost=lost,
                               applied=self.applied_error)
        return PointCloud(points, t.copy())
