"""A trained policy that leaves the simulator: a file that runs with torch alone.

:func:`export_policy` writes the deterministic policy (observation normalisation included) as a
``torch.export`` program (``.pt2``): raw observation (B, D) in, action (B, 2) in [-1, 1] out,
the action TorchRL's deterministic exploration gives (tanh of the Gaussian's mean). The file
also carries ``atrv_warp.json``, the whole contract a robot stack needs to run it without this package
(:func:`contract`): every observation field with its bound, unit and frame; the action's kind, units and
scale; the control period (``step_dt``, the simulator's); the scan's geometry (beams, field of view, range
limits, the sectors' angular edges and clip) and how a missing or too-close return reads; and what the
action history means. The exporter checks the policy against its task first, as ``load_policy`` does.

Load it anywhere torch runs, with no Warp, Newton or TorchRL::

    import json, torch
    extra = {"atrv_warp.json": ""}
    program = torch.export.load("policy.pt2", extra_files=extra)
    spec = json.loads(extra["atrv_warp.json"])
    action = program.module()(observation)          # (B, 10) float32 -> (B, 2)
    torques = action * spec["action"]["scale"]      # [left, right] wheel torque [N·m]

With ``onnx=True`` (``--onnx``; the ``onnx`` extra) it also writes ``OUT.onnx`` with the same
description in its metadata, and checks it with onnxruntime against the torch module.

The command line is ``python -m atrv_warp.export [--onnx] [POLICY] OUT``.
"""

from __future__ import annotations

import json
from pathlib import Path

import torch
from torch import nn

from atrv_warp.policy import load_policy, pretrained_policy_path
from atrv_warp.sim.config import SimConfig
from atrv_warp.sim.scanner import ScannerConfig
from atrv_warp.task.config import get_task
from atrv_warp.task.spec import ACTION_DIM, ACTIONS, observation_bounds, observation_fields, scan_sectors

__all__ = ["EXPORT_FORMAT", "PolicyNet", "contract", "export_onnx", "export_policy", "load_exported"]

EXPORT_FORMAT = "atrv_warp.exported_policy/2"
"""Format tag of an exported policy's ``atrv_warp.json`` (2: the whole contract, :func:`contract`)."""


class PolicyNet(nn.Module):
    """Raw observation (B, obs_dim) -> deterministic action (B, ACTION_DIM) in [-1, 1]."""

    def __init__(self, net: nn.Sequential):
        super().__init__()
        self.normalize, self.mlp = net[0], net[1]  # Normalize, MLP; net[2] splits (loc, scale)
        self.obs_dim = self.normalize.loc.numel()

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        loc = self.mlp(self.normalize(observation))[..., :ACTION_DIM]
        return torch.tanh(loc)


def contract(source: Path, meta: dict, sim: SimConfig | None = None) -> dict:
    """What the exported program expects and gives, as plain values (the file's ``atrv_warp.json``).

    Args:
        source: The policy file it was exported from.
        meta: The policy's metadata (``meta["task"]``: the task it observes, ``reach`` if absent).
        sim: The simulator's settings it was trained at (default: :class:`~atrv_warp.sim.config.SimConfig`'s);
            the control period is its ``step_dt``.
    """
    name = meta.get("task", "reach")
    task, sim = get_task(name), sim or SimConfig()
    fields = observation_fields(task)
    low, high = observation_bounds(task=task)
    sectors = scan_sectors(task)
    scan = None
    if task.scan_beams:
        sc = ScannerConfig(beams=task.scan_beams, fov=task.scan_fov)
        scan = {"beams": sc.beams, "fov_rad": sc.fov, "angles": "evenly spaced over fov, centred on the scanner's +x, "
                "counter-clockwise (right to left), as sensor_msgs/LaserScan orders them", "frame": sc.frame,
                "range_min_m": sc.min_range, "range_max_m": sc.max_range,
                "sectors": sectors.describe() if sectors is not None else None}
    history = None
    if task.action_history:
        history = {"steps": task.action_history, "meaning": "last_action_k_left/right: the action (in [-1, 1], "
                   "clipped) the policy chose k steps before this observation, newest first; zero after a reset"}
    return {
        "format": EXPORT_FORMAT, "source": str(source), "policy_meta": meta, "task": name,
        "observation": [{"name": f.name, "index": i, "low": float(lo), "high": float(hi), "bound": f.bound,
                         "unit": f.unit, "frame": f.frame, "description": f.description}
                        for i, (f, lo, hi) in enumerate(zip(fields, low.tolist(), high.tolist()))],
        "observation_clipped": "each value is clipped to [low, high] before the policy sees it",
        "action": _action_contract(task),
        "step_dt": sim.step_dt, "rate_hz": 1.0 / sim.step_dt,
        "scan": scan, "action_history": history,
    }


def _action_contract(task) -> dict:
    """What the action commands: each side's wheel torque, or a /cmd_vel (:data:`~atrv_warp.task.spec.ACTIONS`)."""
    if task.action == "twist":
        return {"kind": "twist", "names": list(ACTIONS["twist"].columns), "low": -1.0, "high": 1.0,
                "scale": [task.max_linear, task.max_angular], "unit_after_scale": ["m/s", "rad/s"],
                "meaning": "action x scale is a /cmd_vel (geometry_msgs/Twist linear.x, angular.z) to the base's "
                "motor driver; actions are clipped to [-1, 1]"}
    return {"kind": "wheel_torque", "names": ["left", "right"], "low": -1.0, "high": 1.0,
            "scale": task.action_scale, "unit_after_scale": "N·m", "meaning": "action x scale is the torque "
            "of every wheel on that side; actions are clipped to [-1, 1]"}


def export_policy(policy: str | Path | None, out: str | Path, *, onnx: bool = False) -> Path:
    """Write the policy file ``policy`` (default: the shipped one) to ``out`` (``.pt2``), and with
    ``onnx`` also to ``out`` with the suffix ``.onnx``."""
    from atrv_warp.storage import load_weights

    if Path(out).suffix != ".pt2":
        raise ValueError(f"{out}: the exported file must end in .pt2 (a torch.export archive)")
    if onnx:  # a missing extra stops before anything is written
        import onnx as _onnx  # noqa: F401
        import onnxruntime  # noqa: F401
        import onnxscript  # noqa: F401
    source = Path(policy) if policy is not None else pretrained_policy_path()
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
    spec = json.dumps(contract(source, meta), default=str)
    torch.export.save(program, tmp, extra_files={"atrv_warp.json": spec})
    tmp.replace(out)
    if onnx:
        export_onnx(net, out.with_suffix(".onnx"), spec, get_task(meta.get("task", "reach")))
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
    onnx.helper.set_model_props(model, {"atrv_warp.json": spec})
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
    """The exported program's module and its ``atrv_warp.json`` description."""
    extra = {"atrv_warp.json": ""}
    program = torch.export.load(str(path), extra_files=extra)
    return program.module(), json.loads(extra["atrv_warp.json"])
