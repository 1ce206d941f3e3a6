"""Policy export: a .pt2 file that runs with torch alone and gives the TorchRL policy's actions."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
import torch
from tensordict import TensorDict

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
    assert spec["action"]["scale"] == 20.0


def test_export_cli_and_bad_input(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "atrv_warp.export", str(tmp_path / "p.pt2")], capture_output=True,
                          text=True, check=False)
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


def test_onnx_export_checked_with_onnxruntime(tmp_path):
    ort = pytest.importorskip("onnxruntime", reason="pip install -e '.[onnx]'")
    import json

    import numpy as np
    import onnx

    path = export_policy(None, tmp_path / "policy.pt2", onnx=True)
    model = tmp_path / "policy.onnx"
    assert model.is_file()
    props = {p.key: p.value for p in onnx.load(str(model)).metadata_props}
    assert json.loads(props["atrv_warp.json"])["action"]["scale"] == 20.0
    obs = torch.rand(1000, len(OBSERVATION), generator=torch.Generator().manual_seed(1)) * 4 - 2
    got = ort.InferenceSession(str(model), providers=["CPUExecutionProvider"]).run(None, {"observation": obs.numpy()})[0]
    expected = load_policy()(TensorDict(observation=obs, batch_size=[1000]))["action"].numpy()
    assert np.abs(got - expected).max() < 1e-5
    assert path.is_file()
