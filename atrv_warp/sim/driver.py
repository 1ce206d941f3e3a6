"""The base's motor driver, as a real mobile base runs it: ``/cmd_vel`` (linear [m/s], angular [rad/s]) through
optional speed and acceleration limits and the skid-steer kinematics to each side's wheel-speed target, then a PI
loop on the wheel encoders every solver substep (100 Hz at the default 0.01 s), within the motor's torque
limit, with anti-windup and a command timeout; wheel odometry from the same encoders, and the pose a base's filter
fuses from them and the IMU's gyro.

The driver knows what a real one knows: its wheel radius and track are its configured values (the nominal
rover's unless set), not the physical rover's. Under randomization, a payload or a worn tyre, its targets and
its odometry carry the scale error that a real base's do.

The kernels are in :mod:`atrv_warp.sim.kernels.driver`; :class:`~atrv_warp.sim.RoverSim` runs them inside its
step, :class:`~atrv_warp.sim.diff.DiffRollout` on its tape, and the ROS node, the velocity actions of the task
and the calibration's replay all go through them.

The limits are off by default, as ``diff_drive_controller``'s are. Each robot's published ones are in its robot file
(``atrv_warp/robots/<name>.toml``, ``[limits]``, with their sources; the docs' robots page lists them), and a task
sets the limits its base trains with (:meth:`atrv_warp.task.config.TaskConfig.driver`). The gains, the torque limit
and the effective track factor are the robot's too, unless set here (:data:`ROBOT_OWN`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import torch
import warp as wp

from atrv_warp.core.kinematics import SkidSteer, track_width
from atrv_warp.sim.kernels.driver import DRIVE_TORQUE, DRIVE_TWIST, DriverParams, DriverState, reset_driver

__all__ = ["DRIVER_LIMITS", "DRIVE_TORQUE", "DRIVE_TWIST", "ROBOT_OWN", "SNAPSHOT_ADDED", "Driver", "DriverConfig"]

DRIVER_LIMITS = ("linear_max_velocity", "linear_max_acceleration", "angular_max_velocity", "angular_max_acceleration")
"""The limits, each ``diff_drive_controller``'s ``linear.x.max_velocity``, ``linear.x.max_acceleration``,
``angular.z.max_velocity`` and ``angular.z.max_acceleration``."""

ROBOT_OWN = ("kp", "ki", "torque_limit", "effective_track_factor")
"""The :class:`DriverConfig` fields that are the robot's (its file's ``[driver]`` and ``[motor]``) unless set."""

SNAPSHOT_ADDED = ("driver.fused_velocity", "driver.velocity")
"""Snapshot entries that a snapshot of an earlier version lacks: the accelerometer filter's state
(:attr:`DriverConfig.odometry_accel_time`), zero wherever the filter is off, so such a snapshot restores them as
zero."""


@dataclass(frozen=True)
class DriverConfig:
    """A skid-steer base's motor driver (the ROS node's parameters of the same names)."""

    wheel_radius: float | None = None
    """The wheel radius the driver is configured with [m]; ``None``: the nominal rover's (its
    :class:`~atrv_warp.sim.config.RoverConfig` before a calibration's ``sim_config`` is applied)."""
    track_width: float | None = None
    """The configured wheel track [m]; ``None``: the nominal rover's (:func:`~atrv_warp.core.kinematics.track_width`)."""
    effective_track_factor: float | None = None
    """Effective track / wheel track [-] the driver's kinematics assume (skid steering turns slower); ``None``: the
    robot's (:attr:`~atrv_warp.core.robot.Robot.effective_track_factor`)."""
    kp: float | None = None
    """PI proportional gain [N·m per rad/s]; ``None``: the robot's. The loop runs every substep; a slipping wheel
    bounds it: ``kp x sim_dt / J`` must stay below 2 (the ATRV-Jr's 3.0 on its 0.02 kg·m² wheel: 1.5). The robot
    check (``python -m atrv_warp.robot check``) chooses it with ``ki`` for the wheel's inertia."""
    ki: float | None = None
    """PI integral gain [N·m per rad]; ``None``: the robot's."""
    torque_limit: float | None = None
    """The motor's torque limit [N·m] (the torque task's action scale); ``None``: the robot's."""
    linear_max_velocity: float | None = None
    """``linear.x.max_velocity`` [m/s] (``None``: no limit)."""
    linear_max_acceleration: float | None = None
    """``linear.x.max_acceleration`` [m/s²] (``None``: no limit)."""
    angular_max_velocity: float | None = None
    """``angular.z.max_velocity`` [rad/s] (``None``: no limit)."""
    angular_max_acceleration: float | None = None
    """``angular.z.max_acceleration`` [rad/s²] (``None``: no limit)."""
    cmd_vel_timeout: float = 0.5
    """Without a command for this long [s], the target drops to zero (``diff_drive_controller``'s default)."""
    implicit_speed_loop: bool | None = None
    """``True``: the loop's proportional term acts on each wheel's speed at the substep's end, solved with its ground
    contact (:func:`~atrv_warp.sim.kernels.friction.friction_kernels`): no gain is bounded by the substep, where the
    explicit loop (``False``) goes unstable once a slipping wheel's ``kp x sim_dt / J`` reaches 2. Coulomb friction
    only (the viscous law has no solve to put it in). ``None`` (the default): implicit under Coulomb friction (the
    default law), explicit under the viscous law (:meth:`implicit_under`)."""
    odometry_accel_time: float | None = None
    """The fused odometry's velocity from the encoders and the IMU's accelerometer: a complementary filter with this
    time constant [s], which follows the integrated accelerometer over shorter spans and the encoders (their speed
    along the gyro's heading, no sideways motion) over longer ones, as ``robot_localization`` fusing the IMU's linear
    acceleration with wheel odometry. Where the wheels slip, in launches and turns on slippery ground, the encoders
    over-read and the accelerometer does not. ``None`` (the default): the encoders' speed alone. The accelerometer
    here is the simulator's, without noise or bias (a bias ``b`` would add up to ``b x odometry_accel_time`` to the
    velocity)."""

    def __post_init__(self):
        positive = ["cmd_vel_timeout", *DRIVER_LIMITS, *ROBOT_OWN]
        positive += [n for n in ("wheel_radius", "track_width", "odometry_accel_time") if getattr(self, n) is not None]
        for name in positive:
            value = getattr(self, name)
            if value is None and name in DRIVER_LIMITS + ROBOT_OWN:
                continue
            if not _finite_positive(value) and not (name in ("kp", "ki") and value == 0):
                at_least = ">= 0" if name in ("kp", "ki") else "> 0"
                raise ValueError(f"DriverConfig.{name} must be a finite number {at_least}, got {value!r}")

    def implicit_under(self, friction_law: str = "coulomb") -> bool:
        """Whether the speed loop is implicit (:attr:`implicit_speed_loop`) with the wheels' ``friction_law``
        (:attr:`~atrv_warp.sim.config.ContactConfig.friction_law`)."""
        if self.implicit_speed_loop is None:
            return friction_law == "coulomb"
        return bool(self.implicit_speed_loop)

    def resolved(self, robot) -> DriverConfig:
        """This config with every field left ``None`` that is the robot's (:data:`ROBOT_OWN`) taken from ``robot``
        (a :class:`~atrv_warp.core.robot.Robot`, a shipped robot's name or a robot file's path)."""
        from atrv_warp.core.robot import load_robot

        robot = load_robot(robot)
        own = {name: getattr(robot, name) for name in ROBOT_OWN if getattr(self, name) is None}
        return dataclasses.replace(self, **own) if own else self

    def kinematics(self, description, nominal_rover) -> SkidSteer:
        """The driver's kinematics: its configured radius, track and factor, else the nominal rover's (and its
        robot's factor)."""
        radius = self.wheel_radius if self.wheel_radius is not None else nominal_rover.wheel_radius
        track = self.track_width if self.track_width is not None else track_width(description, nominal_rover)
        factor = self.effective_track_factor
        if factor is None:
            factor = nominal_rover.robot_spec.effective_track_factor
        return SkidSteer(radius, track, factor)

    def kernel_params(self, kinematics: SkidSteer, dt: float) -> DriverParams:
        """The kernels' :class:`~atrv_warp.sim.kernels.driver.DriverParams` at substep ``dt`` [s] (of a
        :meth:`resolved` config)."""
        unresolved = [name for name in ROBOT_OWN if getattr(self, name) is None]
        if unresolved:
            raise ValueError(f"DriverConfig {unresolved} unset: resolve the robot's values first (DriverConfig.resolved)")
        p = DriverParams()
        p.wheel_radius, p.effective_track = kinematics.wheel_radius, kinematics.effective_track
        p.kp, p.ki, p.torque_limit = self.kp, self.ki, self.torque_limit
        limit = {name: math.inf if getattr(self, name) is None else float(getattr(self, name)) for name in DRIVER_LIMITS}
        p.max_linear, p.max_linear_accel = limit["linear_max_velocity"], limit["linear_max_acceleration"]
        p.max_angular, p.max_angular_accel = limit["angular_max_velocity"], limit["angular_max_acceleration"]
        p.timeout, p.dt = self.cmd_vel_timeout, dt
        p.implicit = int(self.implicit_under())
        p.accel_time = 0.0 if self.odometry_accel_time is None else float(self.odometry_accel_time)
        if p.accel_time and p.accel_time < 2.0 * dt:
            raise ValueError(f"DriverConfig.odometry_accel_time must be at least two substeps ({2.0 * dt:g} s), got "
                             f"{p.accel_time:g}")
        return p


def _finite_positive(value) -> bool:
    try:
        return math.isfinite(float(value)) and float(value) > 0
    except (TypeError, ValueError):
        return False


class Driver:
    """Every world's motor driver: its configuration, state and commands as Warp arrays and torch views.

    Views (N rows, updated in place by the simulator's step):
        ``mode`` (N,) int32: ``DRIVE_TORQUE`` (0) or ``DRIVE_TWIST`` (1).
        ``twist`` (N, 2): the commanded (linear [m/s], angular [rad/s]); write with :meth:`~atrv_warp.sim.RoverSim.set_twist`.
        ``odometry`` (N, 3): wheel odometry x [m], y [m], yaw [rad] in the odometry frame (the pose at reset).
        ``odom_twist`` (N, 2): the encoders' (linear [m/s], angular [rad/s]).
        ``fused`` (N, 3): x [m], y [m], yaw [rad] in the odometry frame as a base's filter keeps it
        (``robot_localization`` fusing wheel odometry and an IMU, Clearpath's ``odometry/filtered``): the encoders'
        distance along the heading the gyro integrates. Skid-steer wheel odometry's heading drifts on every turn
        (a rover's wheels turn before its chassis does); this one's does not, its distance still slips (less with
        :attr:`DriverConfig.odometry_accel_time`, which blends in the accelerometer).
        ``reference`` (N, 2): the limited twist being tracked.
        ``age`` (N,): time since the last command [s]; past ``cmd_vel_timeout`` the driver stops the rover.
        ``lag`` (N,): the motor's torque lag time constant [s] (0: none), e.g. a randomization's draw.
    """

    def __init__(self, cfg: DriverConfig, kinematics: SkidSteer, num_worlds: int, dt: float, device):
        self.cfg = cfg
        self.kinematics = kinematics
        """The driver's :class:`~atrv_warp.core.kinematics.SkidSteer` (configured radius and track)."""
        self.params = cfg.kernel_params(kinematics, dt)
        n = num_worlds
        self.mode_array = wp.full(n, DRIVE_TORQUE, dtype=wp.int32, device=device)
        self.twist_array = wp.zeros(n, dtype=wp.vec2, device=device)
        self.lag_array = wp.zeros(n, dtype=float, device=device)
        self.state = make_state(n, device)
        self.mode = wp.to_torch(self.mode_array)
        self.twist = wp.to_torch(self.twist_array).view(n, 2)
        self.lag = wp.to_torch(self.lag_array)
        s = self.state
        self.odometry = wp.to_torch(s.odometry).view(n, 3)
        self.odom_twist = wp.to_torch(s.odom_twist).view(n, 2)
        self.fused = wp.to_torch(s.fused).view(n, 3)
        self.reference = wp.to_torch(s.reference).view(n, 2)
        self.age = wp.to_torch(s.age)

    @property
    def timed_out(self) -> torch.Tensor:
        """(N,) bool: a twist-driven world that has had no command for longer than ``cmd_vel_timeout``."""
        return (self.mode == int(DRIVE_TWIST)) & (self.age > self.cfg.cmd_vel_timeout)

    def snapshot_arrays(self) -> dict[str, wp.array]:
        """Everything of the driver that the next step reads, by snapshot key."""
        s = self.state
        return {"driver.mode": self.mode_array, "driver.twist": self.twist_array, "driver.lag": self.lag_array,
                "driver.reference": s.reference, "driver.integral": s.integral, "driver.applied": s.applied,
                "driver.age": s.age, "driver.odometry": s.odometry, "driver.odom_twist": s.odom_twist,
                "driver.fused": s.fused, "driver.fused_velocity": s.fused_velocity, "driver.velocity": s.velocity}

    def reset(self, mask: wp.array) -> None:
        wp.launch(reset_driver, dim=len(mask), inputs=[mask], outputs=[self.twist_array, self.state],
                  device=mask.device)


def make_state(num_worlds: int, device, requires_grad: bool = False) -> DriverState:
    """A zeroed :class:`~atrv_warp.sim.kernels.driver.DriverState` of ``num_worlds`` rows."""
    s = DriverState()
    s.reference = wp.zeros(num_worlds, dtype=wp.vec2, device=device, requires_grad=requires_grad)
    s.integral = wp.zeros(num_worlds, dtype=wp.vec2, device=device, requires_grad=requires_grad)
    s.applied = wp.zeros(num_worlds, dtype=wp.vec2, device=device, requires_grad=requires_grad)
    s.age = wp.zeros(num_worlds, dtype=float, device=device, requires_grad=requires_grad)
    s.odometry = wp.zeros(num_worlds, dtype=wp.vec3, device=device, requires_grad=requires_grad)
    s.odom_twist = wp.zeros(num_worlds, dtype=wp.vec2, device=device, requires_grad=requires_grad)
    s.fused = wp.zeros(num_worlds, dtype=wp.vec3, device=device, requires_grad=requires_grad)
    s.fused_velocity = wp.zeros(num_worlds, dtype=wp.vec2, device=device, requires_grad=requires_grad)
    s.velocity = wp.zeros(num_worlds, dtype=wp.vec3, device=device, requires_grad=requires_grad)
    return s


def replay(cfg: DriverConfig, kinematics: SkidSteer, twist, fresh, speeds, *, step_dt: float, substeps: int
           ) -> dict[str, torch.Tensor]:
    """The driver replayed open loop along recorded drives, on the CPU: ``twist`` (L, T, 2) each step's command,
    ``fresh`` (L, T) whether it was within the timeout, ``speeds`` (L, T + 1, 2) each side's recorded wheel speed
    [rad/s] at the step boundaries (linear in between). Returns the driver's ``reference``, ``integral`` and
    ``applied`` torque at every step boundary, (L, T + 1, 2) each: the state a replay starting there starts from
    (the calibration's segments). The same functions as the simulator's kernel (no motor lag)."""
    from atrv_warp.sim.kernels.driver import replay_driver

    twist = torch.as_tensor(twist, dtype=torch.float32)
    lengths, steps = twist.shape[:2]
    params = cfg.kernel_params(kinematics, step_dt / substeps)
    out = {name: wp.zeros((lengths, steps + 1), dtype=wp.vec2, device="cpu")
           for name in ("reference", "integral", "applied")}
    wp.launch(replay_driver, dim=lengths,
              inputs=[params, wp.from_torch(twist.contiguous(), dtype=wp.vec2),
                      wp.from_torch(torch.as_tensor(fresh, dtype=torch.bool).contiguous()),
                      wp.from_torch(torch.as_tensor(speeds, dtype=torch.float32).contiguous(), dtype=wp.vec2),
                      substeps], outputs=list(out.values()), device="cpu")
    return {name: wp.to_torch(a).clone() for name, a in out.items()}
