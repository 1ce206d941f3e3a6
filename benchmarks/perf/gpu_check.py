"""The GPU check: on a machine with a GPU, what docs/gpu.md should say about it, compile included.

Run: ``python -m benchmarks.perf.gpu_check [--device cuda:0] [--parts compile tiers updates train] [--seeds 0 1 2]
[--minutes 1.5] [--with-adjoints] [--batch N] [--threads N]``

Four parts, each written to the results file as it ends (so a run cut short keeps what it measured, and a later
call adds to it): ``--parts compile tiers updates`` and ``--parts train`` each fit a call of 10 minutes.

- ``compile``: seconds from an empty Warp kernel cache to the first step of ``nav_deploy`` at 1,024 worlds (a fresh
  process with its own cache folder, so nothing compiled before counts), then the same with the cache it left.
- ``tiers``: Isaac Lab's three tiers at 4,096 and 16,384 worlds, in env-steps/s (worlds x steps per second): the env
  stepped with random actions; stepped with the shipped ATRV-Jr policy choosing every action; and stepped with the
  policy while the ``nav_deploy_gpu`` recipe learns (its batch, its updates per env step, its built update). Then
  the env in map worlds with random actions: 16 procedural buildings with Nav2's planner in the loop (the scan and
  the contact against the grid, a plan on a 0.2 m grid every reset, a replan every second), against the first
  tier.
- ``updates``: SAC updates/s at the recipe's batch, eager against each built form (``compile``, ``cudagraphs``),
  in interleaved rounds on the same learner state.
- ``train``: time to 90 % validation success on ``nav_deploy`` with the ``nav_deploy_gpu`` preset, per seed (as
  ``benchmarks/training/train_to_success.py`` counts it: from the first env step, validation included, compile apart), then the
  best policy on the 1,000-episode test set under ``wide``; the task's fingerprint and commit are recorded.

``--device cpu --quick`` runs every part small on the CPU (what ``tests/test_gpu_recipe.py`` runs): a check of the
script, not a measurement. A GPU machine here has no network: ``../shared/tools/offline-wheels.sh`` stages the
wheels it lacks. Writes ``benchmarks/results/gpu_check.json`` (``--out``).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks._common import write_results

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

ROOT = Path(__file__).resolve().parents[2]
RESULTS = Path(__file__).resolve().parents[1] / "results"
PRESET = "nav_deploy_gpu"
PARTS = ("compile", "tiers", "updates", "train")

_FIRST_STEP = """
import sys, time
t0 = time.perf_counter()
import torch
from atrv_warp.task.env import RoverEnv
if {adjoints}:
    from atrv_warp.runtime import enable_gradients
    enable_gradients()
t1 = time.perf_counter()
env = RoverEnv({worlds}, task="nav_deploy", device="{device}")
td = env.reset()
td["action"] = torch.zeros({worlds}, 2, device=env.device)
env.step(td)
if env.device.type == "cuda":
    torch.cuda.synchronize()
print(f"{{t1 - t0:.3f}} {{time.perf_counter() - t1:.3f}}")
"""


def _first_step(device: str, worlds: int, cache: str, adjoints: bool = False) -> dict:
    """Seconds to import, then to build the env and take its first step, in a fresh process with ``cache``
    (``adjoints``: the kernels compiled with their adjoints, as before they were left out)."""
    env = {**os.environ, "WARP_CACHE_PATH": cache}
    code = _FIRST_STEP.format(worlds=worlds, device=device, adjoints=adjoints)
    proc = subprocess.run([sys.executable, "-c", code], env=env,
                          capture_output=True, text=True, cwd=ROOT, check=True)
    imported, first = map(float, proc.stdout.split()[-2:])
    return {"import_s": imported, "first_step_s": first, "console": proc.stdout.strip().splitlines()[:-1]}


def part_compile(args) -> dict:
    worlds = 64 if args.quick else 1024
    with tempfile.TemporaryDirectory(prefix="warp-cold-") as cache:
        cold = _first_step(args.device, worlds, cache)
        print(f"compile: cold {cold['first_step_s']:.1f} s to the first step of {worlds} worlds", flush=True)
        warm = _first_step(args.device, worlds, cache)
        print(f"compile: warm {warm['first_step_s']:.1f} s", flush=True)
    result = {"worlds": worlds, "cold": cold, "warm": warm}
    if args.with_adjoints:
        with tempfile.TemporaryDirectory(prefix="warp-cold-") as cache:
            result["cold_with_adjoints"] = _first_step(args.device, worlds, cache, adjoints=True)
        print(f"compile: cold with adjoints {result['cold_with_adjoints']['first_step_s']:.1f} s", flush=True)
    return result


def _sync(device) -> None:
    import torch

    if torch.device(device).type == "cuda":
        torch.cuda.synchronize()


def _on_device(args) -> dict:
    """The preset's overrides for ``--device``: the device, and on the CPU the eager update (cudagraphs is CUDA's)."""
    return {"run.device": args.device, **({"optim.compile": "off"} if args.device == "cpu" else {})}


QUICK_UPDATE = {"network.width": 32, "optim.batch_size": 64}
"""``--quick``'s update: the networks and batch of ``tests/test_gpu_recipe.py``'s compiled update, so that the check's
compile in CI loads what that test compiled (torch.compile's cache) instead of compiling a second graph."""


def _recipe(args, overrides: dict | None = None):
    from atrv_warp.rl.command_line import load_train_config

    return load_train_config(PRESET, {**_on_device(args), **(overrides or {})})


def part_tiers(args) -> dict:
    """Env-steps/s of the three tiers at each world count."""
    import torch

    from atrv_warp.policy import load_policy, shipped_policy_for
    from atrv_warp.rl.learner import Learner, make_buffer, make_run_actor, replay_frames
    from atrv_warp.task.env import RoverEnv

    steps = 20 if args.quick else 200
    rows = []
    for worlds in (16, 32) if args.quick else (4096, 16384):
        cfg = _recipe(args, {"env.num_envs": worlds})
        env = RoverEnv(worlds, task="nav_deploy", randomization="wide", device=args.device, seed=0)
        policy = load_policy(shipped_policy_for("nav_deploy", "atrvjr"), device=args.device)
        actor, normalize = make_run_actor(cfg)
        learner, buffer = Learner(cfg, actor, normalize), make_buffer(cfg)
        per_step = worlds * cfg.optim.utd_ratio  # the recipe's updates per env step
        row = {"worlds": worlds, "steps": steps, "updates_per_env_step": per_step}
        for tier in ("env", "env+policy", "env+policy+training"):
            td = env.reset()
            credit, updates = 0.0, 0
            for i in range(steps + 5):  # five warm-up steps (a built update compiles or captures in its first calls)
                if i == 5:
                    _sync(args.device)
                    t0 = time.perf_counter()
                    updates = 0
                if tier == "env":
                    td["action"] = torch.rand(worlds, 2, device=env.device) * 2 - 1
                else:
                    with torch.no_grad():
                        td = policy(td)
                out, td = env.step_and_maybe_reset(td)
                if tier == "env+policy+training":
                    buffer.extend(replay_frames(out, args.device))
                    credit += per_step
                    while credit >= 1.0 and len(buffer) >= cfg.optim.batch_size:
                        credit -= 1.0
                        learner.update(buffer.sample())
                        updates += 1
            _sync(args.device)
            seconds = time.perf_counter() - t0
            row[tier] = {"env_steps_per_s": worlds * steps / seconds, "seconds": seconds, "updates": updates}
            print(f"tiers: {worlds:>6} worlds, {tier:<20} {worlds * steps / seconds:>12,.0f} env-steps/s", flush=True)
        row["env in maps"] = _map_tier(args, worlds, steps)
        row["env in maps"]["over_env"] = row["env"]["env_steps_per_s"] / row["env in maps"]["env_steps_per_s"]
        rows.append(row)
    return {"task": "nav_deploy", "randomization": "wide", "rows": rows}


def _map_tier(args, worlds: int, steps: int) -> dict:
    """Env-steps/s of ``nav_deploy`` in 16 procedural buildings with the planner in the loop, random actions; the
    planning grid at 0.2 m, so that 16,384 worlds' fields fit (``sim.planner.FIELD_MEMORY``)."""
    import torch

    from atrv_warp.sim.planner import PlannerConfig
    from atrv_warp.task.env import RoverEnv

    env = RoverEnv(worlds, task="nav_deploy", randomization="wide", device=args.device, seed=0,
                   maps=["building:16"], planner=PlannerConfig(resolution=0.2))
    td = env.reset()
    for i in range(steps + 5):  # five warm-up steps, as the tiers'
        if i == 5:
            _sync(args.device)
            t0 = time.perf_counter()
        td["action"] = torch.rand(worlds, 2, device=env.device) * 2 - 1
        _, td = env.step_and_maybe_reset(td)
    _sync(args.device)
    seconds = time.perf_counter() - t0
    print(f"tiers: {worlds:>6} worlds, {'env in maps':<20} {worlds * steps / seconds:>12,.0f} env-steps/s", flush=True)
    return {"env_steps_per_s": worlds * steps / seconds, "seconds": seconds, "maps": "building:16"}


def part_updates(args) -> dict:
    """Updates/s at the recipe's batch: eager against each built form, in interleaved rounds."""
    import torch
    from tensordict import TensorDict

    from atrv_warp.rl.learner import Learner, make_run_actor
    from atrv_warp.rl.run import resolve_run
    from atrv_warp.task.spec import observation_fields

    cfg = _recipe(args)
    batch_size = args.batch or (QUICK_UPDATE["optim.batch_size"] if args.quick else cfg.optim.batch_size)
    forms = ["off", "compile"] + (["cudagraphs"] if args.device != "cpu" else [])
    rounds, per_round = (2, 5) if args.quick else (5, 200)
    learners = {}
    for form in forms:
        c = _recipe(args, {"optim.compile": form, "optim.batch_size": batch_size,
                           **({"network.width": QUICK_UPDATE["network.width"]} if args.quick else {})})
        torch.manual_seed(0)
        actor, normalize = make_run_actor(c)
        learners[form] = Learner(c, actor, normalize)
    dim = len(observation_fields(resolve_run(cfg).task.config))
    g = torch.Generator(device=args.device).manual_seed(0)
    flags = torch.zeros(batch_size, 1, dtype=torch.bool, device=args.device)

    def batch():
        return TensorDict({"observation": torch.randn(batch_size, dim, generator=g, device=args.device),
                           "action": torch.rand(batch_size, 2, generator=g, device=args.device) * 2 - 1,
                           ("next", "observation"): torch.randn(batch_size, dim, generator=g, device=args.device),
                           ("next", "reward"): torch.randn(batch_size, 1, generator=g, device=args.device),
                           ("next", "done"): flags, ("next", "terminated"): flags, ("next", "truncated"): flags},
                          [batch_size])

    data = [batch() for _ in range(8)]
    build_s = {}
    for form, learner in learners.items():  # compile or capture, timed apart
        _sync(args.device)
        t0 = time.perf_counter()
        for i in range(8):
            learner.update(data[i])
        _sync(args.device)
        build_s[form] = time.perf_counter() - t0
        print(f"updates: {form} built and warmed in {build_s[form]:.1f} s", flush=True)
    rates = {form: [] for form in forms}
    for _ in range(rounds):
        for form, learner in learners.items():
            _sync(args.device)
            t0 = time.perf_counter()
            for i in range(per_round):
                learner.update(data[i % len(data)])
            _sync(args.device)
            rates[form].append(per_round / (time.perf_counter() - t0))
    result = {"batch_size": batch_size, "rounds": rounds, "updates_per_round": per_round, "build_s": build_s,
              "updates_per_s": {form: statistics.median(r) for form, r in rates.items()},
              "per_round": rates}
    eager = result["updates_per_s"]["off"]
    for form, rate in result["updates_per_s"].items():
        print(f"updates: {form:<10} {rate:8.1f} updates/s ({rate / eager:.2f}x eager)", flush=True)
    return result


def part_train(args) -> dict:
    """Time to 90 % per seed with the GPU preset, as train_to_success.py counts it."""
    from benchmarks.training.train_to_success import _one_seed

    seeds = []
    for seed in args.seeds:
        overrides = {"run.name": f"bench_gpu_check_seed{seed}", "run.out_dir": args.runs,
                     "run.seed": seed, "run.max_minutes": args.minutes}
        if args.quick:
            overrides.update({"env.num_envs": 16, "run.total_frames": 2048, "collector.init_random_frames": 512,
                              "optim.batch_size": 64, "logging.eval_every_frames": 1024, "logging.eval_episodes": 8,
                              "logging.final_eval_episodes": 8})
        else:
            overrides.update({"logging.final_eval_episodes": 1000})
        r = _one_seed(PRESET, {**_on_device(args), **overrides}, args.threshold)  # a fresh run folder, trained, summarized
        reached = f"{r['wall_s_to_threshold']:.0f} s" if r["reached"] else "not reached"
        print(f"train: seed {seed}: {100 * args.threshold:.0f} % after {reached}; test set "
              f"{100 * r['final_eval_best_policy']['success_rate']:.1f} %", flush=True)
        seeds.append(r)
    times = [r["wall_s_to_threshold"] for r in seeds if r["reached"]]
    return {"preset": PRESET, "threshold": args.threshold, "minutes_per_seed": args.minutes, "seeds": seeds,
            "median_wall_s_to_threshold": statistics.median(times) if len(times) == len(seeds) else None}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="cuda:0")
    parser.add_argument("--parts", nargs="+", choices=PARTS, default=list(PARTS))
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--minutes", type=float, default=1.5, help="training budget per seed [min]")
    parser.add_argument("--threshold", type=float, default=0.9)
    parser.add_argument("--quick", action="store_true", help="every part small: a check of the script")
    parser.add_argument("--with-adjoints", action="store_true",
                        help="compile: also the cold compile with every kernel's adjoint (as before they were left "
                             "out; minutes on a GPU)")
    parser.add_argument("--batch", type=int, default=0, help="updates: the batch (default: the recipe's)")
    parser.add_argument("--threads", type=int, default=0,
                        help="torch threads (default: torch's; the CPU recipe's trainer runs 1)")
    parser.add_argument("--out", default=str(RESULTS / "gpu_check.json"))
    parser.add_argument("--runs", default=str(ROOT / "runs"), help="where the train part's run folders go")
    args = parser.parse_args(argv)
    import torch

    if args.threads:
        torch.set_num_threads(args.threads)
    if args.device != "cpu" and not torch.cuda.is_available():
        parser.error(f"--device {args.device}: this torch ({torch.__version__}) sees no CUDA device")
    gpu = torch.cuda.get_device_name(torch.device(args.device)) if args.device != "cpu" else "cpu"
    out = Path(args.out)
    result = {"device": args.device, "gpu": gpu, "torch": torch.__version__, "quick": args.quick,
              "threads": torch.get_num_threads()}
    if out.is_file():  # parts measured by an earlier call on the same device are kept
        earlier = json.loads(out.read_text())
        if earlier.get("gpu") == gpu and earlier.get("quick") == args.quick:
            result.update({k: v for k, v in earlier.items() if k in PARTS})
    for part in args.parts:
        t0 = time.perf_counter()
        result[part] = {**globals()[f"part_{part}"](args), "part_wall_s": time.perf_counter() - t0}
        write_results(out, result, version=VERSION, task=True, driver=True, robots=("atrvjr",))
    print(f"written to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
