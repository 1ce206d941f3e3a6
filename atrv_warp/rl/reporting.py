"""What a run reports: the progress bar (:class:`Progress`), the training statistics
(:class:`Stats`, :class:`LossMeans`), the loggers (:class:`Loggers`: scalars, hyperparameters,
evaluation videos) and the learning curve drawn from the CSV scalars (:func:`plot_curve`)."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import torch

from atrv_warp.rl.config import TrainConfig
from atrv_warp.task.spec import EndReason

__all__ = ["Loggers", "LossMeans", "Progress", "Stats", "make_loggers", "pct", "plot_curve"]


def pct(rate: float) -> str:
    """``' 82.4%'``, or ``'  n/a'`` before there is anything to rate."""
    return "  n/a" if math.isnan(rate) else f"{100 * rate:5.1f}%"


class Progress:
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


class Stats:
    """Running training statistics from collected batches (episodes that ended in them), and the
    mean of every reward term over the collected steps."""

    def __init__(self, terms: tuple[str, ...] = ()):
        self.terms = tuple(terms)
        """The task's reward terms, by name (its table: :attr:`atrv_warp.task.definition.Task.term_names`)."""
        self.ended = 0
        self.success = 0
        self.reward_sum = 0.0
        self.reward_n = 0
        self.term_sums = torch.zeros(len(self.terms), dtype=torch.float64)

    def update(self, data) -> None:
        done = data["next", "done"].reshape(-1)
        reasons = data["next", "end_reason"].reshape(-1)[done]
        self.ended += int(done.sum())
        self.success += int((reasons == EndReason.SUCCESS).sum())
        r = data["next", "reward"]
        self.reward_sum += float(r.sum())
        self.reward_n += r.numel()
        terms = data["next", "reward_terms"]
        if self.terms:
            self.term_sums += torch.stack([terms[name].sum() for name in self.terms]).double().cpu()

    def pop(self) -> tuple[float, float, dict[str, float]]:
        """(success rate, mean reward, mean of each reward term), then start over."""
        rate = self.success / self.ended if self.ended else float("nan")
        n = self.reward_n
        reward = self.reward_sum / n if n else float("nan")
        terms = {name: float(v) / n if n else float("nan") for name, v in zip(self.terms, self.term_sums)}
        self.__init__(self.terms)
        return rate, reward, terms


class LossMeans:
    """Means of the learner's losses (``keys``: :attr:`~atrv_warp.rl.learner.Algo.loss_keys`) over the
    updates since the last :meth:`pop`."""

    def __init__(self, keys: tuple[str, ...]):
        self.keys = keys
        self.sums: dict[str, torch.Tensor | float] = {k: 0.0 for k in keys}
        self.n = 0

    def add(self, out) -> None:
        """Add one update's losses, where they are (on a GPU: no wait for the update to finish)."""
        for k in self.keys:
            self.sums[k] = self.sums[k] + out[k].detach().double()
        self.n += 1

    def pop(self) -> dict[str, float]:
        means = {k: float(v) / self.n for k, v in self.sums.items()} if self.n else {}
        self.sums, self.n = {k: 0.0 for k in self.keys}, 0
        return means


def plot_curve(log_dir: Path, out: Path, title: str = "ATRV-Jr drive-to-target, SAC") -> bool:
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
    ax.set_title(title)
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)
    return True


class Loggers:
    """The run's loggers: CSV always (the learning curve is drawn from it), plus TensorBoard, W&B,
    MLflow or a Rerun recording (:attr:`rerun`), which the evaluator records into too."""

    def __init__(self, loggers: list, rerun=None):
        self.loggers = loggers
        self.rerun = rerun
        """The :class:`~atrv_warp.integrations.rerun_logger.RerunLogger` among :attr:`loggers` (``logger=rerun``), or ``None``."""

    @property
    def tracking_id(self) -> str:
        """The W&B or MLflow run these loggers write to (empty for the others): a resumed run continues it."""
        from atrv_warp.integrations.tracking import tracking_run_id

        return next((i for i in map(tracking_run_id, self.loggers) if i), "")

    @property
    def wants_gif(self) -> bool:
        """A logger shows videos as GIFs only (TensorBoard)."""
        from torchrl.record.loggers import TensorboardLogger

        return any(isinstance(lg, TensorboardLogger) for lg in self.loggers)

    def log_hparams(self, params: dict) -> None:
        """The configuration (:func:`~atrv_warp.rl.config.flat_config`) to every logger."""
        for lg in self.loggers:
            lg.log_hparams(params)

    def log_video(self, name: str, video, step: int) -> list[str]:
        """An evaluation video (:class:`~atrv_warp.integrations.video.VideoFile`) to every logger that
        takes one; returns their names."""
        from atrv_warp.integrations.video import log_video

        return [type(lg).__name__ for lg in self.loggers if log_video(lg, name, video, step)]

    def close(self) -> None:
        """Finish the W&B or MLflow run; flush the others."""
        from atrv_warp.integrations.tracking import close_logger

        for lg in self.loggers:
            close_logger(lg)

    @property
    def recording(self):
        """The Rerun recording the scalars go to (``None`` unless ``logger=rerun``)."""
        return None if self.rerun is None else self.rerun.experiment

    def log(self, name: str, value: float, step: int) -> None:
        for lg in self.loggers:
            lg.log_scalar(name, value, step=step)


def make_loggers(cfg: TrainConfig, run_dir: Path, resume: bool, tracking_id: str = "") -> Loggers:
    """CSV always (the learning curve is drawn from it), plus TensorBoard, W&B, MLflow or Rerun
    (``tracking_id``: the W&B or MLflow run a resumed run continues)."""
    from torchrl.record.loggers import CSVLogger

    loggers, rerun = [CSVLogger(exp_name="logs", log_dir=str(run_dir))], None
    if cfg.logging.logger == "tensorboard":
        from torchrl.record.loggers import TensorboardLogger

        loggers.append(TensorboardLogger(exp_name="logs", log_dir=str(run_dir)))
    elif cfg.logging.logger == "rerun":
        from atrv_warp.integrations.rerun_logger import RerunLogger

        rerun = RerunLogger("train", path=run_dir / ("train_resumed.rrd" if resume else "train.rrd"))
        loggers.append(rerun)
    elif cfg.logging.logger in ("wandb", "mlflow"):
        from atrv_warp.integrations.tracking import make_tracking_logger

        loggers.append(make_tracking_logger(cfg.logging.logger, run_dir / "logs", name=cfg.run.name,
                                            project=cfg.logging.project, wandb_mode=cfg.logging.wandb_mode,
                                            mlflow_uri=cfg.logging.mlflow_uri, run_id=tracking_id or None))
    return Loggers(loggers, rerun)
