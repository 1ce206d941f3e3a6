"""One rover in MuJoCo, driven and sensed as our simulator drives and senses it.

:class:`MujocoTwin` compiles one episode's world (:func:`~.mjcf.world_xml`) and steps it at the task's control
period (``SimConfig.step_dt``, 0.05 s) in substeps of ``SimConfig.sim_dt`` (0.01 s). Every substep runs the base's
motor driver as :mod:`atrv_warp.sim.kernels.driver` does, with the same :class:`~atrv_warp.sim.driver.DriverConfig`:
the twist to each side's wheel-speed target through :class:`~atrv_warp.core.kinematics.SkidSteer`, a PI loop on the
encoders within the torque limit (anti-windup), the motor's taper above ``MOTOR_TAPER_START`` of its no-load speed,
the wheel odometry and the fused pose (the encoders' distance along the gyro's heading); a driver that leaves its
wheel radius unset is configured for the radius the twin's tyres roll on (:func:`rolling_radius`). The scanner's beams are
MuJoCo's own rays (``mj_multiRay``) from the URDF's scanner frame; the IMU reads the chassis' orientation and
angular velocity in the URDF's IMU frame.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import mujoco
import numpy as np

from atrv_warp.core.geometry import quat_to_rpy
from atrv_warp.sim.config import ArenaConfig, ContactConfig, RoverConfig, SimConfig
from atrv_warp.sim.driver import DriverConfig
from atrv_warp.sim.kernels.rover import MOTOR_TAPER_START
from atrv_warp.sim.scanner import ScannerConfig
from atrv_warp.sim.terrain import HeightGrid
from atrv_warp.sim.urdf import RoverDescription, load_rover

from .mjcf import SCENE_GROUP, MujocoContact, Obstacle, world_xml

__all__ = ["FLAG_CHASSIS_GROUND", "FLAG_OBSTACLE", "FLAG_WALL", "MujocoTwin", "rolling_radius"]

STATE = mujoco.mjtState.mjSTATE_INTEGRATION
"""What a substep that runs again starts from (``mj_getState``)."""
FLAG_WALL = 1
"""A rover shape touched a wall (:attr:`MujocoTwin.contact_flags`; the simulator's bits)."""
FLAG_CHASSIS_GROUND = 2
"""The chassis touched the ground."""
FLAG_OBSTACLE = 4
"""A rover shape touched an obstacle."""


class MujocoTwin:
    """One episode's world in MuJoCo: the rover, the arena, the ground or a terrain tile, the obstacles.

    Args:
        terrain: The height grids (``None``: the flat arena).
        tile: The tile of ``terrain`` this episode drives on.
        obstacles: The episode's obstacles.
        friction: Coulomb µ of every contact [-] (default: ``ContactConfig().friction``, the nominal µ).
        obstacle_height: Height of the obstacles above the flat ground's top [m] (``ObstacleConfig.height``).
        scanner: The scanner's geometry (its noise is not simulated: the twin's ranges are exact).
        rover, arena, sim, driver: As :class:`~atrv_warp.sim.RoverSim` takes them (defaults: the nominal rover).
        contact: MuJoCo's contact settings (default :class:`~.mjcf.MujocoContact`: the tyre's compliance).

    State after :meth:`reset` and each :meth:`step` (numpy, float64): :attr:`odometry` and :attr:`fused` (x [m],
    y [m], yaw [rad] in the odometry frame), :attr:`odom_twist` (linear [m/s], angular [rad/s]),
    :attr:`contact_flags` since the step began, :attr:`wheel_ground_substeps` (per wheel, the substeps of the step
    after which it touched the ground).
    """

    def __init__(self, *, terrain: HeightGrid | None = None, tile: int = 0, obstacles: tuple[Obstacle, ...] = (),
                 friction: float | None = None, obstacle_height: float = 1.0, scanner: ScannerConfig | None = None,
                 rover: RoverConfig | None = None, arena: ArenaConfig | None = None, sim: SimConfig | None = None,
                 driver: DriverConfig | None = None, contact: MujocoContact | None = None):
        self.rover_cfg = rover or RoverConfig()
        self.arena_cfg = arena or ArenaConfig()
        self.sim_cfg = sim or SimConfig()
        self.driver_cfg = (driver or DriverConfig()).resolved(self.rover_cfg.robot_spec)
        if self.driver_cfg.wheel_radius is None:  # the base configured for the radius this rover's tyres roll on
            self.driver_cfg = dataclasses.replace(self.driver_cfg, wheel_radius=rolling_radius(
                self.rover_cfg, self.arena_cfg, self.sim_cfg, contact or MujocoContact()))
        self.scanner_cfg = scanner or ScannerConfig()
        self.contact_cfg = contact or MujocoContact()
        self.friction = ContactConfig().friction if friction is None else float(friction)
        self.description: RoverDescription = load_rover(self.rover_cfg)
        self.kinematics = self.driver_cfg.kinematics(self.description, self.rover_cfg)
        """The driver's :class:`~atrv_warp.core.kinematics.SkidSteer` (its configured radius and track)."""
        self.xml = world_xml(self.description, self.rover_cfg, arena=self.arena_cfg, sim=self.sim_cfg,
                             friction=self.friction, torque_limit=self.driver_cfg.torque_limit,
                             obstacle_top=self.arena_cfg.ground_top + obstacle_height, terrain=terrain, tile=tile,
                             obstacles=tuple(obstacles), contact=self.contact_cfg)
        """The world's MJCF text."""
        self.model = mujoco.MjModel.from_xml_string(self.xml)
        self.data = mujoco.MjData(self.model)
        m = self.model
        self.substeps = self.sim_cfg.substeps
        self.chassis_body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, self.description.chassis)
        joints = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, w.joint) for w in self.description.wheels]
        self.wheel_dof = np.array([m.jnt_dofadr[j] for j in joints])
        self.wheel_sign = np.array([w.drive_sign for w in self.description.wheels])
        self.wheel_side = np.array([w.side for w in self.description.wheels])
        frames = {f.name: np.asarray(f.transform, dtype=np.float64) for f in self.description.frames}
        self.scanner_mount = frames[self.scanner_cfg.frame or self.rover_cfg.robot_spec.laser_frame]
        self.imu_mount = frames[self.rover_cfg.robot_spec.imu_frame]  # ROBOT_OBSERVATION's imu_* fields
        self.beam_angles = np.asarray(self.scanner_cfg.angles, dtype=np.float64)
        self._ray_group = np.zeros(6, dtype=np.uint8)
        self._ray_group[SCENE_GROUP] = 1
        self._ray_id = np.zeros(len(self.beam_angles), dtype=np.int32)
        self._ray_dist = np.zeros(len(self.beam_angles), dtype=np.float64)
        names = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g) or "" for g in range(m.ngeom)]
        self._flag_of_geom = np.array([FLAG_WALL if n.startswith("wall_") else FLAG_OBSTACLE
                                       if n.startswith("obstacle_") else 0 for n in names], dtype=np.int64)
        self._ground_geom = names.index("ground")
        self._chassis_geoms = {g for g in range(m.ngeom) if m.geom_bodyid[g] == self.chassis_body}
        wheel_bodies = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, w.link) for w in self.description.wheels]
        self._wheel_of_geom = np.full(m.ngeom, -1, dtype=np.int64)
        for i, b in enumerate(wheel_bodies):
            self._wheel_of_geom[m.geom_bodyid == b] = i
        self.reset()

    # ------------------------------------------------------------------ state
    def reset(self, position=None, quat_xyzw=None) -> None:
        """The rover at rest at ``position`` (x, y, z) [m] with orientation ``quat_xyzw`` (default: the origin on
        the flat ground, level), wheels still; the driver at rest, the odometry frame at this pose."""
        d = self.data
        mujoco.mj_resetData(self.model, d)
        if position is None:
            axle_z = float(np.mean([w.origin[2, 3] for w in self.description.wheels]))
            position = (0.0, 0.0, self.arena_cfg.ground_top + self.rover_cfg.wheel_radius - axle_z)
        x, y, z, w = (0.0, 0.0, 0.0, 1.0) if quat_xyzw is None else quat_xyzw
        d.qpos[:3] = position
        d.qpos[3:7] = (w, x, y, z)
        mujoco.mj_forward(self.model, d)
        self.twist = np.zeros(2)
        self.reference = np.zeros(2)
        self.integral = np.zeros(2)
        self.applied = np.zeros(2)
        self.wheel_torque = np.zeros(len(self.wheel_dof))
        """(W,) each wheel's motor torque for the clamped loop output [N·m], forward-positive (the simulator's
        ``wheel_torque``: a base's effort)."""
        self._torque_cap = np.zeros(len(self.wheel_dof))  # an implicit loop's torque cap [N·m] (``drive_wheels``')
        self.age = 0.0
        self.odometry = np.zeros(3)
        self.odom_twist = np.zeros(2)
        self.fused = np.zeros(3)
        self.fused_velocity = np.zeros(2)  # odometry frame (with DriverConfig.odometry_accel_time)
        self.velocity = np.zeros(3)  # the chassis COM's at the last substep (the accelerometer's)
        self.contact_flags = 0
        self.wheel_ground_substeps = np.zeros(len(self.description.wheels), dtype=np.int64)
        self.time = 0.0

    def command(self, linear: float, angular: float) -> None:
        """A ``/cmd_vel``: forward speed [m/s] and yaw rate [rad/s]; the driver's timeout restarts."""
        self.twist = np.array([float(linear), float(angular)])
        self.age = 0.0

    @property
    def root_pose(self) -> np.ndarray:
        """(7,) the chassis' position [m] and orientation quaternion (x, y, z, w), world frame."""
        w, x, y, z = self.data.xquat[self.chassis_body]
        return np.concatenate([self.data.xpos[self.chassis_body], [x, y, z, w]])

    @property
    def chassis_rotation(self) -> np.ndarray:
        """(3, 3) the chassis' orientation (world from chassis)."""
        return self.data.xmat[self.chassis_body].reshape(3, 3).copy()

    @property
    def angular_velocity(self) -> np.ndarray:
        """(3,) the chassis' angular velocity [rad/s], world frame (a free joint's is in its body's frame)."""
        return self.chassis_rotation @ self.data.qvel[3:6]

    @property
    def linear_velocity(self) -> np.ndarray:
        """(3,) the chassis origin's velocity [m/s], world frame."""
        return self.data.qvel[:3].copy()

    @property
    def com_velocity(self) -> np.ndarray:
        """(3,) the velocity of the chassis' centre of mass [m/s], world frame (ours' free-joint velocity)."""
        b = self.chassis_body
        return self.linear_velocity + np.cross(self.angular_velocity, self.data.xipos[b] - self.data.xpos[b])

    @property
    def rpy(self) -> np.ndarray:
        """(3,) the chassis' roll, pitch, yaw [rad] (intrinsic Z-Y-X)."""
        return quat_to_rpy(self.root_pose[3:]).numpy()

    @property
    def wheel_speed(self) -> np.ndarray:
        """(W,) forward-positive wheel speeds [rad/s]."""
        return self.wheel_sign * self.data.qvel[self.wheel_dof]

    @property
    def finite(self) -> bool:
        """Whether the state is still finite."""
        return bool(np.isfinite(self.data.qpos).all() and np.isfinite(self.data.qvel).all())

    # ------------------------------------------------------------------ stepping
    def step(self, torques=None) -> None:
        """Advance by ``SimConfig.step_dt``: each substep the driver's loop (or ``torques``, (2,) [left, right]
        wheel torques [N·m] through the motor's taper, as torque actions drive), then one MuJoCo step."""
        self.contact_flags = 0
        self.wheel_ground_substeps[:] = 0
        for _ in range(self.substeps):
            self._drive(None if torques is None else np.asarray(torques, dtype=np.float64))
            damping = self.model.dof_damping[self.wheel_dof].copy()
            saved = None
            if damping.any():  # an implicit loop's damped wheels: kept to their limit as the friction solve keeps them
                saved = np.empty(mujoco.mj_stateSize(self.model, STATE))
                mujoco.mj_getState(self.model, self.data, saved, STATE)
                start = self.wheel_speed
            self._advance()
            if saved is not None:
                end = self.data.ctrl - damping * (self.wheel_speed - start)
                held = (damping > 0.0) & (np.abs(end) > self._torque_cap + 1e-9)
                if held.any():  # friction carried a wheel's end torque past the limit: again, that wheel at the limit
                    mujoco.mj_setState(self.model, self.data, saved, STATE)
                    self.data.ctrl[held] = np.copysign(self._torque_cap[held], end[held])
                    self.model.dof_damping[self.wheel_dof[held]] = 0.0
                    self.data.qfrc_applied[self.wheel_dof[held]] = 0.0
                    self._advance()
            self._note_contacts()
            if not self.finite:
                break
        self.time += self.sim_cfg.step_dt

    def _advance(self) -> None:
        """One substep of MuJoCo steps."""
        for _ in range(self.contact_cfg.steps_per_substep):
            mujoco.mj_step(self.model, self.data)

    def _drive(self, torques: np.ndarray | None) -> None:
        """One substep of :func:`atrv_warp.sim.kernels.driver.drive_wheels` for this rover."""
        c, dt = self.driver_cfg, self.sim_cfg.sim_dt
        wheel = self.wheel_speed
        speeds = np.array([wheel[self.wheel_side == s].mean() for s in (0, 1)])
        self._integrate_odometry(speeds, dt)
        if torques is None:
            target = self.twist if self.age <= c.cmd_vel_timeout else np.zeros(2)
            self.reference = self._limit_twist(target, dt)
            goal = self.kinematics.wheel_speeds(*self.reference).numpy()
            out = np.zeros(2)
            for side in (0, 1):
                out[side], self.integral[side] = _pi_side(goal[side], speeds[side], self.integral[side], c.kp, c.ki,
                                                          c.torque_limit, dt)
            self.applied = out  # the nominal motor has no lag
            torques = self.applied
            if c.implicit_under():  # ``drive_wheels``' ``beyond``: the output past its limit, before the clamp
                raw = c.kp * (goal - speeds) + c.ki * self.integral
                beyond = raw - np.clip(raw, -c.torque_limit, c.torque_limit)
        self.age += dt
        scale = self.rover_cfg.torque_scale
        command = torques[self.wheel_side] * scale
        limit = self.rover_cfg.wheel_speed_limit
        self.data.ctrl[:] = _motor_torque(command, wheel, limit)
        self.wheel_torque = self.data.ctrl.copy()
        if torques is self.applied and c.implicit_under():
            # the implicit loop (``drive_wheels``' ``implicit_drive``): the unclamped output, its proportional action a
            # damping; ``step`` runs a substep again with the motor's torque at the loop's limit on a wheel whose end
            # torque passes it (the friction solve's hold). MuJoCo's Euler integrates a joint's damping implicitly;
            # the applied force makes it act on the speed's change over the substep, not on the speed
            unclamped_command = command + beyond[self.wheel_side] * scale
            taper = np.where(unclamped_command < 0.0, -_motor_torque(-1.0, wheel, limit), _motor_torque(1.0, wheel, limit))
            damping = c.kp * scale * taper
            self.data.ctrl[:] = _motor_torque(unclamped_command, wheel, limit)
            # ``drive_wheels``' ``torque_cap``: the motor's torque at the loop's limit, the most an end torque may reach
            self._torque_cap = np.abs(_motor_torque(np.where(unclamped_command < 0.0, -1.0, 1.0) * c.torque_limit * scale,
                                                    wheel, limit))
            self.model.dof_damping[self.wheel_dof] = damping
            self.data.qfrc_applied[self.wheel_dof] = damping * self.data.qvel[self.wheel_dof]
        else:
            self.model.dof_damping[self.wheel_dof] = 0.0
            self.data.qfrc_applied[self.wheel_dof] = 0.0

    def _limit_twist(self, target: np.ndarray, dt: float) -> np.ndarray:
        """``diff_drive_controller``'s speed and acceleration limits (off by default)."""
        c = self.driver_cfg
        limits = [(c.linear_max_velocity, c.linear_max_acceleration), (c.angular_max_velocity, c.angular_max_acceleration)]
        out = self.reference.copy()
        for k, (vmax, amax) in enumerate(limits):
            value = target[k] if vmax is None else float(np.clip(target[k], -vmax, vmax))
            step = math.inf if amax is None else amax * dt
            out[k] += float(np.clip(value - out[k], -step, step))
        return out

    def _integrate_odometry(self, speeds: np.ndarray, dt: float) -> None:
        """Wheel odometry and the fused pose over one substep, as ``integrate_odometry`` and ``integrate_fused`` do
        (midpoint rule), or with ``DriverConfig.odometry_accel_time`` ``accel_aided_velocity`` and
        ``integrate_fused_velocity``."""
        v, w = (float(t) for t in self.kinematics.twist(speeds))
        self.odom_twist = np.array([v, w])
        gyro = float(self.angular_velocity[2])
        tau = self.driver_cfg.odometry_accel_time
        poses = ((self.odometry, w), (self.fused, gyro)) if tau is None else ((self.odometry, w),)
        for pose, rate in poses:
            mid = pose[2] + 0.5 * rate * dt
            yaw = pose[2] + rate * dt
            pose[:] = (pose[0] + v * math.cos(mid) * dt, pose[1] + v * math.sin(mid) * dt,
                       math.atan2(math.sin(yaw), math.cos(yaw)))
        if tau is not None:  # accel_aided_velocity and integrate_fused_velocity
            velocity, rot = self.com_velocity, self.chassis_rotation
            change = velocity - self.velocity
            ax, ay = float(change @ rot[:, 0]), float(change @ rot[:, 1])
            mid = self.fused[2] + 0.5 * gyro * dt
            c, s = math.cos(mid), math.sin(mid)
            integrated = self.fused_velocity + np.array([c * ax - s * ay, s * ax + c * ay])
            self.fused_velocity = integrated + (np.array([c * v, s * v]) - integrated) * (dt / tau)
            self.velocity = velocity
            yaw = self.fused[2] + gyro * dt
            self.fused[:] = (self.fused[0] + self.fused_velocity[0] * dt, self.fused[1] + self.fused_velocity[1] * dt,
                             math.atan2(math.sin(yaw), math.cos(yaw)))

    def _note_contacts(self) -> None:
        d = self.data
        if d.ncon == 0:
            return
        pairs = d.contact.geom[: d.ncon]
        self.contact_flags |= int(np.bitwise_or.reduce(self._flag_of_geom[pairs].ravel()))
        on_ground = pairs[(pairs == self._ground_geom).any(axis=1)].ravel()
        wheels = self._wheel_of_geom[on_ground]
        self.wheel_ground_substeps[np.unique(wheels[wheels >= 0])] += 1
        for a, b in pairs:
            if (a == self._ground_geom and b in self._chassis_geoms) or (b == self._ground_geom and a in self._chassis_geoms):
                self.contact_flags |= FLAG_CHASSIS_GROUND

    # ------------------------------------------------------------------ sensors
    def frame_pose(self, mount: np.ndarray) -> np.ndarray:
        """(4, 4) world pose of a frame fixed to the chassis at ``mount`` (4x4, chassis frame)."""
        chassis = np.eye(4)
        chassis[:3, :3] = self.chassis_rotation
        chassis[:3, 3] = self.data.xpos[self.chassis_body]
        return chassis @ mount

    def scan(self) -> np.ndarray:
        """(beams,) ranges [m] from the scanner frame, MuJoCo's rays against the scene (the rover's own shapes
        skipped), clamped to [min_range, max_range]; a beam without a return reads ``max_range``."""
        cfg = self.scanner_cfg
        pose = self.frame_pose(self.scanner_mount)
        local = np.stack([np.cos(self.beam_angles), np.sin(self.beam_angles), np.zeros_like(self.beam_angles)], -1)
        directions = local @ pose[:3, :3].T
        mujoco.mj_multiRay(self.model, self.data, pose[:3, 3].copy(), directions.ravel().copy(), self._ray_group, 1, -1,
                           self._ray_id, self._ray_dist, None, len(self.beam_angles), cfg.max_range)
        ranges = np.where(self._ray_id >= 0, self._ray_dist, cfg.max_range)
        return np.clip(ranges, cfg.min_range, cfg.max_range)

    def imu(self) -> tuple[np.ndarray, np.ndarray]:
        """The IMU's orientation quaternion (x, y, z, w) and angular velocity [rad/s] in its own frame."""
        rot = self.frame_pose(self.imu_mount)[:3, :3]
        w, x, y, z = _quat_wxyz(rot)
        return np.array([x, y, z, w]), rot.T @ self.angular_velocity


REST_S = 1.0
"""How long :func:`rolling_radius` lets the rover settle [s]."""


@functools.cache
def rolling_radius(rover: RoverConfig, arena: ArenaConfig, sim: SimConfig, contact: MujocoContact) -> float:
    """The radius [m] the twin's tyres roll on: ``(r + h) / 2``, ``r`` the wheel's radius and ``h`` the axles' mean
    height above the flat ground after :data:`REST_S` at rest (one rover-only world per configuration, cached).

    MuJoCo puts a contact's point midway through the penetration, so a wheel that sinks ``r - h`` pushes on the
    ground ``(r - h) / 2`` inside its radius and rolls that much smaller (4 to 6 % on the shipped robots under the
    tyre's compliance, :class:`~.mjcf.MujocoContact`); ours rolls on ``r``. A :class:`MujocoTwin` whose driver
    leaves its radius unset is configured with this one, as a real base is with its wheels' rolling radius
    (``diff_drive_controller``'s ``wheel_radius_multiplier``) and as our simulator's driver is with the radius the
    nominal rover's wheels roll on there."""
    twin = MujocoTwin(rover=rover, arena=arena, sim=sim, contact=contact, driver=DriverConfig(wheel_radius=rover.wheel_radius))
    for _ in range(round(REST_S / sim.step_dt)):
        twin.step(torques=(0.0, 0.0))
    bodies = [mujoco.mj_name2id(twin.model, mujoco.mjtObj.mjOBJ_BODY, w.link) for w in twin.description.wheels]
    height = float(np.mean(twin.data.xpos[bodies, 2])) - arena.ground_top
    return 0.5 * (rover.wheel_radius + height)


def _quat_wxyz(rot: np.ndarray) -> np.ndarray:
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(rot).ravel())
    return q


def _pi_side(target: float, speed: float, integral: float, kp: float, ki: float, limit: float, dt: float):
    """One side's wheel-speed PI (``pi_side``): torque [N·m] within ``limit`` and the new integral [rad], which
    integrates up to where the output meets the limit and no further (anti-windup)."""
    error = target - speed
    candidate = integral + error * dt
    new = candidate
    if ki > 0.0:
        low, high = min(integral, (-limit - kp * error) / ki), max(integral, (limit - kp * error) / ki)
        new = min(max(candidate, low), high)
    return float(np.clip(kp * error + ki * new, -limit, limit)), new


def _motor_torque(command: np.ndarray, forward_speed: np.ndarray, speed_limit: float) -> np.ndarray:
    """``motor_torque``: full torque while braking or below ``MOTOR_TAPER_START`` of the no-load speed, then a
    linear taper to zero at it."""
    s = np.abs(forward_speed) / speed_limit
    scale = np.clip((1.0 - s) / (1.0 - float(MOTOR_TAPER_START)), 0.0, 1.0)
    return np.where(command * forward_speed <= 0.0, command, command * scale)
