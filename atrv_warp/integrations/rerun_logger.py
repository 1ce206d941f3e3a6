"""A TorchRL ``Logger`` that writes training scalars into a Rerun recording
(:class:`RerunLogger`), the one the periodic evaluations are recorded into."""

from __future__ import annotations

import os

import rerun as rr
from torchrl.record.loggers import Logger

__all__ = ["RerunLogger"]


class RerunLogger(Logger):
    """A TorchRL ``Logger`` writing training scalars into a Rerun recording (``frames`` timeline),
    so that they share one recording with the evaluation episodes a :class:`RerunRecorder` logs."""

    def __init__(self, exp_name: str = "train", *, recording: rr.RecordingStream | None = None,
                 path: str | os.PathLike | None = None):
        self._recording, self._path = recording, path
        super().__init__(exp_name=exp_name, log_dir=None if path is None else os.fspath(path))

    @property
    def path(self) -> str | os.PathLike | None:
        """The ``.rrd`` file the scalars are saved to (``None`` when writing to a given recording)."""
        return self._path

    def _create_experiment(self) -> rr.RecordingStream:
        rec = self._recording or rr.RecordingStream("atrv_warp")
        if self._recording is None and self._path is not None:
            rec.save(os.fspath(self._path))
        return rec

    def log_scalar(self, name: str, value: float, step: int | None = None) -> None:
        if step is not None:
            self.experiment.set_time("frames", sequence=int(step))
        self.experiment.log(f"{self.exp_name}/{name}", rr.Scalars(float(value)))

    def log_video(self, name: str, video: str | os.PathLike, step: int | None = None, **kwargs) -> None:
        """Log the MP4 file ``video`` as a video asset at ``<exp_name>/videos/<name>/<step>``, its frames on
        the ``video_time`` timeline (an evaluation video, :mod:`atrv_warp.integrations.video`)."""
        if not isinstance(video, (str, os.PathLike)):
            raise TypeError("RerunLogger.log_video takes the path of an MP4 file (atrv_warp.integrations.video)")
        entity = f"{self.exp_name}/videos/{name}/{0 if step is None else int(step)}"
        asset = rr.AssetVideo(path=os.fspath(video))
        self.experiment.log(entity, asset, static=True)
        stamps = asset.read_frame_timestamps_nanos()
        self.experiment.send_columns(entity, indexes=[rr.TimeColumn("video_time", duration=stamps * 1e-9)],
                                     columns=rr.VideoFrameReference.columns_nanos(stamps))

    def log_hparams(self, cfg) -> None:
        items = cfg.items() if isinstance(cfg, dict) else vars(cfg).items()
        text = "\n".join(f"- **{k}**: {v}" for k, v in items)
        self.experiment.log(f"{self.exp_name}/hparams", rr.TextDocument(text, media_type=rr.MediaType.MARKDOWN),
                            static=True)

    def log_histogram(self, name: str, data, **kwargs) -> None:
        raise NotImplementedError("RerunLogger does not log histograms")

    def __repr__(self) -> str:
        return f"RerunLogger(exp_name={self.exp_name!r}, path={self._path!r})"
