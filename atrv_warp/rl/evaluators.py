"""The periodic validation of a training run, in the trainer (:class:`Evaluator`) or in a process of its own
(:class:`BackgroundEvaluator`); :func:`make_evaluator` picks one (``logging.eval_in_background``).

Both are used the same way: :meth:`~Evaluator.submit` the policy's weights at ``frames`` collected frames, then
:meth:`~Evaluator.poll` for the :class:`EvalOutcome`. In the trainer the outcome is ready at once and the
training waits for it; in the background the training goes on while the validation runs on the second core (the
collector's, which waits for the learner most of the time), and the outcome comes back with the weights it
judged, so the best policy saved is the one that scored. Same weights, same episodes, same figures: the
validation set is seeded (``VALIDATION_SEED``) and the policy deterministic, wherever it runs.
"""

from __future__ import annotations

import multiprocessing
import time
import traceback
from dataclasses import dataclass
from pathlib import Path

from atrv_warp.rl.config import TrainConfig
from atrv_warp.rl.run import RunSpec, resolve_run
from atrv_warp.runtime import WORKER_CORE, pin_to_core
from atrv_warp.task.env import RoverEnv
from atrv_warp.task.evaluation import VALIDATION_SEED, EvalResult, evaluate

__all__ = ["BackgroundEvaluator", "EvalOutcome", "Evaluator", "make_evaluator"]


@dataclass
class EvalOutcome:
    """One periodic validation: the weights it judged and what it found."""

    frames: int
    """Frames collected when the weights were taken."""
    result: EvalResult
    policy: dict
    """The weights judged, as :func:`~atrv_warp.policy.policy_payload` saves them (``best_policy.pt``)."""
    seconds: float
    """Wall time of the validation itself [s]."""
    video: object | None = None
    """Its video (:class:`~atrv_warp.integrations.video.VideoFile`), where the run draws one."""


class Evaluator:
    """The periodic deterministic evaluation on the fixed seeded validation set (``VALIDATION_SEED``), in the
    trainer's process: :meth:`submit` runs it, and the training waits.

    ``recording``: a Rerun recording (the one the scalars go to, with ``logger=rerun``) that gets
    two worlds of every evaluation, on its ``frames`` timeline; ``None``: nothing is recorded.
    ``video_dir``: every evaluation's first ``video_episodes`` episodes are drawn into
    ``video_dir/eval_<frames>.mp4`` (:attr:`last_video`; with ``gif``, also as a GIF for TensorBoard).
    """

    in_background = False
    """The training waits for it."""

    def __init__(self, cfg: TrainConfig, actor, *, recording=None, video_dir: Path | None = None, gif: bool = False,
                 run: RunSpec | None = None):
        self.cfg, self.actor = cfg, actor
        self.env = RoverEnv(cfg.logging.eval_episodes, seed=VALIDATION_SEED, device=cfg.run.device,
                             **(run or resolve_run(cfg)).env_kwargs(cfg, judged=True))
        self.recorder = None
        if recording is not None:
            from atrv_warp.integrations.recorder import RerunRecorder

            self.recorder = RerunRecorder(self.env.sim, recording=recording, worlds=range(2), training=True)
        self.video, self.video_dir, self.gif = None, video_dir, gif
        if video_dir is not None:
            from atrv_warp.integrations.video import EvalVideo

            self.video = EvalVideo(self.env, episodes=cfg.logging.video_episodes)
        self.last_video = None
        """The video of the latest evaluation (:class:`~atrv_warp.integrations.video.VideoFile`), or ``None``."""
        self.outcome: EvalOutcome | None = None

    def __call__(self, frames: int) -> EvalResult:
        """Evaluate :attr:`actor` as it is now; ``frames`` names the video and the recording's time."""
        self.actor.eval()
        hooks = []
        if self.recorder is not None:
            self.recorder.rec.set_time("frames", sequence=frames)
            hooks.append(self.recorder.env_hook())
        if self.video is not None:
            hooks.append(self.video.env_hook())
        result = evaluate(self.actor, num_episodes=self.cfg.logging.eval_episodes, seed=VALIDATION_SEED, env=self.env,
                          on_step=_each(hooks))
        self.actor.train()
        if self.video is not None:
            self.last_video = self.video.write(self.video_dir / f"eval_{frames:011d}.mp4", gif=self.gif)
        return result

    def submit(self, frames: int, policy: dict) -> None:
        """Evaluate the trainer's actor now (``policy``: its weights as saved, kept with the outcome)."""
        t0 = time.perf_counter()
        result = self(frames)
        self.outcome = EvalOutcome(frames, result, policy, time.perf_counter() - t0, self.last_video)

    def poll(self, *, wait: bool = False) -> EvalOutcome | None:
        """The outcome of the last :meth:`submit`, once (``wait`` changes nothing: it is ready)."""
        outcome, self.outcome = self.outcome, None
        return outcome

    def close(self) -> None:
        if self.recorder is not None:
            self.recorder.close()


class BackgroundEvaluator:
    """The periodic validation in a process of its own, pinned to ``core``: the training goes on while it runs.

    The process starts with the run (its environment built once, as :class:`Evaluator` builds it) and judges one
    set of weights at a time; :meth:`poll` returns the outcome once it has ended (``wait``: blocks until then).
    A failure in the process is re-raised here as a ``RuntimeError`` carrying its message.
    """

    in_background = True
    """The training goes on while it runs."""

    def __init__(self, cfg: TrainConfig, *, video_dir: Path | None = None, gif: bool = False, core: int = WORKER_CORE):
        context = multiprocessing.get_context("spawn")  # a fresh interpreter: no Warp or torch state forked
        self.conn, child = context.Pipe()
        self.process = context.Process(target=_serve, args=(child, cfg, video_dir, gif, core), daemon=True,
                                       name="atrv-validation")
        self.process.start()
        pin_to_core(core, pid=self.process.pid)  # now, not once it has imported the simulator on the trainer's core
        child.close()
        self.in_flight: tuple[int, dict] | None = None
        self.ready = False
        """The process has built its environment (it starts while the run collects its first frames)."""

    def submit(self, frames: int, policy: dict) -> None:
        """Send ``policy`` (weights as :func:`~atrv_warp.policy.policy_payload` gives them) to be judged."""
        if self.in_flight is not None:
            raise RuntimeError("a validation is still running: poll(wait=True) for it before submitting another")
        if not self.ready:
            self._receive("ready")
            self.ready = True
        self.conn.send((frames, policy["state_dict"]))
        self.in_flight = (frames, policy)

    def poll(self, *, wait: bool = False) -> EvalOutcome | None:
        """The outcome of the validation in flight, once it has ended; ``None`` while it runs (or none was sent)."""
        if self.in_flight is None or not (wait or self.conn.poll()):
            return None
        result, video, seconds = self._receive("result")
        (frames, policy), self.in_flight = self.in_flight, None
        return EvalOutcome(frames, result, policy, seconds, video)

    def close(self) -> None:
        """Stop the process (an evaluation in flight is dropped, at once)."""
        if self.process.is_alive() and self.in_flight is None:
            try:
                self.conn.send(None)
            except (BrokenPipeError, OSError):
                pass
            self.process.join(timeout=10)
        if self.process.is_alive():
            self.process.terminate()
            self.process.join(timeout=5)
        self.conn.close()

    def _receive(self, expected: str):
        try:
            kind, body = self.conn.recv()
        except (EOFError, OSError):
            self.process.join(timeout=5)
            raise RuntimeError(f"the background validation's process ended (exit code {self.process.exitcode}) "
                               "without an answer") from None
        if kind == "error":
            self.close()
            raise RuntimeError(f"the background validation failed: {body}")
        if kind != expected:
            raise RuntimeError(f"the background validation answered {kind!r} where {expected!r} was due")
        return body


def _serve(conn, cfg: TrainConfig, video_dir: Path | None, gif: bool, core: int) -> None:
    """The background validation's process: build the actor and the validation environment, then judge every
    set of weights sent until ``None`` comes."""
    import torch

    from atrv_warp.rl.learner import make_run_actor

    try:
        pin_to_core(core)
        torch.set_num_threads(1)
        run = resolve_run(cfg)  # this process's, once
        actor, _ = make_run_actor(cfg, run)
        evaluator = Evaluator(cfg, actor, video_dir=video_dir, gif=gif, run=run)
    except BaseException as err:  # noqa: BLE001 - sent to the trainer, which raises it
        conn.send(("error", f"{type(err).__name__}: {err}"))
        return
    conn.send(("ready", None))
    while (message := conn.recv()) is not None:
        frames, weights = message
        try:
            actor.load_state_dict(weights)
            t0 = time.perf_counter()
            result = evaluator(frames)
            conn.send(("result", (result, evaluator.last_video, time.perf_counter() - t0)))
        except BaseException as err:  # noqa: BLE001 - sent to the trainer, which raises it
            conn.send(("error", f"{type(err).__name__}: {err}\n{traceback.format_exc(limit=4)}"))
            return


def make_evaluator(cfg: TrainConfig, actor, *, recording=None, video_dir: Path | None = None, gif: bool = False,
                   run: RunSpec | None = None):
    """The run's periodic validation: in the background (``logging.eval_in_background``), except where a Rerun
    recording of the training (``logger=rerun``) takes the validation's worlds, which only the trainer holds, and
    on a GPU (``run.device``), where it takes a second or two in the trainer. ``run``: ``cfg`` resolved, for the
    validation in this process (one in the background resolves the names in its own)."""
    if cfg.logging.eval_in_background and recording is None and cfg.run.device == "cpu":
        return BackgroundEvaluator(cfg, video_dir=video_dir, gif=gif)
    return Evaluator(cfg, actor, recording=recording, video_dir=video_dir, gif=gif, run=run)


def _each(hooks: list):
    """One ``on_step`` callback that calls every one of ``hooks`` (``None`` for none)."""
    if not hooks:
        return None

    def on_step(env, td):
        for hook in hooks:
            hook(env, td)

    return on_step
