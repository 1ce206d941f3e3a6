"""A trained policy that leaves the simulator: a file that runs with torch alone.

:func:`export_policy` writes the deterministic policy (observation normalisation included) as a
``torch.export`` program (``.pt2``): raw observation (B, D) in, action (B, 2) in [-1, 1] out,
the action TorchRL's deterministic exploration gives (tanh of the Gaussian's mean). The file
also carries ``atrv_warp.json``, the whole contract a robot stack needs to run it without this package
(:func:`contract`): every observation field with its bound, unit and frame; the action's kind (wheel
``torque`` or a ``twist`` for ``/cmd_vel``), units and scale; the observation's kind; the control period (``step_dt``, the simulator's); the scan's geometry (beams, field of view, range
limits, the sectors' angular edges and clip) and how a missing or too-close return reads; and what the
action history means. The exporter checks the policy against its task first, as ``load_policy`` does.

Load it anywhere torch runs, with no Warp, Newton or TorchRL, through the light core's checked reader (a plain
``torch.export.load`` can unpickle what a crafted file holds; :func:`atrv_warp.core.contract.read_exported` refuses
such a file before torch reads it, and a contract of another format)::

    import torch
    from atrv_warp.core.contract import read_exported
    program, spec = read_exported("policy.pt2")
    action = program.module()(observation)          # (B, D) float32 -> (B, 2)
    command = action * torch.tensor(spec["action"]["scale"])   # torque: [left, right] N·m; twist: [m/s, rad/s]

A robot policy's observation (``observation_kind`` ``robot``) is built from the robot's messages by
:class:`atrv_warp.core.observation.RobotObservation.from_contract(spec) <atrv_warp.core.observation.RobotObservation>`.

With ``onnx=True`` (``--onnx``; the ``onnx`` extra) it also writes ``OUT.onnx`` with the same
description in its metadata, and checks it with onnxruntime against the torch module.

The command line is ``python -m atrv_warp.export [--onnx] [POLICY] OUT``.
"""

from __future__ import annotations

import json
from pathlib import Path

import torch
from torch import nn

from atrv_warp.core.contract import CONTRACT_FILE, EXPORT_FORMAT, read_exported
from atrv_warp.core.files import ExportedFileError
from atrv_warp.policy import load_policy, policy_path, policy_record
from atrv_warp.sim.config import SimConfig
from atrv_warp.sim.scanner import ScannerConfig
from atrv_warp.storage import FileFormatError
from atrv_warp.task.spec import ACTION_DIM, observation_fields, policy_contract

__all__ = ["EXPORT_FORMAT", "PolicyNet", "contract", "export_onnx", "export_policy", "load_exported"]

class PolicyNet(nn.Module):
    """Raw observation (B, obs_dim) -> deterministic action (B, ACTION_DIM) in [-1, 1]."""

    def __init__(self, net: nn.Sequential):
        super().__init__()
        self.normalize, self.mlp = net[0], net[1]  # Normalize, MLP; net[2] splits (loc, scale)
        self.obs_dim = self.normalize.loc.numel()

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        loc = self.mlp(self.normalize(observation))[..., :ACTION_DIM]
        return torch.tanh(loc)


def scanner_mount(robot, frame: str | None = None) -> dict | None:
    """Where the policy's scanner sat: ``frame`` (default: the robot's laser frame) in the robot's chassis link, as
    its URDF places it (``{"parent", "x", "y", "z", "yaw"}``, [m] and [rad]), what the deploy node measures a real
    scanner's mounting against; ``None`` where the robot's URDF cannot be read here."""
    import math

    from atrv_warp.core.robot import RobotFileError, load_robot
    from atrv_warp.sim.config import RoverConfig
    from atrv_warp.sim.urdf import URDFError, load_rover

    frame = frame or robot.laser_frame
    try:  # a record holds the robot's facts, not its URDF: the robot file of that name, if its URDF is the same
        here = load_robot(robot.name)
        if here.urdf_sha256 != robot.urdf_sha256:
            return None
        frames = {f.name: f.transform for f in load_rover(RoverConfig(robot=here.path)).frames}
    except (OSError, RobotFileError, URDFError, ValueError):
        return None
    if frame not in frames:
        return None
    m = frames[frame]
    return {"parent": robot.chassis, "x": float(m[0, 3]), "y": float(m[1, 3]), "z": float(m[2, 3]),
            "yaw": math.atan2(float(m[1, 0]), float(m[0, 0]))}


def robot_footprint(robot) -> list[list[float]] | None:
    """The robot's outline about its chassis origin, as Nav2 writes a footprint (the corners [x, y] [m] of the
    bounding rectangle of the simulator's footprint: its chassis box and wheels), what a Nav2 stack's costmaps need;
    ``None`` where the robot's URDF cannot be read here (as :func:`scanner_mount`)."""
    from atrv_warp.core.robot import RobotFileError, load_robot
    from atrv_warp.sim.config import RoverConfig
    from atrv_warp.sim.urdf import URDFError, footprint_points, load_rover

    try:
        here = load_robot(robot.name)
        if here.urdf_sha256 != robot.urdf_sha256:
            return None
        rover = RoverConfig(robot=here.path)
        points = footprint_points(load_rover(rover), rover)
    except (OSError, RobotFileError, URDFError, ValueError):
        return None
    (x0, y0), (x1, y1) = points.min(axis=0), points.max(axis=0)
    return [[round(float(x), 4), round(float(y), 4)] for x, y in ((x1, y1), (x1, y0), (x0, y0), (x0, y1))]


def contract(source: Path, payload: dict, sim: SimConfig | None = None) -> dict:
    """What the exported program expects and gives, as plain values (the file's ``atrv_warp.json``, format 3).

    The task's part (:func:`atrv_warp.task.spec.policy_contract`): ``observation_kind`` and every observation field
    with low, high, unit and frame; the ``action``'s kind (``torque`` | ``twist``), its scale and units per column
    and the task's limits they come from (``action_scale`` [N·m], or ``max_linear`` [m/s] and ``max_angular``
    [rad/s]), and what a robot does with it; the scan's sectors; the action history. Added here: the format, the
    source file, the policy's metadata, the ``robot`` it was trained on (name, title, limits, IMU and laser frames,
    its ``footprint_m``: :func:`robot_footprint`),
    the control period (``step_dt`` [s], ``rate_hz``), the radius within which its task counts a goal reached
    (``reach_radius_m``: the deploy node's default ``goal_tolerance``) and the scanner's geometry (``beams``,
    ``fov_rad``, ``range_min_m``, ``range_max_m``, ``frame``, and its ``mount`` on the chassis: :func:`scanner_mount`),
    and ``trained_with``, the task and robot records themselves (what ``evaluate`` runs an exported file on, in our
    simulator or the twin; a format-1 policy file has none). All of it from the task and robot the policy records
    (:func:`atrv_warp.policy.policy_record`), never from today's code: a task's limits changed since do not enter an
    old policy's contract. :class:`atrv_warp.core.observation.RobotObservation` builds a robot policy's input from it.

    Args:
        source: The policy file it was exported from.
        payload: The saved policy (:func:`atrv_warp.policy.policy_payload`'s form).
        sim: The simulator's settings it was trained at (default: :class:`~atrv_warp.sim.config.SimConfig`'s);
            the control period is the task's ``control_period`` where it sets one, else its ``step_dt``.
    """
    record = policy_record(payload)
    meta = payload.get("meta", {})
    task, robot, sim = record.task.config, record.robot, sim or SimConfig()
    if robot.sensors:  # the robot side reads one scan (/scan): the contract has no place for another sensor yet
        names = ", ".join(s["name"] for s in robot.sensors)
        raise ValueError(f"{source}: the policy observes its robot file's [[sensors]] ({names}) beside the scan; "
                         "an exported policy and atrv-deploy read links.laser's scan only, so it cannot be exported")
    spec = policy_contract(task)
    if task.scan_beams:
        sc = ScannerConfig(beams=task.scan_beams, fov=task.scan_fov)
        spec["scan"] = {"beams": sc.beams, "fov_rad": sc.fov, "angles": "evenly spaced over fov, centred on the "
                        "scanner's +x, counter-clockwise (right to left), as sensor_msgs/LaserScan orders them",
                        "frame": sc.frame or robot.laser_frame, "mount": scanner_mount(robot, sc.frame),
                        "range_min_m": sc.min_range, "range_max_m": sc.max_range,
                        **(spec["scan"] or {"sectors": None})}
    step_dt = task.control_period or sim.step_dt
    lim = robot.limits
    robot_part = {"name": robot.name, "title": robot.title, "imu_frame": robot.imu_frame,
                  "laser_frame": robot.laser_frame, "recorded": record.recorded,
                  "limits": {"linear_velocity": lim.linear_velocity, "angular_velocity": lim.angular_velocity,
                             "linear_acceleration": lim.linear_acceleration,
                             "angular_acceleration": lim.angular_acceleration},
                  "footprint_m": robot_footprint(robot)}
    contract = {"format": EXPORT_FORMAT, "source": str(source), "policy_meta": meta, "task": record.task.name,
                "robot": robot_part, **spec, "step_dt": step_dt, "rate_hz": 1.0 / step_dt,
                "reach_radius_m": task.reach_radius}
    if record.recorded:  # the task and robot as trained, as the policy file keeps them: what evaluate runs it on
        contract["trained_with"] = {"meta": {"task": record.task.name}, "task_record": payload["task_record"],
                                    "robot": payload["robot"]} | ({"sites": payload["sites"]} if "sites" in payload else {})
    return contract


def export_policy(policy: str | Path | None, out: str | Path, *, onnx: bool = False, force: bool = False) -> Path:
    """Write the policy file ``policy`` (or a shipped policy's name, :data:`atrv_warp.policy.SHIPPED_POLICIES`;
    default: the shipped ``reach`` one) to ``out`` (``.pt2``), and with ``onnx`` also to ``out`` with the suffix
    ``.onnx``.

    Raises:
        FileExistsError: ``out`` (or its ``.onnx``) exists and ``force`` is not set.
        OutputPathError: ``out`` cannot be written (named), before anything is loaded.
    """
    from atrv_warp.core.files import check_output_path
    from atrv_warp.storage import load_weights

    if Path(out).suffix != ".pt2":
        raise ValueError(f"{out}: the exported file must end in .pt2 (a torch.export archive)")
    for target in (Path(out), *([Path(out).with_suffix(".onnx")] if onnx else [])):
        check_output_path(target, "exported policy", new_folders=True)
        if target.exists() and not force:
            raise FileExistsError(f"{target} exists: pass --force to overwrite it, or name another file")
    if onnx:  # a missing extra stops before anything is written
        import onnx as _onnx  # noqa: F401
        import onnxruntime  # noqa: F401
        import onnxscript  # noqa: F401
    source = policy_path(policy)
    payload = load_weights(source, "policy file")  # a file that is no policy is named
    payload = payload["policy"] if isinstance(payload.get("policy"), dict) else payload  # a training checkpoint's
    meta = payload.get("meta", {})
    # the contract is the task's: a policy trained on another version of it is refused, naming both widths
    actor = load_policy(source, deterministic=False, task=meta.get("task", "reach"))
    net = PolicyNet(actor.module[0].module).eval()
    example = torch.zeros(2, net.obs_dim)
    batch = torch.export.Dim("batch")
    with torch.no_grad():
        program = torch.export.export(net, (example,), dynamic_shapes=({0: batch},))
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.stem}.tmp.pt2")  # atomic: written beside, then renamed
    spec = json.dumps(contract(source, payload), default=str)
    torch.export.save(program, tmp, extra_files={CONTRACT_FILE: spec})
    tmp.replace(out)
    if onnx:
        export_onnx(net, out.with_suffix(".onnx"), spec, policy_record(payload).task.config)
    return out


def export_onnx(net: PolicyNet, out: Path, spec: str, task=None, checks: int = 1000) -> Path:
    """``net`` as ONNX (dynamic batch), ``spec`` in its metadata, checked with onnxruntime on
    ``checks`` random observations (largest difference from torch under 1e-5, else ``RuntimeError``)."""
    import contextlib
    import io
    import logging
    import warnings

    import numpy as np
    import onnx
    import onnxruntime

    tmp = out.with_name(f".{out.stem}.tmp.onnx")
    onnx_log = logging.getLogger("torch.onnx")
    level = onnx_log.level
    onnx_log.setLevel(logging.ERROR)  # e.g. "torchvision is not installed. Skipping torchvision::nms"
    try:
        with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):  # the exporter's progress lines
            warnings.simplefilter("ignore")
            torch.onnx.export(net, (torch.zeros(2, net.obs_dim),), str(tmp), dynamo=True, verbose=False,
                              input_names=["observation"], output_names=["action"],
                              dynamic_shapes=({0: torch.export.Dim("batch")},))
    finally:
        onnx_log.setLevel(level)
    model = onnx.load(str(tmp))
    onnx.helper.set_model_props(model, {CONTRACT_FILE: spec})
    onnx.save(model, str(tmp))
    bound = np.array([f.bound for f in observation_fields(task)], dtype=np.float32)
    obs = np.random.default_rng(0).uniform(-1.1, 1.1, (checks, net.obs_dim)).astype(np.float32) * bound
    session = onnxruntime.InferenceSession(str(tmp), providers=["CPUExecutionProvider"])
    got = session.run(None, {"observation": obs})[0]
    with torch.no_grad():
        want = net(torch.from_numpy(obs)).numpy()
    err = float(np.abs(got - want).max())
    if not err < 1e-5:
        tmp.unlink()
        raise RuntimeError(f"ONNX export disagrees with the torch policy by {err:.2e} (> 1e-5); not written")
    tmp.replace(out)
    return out


def load_exported(path: str | Path) -> tuple[nn.Module, dict]:
    """The exported program's module and its ``atrv_warp.json`` description, read by
    :func:`atrv_warp.core.contract.read_exported` (the file checked before torch loads it).

    Raises:
        FileNotFoundError: No such file.
        FileFormatError: The file is refused by the check (named: nothing in it ran), carries no contract, or one of
            a format this version does not read (named, with the one expected: export the policy again).
    """
    try:
        program, spec = read_exported(path)
    except ExportedFileError as err:
        raise FileFormatError(str(err)) from None
    return program.module(), spec
