"""Segments replayed in the simulator, a batch of worlds at once, each world with its own parameter values: the
residuals the fit lowers and the paths the report draws."""

from __future__ import annotations

import math

import numpy as np
import torch

from atrv_warp.core.geometry import quat_to_yaw, wrap_angle
from atrv_warp.sim.config import ContactConfig, RoverConfig
from atrv_warp.sim.driver import DriverConfig
from atrv_warp.sim.sysid.config import HEADING_ARM, CalibrationConfig
from atrv_warp.sim.sysid.segments import Segments, integral_from_effort

__all__ = ["Replay"]

_POSITION_SCALE = 0.05  # [m]: position error that costs 1
_WHEEL_SCALE = 0.5  # [rad/s]: wheel-speed error that costs 1
_EFFORT_SCALE = 1.0  # [N·m]: wheel-effort error that costs 1
_NO_TAPER = 1.0e4  # [rad/s]: an effort replay's motor no-load speed (the recorded torques already taper)


class Replay:
    """Segments replayed forward in chunks of a :class:`~atrv_warp.sim.diff.DiffRollout`'s worlds, each world with
    its own parameter values; no tape: the fit's derivatives are finite differences, each in worlds of its own."""

    def __init__(self, segments: Segments, worlds: int, rover: RoverConfig, contact: ContactConfig,
                 cfg: CalibrationConfig, driver: DriverConfig):
        from atrv_warp.sim.diff import DiffRollout

        # the mass matrix refreshed once per step, as the simulator steps by default (its dense products are most of
        # a CPU rollout's time)
        self.roll = DiffRollout(worlds, steps=segments.inputs.shape[1], rover=rover, contact=contact,
                                twist=segments.command == "cmd_vel", driver=driver, action_scale=1.0,
                                mass_matrix_interval=None)
        self.segments, self.worlds = segments, worlds
        self.rover, self.driver = rover, driver
        self.warmup = round(cfg.warmup / 0.05) if segments.command == "cmd_vel" else 0
        self.nominal_chassis_mass = self.roll.nominal_chassis_mass
        joints = [w.joint for w in self.roll.sim.description.wheels]
        self.start_wheels = segments.wheel  # (S, 2) each side's speed, or (S, W) each wheel's in the rover's order
        if segments.wheel_each is not None and set(segments.wheel_joints) == set(joints):
            self.start_wheels = segments.wheel_each[:, [segments.wheel_joints.index(j) for j in joints]]

    def start_integral(self, pad: np.ndarray, kwargs: dict) -> torch.Tensor:
        """(W, 2) the driver's PI integral at the segments' starts, for each world's motor
        (:func:`integral_from_effort`, and the replayed driver's where that has none)."""
        seg = self.segments
        replayed = torch.as_tensor(seg.integral[pad], dtype=torch.float32)
        if seg.start_effort is None or seg.start_target is None:
            return replayed
        w = len(pad)
        scale = torch.as_tensor(kwargs.get("torque_scale", self.rover.torque_scale), dtype=torch.float32).expand(w)
        limit = torch.as_tensor(kwargs.get("speed_limit", self.rover.wheel_speed_limit), dtype=torch.float32).expand(w)
        integral = integral_from_effort(seg.start_effort[pad], seg.start_target[pad], seg.wheel[pad], self.driver,
                                        torque_scale=scale[:, None], speed_limit=limit[:, None])
        return torch.where(torch.isfinite(integral), integral, replayed)

    @torch.no_grad()
    def _chunk(self, index: np.ndarray, values: dict[str, np.ndarray]) -> tuple[torch.Tensor, torch.Tensor,
                                                                               torch.Tensor]:
        seg, n, w = self.segments, len(index), self.worlds
        pad = np.concatenate([index, np.full(w - n, index[0])])
        poses = torch.zeros(w, 3)
        poses[:, 2] = torch.as_tensor(seg.yaw0[pad], dtype=torch.float32)
        kwargs = {} if seg.command == "cmd_vel" else {"torque_scale": 1.0, "speed_limit": _NO_TAPER}
        for name, v in values.items():
            v = torch.as_tensor(np.concatenate([v, np.full(w - n, v[0])]), dtype=torch.float32)
            if name == "payload_mass":
                kwargs["chassis_mass"] = self.nominal_chassis_mass + v
            else:
                kwargs[name] = v
        # each world starts at the rest height of its own wheel radius and payload, as the recorded rover drove
        payload = kwargs["chassis_mass"] - self.nominal_chassis_mass if "chassis_mass" in kwargs else None
        state = self.roll.moving_state(poses, torch.as_tensor(seg.velocity[pad], dtype=torch.float32),
                                       torch.as_tensor(seg.yaw_rate[pad], dtype=torch.float32),
                                       torch.as_tensor(self.start_wheels[pad], dtype=torch.float32),
                                       wheel_radius=kwargs.get("wheel_radius"), payload_mass=payload,
                                       tilt=None if seg.tilt is None else torch.as_tensor(seg.tilt[pad]),
                                       tilt_rate=None if seg.tilt_rate is None else torch.as_tensor(seg.tilt_rate[pad]))
        actions = torch.as_tensor(seg.inputs[pad], dtype=torch.float32).transpose(0, 1).contiguous()
        integral = self.start_integral(pad, kwargs)
        sim_poses, speeds, torques = self.roll(actions, state, integral=integral, wheel_speeds=True,
                                               wheel_torques=True, **kwargs)
        ref = torch.as_tensor(seg.ref_pose[pad], dtype=torch.float32).transpose(0, 1)  # (L + 1, W, 3)
        ref_wheel = torch.as_tensor(seg.ref_wheel[pad], dtype=torch.float32).transpose(0, 1)
        xy = sim_poses[..., :2] - sim_poses[:1, :, :2]
        yaw = quat_to_yaw(sim_poses[..., 3:7])
        dxy = xy - ref[..., :2]
        dyaw = wrap_angle(yaw - ref[..., 2])
        # residuals whose squares sum to the segment's loss: each term's mean over its steps. The motor terms skip
        # the first steps, while the driver's reconstructed integral settles (its error decays within a few of its
        # 0.01 s loops); the path keeps them, it integrates what they do
        settled = slice(self.warmup, None)
        parts = [dxy / (_POSITION_SCALE * math.sqrt(len(dxy))),
                 (HEADING_ARM * dyaw / (_POSITION_SCALE * math.sqrt(len(dyaw))))[..., None]]
        wheel = (speeds - ref_wheel)[settled]
        parts.append(wheel / (_WHEEL_SCALE * math.sqrt(len(wheel))))
        if seg.ref_effort is not None:
            ref_effort = torch.as_tensor(seg.ref_effort[pad], dtype=torch.float32).transpose(0, 1)
            effort = (torques - ref_effort)[settled]
            parts.append(effort / (_EFFORT_SCALE * math.sqrt(len(effort))))
        residuals = torch.cat([p.transpose(0, 1).reshape(w, -1) for p in parts], -1)  # (W, R)
        path = torch.cat([xy, yaw[..., None]], -1)
        return residuals[:n], dxy.norm(dim=-1).mean(0)[:n], path[:, :n]

    def channels(self, residuals: np.ndarray) -> dict[str, np.ndarray]:
        """Each segment's root-mean-square error per channel, in its unit, from its residuals (S, R) as
        :meth:`residuals` returns them: ``position`` [m], ``heading`` [rad], ``wheel_speed`` [rad/s] (per side) and,
        where the bag has efforts, ``effort`` [N·m] (per side)."""
        steps = self.segments.inputs.shape[1]
        sizes = {"position": 2 * (steps + 1), "heading": steps + 1, "wheel_speed": 2 * (steps + 1 - self.warmup)}
        if self.segments.ref_effort is not None:
            sizes["effort"] = 2 * (steps - self.warmup)
        scale = {"position": _POSITION_SCALE, "heading": _POSITION_SCALE / HEADING_ARM,
                 "wheel_speed": _WHEEL_SCALE / math.sqrt(2.0), "effort": _EFFORT_SCALE / math.sqrt(2.0)}
        out, at = {}, 0
        for name, size in sizes.items():
            out[name] = scale[name] * np.sqrt((residuals[:, at:at + size] ** 2).sum(-1))
            at += size
        return out

    def residuals(self, index: np.ndarray, values: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Replay segments ``index`` (any number, in chunks of :attr:`worlds`), world i with ``values[p][i]``;
        returns each segment's residuals (S, R) (their squares sum to its loss), its mean position error [m] (S,)
        and the simulated path (L + 1, S, 3)."""
        out = [self._chunk(index[i:i + self.worlds], {p: v[i:i + self.worlds] for p, v in values.items()})
               for i in range(0, len(index), self.worlds)]
        return tuple(np.concatenate([o[j].double().numpy() for o in out], 1 if j == 2 else 0) for j in range(3))
