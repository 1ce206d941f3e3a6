"""Experiment tracking: Weights & Biases and MLflow, through TorchRL's loggers (the ``track`` extra).

:func:`make_tracking_logger` builds the TorchRL ``Logger`` a backend names: W&B through TorchRL's
``get_logger`` (offline by default: the run folder is written under ``<log_dir>/wandb``, and
``wandb sync`` uploads it later), MLflow as :class:`MLflowLogger`, TorchRL's ``MLFlowLogger`` on a
local SQLite store in ``<log_dir>`` unless a tracking URI is given. MLflow 3.10 and later refuse the
old ``./mlruns`` file store, which is why ``get_logger("mlflow", ...)``, which builds a ``file:`` URI,
is not used for MLflow. Both resume the run they logged to before, by the id
:func:`tracking_run_id` returns (saved in the training checkpoint).

Nothing here knows the trainer: it takes names, folders and plain dicts.
"""

from __future__ import annotations

import importlib.util
import logging
from pathlib import Path

from torchrl.record.loggers import Logger, MLFlowLogger

from atrv_warp.runtime import is_verbose

__all__ = ["INSTALL_HINT", "TRACKING_BACKENDS", "MLflowLogger", "close_logger", "make_tracking_logger",
           "require_tracking", "tracking_run_id"]

TRACKING_BACKENDS = {"wandb": "wandb", "mlflow": "mlflow"}
"""Tracking backends and the module each needs."""
INSTALL_HINT = 'logger={backend} needs {module}, the optional extra [track]: pip install -e ".[track]"'
"""What a run says, before any work, where a backend's package is not installed."""


def require_tracking(backend: str) -> None:
    """Raise ``ModuleNotFoundError`` in one line (:data:`INSTALL_HINT`) where ``backend``'s package is missing."""
    module = TRACKING_BACKENDS[backend]
    if importlib.util.find_spec(module) is None:
        raise ModuleNotFoundError(INSTALL_HINT.format(backend=backend, module=module))


class MLflowLogger(MLFlowLogger):
    """TorchRL's ``MLFlowLogger``, with a named run that a resumed training continues (``run_id``),
    hyperparameters logged without OmegaConf, and files logged as artifacts.

    Args:
        experiment: The MLflow experiment (created if missing).
        tracking_uri: Where MLflow stores runs: ``sqlite:///path/mlflow.db``, a server's URL, ...
        artifact_location: Where a new experiment stores its artifacts (videos).
        run_name: The run's name in the experiment.
        run_id: Continue this run instead of starting one.
    """

    def __init__(self, experiment: str, *, tracking_uri: str, artifact_location: str | None, run_name: str,
                 run_id: str | None = None):
        self.run_name, self.resume_id = run_name, run_id
        super().__init__(experiment, tracking_uri=tracking_uri, artifact_location=artifact_location)

    def _create_experiment(self):
        import mlflow

        experiment = mlflow.get_experiment_by_name(self._mlflow_kwargs["name"])
        self.id = experiment.experiment_id if experiment is not None else mlflow.create_experiment(**self._mlflow_kwargs)
        if self.resume_id:
            return mlflow.start_run(run_id=self.resume_id)
        return mlflow.start_run(experiment_id=self.id, run_name=self.run_name)

    @property
    def run_id(self) -> str:
        """The MLflow run this logger writes to."""
        return self.experiment.info.run_id

    def log_hparams(self, cfg: dict) -> None:
        """Log ``cfg`` as the run's parameters; a resumed run keeps the values it first logged (MLflow
        refuses to change a parameter), and a changed one is logged as the tag ``resumed.<name>``."""
        import mlflow

        logged = mlflow.get_run(self.run_id).data.params
        mlflow.log_params({k: v for k, v in cfg.items() if k not in logged})
        changed = {f"resumed.{k}": str(v) for k, v in cfg.items() if k in logged and logged[k] != str(v)}
        if changed:
            mlflow.set_tags(changed)

    def log_file(self, path: str | Path, folder: str) -> None:
        """Log the file at ``path`` as an artifact under ``folder``."""
        import mlflow

        mlflow.log_artifact(str(path), folder)


def make_tracking_logger(backend: str, log_dir: Path, *, name: str, project: str, wandb_mode: str = "offline",
                         mlflow_uri: str = "", run_id: str | None = None) -> Logger:
    """The TorchRL logger of ``backend`` (``wandb`` or ``mlflow``) for the run ``name`` in ``project``.

    Args:
        backend: ``wandb`` or ``mlflow``.
        log_dir: The run's log folder: W&B writes ``wandb/`` here; MLflow's default store is
            ``mlflow.db`` and ``mlflow_artifacts/`` here.
        name: The run's name.
        project: The W&B project, or the MLflow experiment.
        wandb_mode: ``offline`` (a run folder to ``wandb sync`` later) or ``online`` (needs ``wandb login``).
        mlflow_uri: MLflow tracking URI; empty = the SQLite store in ``log_dir``.
        run_id: The id of a run to continue (:func:`tracking_run_id` of its first session's logger).
    """
    require_tracking(backend)
    log_dir = Path(log_dir).resolve()
    log_dir.mkdir(parents=True, exist_ok=True)
    if backend == "wandb":
        import wandb
        from torchrl.record.loggers import get_logger

        # console="off": the run's console output stays ours (W&B would otherwise wrap stdout)
        kwargs = {"offline": wandb_mode == "offline", "mode": wandb_mode, "project": project,
                  "log_env_packages": False, "settings": wandb.Settings(console="off", quiet=True)}
        if run_id:
            kwargs.update(id=run_id, resume="allow")
        return get_logger("wandb", logger_name=str(log_dir), experiment_name=name, wandb_kwargs=kwargs)
    if backend == "mlflow":
        if not is_verbose():  # the store's set-up (MLflow's and Alembic's INFO lines) is library detail
            for library in ("mlflow", "alembic"):
                logging.getLogger(library).setLevel(logging.WARNING)
        uri = mlflow_uri or f"sqlite:///{log_dir / 'mlflow.db'}"
        artifacts = None if mlflow_uri else (log_dir / "mlflow_artifacts").as_uri()
        return MLflowLogger(project, tracking_uri=uri, artifact_location=artifacts, run_name=name, run_id=run_id)
    raise ValueError(f"unknown tracking backend {backend!r}; known: {sorted(TRACKING_BACKENDS)}")


def tracking_run_id(logger: Logger) -> str | None:
    """The id a later session passes as ``run_id`` to continue ``logger``'s run; ``None`` for others."""
    if isinstance(logger, MLflowLogger):
        return logger.run_id
    from torchrl.record.loggers import WandbLogger

    if isinstance(logger, WandbLogger):
        return logger.experiment.id
    return None


def close_logger(logger: Logger) -> None:
    """Finish ``logger``'s run (W&B writes its summary, MLflow marks the run finished); others are flushed."""
    from torchrl.record.loggers import WandbLogger

    if isinstance(logger, WandbLogger):
        logger.experiment.finish()
    elif isinstance(logger, MLFlowLogger):
        import mlflow

        mlflow.end_run()
    else:
        logger.flush()
