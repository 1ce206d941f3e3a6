"""Train a driver with TorchRL SAC: ``python -m atrv_warp.train``.

Usage::

    python -m atrv_warp.train                                  # configs/default.toml
    python -m atrv_warp.train --config configs/smoke.toml      # tiny budget
    python -m atrv_warp.train num_envs=128 max_minutes=5       # override any field
    python -m atrv_warp.train --resume runs/default            # continue a killed run

Outputs in ``<out_dir>/<name>/``: ``config.toml`` (resolved), ``checkpoint.pt`` (atomic,
at every evaluation), ``best_policy.pt`` (best periodic evaluation), ``final_eval.json``,
``logs/`` (CSV or TensorBoard scalars), ``learning_curve.png``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys
import time
from pathlib import Path

import torch

from .config import TrainConfig, load_train_config

__all__ = ["main", "train"]

DEFAULT_CONFIG = Path(__file__).resolve().parent.parent / "configs" / "default.toml"


def _pin_to_core(index: int) -> None:
    if hasattr(os, "sched_setaffinity"):
        cores = sorted(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {cores[index % len(cores)]})


def _write_toml(cfg: TrainConfig, path: Path) -> None:
    lines = []
    for f in dataclasses.fields(cfg):
        v = getattr(cfg, f.name)
        lines.append(f"{f.name} = {json.dumps(v) if not isinstance(v, bool) else str(v).lower()}")
    path.write_text("\n".join(lines) + "\n")


def _atomic_save(obj, path: Path) -> None:
    tmp = path.with_suffix(path.suffix + ".tmp")
    torch.save(obj, tmp)
    tmp.replace(path)


class _Stats:
    """Running training statistics from collected batches (episodes that ended in them)."""

    def __init__(self):
        self.ended = 0
        self.success = 0
        self.reward_sum = 0.0
        self.reward_n = 0

    def update(self, data) -> None:
        from .env import END_REASONS

        done = data["next", "done"].reshape(-1)
        reasons = data["next", "end_reason"].reshape(-1)[done]
        self.ended += int(done.sum())
        self.success += int((reasons == END_REASONS.index("success")).sum())
        r = data["next", "reward"]
        self.reward_sum += float(r.sum())
        self.reward_n += r.numel()

    def pop(self) -> tuple[float, float]:
        rate = self.success / self.ended if self.ended else float("nan")
        reward = self.reward_sum / self.reward_n if self.reward_n else float("nan")
        self.__init__()
        return rate, reward


def _plot_curve(log_dir: Path, out: Path) -> bool:
    """Learning curve PNG from the CSV scalars; returns False if there is nothing to plot."""
    scalars = log_dir / "scalars"
    series = {}
    for name in ("eval_success_rate", "train_success_rate", "train_reward"):
        f = scalars / f"{name}.csv"
        if f.is_file():
            rows = [line.split(",") for line in f.read_text().splitlines() if line.strip()]
            series[name] = ([float(a) for a, _ in rows], [float(b) for _, b in rows])
    if "eval_success_rate" not in series:
        return False
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4), dpi=100)
    x, y = series["eval_success_rate"]
    ax.plot(x, [100 * v for v in y], "o-", label="evaluation success (deterministic)")
    if "train_success_rate" in series:
        x, y = series["train_success_rate"]
        ax.plot(x, [100 * v for v in y], alpha=0.5, label="training episodes' success (stochastic)")
    ax.set_xlabel("environment frames")
    ax.set_ylabel("success rate [%]")
    ax.set_ylim(0, 100)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right")
    ax.set_title("ATRV-Jr drive-to-target, SAC")
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)
    return True


def train(cfg: TrainConfig, *, resume: bool = False) -> Path:
    """Run SAC training with ``cfg``; returns the run folder."""
    import warp as wp

    wp.config.quiet = True
    from tensordict import TensorDict
    from torchrl.collectors import Collector, MultiAsyncCollector
    from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
    from torchrl.objectives import SACLoss, SoftUpdate
    from torchrl.record.loggers import CSVLogger
    from tqdm import tqdm

    from .agents import Normalize, make_actor, make_qvalue, save_policy
    from .env import ATRVjrEnv, EnvFactory
    from .evaluation import EVAL_SEED, evaluate, format_result

    if cfg.logger == "tensorboard":
        import importlib.util

        if importlib.util.find_spec("tensorboard") is None:
            raise ModuleNotFoundError("logger=tensorboard needs the tensorboard package: pip install -e '.[tensorboard]'")
    run_dir = Path(cfg.out_dir) / cfg.name
    ckpt_path = run_dir / "checkpoint.pt"
    if resume and not ckpt_path.is_file():
        raise FileNotFoundError(f"--resume: no checkpoint at {ckpt_path}")
    if not resume and ckpt_path.exists():
        raise FileExistsError(f"{run_dir} already holds a run; use --resume to continue it or another name=")
    run_dir.mkdir(parents=True, exist_ok=True)
    _write_toml(cfg, run_dir / "config.toml")

    torch.manual_seed(cfg.seed)
    torch.set_num_threads(cfg.threads)
    if cfg.collector == "async":
        _pin_to_core(0)

    normalize = Normalize()
    actor = make_actor(cfg.width, cfg.depth, normalize=normalize)
    buffer = TensorDictReplayBuffer(storage=LazyTensorStorage(cfg.buffer_size), batch_size=cfg.batch_size)
    parts: dict = {}

    def build_learner() -> None:
        """Critics, loss, optimisers: built once the observation statistics are final, so the
        critics' (copied) normalisation matches the actor's."""
        qvalue = make_qvalue(cfg.width, cfg.depth, normalize=normalize)
        loss = SACLoss(actor, qvalue, num_qvalue_nets=2, alpha_init=cfg.init_alpha, target_entropy=-2.0)
        loss.make_value_estimator(gamma=cfg.gamma)
        parts["loss"] = loss
        parts["target_update"] = SoftUpdate(loss, tau=cfg.tau)
        parts["opts"] = {
            "actor": torch.optim.Adam(loss.actor_network_params.flatten_keys().values(), lr=cfg.lr),
            "critic": torch.optim.Adam(loss.qvalue_network_params.flatten_keys().values(), lr=cfg.lr),
            "alpha": torch.optim.Adam([loss.log_alpha], lr=cfg.lr),
        }

    frames, updates, best, elapsed_before, next_eval = 0, 0, -1.0, 0.0, cfg.eval_every_frames
    stats_ready = False
    if resume:
        ck = torch.load(ckpt_path, map_location="cpu", weights_only=True)
        frames, updates, best = ck["frames"], ck["updates"], ck["best_success"]
        elapsed_before, next_eval, stats_ready = ck["elapsed_s"], ck["next_eval"], ck["stats_ready"]
        actor.load_state_dict(ck["policy"]["state_dict"])
        if stats_ready:
            build_learner()
            parts["loss"].load_state_dict(ck["loss"])
            for k, opt in parts["opts"].items():
                opt.load_state_dict(ck["opts"][k])
        torch.set_rng_state(ck["rng"])
        if (run_dir / "buffer").is_dir():
            buffer.loads(run_dir / "buffer")
        print(f"resumed {run_dir} at {frames:,} frames, {updates:,} updates, best success {100 * best:.1f}%")
    if frames >= cfg.total_frames:
        print(f"nothing to do: {frames:,} frames already collected (total_frames={cfg.total_frames:,}); "
              "raise total_frames= to train further")
        return run_dir

    loggers = [CSVLogger(exp_name="logs", log_dir=str(run_dir))]  # always: the learning curve is drawn from it
    if cfg.logger == "tensorboard":
        from torchrl.record.loggers import TensorboardLogger

        loggers.append(TensorboardLogger(exp_name="logs", log_dir=str(run_dir)))
    elif cfg.logger == "rerun":
        from .viz import RerunLogger

        loggers.append(RerunLogger("train", path=run_dir / ("train_resumed.rrd" if resume else "train.rrd")))

    def log_scalar(name: str, value: float) -> None:
        for lg in loggers:
            lg.log_scalar(name, value, step=frames)

    remaining = max(cfg.total_frames - frames, 0)
    random_left = max(cfg.init_random_frames - frames, 0)
    fpb = cfg.frames_per_batch
    env_seed = cfg.seed + 7919 * (frames // fpb + 1)  # a resumed run draws new episodes
    if cfg.collector == "async":
        collector = MultiAsyncCollector([EnvFactory(cfg.num_envs, seed=env_seed, core=1)], actor,
                                        frames_per_batch=fpb, total_frames=max(remaining, fpb),
                                        init_random_frames=random_left)
    else:
        # the MLP policy is stateless: it needs no env transform (InitTracker) appended for it
        collector = Collector(ATRVjrEnv(cfg.num_envs, seed=env_seed), actor, frames_per_batch=fpb,
                              total_frames=max(remaining, fpb), init_random_frames=random_left,
                              auto_register_policy_transforms=False)
    eval_env = ATRVjrEnv(cfg.eval_episodes, seed=EVAL_SEED)
    eval_recorder = None
    if cfg.logger == "rerun":  # periodic evaluations go into the same recording as the scalars
        from .viz import RerunRecorder

        eval_recorder = RerunRecorder(eval_env.sim, recording=loggers[-1].experiment, worlds=range(2))

    def run_eval() -> float:
        actor.eval()
        on_step = None
        if eval_recorder is not None:
            eval_recorder.rec.set_time("frames", sequence=frames)
            on_step = eval_recorder.env_hook()
        r = evaluate(actor, num_episodes=cfg.eval_episodes, seed=EVAL_SEED, env=eval_env, on_step=on_step)
        actor.train()
        for k, v in r.as_dict().items():
            if k != "episodes":
                log_scalar(f"eval_{k}", v)
        return r.success_rate

    def checkpoint() -> None:
        elapsed = elapsed_before + time.perf_counter() - t_start
        learner = {}
        if stats_ready:
            learner = {"loss": parts["loss"].state_dict(),
                       "opts": {k: o.state_dict() for k, o in parts["opts"].items()}}
        _atomic_save({**learner, "frames": frames, "updates": updates, "best_success": best, "elapsed_s": elapsed,
                      "next_eval": next_eval, "stats_ready": stats_ready, "rng": torch.get_rng_state(),
                      "policy": {"format": "atrv_warp.policy/1", "width": cfg.width, "depth": cfg.depth,
                                 "state_dict": actor.state_dict(), "meta": {"frames": frames}},
                      "config": dataclasses.asdict(cfg)}, ckpt_path)
        if stats_ready and len(buffer):
            buffer.dumps(run_dir / "buffer")

    budget_s = cfg.max_minutes * 60.0 if cfg.max_minutes > 0 else math.inf
    t_start = time.perf_counter()
    stats = _Stats()
    update_credit = 0.0
    last_eval_success, last_train = float("nan"), (float("nan"), float("nan"))
    bar = tqdm(total=cfg.total_frames, initial=frames, unit="frame", unit_scale=True, dynamic_ncols=True,
               disable=not cfg.progress, desc="train")
    print(f"run folder: {run_dir}  ({cfg.collector} collector, {cfg.num_envs} worlds, batch {fpb} frames)")
    stopped_by = "total_frames"
    try:
        for data in collector:
            n = data.numel()
            frames += n
            stats.update(data)
            buffer.extend(data.reshape(-1).cpu())
            bar.update(n)
            if frames >= cfg.init_random_frames:
                if not stats_ready:
                    obs = buffer[:]["observation"]
                    normalize.set_stats(obs.mean(0), obs.std(0))
                    stats_ready = True
                    build_learner()
                loss, opts = parts["loss"], parts["opts"].values()
                update_credit += n * cfg.utd_ratio
                while update_credit >= 1.0:
                    update_credit -= 1.0
                    out = loss(buffer.sample())
                    for opt in opts:
                        opt.zero_grad(set_to_none=True)
                    (out["loss_actor"] + out["loss_qvalue"] + out["loss_alpha"]).backward()
                    for opt in opts:
                        opt.step()
                    parts["target_update"].step()
                    updates += 1
                if cfg.collector == "async":  # the worker holds a copy; the sync collector shares `actor`
                    collector.update_policy_weights_(TensorDict.from_module(actor))
            elapsed = elapsed_before + time.perf_counter() - t_start
            if frames >= next_eval or frames >= cfg.total_frames or elapsed >= budget_s:
                last_train = stats.pop()
                log_scalar("train_success_rate", last_train[0])
                log_scalar("train_reward", last_train[1])
                log_scalar("updates", updates)
                log_scalar("wall_time_s", elapsed)
                if stats_ready:
                    log_scalar("alpha", float(parts["loss"].log_alpha.detach().exp()))
                if stats_ready:
                    last_eval_success = run_eval()
                    if last_eval_success > best:
                        best = last_eval_success
                        save_policy(actor, run_dir / "best_policy.pt", width=cfg.width, depth=cfg.depth,
                                    meta={"frames": frames, "eval_success": best})
                next_eval = (frames // cfg.eval_every_frames + 1) * cfg.eval_every_frames
                checkpoint()
            left = budget_s - (elapsed_before + time.perf_counter() - t_start)
            frame_rate = bar.format_dict["rate"] or 1.0
            eta = min(left, (cfg.total_frames - frames) / frame_rate)
            bar.set_postfix_str(f"eval {100 * last_eval_success:.0f}% | train {100 * last_train[0]:.0f}% | "
                                f"reward {last_train[1]:+.3f} | updates {updates:,} | ETA {eta / 60:.1f} min",
                                refresh=False)
            if elapsed >= budget_s:
                stopped_by = f"max_minutes={cfg.max_minutes}"
                break
            if frames >= cfg.total_frames:
                break
    finally:
        bar.close()
        collector.shutdown()
    elapsed = elapsed_before + time.perf_counter() - t_start
    print(f"training stopped by {stopped_by}: {frames:,} frames, {updates:,} updates, {elapsed / 60:.1f} min")

    result = {"frames": frames, "updates": updates, "train_minutes": elapsed / 60, "best_periodic_success": best}
    best_path = run_dir / "best_policy.pt"
    if best_path.is_file():
        from .agents import load_policy

        final = evaluate(load_policy(best_path), num_episodes=cfg.final_eval_episodes, seed=EVAL_SEED)
        print(format_result("best policy, final evaluation", final))
        result["final_eval"] = final.as_dict()
    (run_dir / "final_eval.json").write_text(json.dumps(result, indent=2) + "\n")
    if eval_recorder is not None:
        eval_recorder.close()
        print(f"rerun recording: {loggers[-1]._path}")
    if _plot_curve(run_dir / "logs", run_dir / "learning_curve.png"):
        print(f"learning curve: {run_dir / 'learning_curve.png'}")
    print(f"checkpoint: {ckpt_path}\nbest policy: {best_path if best_path.is_file() else '(none yet)'}\n"
          f"logs: {run_dir / 'logs'}\nevaluate: python -m atrv_warp.evaluate {best_path}")
    return run_dir


def _parse_overrides(items: list[str]) -> dict:
    out = {}
    for item in items:
        if "=" not in item:
            raise ValueError(f"override {item!r} must look like key=value")
        k, v = item.split("=", 1)
        out[k.strip()] = v
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m atrv_warp.train", description=__doc__.splitlines()[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    parser.add_argument("--config", default=None, help=f"TOML config (default: {DEFAULT_CONFIG.name} if present)")
    parser.add_argument("--resume", metavar="RUN_DIR", default=None, help="continue the run in RUN_DIR")
    parser.add_argument("overrides", nargs="*", help="key=value overrides of any TrainConfig field")
    args = parser.parse_args(argv)
    try:
        overrides = _parse_overrides(args.overrides)
        if args.resume:
            run_dir = Path(args.resume)
            cfg_file = run_dir / "config.toml"
            if not cfg_file.is_file():
                raise FileNotFoundError(f"--resume: {cfg_file} not found")
            overrides = {"out_dir": str(run_dir.parent), "name": run_dir.name, **overrides}
            cfg = load_train_config(str(cfg_file), overrides)
        else:
            path = args.config or (str(DEFAULT_CONFIG) if DEFAULT_CONFIG.is_file() else None)
            cfg = load_train_config(path, overrides)
    except (ValueError, FileNotFoundError) as err:
        parser.error(str(err))
    try:
        train(cfg, resume=bool(args.resume))
    except (FileExistsError, FileNotFoundError, ModuleNotFoundError) as err:
        parser.error(str(err))
    return 0


if __name__ == "__main__":
    sys.exit(main())
