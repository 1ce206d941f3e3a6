"""Training, SAC or PPO: :func:`train` reads top to bottom; it gets its parts from small factories
(:mod:`.collectors`, :mod:`.learner` and :mod:`.ppo`, :mod:`.checkpoint`, :mod:`.reporting`) and runs
them in :class:`TrainLoop` until a budget ends the run. The command line is ``python -m atrv_warp.train``."""

from __future__ import annotations

import json
import math
import time
import uuid
from pathlib import Path

import torch
from tensordict import TensorDict

from atrv_warp.core.files import check_output_path
from atrv_warp.policy import Normalize, load_policy, policy_payload
from atrv_warp.rl.checkpoint import Checkpoint, RunLock, RunState, load_checkpoint, warm_start
from atrv_warp.rl.collectors import COLLECTORS, WORKER_KEY, make_collector, pin_to_core
from atrv_warp.rl.config import TrainConfig, flat_config, to_toml
from atrv_warp.rl.evaluators import EvalOutcome, Evaluator, make_evaluator
from atrv_warp.rl.exploration import collection_policy
from atrv_warp.rl.learner import ALGOS, annealed_lr, make_buffer, make_learner, make_run_actor, replay_frames, set_lr
from atrv_warp.rl.reporting import Loggers, LossMeans, Progress, Stats, make_loggers, pct, plot_curve
from atrv_warp.rl.run import TASK_MODULE_RECORD, RunSpec, resolve_run, task_module_record
from atrv_warp.runtime import device_summary
from atrv_warp.sim.config import SimConfig
from atrv_warp.task.evaluation import EVAL_SEED, evaluate, format_result

__all__ = ["Evaluator", "TrainLoop", "train"]


def train(cfg: TrainConfig, *, resume: bool = False) -> Path:
    """Train with ``cfg`` (SAC or PPO, ``cfg.optim.algo``); returns the run folder."""
    run_dir, ck, lock = _prepare_run(cfg, resume)
    try:
        return _train(cfg, run_dir, ck, resume)
    finally:
        lock.release()


def _train(cfg: TrainConfig, run_dir: Path, ck: dict | None, resume: bool) -> Path:
    """:func:`train` in the run folder ``run_dir``, which this process holds (``ck``: the save to resume from)."""
    run = resolve_run(cfg)  # the robot, the task fitted to it, the randomizations: once, passed down
    torch.manual_seed(cfg.run.seed)
    torch.set_num_threads(cfg.run.threads)
    kind = COLLECTORS[cfg.collector.kind]
    if kind.trainer_core is not None:
        pin_to_core(kind.trainer_core)
    actor, normalize = make_run_actor(cfg, run)
    buffer = make_buffer(cfg)
    checkpoint = Checkpoint(run_dir)
    state, learner = RunState(next_eval=cfg.logging.eval_every_frames), None
    if ck is not None:
        state, learner = checkpoint.restore(ck, cfg, actor, normalize, buffer, run=run)
        print(f"resumed {run_dir} at {state.frames:,} frames, {state.updates:,} updates, "
              f"best success {100 * state.best_success:.1f}% (save {checkpoint.generation})")
        for line in checkpoint.notes:
            print(line)
        if not checkpoint.folder_run_id():  # a folder from before runs had an identity takes its save's
            state.run_id = state.run_id or uuid.uuid4().hex
            checkpoint.claim(state.run_id)
    else:
        checkpoint.start_over()  # what a run killed before its first save left (its logs, a half-written file)
        if cfg.run.init_from:
            learner = warm_start(cfg.run.init_from, cfg, actor, normalize, run=run)
            state.stats_ready = learner is not None
            print(f"starting from the networks of {cfg.run.init_from}")
        state.run_id = uuid.uuid4().hex
        checkpoint.claim(state.run_id)
    if state.frames >= cfg.run.total_frames:
        print(f"nothing to do: {state.frames:,} frames already collected (total_frames={cfg.run.total_frames:,}); "
              "raise total_frames= to train further")
        return run_dir
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "config.toml").write_text(to_toml(cfg))
    if cfg.env.task_module:  # the module's path and sha256: a resume names the module, and must name this one
        (run_dir / TASK_MODULE_RECORD).write_text(json.dumps(task_module_record(cfg.env.task_module), indent=1) + "\n")
    # the task resolved: every field of its config and its reward table, as this run trains it
    (run_dir / "task.json").write_text(json.dumps(run.task.record(), indent=1, default=str) + "\n")
    # the robot resolved: every field of its file, as this run trains on it (its saved policies keep the same)
    (run_dir / "robot.json").write_text(json.dumps(run.record()["robot"], indent=1) + "\n")
    # what the envs draw, in absolute ranges: `around` resolved against the sim config, so a run says what it trained on
    (run_dir / "randomization.json").write_text(json.dumps(
        {"randomization": cfg.env.randomization, "eval_randomization": cfg.env.eval_randomization or None,
         "sim_config": cfg.env.sim_config,
         "resolved": run.randomization.describe()}, indent=1) + "\n")
    loggers = make_loggers(cfg, run_dir, resume, state.tracking_id)
    state.tracking_id = loggers.tracking_id
    loggers.log_hparams(flat_config(cfg))
    # what the collectors step: the actor, or the actor with correlated exploration noise (SAC)
    policy = collection_policy(actor, cfg.collector.noise_correlation, seed=cfg.run.seed + 104_729 * state.frames)
    collector = make_collector(cfg, policy, state.frames, run=run)
    evaluator = make_evaluator(cfg, actor, run=run, recording=loggers.recording,
                               video_dir=run_dir / "videos" if cfg.logging.video_episodes else None,
                               gif=loggers.wants_gif)
    budget = (f"{cfg.run.total_frames:,} frames or {cfg.run.max_minutes:g} min, whichever ends first"
              if cfg.run.max_minutes else f"{cfg.run.total_frames:,} frames, no time limit")
    print(f"run folder: {run_dir}  ({cfg.optim.algo}, {kind.describe(cfg)}, batch {cfg.frames_per_batch} frames, "
          f"solver substep {SimConfig().step_dt / cfg.env.substeps:.4g} s; budget {budget})")
    task_cfg = run.task.config
    speeds = f" at {task_cfg.max_linear:g} m/s, {task_cfg.max_angular:g} rad/s" if task_cfg.action == "twist" else ""
    period = task_cfg.control_period or 0.05
    print(f"robot {cfg.env.robot}, task {cfg.env.task}{speeds}, controlled every {period:g} s")
    print(device_summary(cfg.run.device))
    loop = TrainLoop(cfg, state, actor, normalize, buffer, learner, loggers, evaluator, checkpoint, run_dir,
                     policy=policy, run=run)
    try:
        if kind.placements is not None:
            print(f"{cfg.collector.kind} collectors on: {kind.placements(collector)}")
        stopped_by = loop.run(collector)
        if loop.record(evaluator.poll(wait=True)):  # the last validation, where it still runs
            loop.save_checkpoint()
    finally:
        evaluator.close()
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
    _finish(cfg, state, run_dir, loggers, run)
    return run_dir


def _prepare_run(cfg: TrainConfig, resume: bool) -> tuple[Path, dict | None, RunLock]:
    """Check the run folder and take it (:class:`~atrv_warp.rl.checkpoint.RunLock`: one training per folder), and read the
    checkpoint to resume from, before anything is written."""
    if cfg.logging.logger == "tensorboard":
        import importlib.util

        if importlib.util.find_spec("tensorboard") is None:
            raise ModuleNotFoundError("logger=tensorboard needs the tensorboard package: pip install -e '.[tensorboard]'")
    if cfg.logging.logger in ("wandb", "mlflow"):
        from atrv_warp.integrations.tracking import require_tracking

        require_tracking(cfg.logging.logger)
    require = COLLECTORS[cfg.collector.kind].require
    if require is not None:
        require()
    run_dir = Path(cfg.run.out_dir) / cfg.run.name
    check_output_path(run_dir / "config.toml", "run folder", new_folders=True)  # fails before any work
    lock = RunLock(run_dir)  # a second training on this folder stops here, before it writes
    try:
        ckpt_path = Checkpoint(run_dir).path
        if resume and not ckpt_path.is_file():
            print(f"--resume: {run_dir} holds no save yet (stopped before its first): starting it from the beginning")
            resume = False
        if not resume and ckpt_path.exists():
            raise FileExistsError(f"{run_dir} already holds a run; use --resume to continue it or another name=")
        return run_dir, (load_checkpoint(ckpt_path) if resume else None), lock  # a bad file loses nothing
    except BaseException:
        lock.release()
        raise


class TrainLoop:
    """Collect, learn, evaluate and checkpoint until a budget ends the run."""

    def __init__(self, cfg: TrainConfig, state: RunState, actor, normalize: Normalize, buffer, learner,
                 loggers: Loggers, evaluator, checkpoint: Checkpoint, run_dir: Path, *, policy=None,
                 run: RunSpec | None = None):
        self.cfg, self.state, self.actor, self.normalize, self.buffer = cfg, state, actor, normalize, buffer
        self.policy = actor if policy is None else policy
        """What the collectors step (``actor``, or it inside :class:`~atrv_warp.rl.exploration.CorrelatedExploration`);
        its weights are the actor's."""
        self.learner, self.loggers, self.evaluator, self.checkpoint = learner, loggers, evaluator, checkpoint
        self.run_dir = run_dir
        self.spec = run or resolve_run(cfg)
        """The run resolved (:class:`~atrv_warp.rl.run.RunSpec`): its task and robot, which the saves record."""
        self.algo = ALGOS[cfg.optim.algo]
        self.stats, self.losses = Stats(self.spec.task.term_names), LossMeans(self.algo.loss_keys)
        self.push_weights = COLLECTORS[cfg.collector.kind].push_weights
        self.frames_by_collector: list[int] = []
        """Frames from each Ray collector (their batches carry the collector's index); empty otherwise."""
        self.progress = Progress(cfg, state.frames, state.elapsed_s)
        self.last_eval, self.last_train = float("nan"), (float("nan"), float("nan"), {})
        self.point = ""
        """The console line of the latest evaluation point, its validation's success left as ``{}``."""
        self.budget_s = cfg.run.max_minutes * 60.0 if cfg.run.max_minutes > 0 else math.inf
        self.clock0 = (state.elapsed_s, time.perf_counter())

    def elapsed(self) -> float:
        """Training time of the whole run [s], earlier sessions of a resumed run included."""
        return self.clock0[0] + time.perf_counter() - self.clock0[1]

    def log(self, name: str, value: float) -> None:
        self.loggers.log(name, value, step=self.state.frames)

    def run(self, collector) -> str:
        cfg, st = self.cfg, self.state
        credit = 0.0
        for data in collector:
            n = data.numel()
            st.frames += n
            self.stats.update(data)
            self.count_by_collector(data)
            if not (self.algo.on_policy and st.stats_ready):  # PPO keeps the random frames only, for the statistics
                self.buffer.extend(replay_frames(data, cfg.run.device))
            if st.frames >= cfg.collector.init_random_frames:
                credit = self.learn(data, credit + n * cfg.optim.utd_ratio)
                if self.push_weights:  # the worker holds a copy; the sync collector shares `actor`
                    collector.update_policy_weights_(TensorDict.from_module(self.policy))
                # ray: the next request to the collector that delivered `data` carries the weights, once
                # this body is done
            if self.record(self.evaluator.poll()):  # a background validation that found a new best
                self.save_checkpoint()
            st.elapsed_s = self.elapsed()
            if st.frames >= st.next_eval or st.frames >= cfg.run.total_frames or st.elapsed_s >= self.budget_s:
                self.evaluate_and_save()
            self.progress.update(st.frames, st.elapsed_s, f"eval {pct(self.last_eval)} | train "
                                                           f"{pct(self.last_train[0])} | updates {st.updates:,}")
            if st.elapsed_s >= self.budget_s:
                return f"max_minutes={cfg.run.max_minutes}"
            if st.frames >= cfg.run.total_frames:
                break
        return "total_frames"

    def count_by_collector(self, data) -> None:
        """Add each collector's frames in ``data`` to :attr:`frames_by_collector`, where its frames carry
        the collector's index (Ray's do)."""
        if WORKER_KEY in data.keys(include_nested=True):
            counts = torch.bincount(data[WORKER_KEY].reshape(-1).long(), minlength=self.cfg.collector.num_collectors)
            self.frames_by_collector = [a + int(b) for a, b in
                                        zip(self.frames_by_collector or [0] * len(counts), counts, strict=True)]

    def learn(self, data, credit: float) -> float:
        """Freeze the observation statistics on first use; then SAC spends whole update credits on
        replayed samples, PPO learns from ``data`` (a batch the policy collected)."""
        if not self.state.stats_ready:
            obs = self.buffer[:]["observation"]
            self.normalize.set_stats(obs.mean(0), obs.std(0))
            self.state.stats_ready = True
            self.learner = make_learner(self.cfg, self.actor, self.normalize)
            if self.algo.on_policy:
                return 0.0  # this batch's actions were random (init_random_frames): not the policy's
        if self.cfg.optim.lr_final_fraction != 1.0:
            set_lr(self.learner, annealed_lr(self.cfg, self.state.frames))
        if self.algo.on_policy:
            for out in self.learner.learn_batch(data):
                self.losses.add(out)
                self.state.updates += 1
            return 0.0
        while credit >= 1.0:
            credit -= 1.0
            self.losses.add(self.learner.update(self.buffer.sample()))
            self.state.updates += 1
        return credit

    def evaluate_and_save(self) -> None:
        """Log the training's figures, send the policy to be validated, and checkpoint the run."""
        cfg, st = self.cfg, self.state
        if self.record(self.evaluator.poll(wait=True)):  # one validation at a time, logged in order
            st.elapsed_s = self.elapsed()
        self.last_train = self.stats.pop()
        self.log("train_success_rate", self.last_train[0])
        self.log("train_reward", self.last_train[1])
        for name, value in self.last_train[2].items():
            self.log(f"train_reward_{name}", value)
        self.log("updates", st.updates)
        for name, value in self.losses.pop().items():
            self.log(name, value)
        self.log("wall_time_s", st.elapsed_s)
        self.point = (f"{st.frames:>11,} frames {st.elapsed_s / 60:5.1f} min  eval success {{}}  training episodes "
                      f"{pct(self.last_train[0])}  reward {self.last_train[1]:+.3f}  updates {st.updates:,}")
        if self.learner is not None:
            self.log("lr", annealed_lr(cfg, st.frames))
            for name, value in self.learner.scalars().items():
                self.log(name, value)
            self.evaluator.submit(st.frames, policy_payload(self.actor, width=cfg.network.width,
                                                            depth=cfg.network.depth,
                                                            meta={"frames": st.frames, "task": cfg.env.task},
                                                            task=self.spec.task, record=self.spec.record()))
            self.record(self.evaluator.poll())  # in the trainer, ready now; in the background, later
        else:
            self.progress.log(self.point.format(pct(math.nan)))
        st.next_eval = (st.frames // cfg.logging.eval_every_frames + 1) * cfg.logging.eval_every_frames
        self.save_checkpoint()

    def record(self, outcome: EvalOutcome | None) -> bool:
        """Log a validation's figures at the frames of the weights it judged, and stage those weights as the best
        policy where they beat every earlier one; returns whether they did (``None``: nothing to record)."""
        if outcome is None:
            return False
        st, result = self.state, outcome.result
        if outcome.video is not None:
            self.loggers.log("video_render_s", outcome.video.render_s, step=outcome.frames)
            self.loggers.log_video("eval_video", outcome.video, outcome.frames)
        for k, v in result.as_dict().items():
            if k != "episodes":
                self.loggers.log(f"eval_{k}", v, step=outcome.frames)
        self.loggers.log("eval_s", outcome.seconds, step=outcome.frames)
        # when the figures were known, on the training's clock: wall_time_s plus the validation in the trainer,
        # later than wall_time_s by the validation's time (and the poll's) in the background
        self.loggers.log("eval_known_wall_s", self.elapsed(), step=outcome.frames)
        self.last_eval = result.success_rate
        aside = f"  (validated in the background in {outcome.seconds:.0f} s)" if self.evaluator.in_background else ""
        self.progress.log(self.point.format(pct(result.success_rate)) + aside)
        # equal success (100 % is common once learnt): the higher mean return, a quicker drive, wins
        if (result.success_rate, result.mean_return) <= (st.best_success, st.best_return):
            return False
        st.best_success, st.best_return = result.success_rate, result.mean_return
        outcome.policy["meta"].update(eval_success=result.success_rate, eval_return=result.mean_return)
        self.checkpoint.best = outcome.policy  # written with the save that follows, then best_policy.pt
        return True

    def save_checkpoint(self) -> None:
        self.state.elapsed_s = self.elapsed()
        self.checkpoint.save(self.cfg, self.state, self.actor, self.learner, self.buffer, run=self.spec)


def _finish(cfg: TrainConfig, state: RunState, run_dir: Path, loggers: Loggers, run: RunSpec) -> None:
    """Final evaluation of the best policy on the full set, results file, learning curve, summary."""
    result = {"frames": state.frames, "updates": state.updates, "train_minutes": state.elapsed_s / 60,
              "best_periodic_success": state.best_success}
    best_path = run_dir / "best_policy.pt"
    if best_path.is_file():
        final = evaluate(load_policy(best_path, device=cfg.run.device), num_episodes=cfg.logging.final_eval_episodes,
                         seed=EVAL_SEED, device=cfg.run.device, **run.env_kwargs(cfg, judged=True))
        print(format_result("best policy, final evaluation", final))
        result["final_eval"] = final.as_dict()
        for k, v in final.as_dict().items():
            loggers.log(f"final_eval_{k}", v, step=state.frames)
    (run_dir / "final_eval.json").write_text(json.dumps(result, indent=2) + "\n")
    if loggers.recording is not None:
        print(f"rerun recording: {loggers.rerun.path}")
    loggers.close()
    if plot_curve(run_dir / "logs", run_dir / "learning_curve.png", f"{cfg.env.task}, {cfg.optim.algo.upper()}"):
        print(f"learning curve: {run_dir / 'learning_curve.png'}")
    module = f" --task-module {cfg.env.task_module}" if cfg.env.task_module else ""
    print(f"checkpoint: {Checkpoint(run_dir).path}\nbest policy: {best_path if best_path.is_file() else '(none yet)'}\n"
          f"logs: {run_dir / 'logs'}\nevaluate: python -m atrv_warp.evaluate {best_path}{module}")
