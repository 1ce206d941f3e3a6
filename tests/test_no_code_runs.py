"""No file the project loads runs code: a crafted ``.pt2`` of each kind ``torch.export.load`` would run or unpickle,
and a crafted replay buffer, are refused with a named error by every loader and command, and a marker file proves
that nothing ran. Each payload is first shown live: through a plain ``torch.export.load`` (or ``pickle``), in a
process of its own, it does write the marker."""

from __future__ import annotations

import io
import json
import os
import pickle
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
import torch
from test_deploy import task_contract, write_policy

from atrv_warp.core.files import ExportedFileError, load_exported_program

ROOT = Path(__file__).resolve().parent.parent


class _Payload:
    """Unpickled, it runs ``touch MARKER``."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return os.system, (f"touch {self.marker}",)


def _rewrite(src: Path, dst: Path, change) -> Path:
    """A copy of the archive ``src`` with ``change(members)`` applied (member name without the root -> bytes)."""
    with zipfile.ZipFile(src) as z:
        root = z.namelist()[0].split("/", 1)[0]
        members = {n[len(root) + 1:]: z.read(n) for n in z.namelist()}
    change(members)
    with zipfile.ZipFile(dst, "w") as z:
        for name, data in members.items():
            z.writestr(f"{root}/{name}", data)
    return dst


def _json_member(members: dict, name: str, edit) -> None:
    value = json.loads(members[name])
    edit(value)
    members[name] = json.dumps(value).encode()


def _pickled_weight(marker):
    def change(m):
        m["data/weights/weight_0"] = pickle.dumps(_Payload(marker))
        _json_member(m, "data/weights/model_weights_config.json",
                     lambda c: next(iter(c["config"].values())).update(use_pickle=True))
    return change


def _pickled_constant(prefix: str, marker):
    def change(m):
        m[f"data/constants/{prefix}0"] = pickle.dumps(_Payload(marker))
        _json_member(m, "data/constants/model_constants_config.json", lambda c: c["config"].update(
            {"lifted_tensor_0": {"path_name": f"{prefix}0", "is_param": False, "use_pickle": True,
                                 "tensor_meta": None}}))
    return change


def _legacy_weights(marker):
    def change(m):
        m["data/weights/model.pt"] = pickle.dumps(_Payload(marker))
    return change


def _sample_inputs(marker):
    def change(m):
        buf = io.BytesIO()
        torch.save(((torch.zeros(1),), {}), buf)
        with zipfile.ZipFile(io.BytesIO(buf.getvalue())) as z:
            parts = {n: z.read(n) for n in z.namelist()}
        out = io.BytesIO()
        with zipfile.ZipFile(out, "w") as z:
            for n, data in parts.items():
                z.writestr(n, pickle.dumps(_Payload(marker), protocol=2) if n.endswith("data.pkl") else data)
        m["data/sample_inputs/model.pt"] = out.getvalue()
    return change


def _guards(marker):
    return lambda m: _json_member(m, "models/model.json",
                                  lambda p: p.update(guards_code=[f"__import__('os').system('touch {marker}')"]))


def _expression(marker):
    def edit(p):
        values = p["graph_module"]["graph"]["tensor_values"]
        first = next(iter(values.values()))
        first["sizes"][0] = {"as_expr": {"expr_str": f"__import__('os').system('touch {marker}')", "hint": None}}
    return lambda m: _json_member(m, "models/model.json", edit)


CRAFTED = {  # kind -> (how, what the refusal names, whether torch 2.13's own loader runs it)
    "a weight flagged use_pickle": (_pickled_weight, "is not a plain tensor", True),
    "a constant flagged use_pickle": (lambda mk: _pickled_constant("tensor_", mk), "is not a plain tensor", True),
    "an opaque object constant": (lambda mk: _pickled_constant("opaque_obj_", mk),
                                  "unknown archive member(s) ['data/constants/opaque_obj_0']", True),
    "a custom object constant": (lambda mk: _pickled_constant("custom_obj_", mk),
                                 "unknown archive member(s) ['data/constants/custom_obj_0']", False),
    "legacy pickled weights": (_legacy_weights, "unknown archive member(s) ['data/weights/model.pt']", True),
    "pickled sample inputs": (_sample_inputs, "its sample inputs hold more than tensors", True),
    "guard code": (_guards, "it carries guard code", True),
    "a symbolic shape that is code": (_expression, "a symbolic shape expression outside the known grammar", True),
    "an AOTInductor library": (lambda mk: lambda m: m.update({"data/aotinductor/model/model.so": b"\x7fELF"}),
                               "unknown archive member(s) ['data/aotinductor/model/model.so']", False),
}

_PLAIN_LOAD = """
import sys, torch
try:
    torch.export.load(sys.argv[1]).module()(torch.zeros(2, int(sys.argv[2])))
except Exception as err:
    print(type(err).__name__, err)
"""


@pytest.fixture(scope="module")
def policy(tmp_path_factory) -> Path:
    return write_policy(tmp_path_factory.mktemp("crafted") / "ok.pt2", task_contract())


@pytest.mark.parametrize("kind", list(CRAFTED))
def test_a_crafted_exported_program_is_refused_before_anything_runs(kind, policy, tmp_path):
    how, named, live = CRAFTED[kind]
    marker = tmp_path / "ran"
    crafted = _rewrite(policy, tmp_path / "crafted.pt2", how(marker))
    if live:  # the threat is real: torch's own loader runs the payload
        subprocess.run([sys.executable, "-c", _PLAIN_LOAD, str(crafted), str(len(task_contract()["observation"]))],
                       capture_output=True, timeout=300, check=False)
        assert marker.exists(), f"{kind}: the payload did not run through torch.export.load"
        marker.unlink()
    with pytest.raises(ExportedFileError) as err:
        load_exported_program(crafted)
    assert named in str(err.value) and "nothing in it was loaded" in str(err.value), str(err.value)
    assert not marker.exists()


def test_the_graph_may_call_only_tensor_maths(policy, tmp_path):
    def edit(p):
        p["graph_module"]["graph"]["nodes"][0]["target"] = "torch.serialization.os.system"
    crafted = _rewrite(policy, tmp_path / "os.pt2",
                       lambda m: _json_member(m, "models/model.json", edit))
    with pytest.raises(ExportedFileError, match=r"its graph calls 'torch.serialization.os.system'"):
        load_exported_program(crafted)
    program, extra = load_exported_program(policy)  # the file it was made from loads and runs
    assert program.module()(torch.zeros(3, len(task_contract()["observation"]))).shape == (3, 2)
    assert json.loads(extra["atrv_warp.json"])["task"] == "nav_deploy"


@pytest.mark.slow  # four commands in processes of their own
def test_no_command_runs_a_crafted_policy(policy, tmp_path):
    """``atrv-deploy``, ``evaluate --engine mujoco``, ``rl.export.load_exported`` and the torch-only example refuse
    the crafted files, exit 2 where they are commands, and the marker is never written."""
    marker = tmp_path / "ran"
    crafted = _rewrite(policy, tmp_path / "crafted.pt2", _pickled_weight(marker))
    commands = [[sys.executable, "-m", "atrv_warp.deploy", str(crafted)],
                [sys.executable, str(ROOT / "examples" / "run_exported_policy.py"), str(crafted)]]
    if __import__("importlib").util.find_spec("mujoco") is not None:
        commands.append([sys.executable, "-m", "atrv_warp.evaluate", str(crafted), "--engine", "mujoco",
                         "--episodes", "1"])
    for cmd in commands:
        proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600, check=False)
        assert proc.returncode == 2, (cmd, proc.stdout[-2000:], proc.stderr[-2000:])
        assert "is not a plain tensor" in proc.stderr and "Traceback" not in proc.stderr, (cmd, proc.stderr)
        assert not marker.exists(), cmd
    from atrv_warp.rl.export import load_exported
    from atrv_warp.storage import FileFormatError

    with pytest.raises(FileFormatError, match="is not a plain tensor"):
        load_exported(crafted)
    assert not marker.exists()


def test_a_crafted_replay_buffer_or_checkpoint_is_refused_unread(tmp_path):
    """A save's buffer replaced by a pickle (its record in the checkpoint updated to match, as an attacker with the
    folder could) is refused naming it, as is a checkpoint that holds one; nothing ran."""
    from test_saves import Run, _resume

    from atrv_warp.rl.checkpoint import load_checkpoint
    from atrv_warp.storage import FileFormatError, atomic_save, file_sha256

    marker = tmp_path / "ran"
    run = Run(tmp_path / "run")
    run.advance(1)
    run.save()
    ck = load_checkpoint(run.checkpoint.path)
    entry = ck["save"]["files"]["buffer"]
    path = run.checkpoint.run_dir / entry["path"]
    torch.save({"format": "atrv_warp.replay_buffer/1", "rows": {"x": _Payload(marker)}}, path)
    entry.update(bytes=path.stat().st_size, sha256=file_sha256(path))
    atomic_save(ck, run.checkpoint.path)
    with pytest.raises(FileFormatError, match="it holds Python objects other than tensors"):
        _resume(run.checkpoint.run_dir)
    torch.save({**ck, "frames": _Payload(marker)}, run.checkpoint.path)
    with pytest.raises(FileFormatError, match=r"nothing was unpickled"):
        load_checkpoint(run.checkpoint.path)
    assert not marker.exists()
    old = tmp_path / "old"  # a run folder from before whole saves: its TorchRL buffer is not read
    (old / "buffer").mkdir(parents=True)
    (old / "buffer" / "prefetch.pkl").write_bytes(pickle.dumps(_Payload(marker)))
    fresh = Run(old)
    legacy = {k: v for k, v in ck.items() if k != "save"}
    fresh.checkpoint.restore(legacy, fresh.cfg, fresh.actor, fresh.normalize, fresh.buffer)
    assert len(fresh.buffer) == 0 and "is not read" in fresh.checkpoint.notes[0]
    assert not marker.exists()


def _module(path: Path, marker: Path, body: str = "") -> Path:
    """A task module that leaves ``marker`` when imported, then runs ``body``."""
    path.write_text(f"from pathlib import Path\nPath({str(marker)!r}).write_text('ran')\n{body}")
    return path


def test_a_run_folder_names_no_code_that_resume_imports(tmp_path, capsys):
    """``--resume`` reads a run folder's ``config.toml`` as data: the task module it names is not imported (the
    command line must name it), a module other than the one the run recorded is refused, and a module that exits or
    raises is one line naming it, exit 2 (issue 70)."""
    from atrv_warp.cli.train import main
    from atrv_warp.rl.command_line import load_train_config, parse_command
    from atrv_warp.rl.config import to_toml
    from atrv_warp.rl.run import TASK_MODULE_RECORD, task_module_record

    marker = tmp_path / "ran"
    evil = _module(tmp_path / "evil.py", marker, "raise SystemExit(0)\n")
    run = tmp_path / "runs" / "sent"  # a run folder someone sent: its config names their module
    run.mkdir(parents=True)
    text = to_toml(load_train_config("smoke")).replace('task_module = ""', f"task_module = {json.dumps(str(evil))}")
    (run / "config.toml").write_text(text)
    assert main(["--resume", str(run)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"the run used the task module {evil}" in err[0] and "env.task_module=" in err[0], err
    assert not marker.exists()
    other = tmp_path / "other.py"  # named on the command line, but not the module the run recorded
    other.write_text("# another module\n")
    (run / TASK_MODULE_RECORD).write_text(json.dumps(task_module_record(evil)))
    assert main(["--resume", str(run), f"env.task_module={other}"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"the task module {other} is not the one the run trained with" in err[0], err
    assert not marker.exists()
    (run / TASK_MODULE_RECORD).write_text(json.dumps(task_module_record(other)))  # the recorded module: resumes
    assert parse_command(["--resume", str(run), f"env.task_module={other}"]).train.env.task_module == str(other)
    for body, name in (("raise SystemExit(0)\n", "SystemExit: 0"), ("raise KeyboardInterrupt\n", "KeyboardInterrupt"),
                       ("import no_such_module_here\n", "ModuleNotFoundError")):
        module = _module(tmp_path / f"{name.split(':')[0].lower()}.py", tmp_path / "asked", body)
        assert main([f"task_module={module}", "--config", "smoke"]) == 2  # a module the user names runs, and says so
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and f"task module {module}: {name}" in err[0], err


def test_a_crafted_run_folder_runs_no_code_through_evaluate_or_export(tmp_path):
    """Issue 70: a run folder someone sent, its policy of a task their module registers (the policy's record names the
    module): ``evaluate`` and ``export`` read the policy as data. The task is unknown here and named, with the option
    that gives its module; the module, which leaves a marker when imported, never runs."""
    from atrv_warp.policy import make_actor, save_policy
    from atrv_warp.task.registry import TASKS, load_task_module

    marker = tmp_path / "ran"
    module = tmp_path / "their_task.py"  # the parking example, renamed, leaving a marker when ATRV_CRAFTED is set
    module.write_text((ROOT / "examples" / "custom_task.py").read_text().replace('Task("parking"', 'Task("their_parking"')
                      + "\nimport os, pathlib\nif os.environ.get('ATRV_CRAFTED'):\n"
                      "    pathlib.Path(os.environ['ATRV_CRAFTED']).write_text('ran')\n")
    load_task_module(module)  # here, to write their policy (its record names the module as the task's source)
    try:
        run = tmp_path / "runs" / "sent"
        run.mkdir(parents=True)
        from atrv_warp.task.spec import observation_fields

        obs = len(observation_fields(TASKS["their_parking"].config))
        save_policy(make_actor(8, 1, obs_dim=obs), run / "best_policy.pt", width=8, depth=1,
                    meta={"task": "their_parking"}, task=TASKS["their_parking"].config)
    finally:
        TASKS.pop("their_parking", None)
    env = dict(os.environ, ATRV_CRAFTED=str(marker))
    for cmd in (["-m", "atrv_warp.evaluate", str(run / "best_policy.pt"), "--episodes", "1"],
                ["-m", "atrv_warp.export", str(run / "best_policy.pt"), str(tmp_path / "out.pt2")]):
        proc = subprocess.run([sys.executable, *cmd], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300,
                              check=False)
        assert proc.returncode == 2 and "Traceback" not in proc.stderr, (cmd, proc.stderr[-2000:])
        assert "their_parking" in proc.stderr and "--task-module" in proc.stderr, (cmd, proc.stderr[-2000:])
        assert not marker.exists(), cmd
