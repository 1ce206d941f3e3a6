"""SAC training from small parts: :func:`make_buffer`, :func:`make_collector`,
:func:`make_loggers`, :class:`Learner`, :class:`Evaluator`, :class:`Checkpoint`, and
:func:`train`, which reads top to bottom. The command line is ``python -m atrv_warp.train``."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import torch
from tensordict import TensorDict

from atrv_warp.rl.agents import Normalize, load_policy, make_actor, make_qvalue, policy_payload, save_policy
from atrv_warp.rl.config import TrainConfig, to_toml
from atrv_warp.runtime import device_summary
from atrv_warp.storage import FileFormatError, atomic_save, load_weights
from atrv_warp.task.config import get_task
from atrv_warp.task.env import ATRVjrEnv, EnvFactory
from atrv_warp.task.evaluation import EVAL_SEED, evaluate, format_result
from atrv_warp.task.spec import REWARD_TERMS, EndReason, observation_fields

__all__ = ["CHECKPOINT_KEYS", "Checkpoint", "Evaluator", "Learner", "RunState", "load_checkpoint", "make_buffer",
           "make_collector", "make_loggers", "make_loss", "train"]

CHECKPOINT_KEYS = ("frames", "updates", "best_success", "elapsed_s", "next_eval", "stats_ready", "rng", "policy")
"""Entries every training checkpoint holds (``loss`` and ``opts`` too once learning has started)."""


def _pin_to_core(index: int) -> None:
    if hasattr(os, "sched_setaffinity"):
        cores = sorted(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {cores[index % len(cores)]})


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

        self.total_frames, self.budget_s = cfg.run.total_frames, cfg.run.max_minutes * 60.0
        self.frames0, self.elapsed0 = frames, elapsed_s
        self.interactive = cfg.logging.progress and sys.stderr.isatty()
        self.bar = tqdm(total=1000, disable=not self.interactive, dynamic_ncols=True,
                        bar_format="train {percentage:3.0f}%|{bar}| {desc}", mininterval=0.5)
        self.enabled = cfg.logging.progress

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


@dataclass
class RunState:
    """Where a run stands; saved in every checkpoint and restored by ``--resume``."""

    frames: int = 0
    updates: int = 0
    best_success: float = -1.0
    best_return: float = -math.inf
    """Mean return of the best policy's evaluation: the tie-break between equal success rates."""
    elapsed_s: float = 0.0
    next_eval: int = 0
    stats_ready: bool = False
    """Observation statistics are frozen and the learner exists (after ``init_random_frames``)."""


def make_loss(cfg: TrainConfig, actor, normalize: Normalize):
    """The TorchRL loss ``cfg.optim.loss`` names, with new critics that share ``normalize``."""
    from torchrl.objectives import CrossQLoss, REDQLoss, SACLoss

    width, depth = cfg.network.width, cfg.network.depth
    common = {"alpha_init": cfg.optim.init_alpha, "target_entropy": -2.0}
    if cfg.optim.loss == "crossq":
        qvalue = make_qvalue(width, depth, normalize=normalize, batch_renorm=True)
        loss = CrossQLoss(actor, qvalue, num_qvalue_nets=2, **common)
    elif cfg.optim.loss == "redq":
        qvalue = make_qvalue(width, depth, normalize=normalize)
        # REDQLoss needs temperature bounds; its default floor (0.1) would outweigh this task's rewards
        loss = REDQLoss(actor, qvalue, num_qvalue_nets=10, sub_sample_len=2, min_alpha=1e-4, max_alpha=10.0,
                        **common)
    else:
        loss = SACLoss(actor, make_qvalue(width, depth, normalize=normalize), num_qvalue_nets=2, **common)
    loss.make_value_estimator(gamma=cfg.optim.gamma)
    _ = loss.target_entropy  # REDQ registers this buffer lazily: a resumed run's state dict must find it
    return loss


class Learner:
    """SAC's critics, loss, target-network update and optimisers.

    Built once the observation statistics are final, so the critics' (copied) normalisation
    matches the actor's.
    """

    def __init__(self, cfg: TrainConfig, actor, normalize: Normalize):
        self.loss = make_loss(cfg, actor, normalize)
        self.target_update = None
        if cfg.optim.loss != "crossq":  # CrossQ has no target networks
            from torchrl.objectives import SoftUpdate

            self.target_update = SoftUpdate(self.loss, tau=cfg.optim.tau)
        self.opts = {
            "actor": torch.optim.Adam(self.loss.actor_network_params.flatten_keys().values(), lr=cfg.optim.lr),
            "critic": torch.optim.Adam(self.loss.qvalue_network_params.flatten_keys().values(), lr=cfg.optim.lr),
            "alpha": torch.optim.Adam([self.loss.log_alpha], lr=cfg.optim.lr),
        }

    def update(self, batch, phase=None):
        """One gradient step on every network and the temperature; returns the loss TensorDict.

        ``phase``: optional ``phase(name)`` context-manager factory that times each part (loss,
        backward, optimiser, target), as ``benchmarks/train_profile.py`` does.
        """
        phase = phase or (lambda name: contextlib.nullcontext())
        with phase("loss"):
            out = self.loss(batch)
        with phase("backward"):
            for opt in self.opts.values():
                opt.zero_grad(set_to_none=True)
            (out["loss_actor"] + out["loss_qvalue"] + out["loss_alpha"]).backward()
        with phase("optimiser"):
            for opt in self.opts.values():
                opt.step()
        if self.target_update is not None:
            with phase("target"):
                self.target_update.step()
        return out

    @property
    def alpha(self) -> float:
        return float(self.loss.log_alpha.detach().exp())

    def state_dict(self) -> dict:
        return {"loss": self.loss.state_dict(), "opts": {k: o.state_dict() for k, o in self.opts.items()}}

    def load_state_dict(self, sd: dict) -> None:
        self.loss.load_state_dict(sd["loss"])
        for k, opt in self.opts.items():
            opt.load_state_dict(sd["opts"][k])


class Checkpoint:
    """``checkpoint.pt`` (atomic) and the replay buffer beside it; :meth:`save` and :meth:`restore`
    mirror each other."""

    def __init__(self, run_dir: Path):
        self.path, self.buffer_dir = run_dir / "checkpoint.pt", run_dir / "buffer"

    def save(self, cfg: TrainConfig, state: RunState, actor, learner: Learner | None, buffer) -> None:
        payload = {**dataclasses.asdict(state), "rng": torch.get_rng_state(), "config": dataclasses.asdict(cfg),
                   "policy": policy_payload(actor, width=cfg.network.width, depth=cfg.network.depth,
                                          meta={"frames": state.frames, "task": cfg.env.task})}
        if learner is not None:
            payload.update(learner.state_dict())
        atomic_save(payload, self.path)
        if learner is not None and len(buffer):
            buffer.dumps(self.buffer_dir)

    def restore(self, ck: dict, cfg: TrainConfig, actor, normalize: Normalize, buffer) -> tuple[RunState, Learner | None]:
        """Load a checkpoint read by :func:`load_checkpoint` into fresh networks and buffer."""
        # keys added after a checkpoint was written take their defaults
        state = RunState(**{f.name: ck[f.name] for f in dataclasses.fields(RunState) if f.name in ck})
        learner = None
        try:
            actor.load_state_dict(ck["policy"]["state_dict"])
            if state.stats_ready:
                learner = Learner(cfg, actor, normalize)
                learner.load_state_dict(ck)
        except (KeyError, TypeError, ValueError, RuntimeError) as err:
            raise FileFormatError(f"{self.path}: does not match this run's networks (width={cfg.network.width}, "
                                  f"depth={cfg.network.depth}): {_first_line(err)}") from None
        torch.set_rng_state(ck["rng"])
        if self.buffer_dir.is_dir():
            try:
                buffer.loads(self.buffer_dir)
            except Exception as err:  # noqa: BLE001 - any failure here means a damaged buffer folder
                raise FileFormatError(f"{self.buffer_dir}: damaged replay buffer ({type(err).__name__}: "
                                      f"{_first_line(err)})") from None
        return state, learner


def _describe_collection(cfg: TrainConfig) -> str:
    """``'async collector, 256 worlds'``, or ``'2 ray collectors x 64 worlds (local Ray)'``."""
    if cfg.collector.kind != "ray":
        return f"{cfg.collector.kind} collector, {cfg.env.num_envs} worlds"
    where = f"Ray at {cfg.collector.ray_address}" if cfg.collector.ray_address else "local Ray"
    return f"{cfg.collector.num_collectors} ray collectors x {cfg.worlds_per_collector} worlds ({where})"


def _first_line(err: Exception) -> str:
    return (str(err).strip().splitlines() or [type(err).__name__])[0][:200]


def make_buffer(cfg: TrainConfig):
    from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer

    return TensorDictReplayBuffer(storage=LazyTensorStorage(cfg.optim.buffer_size), batch_size=cfg.optim.batch_size)


def make_collector(cfg: TrainConfig, actor, frames_done: int):
    """``async``: one worker process on the second core; ``sync``: collect in this process; ``ray``:
    ``num_collectors`` Ray actors (:func:`atrv_warp.rl.ray_collection.make_ray_collector`)."""
    from torchrl.collectors import Collector, MultiAsyncCollector

    fpb = cfg.frames_per_batch
    remaining = max(cfg.run.total_frames - frames_done, 0)
    random_left = max(cfg.collector.init_random_frames - frames_done, 0)
    env_seed = cfg.run.seed + 7919 * (frames_done // fpb + 1)  # a resumed run draws new episodes
    whole_batches = max(math.ceil(remaining / fpb), 1) * fpb  # the loop stops at total_frames itself
    if cfg.collector.kind == "ray":
        from atrv_warp.rl.ray_collection import make_ray_collector

        return make_ray_collector(cfg, actor, total_frames=whole_batches, init_random_frames=random_left,
                                  env_seed=env_seed)
    if cfg.collector.kind == "async":
        factory = EnvFactory(cfg.env.num_envs, seed=env_seed, core=1, env_kwargs=cfg.env.env_kwargs())
        failure = None
        try:
            return MultiAsyncCollector([factory], actor, frames_per_batch=fpb, total_frames=whole_batches,
                                       init_random_frames=random_left)
        except Exception as err:  # noqa: BLE001 - re-raised below, once the half-built collector is gone
            failure = f"{type(err).__name__}: {err}"
        # The half-built collector dies with the exception's frames, here: torchrl 0.14's weight-sync
        # scheme shuts down in __del__, which deadlocks if it is left for interpreter exit.
        import gc

        gc.collect()
        raise RuntimeError(f"the collector's worker process failed to start: {failure}")
    # the MLP policy is stateless: it needs no env transform (InitTracker) appended for it
    env = ATRVjrEnv(cfg.env.num_envs, seed=env_seed, **dict(cfg.env.env_kwargs()))
    return Collector(env, actor, frames_per_batch=fpb, total_frames=whole_batches, init_random_frames=random_left,
                     auto_register_policy_transforms=False)


def make_loggers(cfg: TrainConfig, run_dir: Path, resume: bool) -> list:
    """CSV always (the learning curve is drawn from it), plus TensorBoard or Rerun."""
    from torchrl.record.loggers import CSVLogger

    loggers = [CSVLogger(exp_name="logs", log_dir=str(run_dir))]
    if cfg.logging.logger == "tensorboard":
        from torchrl.record.loggers import TensorboardLogger

        loggers.append(TensorboardLogger(exp_name="logs", log_dir=str(run_dir)))
    elif cfg.logging.logger == "rerun":
        from atrv_warp.integrations.rerun import RerunLogger

        loggers.append(RerunLogger("train", path=run_dir / ("train_resumed.rrd" if resume else "train.rrd")))
    return loggers


class Evaluator:
    """The periodic deterministic evaluation on the fixed seeded set (and its Rerun recording)."""

    def __init__(self, cfg: TrainConfig, actor, loggers: list):
        self.cfg, self.actor = cfg, actor
        self.env = ATRVjrEnv(cfg.logging.eval_episodes, seed=EVAL_SEED, **dict(cfg.env.env_kwargs()))
        self.recorder = None
        if cfg.logging.logger == "rerun":  # periodic evaluations go into the same recording as the scalars
            from atrv_warp.integrations.rerun import RerunRecorder

            self.recorder = RerunRecorder(self.env.sim, recording=loggers[-1].experiment, worlds=range(2))

    def __call__(self, frames: int):
        self.actor.eval()
        on_step = None
        if self.recorder is not None:
            self.recorder.rec.set_time("frames", sequence=frames)
            on_step = self.recorder.env_hook()
        result = evaluate(self.actor, num_episodes=self.cfg.logging.eval_episodes, seed=EVAL_SEED, env=self.env,
                          on_step=on_step)
        self.actor.train()
        return result

    def close(self) -> None:
        if self.recorder is not None:
            self.recorder.close()


def _prepare_run(cfg: TrainConfig, resume: bool) -> tuple[Path, dict | None]:
    """Check the run folder, and read the checkpoint to resume from before anything is written."""
    if cfg.logging.logger == "tensorboard":
        import importlib.util

        if importlib.util.find_spec("tensorboard") is None:
            raise ModuleNotFoundError("logger=tensorboard needs the tensorboard package: pip install -e '.[tensorboard]'")
    if cfg.collector.kind == "ray":
        from atrv_warp.rl.ray_collection import require_ray

        require_ray()
    run_dir = Path(cfg.run.out_dir) / cfg.run.name
    ckpt_path = Checkpoint(run_dir).path
    if resume and not ckpt_path.is_file():
        raise FileNotFoundError(f"--resume: no checkpoint at {ckpt_path}")
    if not resume and ckpt_path.exists():
        raise FileExistsError(f"{run_dir} already holds a run; use --resume to continue it or another name=")
    return run_dir, (load_checkpoint(ckpt_path) if resume else None)  # a bad file loses nothing


def train(cfg: TrainConfig, *, resume: bool = False) -> Path:
    """Run SAC training with ``cfg``; returns the run folder."""
    run_dir, ck = _prepare_run(cfg, resume)
    torch.manual_seed(cfg.run.seed)
    torch.set_num_threads(cfg.run.threads)
    if cfg.collector.kind == "async":
        _pin_to_core(0)
    obs_dim = len(observation_fields(get_task(cfg.env.task)))
    normalize = Normalize(obs_dim)
    actor = make_actor(cfg.network.width, cfg.network.depth, normalize=normalize, obs_dim=obs_dim)
    buffer = make_buffer(cfg)
    checkpoint = Checkpoint(run_dir)
    state, learner = RunState(next_eval=cfg.logging.eval_every_frames), None
    if ck is not None:
        state, learner = checkpoint.restore(ck, cfg, actor, normalize, buffer)
        print(f"resumed {run_dir} at {state.frames:,} frames, {state.updates:,} updates, "
              f"best success {100 * state.best_success:.1f}%")
    if state.frames >= cfg.run.total_frames:
        print(f"nothing to do: {state.frames:,} frames already collected (total_frames={cfg.run.total_frames:,}); "
              "raise total_frames= to train further")
        return run_dir
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "config.toml").write_text(to_toml(cfg))
    loggers = make_loggers(cfg, run_dir, resume)
    collector = make_collector(cfg, actor, state.frames)
    evaluator = Evaluator(cfg, actor, loggers)
    budget = (f"{cfg.run.total_frames:,} frames or {cfg.run.max_minutes:g} min, whichever ends first"
              if cfg.run.max_minutes else f"{cfg.run.total_frames:,} frames, no time limit")
    print(f"run folder: {run_dir}  ({_describe_collection(cfg)}, batch {cfg.frames_per_batch} frames, "
          f"{cfg.env.substeps} substeps per step; budget {budget})")
    print(device_summary("cpu"))
    loop = _TrainLoop(cfg, state, actor, normalize, buffer, learner, loggers, evaluator, checkpoint, run_dir)
    try:
        if cfg.collector.kind == "ray":
            from atrv_warp.rl.ray_collection import describe_placements

            print(f"ray collectors on: {describe_placements(collector)}")
        stopped_by = loop.run(collector)
    finally:
        loop.progress.close()
        collector.shutdown()
        # TorchRL's shutdown resets torch's thread count (to the machine's cores); on the core this
        # process is pinned to, two threads make every op of the final evaluation ~40x slower
        torch.set_num_threads(cfg.run.threads)
    state.elapsed_s = loop.elapsed()
    print(f"training stopped by {stopped_by}: {state.frames:,} frames, {state.updates:,} updates, "
          f"{state.elapsed_s / 60:.1f} min")
    if loop.frames_by_collector:
        print(f"frames per collector: {', '.join(f'{n:,}' for n in loop.frames_by_collector)}")
    _finish(cfg, state, run_dir, evaluator, loggers)
    return run_dir


class _TrainLoop:
    """Collect, learn, evaluate and checkpoint until a budget ends the run."""

    def __init__(self, cfg, state, actor, normalize, buffer, learner, loggers, evaluator, checkpoint, run_dir):
        self.cfg, self.state, self.actor, self.normalize, self.buffer = cfg, state, actor, normalize, buffer
        self.learner, self.loggers, self.evaluator, self.checkpoint = learner, loggers, evaluator, checkpoint
        self.run_dir = run_dir
        self.stats, self.losses = _Stats(), _LossMeans()
        self.frames_by_collector: list[int] = []
        """Frames from each Ray collector (their batches carry the collector's index); empty otherwise."""
        self.progress = _Progress(cfg, state.frames, state.elapsed_s)
        self.last_eval, self.last_train = float("nan"), (float("nan"), float("nan"), {})
        self.budget_s = cfg.run.max_minutes * 60.0 if cfg.run.max_minutes > 0 else math.inf
        self.clock0 = (state.elapsed_s, time.perf_counter())

    def elapsed(self) -> float:
        """Training time of the whole run [s], earlier sessions of a resumed run included."""
        return self.clock0[0] + time.perf_counter() - self.clock0[1]

    def log(self, name: str, value: float) -> None:
        for lg in self.loggers:
            lg.log_scalar(name, value, step=self.state.frames)

    def run(self, collector) -> str:
        cfg, st = self.cfg, self.state
        credit = 0.0
        for data in collector:
            n = data.numel()
            st.frames += n
            self.stats.update(data)
            if cfg.collector.kind == "ray":
                self.count_by_collector(data)
            # the full-resolution scan is for viewers; the policy observes its sectors
            self.buffer.extend(data.exclude("scan", ("next", "scan")).reshape(-1).cpu())
            if st.frames >= cfg.collector.init_random_frames:
                credit = self.learn(credit + n * cfg.optim.utd_ratio)
                if cfg.collector.kind == "async":  # the worker holds a copy; the sync collector shares `actor`
                    collector.update_policy_weights_(TensorDict.from_module(self.actor))
                # ray: the RayCollector sends the weights to the collector that delivered `data` once
                # this body is done (update_after_each_batch)
            st.elapsed_s = self.elapsed()
            if st.frames >= st.next_eval or st.frames >= cfg.run.total_frames or st.elapsed_s >= self.budget_s:
                self.evaluate_and_save()
            self.progress.update(st.frames, st.elapsed_s, f"eval {_pct(self.last_eval)} | train "
                                                           f"{_pct(self.last_train[0])} | updates {st.updates:,}")
            if st.elapsed_s >= self.budget_s:
                return f"max_minutes={cfg.run.max_minutes}"
            if st.frames >= cfg.run.total_frames:
                break
        return "total_frames"

    def count_by_collector(self, data) -> None:
        """Add each Ray collector's frames in ``data`` (stamped with its index) to :attr:`frames_by_collector`."""
        from atrv_warp.rl.ray_collection import WORKER_KEY

        if WORKER_KEY in data.keys(include_nested=True):
            counts = torch.bincount(data[WORKER_KEY].reshape(-1).long(), minlength=self.cfg.collector.num_collectors)
            self.frames_by_collector = [a + int(b) for a, b in
                                        zip(self.frames_by_collector or [0] * len(counts), counts, strict=True)]

    def learn(self, credit: float) -> float:
        """Freeze the observation statistics on first use, then spend whole update credits."""
        if not self.state.stats_ready:
            obs = self.buffer[:]["observation"]
            self.normalize.set_stats(obs.mean(0), obs.std(0))
            self.state.stats_ready = True
            self.learner = Learner(self.cfg, self.actor, self.normalize)
        while credit >= 1.0:
            credit -= 1.0
            self.losses.add(self.learner.update(self.buffer.sample()))
            self.state.updates += 1
        return credit

    def evaluate_and_save(self) -> None:
        cfg, st = self.cfg, self.state
        self.last_train = self.stats.pop()
        self.log("train_success_rate", self.last_train[0])
        self.log("train_reward", self.last_train[1])
        for name, value in self.last_train[2].items():
            self.log(f"train_reward_{name}", value)
        self.log("updates", st.updates)
        for name, value in self.losses.pop().items():
            self.log(name, value)
        self.log("wall_time_s", st.elapsed_s)
        if self.learner is not None:
            self.log("alpha", self.learner.alpha)
            result = self.evaluator(st.frames)
            for k, v in result.as_dict().items():
                if k != "episodes":
                    self.log(f"eval_{k}", v)
            self.last_eval = result.success_rate
            # equal success (100 % is common once learnt): the higher mean return, a quicker drive, wins
            if (self.last_eval, result.mean_return) > (st.best_success, st.best_return):
                st.best_success, st.best_return = self.last_eval, result.mean_return
                save_policy(self.actor, self.run_dir / "best_policy.pt", width=cfg.network.width, depth=cfg.network.depth,
                            meta={"frames": st.frames, "eval_success": st.best_success, "task": cfg.env.task})
        st.next_eval = (st.frames // cfg.logging.eval_every_frames + 1) * cfg.logging.eval_every_frames
        st.elapsed_s = self.elapsed()  # the evaluation's time counts too
        self.checkpoint.save(cfg, st, self.actor, self.learner, self.buffer)
        self.progress.log(f"{st.frames:>11,} frames {st.elapsed_s / 60:5.1f} min  eval success "
                          f"{_pct(self.last_eval)}  training episodes {_pct(self.last_train[0])}  reward "
                          f"{self.last_train[1]:+.3f}  updates {st.updates:,}")


def _finish(cfg: TrainConfig, state: RunState, run_dir: Path, evaluator: Evaluator, loggers: list) -> None:
    """Final evaluation of the best policy on the full set, results file, learning curve, summary."""
    result = {"frames": state.frames, "updates": state.updates, "train_minutes": state.elapsed_s / 60,
              "best_periodic_success": state.best_success}
    best_path = run_dir / "best_policy.pt"
    if best_path.is_file():
        final = evaluate(load_policy(best_path), num_episodes=cfg.logging.final_eval_episodes, seed=EVAL_SEED,
                         **dict(cfg.env.env_kwargs()))
        print(format_result("best policy, final evaluation", final))
        result["final_eval"] = final.as_dict()
    (run_dir / "final_eval.json").write_text(json.dumps(result, indent=2) + "\n")
    if evaluator.recorder is not None:
        evaluator.close()
        print(f"rerun recording: {loggers[-1].path}")
    if _plot_curve(run_dir / "logs", run_dir / "learning_curve.png"):
        print(f"learning curve: {run_dir / 'learning_curve.png'}")
    print(f"checkpoint: {Checkpoint(run_dir).path}\nbest policy: {best_path if best_path.is_file() else '(none yet)'}\n"
          f"logs: {run_dir / 'logs'}\nevaluate: python -m atrv_warp.evaluate {best_path}")
