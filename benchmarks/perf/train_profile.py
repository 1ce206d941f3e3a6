"""Where a SAC training step's time goes, per phase: ``python -m benchmarks.perf.train_profile``.

Builds the default run's parts from the trainer's own factories (``make_collector``,
``make_buffer``, :class:`Learner`; collector, width, batch and update ratio from the ``default``
preset), fills the replay buffer with the random-action frames, then times the training loop for
``--seconds``: waiting for the collector, buffer extend, sampling, loss, backward, optimiser
steps, target update, weight sync to the worker. Then the same update in isolation (the worker
idle) for comparison; one periodic evaluation, with its share of a run; and an update after
``collector.shutdown()``, which resets torch's thread count. Kernel compilation happens during
the warm-up and is not counted. Prints the breakdown and writes ``benchmarks/results/train_profile.json``.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import time
from collections import defaultdict
from pathlib import Path

from benchmarks._common import write_results

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

RESULTS = Path(__file__).resolve().parents[1] / "results"


class Phases:
    """Wall time and call count per named phase."""

    def __init__(self):
        self.total, self.calls = defaultdict(float), defaultdict(int)

    @contextlib.contextmanager
    def __call__(self, name: str):
        t0 = time.perf_counter()
        yield
        self.total[name] += time.perf_counter() - t0
        self.calls[name] += 1


def build_parser() -> argparse.ArgumentParser:
    """The command line's options."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="timed training loop [s]")
    parser.add_argument("--isolated-updates", type=int, default=300)
    parser.add_argument("--config", default="default", help="training preset whose parts are profiled")
    parser.add_argument("--out", default=str(RESULTS / "train_profile.json"))
    return parser


def isolated_phases(learner, buffer, n: int) -> Phases:
    """The phases of ``n`` updates with the collector's worker idle."""
    iso = Phases()
    for _ in range(n):
        with iso("sample"):
            batch = buffer.sample()
        learner.update(batch, phase=iso)
    return iso


def update_ms(learner, buffer, n: int) -> float:
    """Milliseconds per update over ``n`` updates."""
    t = time.perf_counter()
    for _ in range(n):
        learner.update(buffer.sample())
    return 1e3 * (time.perf_counter() - t) / n


def print_phases(rows: list[dict], loop_s: float) -> None:
    """Print each phase's share of the loop's ``loop_s`` seconds, then the loop's own overhead."""
    print(f"{'phase':<16}{'share':>8}{'ms/call':>10}{'calls':>8}")
    for r in rows:
        print(f"{r['phase']:<16}{100 * r['share']:>7.1f}%{r['ms_per_call']:>10.2f}{r['calls']:>8}")
    other = loop_s - sum(r["seconds"] for r in rows)
    print(f"{'(loop overhead)':<16}{100 * other / loop_s:>7.1f}%")


def main() -> int:
    args = build_parser().parse_args()

    import torch
    from tensordict import TensorDict

    from atrv_warp.policy import Normalize, make_actor
    from atrv_warp.rl.collectors import make_collector, pin_to_core
    from atrv_warp.rl.command_line import load_train_config
    from atrv_warp.rl.learner import Learner, make_buffer, replay_frames
    from atrv_warp.rl.loop import Evaluator
    from atrv_warp.task.registry import get_task
    from atrv_warp.task.spec import observation_fields

    cfg = load_train_config(args.config)
    torch.manual_seed(0)
    torch.set_num_threads(cfg.run.threads)
    pin_to_core(0)
    obs_dim = len(observation_fields(get_task(cfg.env.task)))
    normalize = Normalize(obs_dim)
    actor = make_actor(cfg.network.width, cfg.network.depth, normalize=normalize, obs_dim=obs_dim)
    buffer = make_buffer(cfg)
    collector = make_collector(cfg, actor, 0)
    phases, learner, frames, updates, credit = Phases(), None, 0, 0, 0.0
    it = iter(collector)
    t_warm = time.perf_counter()
    while frames < cfg.collector.init_random_frames:  # warm-up: compile, random frames, statistics
        data = next(it)
        frames += data.numel()
        buffer.extend(replay_frames(data))  # as the trainer keeps it
    obs = buffer[:]["observation"]
    normalize.set_stats(obs.mean(0), obs.std(0))
    learner = Learner(cfg, actor, normalize)
    print(f"warm-up (compile + {frames:,} random frames): {time.perf_counter() - t_warm:.1f} s", flush=True)
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < args.seconds:
        with phases("collector wait"):
            data = next(it)
        frames += data.numel()
        with phases("buffer extend"):
            buffer.extend(replay_frames(data))  # as the trainer keeps it
        credit += data.numel() * cfg.optim.utd_ratio
        while credit >= 1.0:
            credit -= 1.0
            with phases("sample"):
                batch = buffer.sample()
            learner.update(batch, phase=phases)
            updates += 1
        with phases("weight sync"):
            collector.update_policy_weights_(TensorDict.from_module(actor))
    loop_s = time.perf_counter() - t0
    iso = isolated_phases(learner, buffer, args.isolated_updates)
    evaluator = Evaluator(cfg, actor)  # the periodic evaluation in the trainer (logging.eval_in_background=false)
    evaluator(frames)  # warm: its environment's first steps
    t_eval = time.perf_counter()
    evaluator(frames)
    eval_s = time.perf_counter() - t_eval
    threads_before = torch.get_num_threads()
    collector.shutdown()
    threads_after = torch.get_num_threads()  # TorchRL's shutdown resets it; train() sets it back
    after_shutdown = update_ms(learner, buffer, 10)
    torch.set_num_threads(cfg.run.threads)
    restored = update_ms(learner, buffer, 50)
    print(f"torch threads: {threads_before} in the loop, {threads_after} after collector.shutdown(); one update "
          f"then {after_shutdown:.1f} ms on this process's one pinned core, {restored:.1f} ms with "
          f"{cfg.run.threads} thread(s) again (train() restores it before the final evaluation)")
    update_phases = ("sample", "loss", "backward", "optimiser", "target")
    in_loop = sum(phases.total[p] for p in update_phases) / max(updates, 1)
    isolated = sum(iso.total[p] for p in update_phases) / args.isolated_updates
    rows = [{"phase": p, "seconds": phases.total[p], "calls": phases.calls[p],
             "ms_per_call": 1e3 * phases.total[p] / max(phases.calls[p], 1), "share": phases.total[p] / loop_s}
            for p in sorted(phases.total, key=phases.total.get, reverse=True)]
    print(f"\n{args.seconds:g} s of the default loop: {frames:,} frames, {updates:,} updates "
          f"({updates / loop_s:.1f} updates/s, {(frames - cfg.collector.init_random_frames) / loop_s:,.0f} frames/s)")
    print_phases(rows, loop_s)
    print(f"\none update: {1e3 * in_loop:.2f} ms in the loop, {1e3 * isolated:.2f} ms in isolation "
          f"(ratio {in_loop / isolated:.2f})")
    between_evals_s = cfg.logging.eval_every_frames / ((frames - cfg.collector.init_random_frames) / loop_s)
    eval_share = eval_s / (eval_s + between_evals_s)
    print(f"one periodic evaluation ({cfg.logging.eval_episodes} episodes): {eval_s:.2f} s every "
          f"{cfg.logging.eval_every_frames:,} frames ({between_evals_s:.0f} s of this loop): {100 * eval_share:.1f} % "
          "of a run")
    result = {"seconds": loop_s, "frames": frames, "updates": updates, "phases": rows,
              "update_ms_in_loop": 1e3 * in_loop, "update_ms_isolated": 1e3 * isolated,
              "isolated_phases_ms": {p: 1e3 * iso.total[p] / args.isolated_updates for p in update_phases},
              "threads_after_collector_shutdown": threads_after, "update_ms_after_shutdown": after_shutdown,
              "update_ms_threads_restored": restored, "evaluation_s": eval_s, "evaluation_share": eval_share,
              "config": f"{args.config} preset", "time": time.strftime("%Y-%m-%d %H:%M:%S")}
    write_results(args.out, result, version=VERSION, task=True)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
