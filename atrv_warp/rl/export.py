"""A trained policy that leaves the simulator: a file that runs with torch alone.

:func:`export_policy` writes the deterministic policy (observation normalisation included) as a
``torch.export`` program (``.pt2``): raw observation (B, 10) in, action (B, 2) in [-1, 1] out,
the action TorchRL's deterministic exploration gives (tanh of the Gaussian's mean). The file
also carries ``atrv_warp.json``: the observation fields with their bounds, the action's meaning
and the policy's metadata, so a robot stack can build the observation without this package.

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
from atrv_warp.task.config import get_task
from atrv_warp.task.spec import ACTION_DIM, observation_fields

__all__ = ["EXPORT_FORMAT", "PolicyNet", "export_onnx", "export_policy", "load_exported"]

EXPORT_FORMAT = "atrv_warp.exported_policy/1"


class PolicyNet(nn.Module):
    """Raw observation (B, obs_dim) -> deterministic action (B, ACTION_DIM) in [-1, 1]."""

    def __init__(self, net: nn.Sequential):
        super().__init__()
        self.normalize, self.mlp = net[0], net[1]  # Normalize, MLP; net[2] splits (loc, scale)
        self.obs_dim = self.normalize.loc.numel()

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        loc = self.mlp(self.normalize(observation))[..., :ACTION_DIM]
        return torch.tanh(loc)


def _spec(source: Path, meta: dict) -> dict:
    task = get_task(meta.get("task", "reach"))
    return {"format": EXPORT_FORMAT, "source": str(source), "policy_meta": meta, "task": meta.get("task", "reach"),
            "observation": [{"name": f.name, "bound": f.bound, "description": f.description}
                            for f in observation_fields(task)],
            "action": {"names": ["left", "right"], "low": -1.0, "high": 1.0, "scale": task.action_scale,
                       "unit_after_scale": "N·m wheel torque, per side"},
            "step_dt": 0.05}


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
    actor = load_policy(source, deterministic=False)  # checks the file, names any problem
    payload = load_weights(source, "policy file")
    meta = payload.get("policy", payload).get("meta", {})
    net = PolicyNet(actor.module[0].module).eval()
    example = torch.zeros(2, net.obs_dim)
    batch = torch.export.Dim("batch")
    with torch.no_grad():
        program = torch.export.export(net, (example,), dynamic_shapes=({0: batch},))
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.stem}.tmp.pt2")  # atomic: written beside, then renamed
    spec = json.dumps(_spec(source, meta), default=str)
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
