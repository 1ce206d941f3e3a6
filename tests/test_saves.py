"""A save is whole or absent: a run killed at any write of a save resumes from the last whole save (its replay
buffer, networks, best policy and logged scalars together), and a changed byte is refused by name."""

from __future__ import annotations

import os
import random
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch
from tensordict import TensorDict

from atrv_warp.policy import policy_payload
from atrv_warp.rl.checkpoint import Checkpoint, RunState, buffer_state, load_checkpoint
from atrv_warp.rl.command_line import load_train_config
from atrv_warp.rl.learner import make_buffer, make_learner, make_run_actor
from atrv_warp.storage import FileFormatError

ROOT = Path(__file__).resolve().parent.parent


class Killed(Exception):
    """Stands for the process dying at that instant."""


def _rows(n: int, seed: int, obs_dim: int) -> TensorDict:
    g = torch.Generator().manual_seed(seed)
    return TensorDict({"observation": torch.randn(n, obs_dim, generator=g), "action": torch.rand(n, 2, generator=g),
                       ("next", "observation"): torch.randn(n, obs_dim, generator=g),
                       ("next", "reward"): torch.randn(n, 1, generator=g),
                       ("next", "done"): torch.zeros(n, 1, dtype=torch.bool),
                       ("next", "terminated"): torch.zeros(n, 1, dtype=torch.bool),
                       ("next", "truncated"): torch.zeros(n, 1, dtype=torch.bool)}, [n])


class Run:
    """A run's parts in memory, saved with :class:`Checkpoint` as the training loop saves them."""

    def __init__(self, run_dir: Path):
        self.cfg = load_train_config("smoke", {"buffer_size": 700})
        self.actor, self.normalize = make_run_actor(self.cfg)
        self.obs_dim = self.normalize.loc.numel()
        self.normalize.set_stats(torch.zeros(self.obs_dim), torch.ones(self.obs_dim))
        self.buffer = make_buffer(self.cfg)
        self.learner = make_learner(self.cfg, self.actor, self.normalize)
        self.checkpoint = Checkpoint(run_dir)
        self.state = RunState(stats_ready=True)
        (run_dir / "logs" / "scalars").mkdir(parents=True, exist_ok=True)

    def advance(self, step: int) -> None:
        """Collect, learn, log and find a new best, as between two saves."""
        self.buffer.extend(_rows(300, step, self.obs_dim))  # wraps around the 700 rows by the third
        self.state.frames += 300
        with torch.no_grad():
            next(self.actor.parameters()).add_(0.01 * step)
        self.checkpoint.best = policy_payload(self.actor, width=self.cfg.network.width, depth=self.cfg.network.depth,
                                              meta={"frames": self.state.frames, "task": self.cfg.env.task})
        with open(self.checkpoint.logs / "eval_success_rate.csv", "a") as f:
            f.write(f"{self.state.frames},0.{step}\n")
        if step == 3:  # a scalar first logged after the second save
            (self.checkpoint.logs / "lr.csv").write_text(f"{self.state.frames},0.001\n")

    def save(self) -> None:
        self.checkpoint.save(self.cfg, self.state, self.actor, self.learner, self.buffer)

    def snapshot(self) -> dict:
        run = self.checkpoint.run_dir
        return {"frames": self.state.frames, "buffer": buffer_state(self.buffer),
                "logs": {p.name: p.read_text() for p in sorted(self.checkpoint.logs.glob("*.csv"))},
                "best": torch.load(run / "best_policy.pt", weights_only=True)}


def _equal(a: dict, b: dict) -> bool:
    ba, bb = a["buffer"], b["buffer"]
    best = a["best"]["meta"] == b["best"]["meta"] and all(
        torch.equal(v, b["best"]["state_dict"][k]) for k, v in a["best"]["state_dict"].items())
    return (a["frames"] == b["frames"] and a["logs"] == b["logs"] and best
            and ba["length"] == bb["length"] and ba["writer"] == bb["writer"] and ba["rows"].keys() == bb["rows"].keys()
            and all(torch.equal(ba["rows"][k], bb["rows"][k]) for k in ba["rows"]))


def _resume(run_dir: Path) -> tuple[Run, dict]:
    """A fresh process's view: the run's parts built anew and restored from the folder."""
    fresh = Run(run_dir)
    ck = load_checkpoint(fresh.checkpoint.path)
    fresh.state, fresh.learner = fresh.checkpoint.restore(ck, fresh.cfg, fresh.actor, fresh.normalize, fresh.buffer)
    return fresh, fresh.snapshot()


def _kill_at(monkeypatch, k: int) -> list[str]:
    """Make the k-th write of the save (1-based) die: a ``torch.save`` half written, a rename, a copy or a removal not
    done. Returns the writes seen, by kind."""
    seen: list[str] = []
    real_save, real_replace, real_copy, real_unlink = torch.save, Path.replace, shutil.copyfile, Path.unlink

    def count(kind: str) -> None:
        seen.append(kind)
        if len(seen) == k:
            raise Killed(kind)

    def save(obj, f, *a, **kw):
        if len(seen) + 1 == k:  # half of the bytes reach the file, then the process dies
            import io

            buf = io.BytesIO()
            real_save(obj, buf, *a, **kw)
            data = buf.getvalue()
            f.write(data[: len(data) // 2]) if hasattr(f, "write") else Path(f).write_bytes(data[: len(data) // 2])
        count("torch.save")
        return real_save(obj, f, *a, **kw)

    def replace(self, target):
        count(f"rename {self.name}")
        return real_replace(self, target)

    def copy(src, dst, *a, **kw):
        count("copy best_policy")
        return real_copy(src, dst, *a, **kw)

    def unlink(self, *a, **kw):
        count(f"remove {self.name}")
        return real_unlink(self, *a, **kw)

    monkeypatch.setattr(torch, "save", save)
    monkeypatch.setattr(Path, "replace", replace)
    monkeypatch.setattr(shutil, "copyfile", copy)
    monkeypatch.setattr(Path, "unlink", unlink)
    return seen


def test_a_save_killed_at_any_write_resumes_from_one_whole_save(tmp_path, monkeypatch):
    """Three saves; the third killed at each of its writes in turn (the first save's too, in a run of its own): each
    resume finds the second save or the third, whole, never a mix, and the logs cut back to it."""
    template = tmp_path / "template"
    run = Run(template)
    run.advance(1)
    run.save()
    run.advance(2)
    run.save()
    second = run.snapshot()
    # the whole third save, written once without a failure: what a completed save looks like
    whole_dir = tmp_path / "whole"
    shutil.copytree(template, whole_dir)
    probe, _ = _resume(whole_dir)
    probe.advance(3)
    probe.save()
    third = probe.snapshot()
    assert not _equal(second, third) and third["buffer"]["writer"]["_cursor"] == 200  # the buffer wrapped around
    outcomes = []
    for k in range(1, 40):
        run_dir = tmp_path / f"kill{k}"
        shutil.copytree(template, run_dir)
        attempt, _ = _resume(run_dir)
        attempt.advance(3)
        with monkeypatch.context() as m:
            seen = _kill_at(m, k)
            try:
                attempt.save()
            except Killed:
                pass
            else:
                break  # k is past the last write of a save
        _, resumed = _resume(run_dir)
        which = "second" if _equal(resumed, second) else "third" if _equal(resumed, third) else "neither"
        outcomes.append((seen[-1], which))
        assert which != "neither", f"killed at write {k} ({seen[-1]}): the resumed run matches neither save"
        leftovers = sorted(p.name for p in (run_dir / "save").iterdir())
        assert len(leftovers) == 2, leftovers  # one buffer and one best policy: the killed save's files are gone
    kinds = [kind for kind, _ in outcomes]
    assert {"torch.save", "rename checkpoint.pt.tmp", "copy best_policy"} <= set(kinds), kinds
    assert outcomes[0][1] == "second" and outcomes[-1][1] == "third", outcomes  # before the commit, and after it
    print(outcomes)


def test_a_first_save_killed_leaves_a_run_that_starts_over(tmp_path, monkeypatch):
    for k in (1, 2, 3):
        run = Run(tmp_path / f"first{k}")
        run.advance(1)
        with monkeypatch.context() as m:
            _kill_at(m, k)
            with pytest.raises(Killed):
                run.save()
        assert not run.checkpoint.path.exists()
        run.checkpoint.start_over()
        assert not list(run.checkpoint.logs.glob("*.csv")) and not list(run.checkpoint.folder.glob("*"))


def test_a_changed_byte_in_a_save_is_named(tmp_path):
    run = Run(tmp_path / "run")
    run.advance(1)
    run.save()
    entry = run.checkpoint.files["buffer"]
    path = run.checkpoint.run_dir / entry["path"]
    data = bytearray(path.read_bytes())
    data[len(data) // 2: len(data) // 2 + 8] = b"\x00\x01\x02\x03\x04\x05\x06\x07"
    path.write_bytes(bytes(data))
    with pytest.raises(FileFormatError, match=r"the buffer differs from the one the save .* recorded"):
        _resume(run.checkpoint.run_dir)
    ck = bytearray(run.checkpoint.path.read_bytes())
    ck[len(ck) // 3: len(ck) // 3 + 8] = b"\xff" * 8  # inside a tensor of the checkpoint itself
    run.checkpoint.path.write_bytes(bytes(ck))
    with pytest.raises(FileFormatError, match="a byte changed"):
        load_checkpoint(run.checkpoint.path)


@pytest.mark.slow  # trains, killed from outside
def test_training_killed_with_sigkill_resumes_and_logs_no_row_twice(tmp_path):
    """SIGKILL at random instants of a run that saves every 1,024 frames; each ``--resume`` continues it, and at
    the end every scalar's CSV has strictly increasing frame counts (no row logged twice)."""
    out = tmp_path / "runs"
    base = [sys.executable, "-m", "atrv_warp.train", "--config", "smoke", f"out_dir={out}", "total_frames=16384",
            "eval_every_frames=1024", "eval_episodes=4", "final_eval_episodes=8", "progress=true"]
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    rng = random.Random(0)
    kills = 0
    cmd = base
    for _ in range(4):
        proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        saved = 0
        deadline = time.monotonic() + 300
        for line in proc.stdout:  # wait for a few evaluations (each followed by a save), then kill at random
            saved += "eval success" in line
            if saved >= 2 or time.monotonic() > deadline:
                break
        time.sleep(rng.uniform(0.0, 1.5))
        if proc.poll() is None:
            proc.send_signal(signal.SIGKILL)
            kills += 1
        proc.wait(timeout=60)
        cmd = [sys.executable, "-m", "atrv_warp.train", "--resume", str(out / "smoke"), "total_frames=16384"]
    done = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=900, check=False)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    assert kills >= 2
    for csv in (out / "smoke" / "logs" / "scalars").glob("*.csv"):
        steps = [int(float(line.split(",")[0])) for line in csv.read_text().splitlines()]
        assert steps == sorted(set(steps)), (csv.name, steps)
    ck = load_checkpoint(out / "smoke" / "checkpoint.pt")
    assert ck["frames"] >= 16384


def test_a_resume_that_is_another_run_is_refused_naming_what_differs(tmp_path):
    """A resume continues its run as it was (issue 70): another seed, robot or network shape is refused naming the
    setting, and another run's save put in the folder is refused naming both runs; the folder's own save resumes."""
    import dataclasses

    from atrv_warp.rl.checkpoint import RunMismatch

    runs = {}
    for name, run_id in (("a", "a" * 32), ("b", "b" * 32)):
        run = runs[name] = Run(tmp_path / name)
        run.state.run_id = run_id
        run.checkpoint.claim(run_id)
        run.advance(1)
        run.save()
    fresh = Run(tmp_path / "a")
    ck = load_checkpoint(fresh.checkpoint.path)
    cfg = fresh.cfg
    changes = {"run.seed=1": dataclasses.replace(cfg, run=dataclasses.replace(cfg.run, seed=1)),
               "env.robot='jackal'": dataclasses.replace(cfg, env=dataclasses.replace(cfg.env, robot="jackal")),
               "network.width=64": dataclasses.replace(cfg, network=dataclasses.replace(cfg.network, width=64))}
    for named, changed in changes.items():
        with pytest.raises(RunMismatch, match=f"{named.replace('(', '[(]')}, but the run trained with"):
            fresh.checkpoint.restore(ck, changed, fresh.actor, fresh.normalize, fresh.buffer)
    assert fresh.checkpoint.restore(ck, cfg, fresh.actor, fresh.normalize, fresh.buffer)[0].run_id == "a" * 32
    b = tmp_path / "b"  # run b's whole save copied into run a's folder
    shutil.copy(b / "checkpoint.pt", tmp_path / "a" / "checkpoint.pt")
    shutil.copytree(b / "save", tmp_path / "a" / "save", dirs_exist_ok=True)
    with pytest.raises(RunMismatch, match=f"belongs to run {'b' * 32}, but the folder .* holds run {'a' * 32}"):
        _resume(tmp_path / "a")


def test_one_training_per_run_folder_and_a_dead_ones_lock_is_free(tmp_path):
    """A second training on a folder in use stops before it writes, naming the holder's pid; the lock goes with its
    process, killed with SIGKILL included (issue 70)."""
    from atrv_warp.rl.checkpoint import RunLock, RunMismatch
    from atrv_warp.rl.loop import _prepare_run  # what train() does first (the quick tier trains nothing)

    cfg = load_train_config("smoke", {"out_dir": str(tmp_path), "name": "busy"})
    code = ("import pathlib, time; from atrv_warp.rl.checkpoint import RunLock; "
            f"lock = RunLock(pathlib.Path({str(tmp_path / 'busy')!r})); print('held', flush=True); time.sleep(600)")
    holder = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(RunMismatch, match=rf"is in use by another training \(pid {holder.pid}\)"):
            _prepare_run(cfg, resume=False)
        assert sorted(p.name for p in (tmp_path / "busy").iterdir()) == ["training.lock"]  # nothing written
    finally:
        holder.send_signal(signal.SIGKILL)
        holder.wait()
    RunLock(tmp_path / "busy").release()  # the dead process's lock is free
