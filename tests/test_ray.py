"""Collection on Ray (``collector=ray``): a local Ray trains end to end, the collectors' weights follow
the learner's, a two-node cluster on loopback places the collectors on the worker node, and nothing
of Ray is left behind (processes, shared memory) after a run, a Ctrl-C or an error.

Real Ray throughout, no mocks; small budgets (2 CI cores). ``pytest tests/test_ray.py``.
"""

from __future__ import annotations

import importlib.util
import json
import os
import re
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest
import torch

ROOT = Path(__file__).resolve().parent.parent
needs_ray = pytest.mark.skipif(importlib.util.find_spec("ray") is None, reason='needs the extra: pip install -e ".[ray]"')
RAY_MARKERS = ("gcs_server", "raylet", "ray::", "/ray/dashboard/", "/ray/_private/", "/ray/autoscaler/",
               "default_worker.py", "runtime_env/agent")
"""Substrings of the command lines of Ray's processes (GCS, raylet, workers, agents, monitors)."""


def ray_processes() -> list[str]:
    """``'pid cmdline'`` of every live Ray process on this machine (zombies have no command line)."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            cmd = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace").strip()
        except OSError:
            continue
        if any(m in cmd for m in RAY_MARKERS):
            found.append(f"{entry.name} {cmd[:160]}")
    return found


def shm_entries() -> set[str]:
    return set(os.listdir("/dev/shm")) if os.path.isdir("/dev/shm") else set()


def orphaned_shm(before: set[str]) -> set[str]:
    """Shared-memory segments new since ``before`` that still exist and that no live process maps or
    holds open: left behind. (Segments of live processes do not count: other runs may share this
    machine's ``/dev/shm``.)"""
    candidates = shm_entries() - before  # listed first: a segment created after this is no candidate
    in_use = set()
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            in_use.update(line.split("/dev/shm/", 1)[1].split()[0] for line in (entry / "maps").read_text().splitlines()
                          if "/dev/shm/" in line)
            in_use.update(os.readlink(fd).removeprefix("/dev/shm/") for fd in (entry / "fd").iterdir()
                          if os.readlink(fd).startswith("/dev/shm/"))
        except OSError:
            continue
    return {name for name in candidates - in_use if os.path.exists(f"/dev/shm/{name}")}


def assert_no_ray_left(shm_before: set[str], timeout_s: float = 20.0) -> None:
    """No Ray process and no orphaned shared-memory segment, waiting up to ``timeout_s`` for exits."""
    deadline = time.monotonic() + timeout_s
    while True:
        processes, orphans = ray_processes(), orphaned_shm(shm_before)
        if (not processes and not orphans) or time.monotonic() > deadline:
            break
        time.sleep(0.5)
    assert not processes, processes
    assert not orphans, sorted(orphans)


def train_cmd(*overrides: str) -> list[str]:
    return [sys.executable, "-m", "atrv_warp.train", "--config", "smoke", "collector=ray", *overrides]


def frames_per_collector(stdout: str) -> list[int]:
    line = re.search(r"^frames per collector: (.*)$", stdout, re.MULTILINE)
    assert line, stdout
    return [int(n.replace(",", "")) for n in line.group(1).split(", ")]


@pytest.fixture
def no_ray_before():
    """Refuse to start over a Ray left running by something else; yield the shared memory as found."""
    assert not ray_processes(), f"Ray already running on this machine: {ray_processes()}"
    return shm_entries()


def test_without_the_extra_collector_ray_stops_before_any_work(tmp_path, capsys, monkeypatch):
    """With ``ray`` not importable, one line says how to install the extra, and nothing is written."""
    from atrv_warp.cli.train import main

    monkeypatch.setitem(sys.modules, "ray", None)  # as if not installed: find_spec('ray') is None
    assert main(["--config", "smoke", "collector=ray", f"out_dir={tmp_path}"]) == 2
    expected = 'python -m atrv_warp.train: error: collector=ray needs Ray, the optional extra [ray]: pip install -e ".[ray]"'
    assert capsys.readouterr().err.strip().splitlines() == [expected]
    assert not any(tmp_path.iterdir())


@needs_ray
@pytest.mark.slow  # a Ray cluster
def test_local_ray_trains_end_to_end_with_frames_from_both_collectors(tmp_path, no_ray_before, run_command):
    """The acceptance command on a local Ray: two collectors, every file written, both deliver, no leftovers."""
    proc = run_command(train_cmd(f"out_dir={tmp_path}"), timeout=300)
    run_dir = tmp_path / "smoke"
    for name in ("config.toml", "checkpoint.pt", "best_policy.pt", "final_eval.json", "learning_curve.png"):
        assert (run_dir / name).is_file(), name
    result = json.loads((run_dir / "final_eval.json").read_text())
    assert result["frames"] == 6144 and result["updates"] > 0
    counts = frames_per_collector(proc.stdout)
    assert len(counts) == 2 and all(n > 0 for n in counts) and sum(counts) == 6144, counts
    assert "2 ray collectors x 64 worlds (local Ray)" in proc.stdout
    assert "RayWorker" not in proc.stdout + proc.stderr  # workers print nothing (not even their long repr)
    assert "Traceback" not in proc.stderr and "Warning" not in proc.stdout
    assert_no_ray_left(no_ray_before)


@needs_ray
@pytest.mark.slow  # a Ray cluster
def test_collector_weights_follow_the_learner(no_ray_before):
    """After each batch, the collector that delivered it holds the learner's weights of that moment."""
    import ray

    from atrv_warp.policy import Normalize, make_actor
    from atrv_warp.rl.collectors import WORKER_KEY, make_ray_collector, worker_weights
    from atrv_warp.rl.command_line import load_train_config

    cfg = load_train_config("smoke", {"collector": "ray", "envs_per_collector": "16"})
    normalize = Normalize()
    actor = make_actor(cfg.network.width, cfg.network.depth, normalize=normalize)
    collector = make_ray_collector(cfg, actor, total_frames=10**6, init_random_frames=0, env_seed=3)
    try:
        initial = [w.flatten_keys() for w in worker_weights(collector)]
        learner = snapshot(actor)
        assert all(same(w, learner) for w in initial)  # the first weights reach every collector
        delivered, snapshots, batches = [], [], 8
        for i, data in enumerate(collector):
            assert data.shape == (16, cfg.env.steps_per_batch)
            assert (data[WORKER_KEY] == data[WORKER_KEY].flatten()[0]).all()  # one collector's batch
            delivered.append(int(data[WORKER_KEY].flatten()[0]))
            if i == batches:
                break  # batch i's own weight update has not been sent: stop before the learner "updates"
            with torch.no_grad():  # a learner update: new parameters and new observation statistics
                for p in actor.parameters():
                    p.add_(0.01 * (i + 1))
                normalize.set_stats(torch.full_like(normalize.loc, float(i)), torch.full_like(normalize.scale, i + 2.0))
            snapshots.append(snapshot(actor))
        assert set(delivered[:batches]) == {0, 1}, delivered  # frames from both collectors
        for worker, weights in enumerate(worker_weights(collector)):
            last = max(i for i in range(batches) if delivered[i] == worker)
            assert same(weights.flatten_keys(), snapshots[last]), (worker, last, delivered)
            assert not same(weights.flatten_keys(), learner)
    finally:
        collector.shutdown()
    assert not ray.is_initialized()  # the collector started this Ray, and stopped it
    assert_no_ray_left(no_ray_before)


def snapshot(module):
    """A flat copy of ``module``'s parameters and buffers."""
    from tensordict import TensorDict

    return TensorDict.from_module(module).data.clone().flatten_keys()


def same(a, b) -> bool:
    keys = set(a.keys())  # (iterating a TensorDict walks its batch dimension, not its keys)
    return keys == set(b.keys()) and all(torch.equal(a[k], b[k]) for k in keys)


@needs_ray
@pytest.mark.slow  # a Ray cluster
def test_ctrl_c_and_errors_leave_no_ray_behind(tmp_path, no_ray_before):
    """SIGINT to a run mid-training; an exception inside the training loop (Ray gone while the process
    still lives); after both, no Ray process and no orphaned shared memory."""
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    # A shell's background job (`./.ci/run &`) starts with SIGINT ignored; a child inherits an ignored
    # signal through exec, and a Python started that way never raises KeyboardInterrupt. Spawn the run
    # with SIGINT handled here, so that it gets Ctrl-C as from a terminal.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        proc = subprocess.Popen(train_cmd(f"out_dir={tmp_path}", "total_frames=1000000", "envs_per_collector=16"),
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=ROOT, env=env)
    finally:
        signal.signal(signal.SIGINT, previous)
    try:
        for line in proc.stdout:
            if line.startswith("ray collectors on:"):
                break
        time.sleep(1.0)  # collecting by now
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode != 0 and "KeyboardInterrupt" in out, out[-2000:]
    assert_no_ray_left(no_ray_before)

    failing = ("import sys, ray\n"
               "from atrv_warp.rl import learner, loop\n"
               "from atrv_warp.rl.command_line import load_train_config\n"
               "def broken(self, batch, phase=None):\n"
               "    raise RuntimeError('injected failure')\n"
               "learner.Learner.update = broken  # the first gradient step fails\n"
               f"cfg = load_train_config('smoke', {{'collector': 'ray', 'out_dir': {str(tmp_path / 'error')!r}, "
               "'init_random_frames': '0', 'envs_per_collector': '16'})\n"
               "try:\n"
               "    loop.train(cfg)\n"
               "except RuntimeError as err:\n"
               "    print('raised:', err)\n"
               "print('ray initialized:', ray.is_initialized(), flush=True)\n"
               "sys.stdin.readline()  # lives on while the test looks for Ray processes\n")
    proc = subprocess.Popen([sys.executable, "-c", failing], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, cwd=ROOT, env=env)
    try:
        lines = []
        for line in proc.stdout:
            lines.append(line)
            if line.startswith("ray initialized:"):
                break
        assert "raised: injected failure\n" in lines and lines[-1] == "ray initialized: False\n", "".join(lines)
        deadline = time.monotonic() + 20
        while ray_processes() and time.monotonic() < deadline:
            time.sleep(0.5)
        assert not ray_processes(), ray_processes()  # stopped by train()'s shutdown, not by the exit
        proc.communicate("\n", timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert_no_ray_left(no_ray_before)


@needs_ray
@pytest.mark.slow  # a Ray cluster
def test_two_node_cluster_on_loopback_runs_collectors_on_the_worker_node(tmp_path, no_ray_before, run_command,
                                                                          free_port):
    """``ray start --head`` and ``ray start --address`` (a node offering the custom resource), then a
    run with ``ray_address`` and ``ray_resource``: both collectors are on the worker node; ``ray stop``
    leaves nothing behind."""
    ray_bin = str(Path(sys.executable).with_name("ray"))
    # token authentication, as on a real cluster: every node and the driver share one token
    env = {**os.environ, "RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": uuid.uuid4().hex}
    port = free_port()
    address = f"127.0.0.1:{port}"
    common = ["--node-ip-address=127.0.0.1", "--object-store-memory=100000000", "--disable-usage-stats"]
    try:
        run_command([ray_bin, "start", "--head", f"--port={port}", "--num-cpus=1", "--include-dashboard=false",
             f"--ray-client-server-port={free_port()}", f"--dashboard-agent-listen-port={free_port()}", *common],
            env=env, timeout=120)
        run_command([ray_bin, "start", f"--address={address}", "--num-cpus=2", '--resources={"atrv_collector": 2}',
             f"--dashboard-agent-listen-port={free_port()}", *common], env=env, timeout=120)
        proc = run_command(train_cmd(f"out_dir={tmp_path}", f"ray_address={address}", "ray_resource=atrv_collector",
                             "envs_per_collector=32", "total_frames=2048", "init_random_frames=1024",
                             "eval_every_frames=1024"), env=env)
        assert f"(Ray at {address})" in proc.stdout
        counts = frames_per_collector(proc.stdout)  # first ready, first served: not always an even split
        assert len(counts) == 2 and min(counts) > 0 and sum(counts) == 2048, counts
        placed = re.findall(r"node ([0-9a-f]{8}), pid \d+\)", re.search(r"^ray collectors on: .*$", proc.stdout, re.MULTILINE).group(0))
        query = (f"import json, ray; ray.init(address='{address}', logging_level='ERROR'); "
                 "print(json.dumps([(n['NodeID'], n['Resources']) for n in ray.nodes() if n['Alive']]))")
        nodes = json.loads(run_command([sys.executable, "-c", query], env=env).stdout.strip().splitlines()[-1])
        worker = [node_id for node_id, res in nodes if "atrv_collector" in res]
        assert len(nodes) == 2 and len(worker) == 1, nodes
        assert placed == [worker[0][:8]] * 2, (placed, nodes)
    finally:
        subprocess.run([ray_bin, "stop"], capture_output=True, env=env, timeout=120, check=False)
    assert_no_ray_left(no_ray_before)


@needs_ray
@pytest.mark.slow  # a Ray cluster
def test_a_killed_collector_costs_a_batch_not_the_run(tmp_path, no_ray_before, run_command):
    """SIGKILL to one collector's process mid-run: its batch in flight is dropped, a replacement
    collects again (the run says both, with the recovery time), the run ends normally with a complete
    checkpoint, and ``--resume`` continues it."""
    from atrv_warp.rl.checkpoint import load_checkpoint

    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    total = 30720
    proc = subprocess.Popen(train_cmd(f"out_dir={tmp_path}", f"total_frames={total}", "envs_per_collector=32", "progress=true"),
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=ROOT, env=env)
    lines, killed = [], None
    try:
        for line in proc.stdout:
            lines.append(line)
            if line.startswith("ray collectors on:"):
                pids = [int(p) for p in re.findall(r"pid (\d+)\)", line)]
                assert len(pids) == 2, line
            if killed is None and "eval success" in line:  # mid-run: learning, the first evaluation done
                os.kill(pids[1], signal.SIGKILL)
                killed = time.monotonic()
        proc.wait(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
    out = "".join(lines)
    assert proc.returncode == 0 and killed is not None, out[-3000:]
    lost = [line for line in lines if line.startswith("ray collector 1 lost")]
    assert len(lost) == 1 and "ActorDiedError" in lost[0] and "its batch in flight is dropped" in lost[0], out[-3000:]
    back = re.search(r"^ray collector 1 is back: its replacement delivered ([0-9.]+) s after the loss$", out, re.MULTILINE)
    assert back, out[-3000:]
    print(f"recovery: the replacement delivered {float(back.group(1)):.1f} s after the loss was seen")
    counts = frames_per_collector(out)
    assert len(counts) == 2 and min(counts) > 0 and sum(counts) == total, counts
    run_dir = tmp_path / "smoke"
    ck = load_checkpoint(run_dir / "checkpoint.pt")  # complete: every entry, learner state included
    assert ck["frames"] == total and ck["updates"] > 0 and {"loss", "opts"} <= ck.keys()
    assert json.loads((run_dir / "final_eval.json").read_text())["frames"] == total
    resumed = run_command(train_cmd("--resume", str(run_dir), f"total_frames={total + 2048}"), env=env, timeout=300)
    assert f"resumed {run_dir} at {total:,} frames" in resumed.stdout
    assert load_checkpoint(run_dir / "checkpoint.pt")["frames"] == total + 2048
    assert_no_ray_left(no_ray_before)
