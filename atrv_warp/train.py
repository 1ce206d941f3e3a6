"""Train a driver with TorchRL SAC: ``python -m atrv_warp.train``.

Usage::

    python -m atrv_warp.train                                  # preset "default" (the TrainConfig defaults)
    python -m atrv_warp.train --config smoke                   # preset "smoke": about a minute
    python -m atrv_warp.train --config my_run.toml             # your own TOML file
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

from .config import TrainConfig, load_train_config, preset_names
from .runtime import add_verbose_argument, device_summary, error_line, set_verbose
from .storage import FileFormatError, atomic_save, load_weights
from .task_spec import REWARD_TERMS, EndReason

__all__ = ["CHECKPOINT_KEYS", "load_checkpoint", "main", "train"]

DEFAULT_PRESET = "default"
CHECKPOINT_KEYS = ("frames", "updates", "best_success", "elapsed_s", "next_eval", "stats_ready", "rng", "policy")
"""Entries every training checkpoint holds (``loss`` and ``opts`` too once learning has started)."""


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


def load_checkpoint(path: Path) -> dict:
    """Read a training checkpoint (``weights_only``); a damaged one is a ``FileFormatError`` naming it."""
    ck = load_weights(path, "training checkpoint", CHECKPOINT_KEYS)
    if ck["stats_ready"] and not ({"loss", "opts"} <= ck.keys()):
        raise FileFormatError(f"{path}: not a complete training checkpoint: learner state missing")
    if not isinstance(ck["rng"], torch.Tensor) or ck["rng"].dtype != torch.uint8:
        raise FileFormatError(f"{path}: not a complete training checkpoint: bad random-generator state")
    return ck


def _pct(rate: float) -> str:
    """``' 82.4%'``, or ``'  n/a'`` before there is anything to rate."""
    return "  n/a" if math.isnan(rate) else f"{100 * rate:5.1f}%"


class _Progress:
    """Progress toward whichever budget ends the run first: ``total_frames`` or ``max_minutes``.

    On a terminal: a bar whose percentage is the larger of the two fractions, with frames,
    minutes, ETA and the latest figures. Elsewhere (a log file, CI): one line per evaluation.
    """

    def __init__(self, cfg: TrainConfig, frames: int, elapsed_s: float):
        from tqdm import tqdm

        self.total_frames, self.budget_s = cfg.total_frames, cfg.max_minutes * 60.0
        self.frames0, self.elapsed0 = frames, elapsed_s
        self.interactive = cfg.progress and sys.stderr.isatty()
        self.bar = tqdm(total=1000, disable=not self.interactive, dynamic_ncols=True,
                        bar_format="train {percentage:3.0f}%|{bar}| {desc}", mininterval=0.5)
        self.enabled = cfg.progress

    def fraction(self, frames: int, elapsed_s: float) -> float:
        f = frames / self.total_frames
        if self.budget_s > 0:
            f = max(f, elapsed_s / self.budget_s)
        return min(f, 1.0)

    def eta_s(self, frames: int, elapsed_s: float) -> float:
        rate = (frames - self.frames0) / max(elapsed_s - self.elapsed0, 1e-9)
        eta = (self.total_frames - frames) / rate if rate > 0 else math.inf
        return min(eta, self.budget_s - elapsed_s) if self.budget_s > 0 else eta

    def update(self, frames: int, elapsed_s: float, figures: str) -> None:
        eta = self.eta_s(frames, elapsed_s)
        self.bar.set_description_str(f"{frames / 1e6:.2f}M frames | {elapsed_s / 60:.1f} min | "
                                     f"ETA {eta / 60:.1f} min | {figures}", refresh=False)
        self.bar.update(round(1000 * self.fraction(frames, elapsed_s)) - self.bar.n)  # redraws at most 2/s

    def log(self, line: str) -> None:
        if self.interactive:
            self.bar.write(line)
        elif self.enabled:
            print(line, flush=True)

    def close(self) -> None:
        self.bar.close()


class _Stats:
    """Running training statistics from collected batches (episodes that ended in them), and the
    mean of every reward term over the collected steps."""

    def __init__(self):
        self.ended = 0
        self.success = 0
        self.reward_sum = 0.0
        self.reward_n = 0
        self.term_sums = torch.zeros(len(REWARD_TERMS), dtype=torch.float64)

    def update(self, data) -> None:
        done = data["next", "done"].reshape(-1)
        reasons = data["next", "end_reason"].reshape(-1)[done]
        self.ended += int(done.sum())
        self.success += int((reasons == EndReason.SUCCESS).sum())
        r = data["next", "reward"]
        self.reward_sum += float(r.sum())
        self.reward_n += r.numel()
        terms = data["next", "reward_terms"]
        self.term_sums += torch.stack([terms[name].sum() for name in REWARD_TERMS]).double()

    def pop(self) -> tuple[float, float, dict[str, float]]:
        """(success rate, mean reward, mean of each reward term), then start over."""
        rate = self.success / self.ended if self.ended else float("nan")
        n = self.reward_n
        reward = self.reward_sum / n if n else float("nan")
        terms = {name: float(v) / n if n else float("nan") for name, v in zip(REWARD_TERMS, self.term_sums)}
        self.__init__()
        return rate, reward, terms


class _LossMeans:
    """Means of SAC's losses and entropy over the updates since the last :meth:`pop`."""

    KEYS = ("loss_actor", "loss_qvalue", "loss_alpha", "entropy")

    def __init__(self):
        self.sums = {k: 0.0 for k in self.KEYS}
        self.n = 0

    def add(self, out) -> None:
        for k in self.KEYS:
            self.sums[k] += float(out[k].detach())
        self.n += 1

    def pop(self) -> dict[str, float]:
        means = {k: v / self.n for k, v in self.sums.items()} if self.n else {}
        self.__init__()
        return means


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
    from tensordict import TensorDict
    from torchrl.collectors import Collector, MultiAsyncCollector
    from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
    from torchrl.objectives import SACLoss, SoftUpdate
    from torchrl.record.loggers import CSVLogger

    from .agents import Normalize, make_actor, make_qvalue, policy_payload, save_policy
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
    ck = load_checkpoint(ckpt_path) if resume else None  # before anything is written: a bad file loses nothing

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
    if ck is not None:
        frames, updates, best = ck["frames"], ck["updates"], ck["best_success"]
        elapsed_before, next_eval, stats_ready = ck["elapsed_s"], ck["next_eval"], ck["stats_ready"]
        try:
            actor.load_state_dict(ck["policy"]["state_dict"])
            if stats_ready:
                build_learner()
                parts["loss"].load_state_dict(ck["loss"])
                for k, opt in parts["opts"].items():
                    opt.load_state_dict(ck["opts"][k])
        except (KeyError, TypeError, ValueError, RuntimeError) as err:
            detail = (str(err).strip().splitlines() or [type(err).__name__])[0][:200]
            raise FileFormatError(f"{ckpt_path}: does not match this run's networks (width={cfg.width}, "
                                  f"depth={cfg.depth}): {detail}") from None
        torch.set_rng_state(ck["rng"])
        if (run_dir / "buffer").is_dir():
            try:
                buffer.loads(run_dir / "buffer")
            except Exception as err:  # noqa: BLE001 - any failure here means a damaged buffer folder
                raise FileFormatError(f"{run_dir / 'buffer'}: damaged replay buffer ({type(err).__name__}: "
                                      f"{(str(err).strip().splitlines() or [''])[0][:200]})") from None
        print(f"resumed {run_dir} at {frames:,} frames, {updates:,} updates, best success {100 * best:.1f}%")
    if frames >= cfg.total_frames:
        print(f"nothing to do: {frames:,} frames already collected (total_frames={cfg.total_frames:,}); "
              "raise total_frames= to train further")
        return run_dir
    run_dir.mkdir(parents=True, exist_ok=True)
    _write_toml(cfg, run_dir / "config.toml")

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
    whole_batches = max(math.ceil(remaining / fpb), 1) * fpb  # the loop stops at total_frames itself
    if cfg.collector == "async":
        collector = MultiAsyncCollector([EnvFactory(cfg.num_envs, seed=env_seed, core=1)], actor,
                                        frames_per_batch=fpb, total_frames=whole_batches,
                                        init_random_frames=random_left)
    else:
        # the MLP policy is stateless: it needs no env transform (InitTracker) appended for it
        collector = Collector(ATRVjrEnv(cfg.num_envs, seed=env_seed), actor, frames_per_batch=fpb,
                              total_frames=whole_batches, init_random_frames=random_left,
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
        atomic_save({**learner, "frames": frames, "updates": updates, "best_success": best, "elapsed_s": elapsed,
                      "next_eval": next_eval, "stats_ready": stats_ready, "rng": torch.get_rng_state(),
                     "policy": policy_payload(actor, width=cfg.width, depth=cfg.depth, meta={"frames": frames}),
                     "config": dataclasses.asdict(cfg)}, ckpt_path)
        if stats_ready and len(buffer):
            buffer.dumps(run_dir / "buffer")

    budget_s = cfg.max_minutes * 60.0 if cfg.max_minutes > 0 else math.inf
    t_start = time.perf_counter()
    stats = _Stats()
    losses = _LossMeans()
    update_credit = 0.0
    last_eval_success, last_train = float("nan"), (float("nan"), float("nan"), {})
    print(f"run folder: {run_dir}  ({cfg.collector} collector, {cfg.num_envs} worlds, batch {fpb} frames; "
          f"budget {cfg.total_frames:,} frames or {cfg.max_minutes:g} min, whichever ends first)")
    print(device_summary("cpu"))
    progress = _Progress(cfg, frames, elapsed_before)
    stopped_by = "total_frames"
    try:
        for data in collector:
            n = data.numel()
            frames += n
            stats.update(data)
            buffer.extend(data.reshape(-1).cpu())
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
                    losses.add(out)
                if cfg.collector == "async":  # the worker holds a copy; the sync collector shares `actor`
                    collector.update_policy_weights_(TensorDict.from_module(actor))
            elapsed = elapsed_before + time.perf_counter() - t_start
            if frames >= next_eval or frames >= cfg.total_frames or elapsed >= budget_s:
                last_train = stats.pop()
                log_scalar("train_success_rate", last_train[0])
                log_scalar("train_reward", last_train[1])
                for name, value in last_train[2].items():
                    log_scalar(f"train_reward_{name}", value)
                log_scalar("updates", updates)
                for name, value in losses.pop().items():
                    log_scalar(name, value)
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
                progress.log(f"{frames:>11,} frames {elapsed / 60:5.1f} min  eval success {_pct(last_eval_success)}"
                             f"  training episodes {_pct(last_train[0])}  reward {last_train[1]:+.3f}  "
                             f"updates {updates:,}")
            progress.update(frames, elapsed, f"eval {_pct(last_eval_success)} | train {_pct(last_train[0])} | "
                                             f"updates {updates:,}")
            if elapsed >= budget_s:
                stopped_by = f"max_minutes={cfg.max_minutes}"
                break
            if frames >= cfg.total_frames:
                break
    finally:
        progress.close()
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
        print(f"rerun recording: {loggers[-1].path}")
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
    parser.add_argument("--config", default=None, metavar="PRESET|FILE",
                        help=f"a preset shipped with the package ({', '.join(preset_names())}; default "
                             f"{DEFAULT_PRESET!r}) or a TOML file")
    parser.add_argument("--resume", metavar="RUN_DIR", default=None, help="continue the run in RUN_DIR")
    add_verbose_argument(parser)
    parser.add_argument("overrides", nargs="*", help="key=value overrides of any TrainConfig field")
    args = parser.parse_args(argv)
    if args.verbose:
        set_verbose()
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
            cfg = load_train_config(args.config or DEFAULT_PRESET, overrides)
    except (ValueError, FileNotFoundError) as err:
        return error_line(parser.prog, str(err))
    try:
        train(cfg, resume=bool(args.resume))
    except (FileExistsError, FileNotFoundError, ModuleNotFoundError, FileFormatError) as err:
        return error_line(parser.prog, str(err))
    return 0


if __name__ == "__main__":
    sys.exit(main())
