"""A calibration bag recorded from the MuJoCo twin: a rover whose contact, friction and tyre are another engine's,
for fitting our simulator across engines (``atrv-calibrate --record-example OUT.mcap --engine mujoco``).

:func:`record_twin_bag` drives one :class:`~.twin.MujocoTwin` on flat ground with the calibration's scripted drive
(:class:`~atrv_warp.sim.sysid.excitation.Excitation`, the commands the simulator node's bags get for
the same seed and poses) and writes what the simulator node records for a fit, on the same topics, stamps and
conventions: ``/cmd_vel`` when the command is given (before the step it drives), and after each step
``/joint_states`` (wheel positions, velocities, the motors' applied torques as efforts), ``/ground_truth/odom`` (the
chassis' pose with the reference noise of a motion-capture or RTK fix, its body-frame twist) and ``/odom`` (the
driver's wheel odometry). No rclpy: the bag is written from the message definitions.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from atrv_warp.core.geometry import quat_to_yaw, yaw_to_quat
from atrv_warp.core.kinematics import track_width
from atrv_warp.integrations.ros.bag import BagWriter
from atrv_warp.sim.config import RoverConfig
from atrv_warp.sim.driver import DriverConfig
from atrv_warp.sim.sysid.excitation import Excitation
from atrv_warp.sim.urdf import load_rover

from .mjcf import MujocoContact
from .twin import MujocoTwin

__all__ = ["record_twin_bag", "twin_driver"]


def twin_driver(driver: DriverConfig | None = None, nominal: RoverConfig | None = None) -> DriverConfig:
    """``driver`` (default: the base's) with its wheel radius and track set where it leaves them to the rover: the
    ``nominal`` rover's (default: the realistic one), as the simulator node configures a base whatever the physical
    rover's wear. :class:`~.twin.MujocoTwin` would otherwise take them from the rover it simulates."""
    driver = driver or DriverConfig()
    nominal = nominal or RoverConfig()
    radius = driver.wheel_radius if driver.wheel_radius is not None else nominal.wheel_radius
    track = driver.track_width if driver.track_width is not None else track_width(load_rover(nominal), nominal)
    return dataclasses.replace(driver, wheel_radius=radius, track_width=track)


def record_twin_bag(path, minutes: float = 5.0, *, seed: int = 0, rover: RoverConfig | None = None,
                    friction: float | None = None, driver: DriverConfig | None = None, truth_noise: float = 0.01,
                    truth_yaw_noise: float = 0.02, wheel_speed_noise: float = 0.0, contact: MujocoContact | None = None,
                    progress=None) -> str:
    """Drive the MuJoCo twin of ``rover`` at Coulomb ``friction`` for ``minutes`` of sim time with the scripted
    drive of ``seed`` and record the bag at ``path`` (see the module). ``driver``: the base's driver, its radius and
    track the nominal rover's unless set (:func:`twin_driver`); ``truth_noise`` [m], ``truth_yaw_noise`` [rad]:
    Gaussian noise on the reference pose; ``wheel_speed_noise`` [rad/s]: on the encoders' speeds (the simulator
    node's parameters of the same names); ``contact``: MuJoCo's contact settings (default: the tyre's compliance,
    :class:`~.mjcf.MujocoContact`). ``progress(seconds)`` is called every 10 s of sim time. Returns ``path``.

    Raises:
        ValueError: ``minutes`` or a noise is not a finite number >= 0 (one line naming it); the twin blew up.
    """
    for name, value in (("minutes", minutes), ("truth_noise", truth_noise), ("truth_yaw_noise", truth_yaw_noise),
                        ("wheel_speed_noise", wheel_speed_noise)):
        if not (math.isfinite(value) and value >= 0):
            raise ValueError(f"record_twin_bag: {name} must be a finite number >= 0, got {value!r}")
    twin = MujocoTwin(rover=rover, friction=friction, driver=twin_driver(driver), contact=contact)
    excitation = Excitation(seed)
    noise = np.random.default_rng([seed, 1])  # the reference's and the encoders' noise, apart from the drive's draws
    joints = [w.joint for w in twin.description.wheels]
    dt = twin.sim_cfg.step_dt
    steps = round(60.0 * minutes / dt)
    bag = BagWriter(str(path))
    try:
        reference = _write_state(bag, twin, joints, noise, truth_noise, truth_yaw_noise, wheel_speed_noise)
        for k in range(steps):
            twin.step()
            if not twin.finite:
                raise ValueError(f"record_twin_bag: the twin's state went non-finite at {twin.time:.2f} s")
            reference = _write_state(bag, twin, joints, noise, truth_noise, truth_yaw_noise, wheel_speed_noise)
            if k + 1 < steps:  # the command for the next step, from this step's reference pose
                command = excitation.update(twin.time, reference)
                if command is not None:
                    twin.command(*command)
                    bag.write("/cmd_vel", "geometry_msgs/msg/Twist",
                              {"linear": _vector((command[0], 0.0, 0.0)), "angular": _vector((0.0, 0.0, command[1]))},
                              _ns(twin.time))
            if progress is not None and (k + 1) % round(10.0 / dt) == 0:
                progress(twin.time)
    except BaseException:
        bag.close()
        Path(path).unlink(missing_ok=True)
        raise
    bag.close()
    return str(path)


def _ns(seconds: float) -> int:
    return round(seconds * 1e9)


def _vector(v) -> dict:
    return {"x": float(v[0]), "y": float(v[1]), "z": float(v[2])}


def _quaternion(q) -> dict:
    return {"x": float(q[0]), "y": float(q[1]), "z": float(q[2]), "w": float(q[3])}


def _header(ns: int, frame: str) -> dict:
    return {"stamp": {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}, "frame_id": frame}


def _odometry(ns: int, frame: str, position, quat, linear, angular) -> dict:
    return {"header": _header(ns, frame), "child_frame_id": "base_link",
            "pose": {"pose": {"position": _vector(position), "orientation": _quaternion(quat)}, "covariance": [0.0] * 36},
            "twist": {"twist": {"linear": _vector(linear), "angular": _vector(angular)}, "covariance": [0.0] * 36}}


def _write_state(bag: BagWriter, twin: MujocoTwin, joints: list[str], noise: np.random.Generator, truth_noise: float,
                 truth_yaw_noise: float, wheel_speed_noise: float) -> tuple[float, float, float]:
    """The step's /joint_states, /ground_truth/odom and /odom; the reference pose (x, y, yaw) as recorded."""
    ns = _ns(twin.time)
    velocity = twin.data.qvel[twin.wheel_dof].copy()
    if wheel_speed_noise > 0:
        velocity += wheel_speed_noise * noise.standard_normal(len(velocity))
    bag.write("/joint_states", "sensor_msgs/msg/JointState",
              {"header": _header(ns, ""), "name": joints,
               "position": twin.data.qpos[twin.model.jnt_qposadr[twin.model.dof_jntid[twin.wheel_dof]]].tolist(),
               "velocity": velocity.tolist(), "effort": (twin.wheel_sign * twin.wheel_torque).tolist()}, ns)
    pose = twin.root_pose
    rot = twin.chassis_rotation
    position, quat = pose[:3].copy(), pose[3:]
    if truth_noise > 0 or truth_yaw_noise > 0:  # a motion-capture or RTK fix
        e = noise.standard_normal(3)
        position[:2] += truth_noise * e[:2]
        quat = _turn(yaw_to_quat(truth_yaw_noise * float(e[2])).numpy(), quat)
    bag.write("/ground_truth/odom", "nav_msgs/msg/Odometry",
              _odometry(ns, "world", position, quat, rot.T @ twin.linear_velocity, rot.T @ twin.angular_velocity), ns)
    x, y, yaw = twin.odometry
    bag.write("/odom", "nav_msgs/msg/Odometry",
              _odometry(ns, "odom", (x, y, 0.0), yaw_to_quat(yaw).numpy(), (twin.odom_twist[0], 0.0, 0.0),
                        (0.0, 0.0, twin.odom_twist[1])), ns)
    return float(position[0]), float(position[1]), float(quat_to_yaw(tuple(float(v) for v in quat)))


def _turn(dq: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The quaternion product ``dq * q`` (x, y, z, w)."""
    x1, y1, z1, w1 = dq
    x2, y2, z2, w2 = q
    return np.array([w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2, w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                     w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2, w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2])
