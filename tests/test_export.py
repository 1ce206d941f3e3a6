"""Policy export: a .pt2 file that runs with torch alone and gives the TorchRL policy's actions."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from tensordict import TensorDict

from atrv_warp.core.files import OutputPathError
from atrv_warp.policy import load_policy
from atrv_warp.rl.export import export_policy, load_exported
from atrv_warp.storage import FileFormatError
from atrv_warp.task.spec import OBSERVATION

ROOT = Path(__file__).resolve().parent.parent

# Runs in a fresh interpreter where importing warp, newton, torchrl, tensordict or atrv_warp fails.
_STANDALONE = r"""
import importlib.abc, sys
BLOCKED = ("warp", "newton", "torchrl", "tensordict", "atrv_warp")
class Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in BLOCKED:
            raise ImportError(f"{name} is blocked in this test")
sys.meta_path.insert(0, Block())
import torch
program = torch.export.load(sys.argv[1])
obs = torch.load(sys.argv[2])
torch.save(program.module()(obs).detach(), sys.argv[3])
print("loaded:", sorted(m for m in sys.modules if m.split(".")[0] in BLOCKED))
"""


def test_exported_policy_runs_with_torch_alone_and_matches(tmp_path):
    path = export_policy(None, tmp_path / "policy.pt2")
    gen = torch.Generator().manual_seed(0)
    bound = torch.tensor([f.bound for f in OBSERVATION])
    obs = (torch.rand(1000, len(OBSERVATION), generator=gen) * 2.2 - 1.1) * bound  # also beyond the clip bounds
    torch.save(obs, tmp_path / "obs.pt")
    proc = subprocess.run([sys.executable, "-c", _STANDALONE, str(path), str(tmp_path / "obs.pt"),
                           str(tmp_path / "actions.pt")], capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "loaded: []" in proc.stdout  # none of the blocked packages was needed
    actions = torch.load(tmp_path / "actions.pt")
    expected = load_policy()(TensorDict(observation=obs, batch_size=[1000]))["action"]
    assert actions.shape == (1000, 2)
    assert (actions - expected).abs().max().item() < 1e-5
    _, spec = load_exported(path)
    assert [f["name"] for f in spec["observation"]] == [f.name for f in OBSERVATION]
    assert spec["action"]["scale"] == [20.0, 20.0] and spec["action"]["kind"] == "torque"


def test_export_cli_and_bad_input(tmp_path, run_module):
    proc = run_module("atrv_warp.export", str(tmp_path / "p.pt2"), check=False)
    assert proc.returncode == 0 and (tmp_path / "p.pt2").is_file(), proc.stderr[-2000:]
    example = subprocess.run([sys.executable, str(ROOT / "examples" / "run_exported_policy.py"),
                              str(tmp_path / "p.pt2")], capture_output=True, text=True, check=False)
    assert example.returncode == 0 and "wheel torques" in example.stdout, example.stderr[-2000:]
    (tmp_path / "junk.pt").write_bytes(b"not a policy")
    with pytest.raises(FileFormatError, match="junk.pt: not a policy file"):
        export_policy(tmp_path / "junk.pt", tmp_path / "x.pt2")
    with pytest.raises(ValueError, match=r"must end in \.pt2"):
        export_policy(None, tmp_path / "x.onnx")
    assert not (tmp_path / "x.pt2").exists()
    before = (tmp_path / "p.pt2").read_bytes()  # an existing file is kept unless --force
    again = run_module("atrv_warp.export", "nav", str(tmp_path / "p.pt2"), check=False)
    assert again.returncode == 2 and "p.pt2 exists: pass --force to overwrite it" in again.stderr, again.stderr
    assert (tmp_path / "p.pt2").read_bytes() == before
    export_policy("nav", tmp_path / "p.pt2", force=True)
    assert (tmp_path / "p.pt2").read_bytes() != before
    with pytest.raises(OutputPathError, match="cannot write in /proc"):
        export_policy(None, "/proc/atrv/p.pt2")


def test_onnx_export_checked_with_onnxruntime(tmp_path):
    ort = pytest.importorskip("onnxruntime", reason="pip install -e '.[onnx]'")
    import json

    import numpy as np
    import onnx

    path = export_policy(None, tmp_path / "policy.pt2", onnx=True)
    model = tmp_path / "policy.onnx"
    assert model.is_file()
    props = {p.key: p.value for p in onnx.load(str(model)).metadata_props}
    assert json.loads(props["atrv_warp.json"])["action"]["scale"] == [20.0, 20.0]
    obs = torch.rand(1000, len(OBSERVATION), generator=torch.Generator().manual_seed(1)) * 4 - 2
    got = ort.InferenceSession(str(model), providers=["CPUExecutionProvider"]).run(None, {"observation": obs.numpy()})[0]
    expected = load_policy()(TensorDict(observation=obs, batch_size=[1000]))["action"].numpy()
    assert np.abs(got - expected).max() < 1e-5
    assert path.is_file()


def test_the_shipped_nav_policy_exports_its_whole_contract_and_runs_from_the_file_alone(tmp_path):
    """The .pt2 of the shipped nav policy, run with torch alone on observations of the nav env, gives the TorchRL
    policy's actions; its contract names every field with unit and frame, the rate, the scan and the history."""
    from atrv_warp import ATRVjrEnv
    from atrv_warp.core.scan import ScanSectors, sector_readings
    from atrv_warp.policy import pretrained_nav_policy_path

    path = export_policy(pretrained_nav_policy_path(), tmp_path / "nav.pt2")
    env = ATRVjrEnv(64, seed=11, task="nav")
    policy = load_policy(pretrained_nav_policy_path(), task="nav")
    td = env.rollout(20, policy, break_when_any_done=False)
    obs = td["observation"].reshape(-1, env.obs_dim)
    torch.save(obs, tmp_path / "obs.pt")
    proc = subprocess.run([sys.executable, "-c", _STANDALONE, str(path), str(tmp_path / "obs.pt"),
                           str(tmp_path / "actions.pt")], capture_output=True, text=True, check=False)
    assert proc.returncode == 0 and "loaded: []" in proc.stdout, proc.stderr[-3000:]
    expected = td["action"].reshape(-1, 2)
    assert (torch.load(tmp_path / "actions.pt") - expected).abs().max().item() < 1e-5
    # a consumer that knows only the contract builds the env's scan sectors from the env's ranges
    _, spec = load_exported(path)
    assert len(spec["observation"]) == 32 and all(f["unit"] and f["frame"] for f in spec["observation"])
    assert (spec["step_dt"], spec["rate_hz"], spec["action"]["scale"]) == (0.05, 20.0, [20.0, 20.0])
    scan, names = spec["scan"], [f["name"] for f in spec["observation"]]
    angles = torch.linspace(-scan["fov_rad"] / 2, scan["fov_rad"] / 2, scan["beams"], dtype=torch.float64)
    sectors = ScanSectors(tuple(scan["sectors"]["edges_rad"]), scan["sectors"]["clip_m"])
    ranges = td["next", "scan"].reshape(-1, scan["beams"]).clone()
    ranges[ranges >= scan["range_max_m"]] = math.inf  # as a LaserScan carries no return
    readings = sector_readings(ranges, angles, sectors, range_min=scan["range_min_m"], range_max=scan["range_max_m"])
    columns = [names.index(f"scan_{k}") for k in range(sectors.count)]
    assert torch.equal(readings, td["next", "observation"].reshape(-1, 32)[:, columns])
    low = torch.tensor([f["low"] for f in spec["observation"]])
    high = torch.tensor([f["high"] for f in spec["observation"]])
    assert ((obs >= low) & (obs <= high)).all() and (obs == high).any()  # the bounds the env clips to


def test_export_refuses_a_policy_that_does_not_fit_its_task(tmp_path, run_module):
    """A nav policy from before the task observed its last actions (26 values, the task 32): one line, exit 2,
    nothing written."""
    from atrv_warp.policy import make_actor, save_policy

    old = tmp_path / "old_nav.pt"
    save_policy(make_actor(16, 1, obs_dim=26), old, width=16, depth=1, meta={"task": "nav"})
    proc = run_module("atrv_warp.export", str(old), str(tmp_path / "old.pt2"), check=False)
    assert proc.returncode == 2, proc.stderr[-2000:]
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "observes 26 values, task 'nav' observes 32" in lines[0], proc.stderr
    assert not list(tmp_path.glob("*.pt2"))
