"""Experiment tracking and evaluation videos, for real and without network: a W&B offline run folder
read back record by record, an MLflow SQLite store read back through MLflow's client, TensorBoard's
event file, a Rerun recording, and every video decoded back frame by frame.

``pytest tests/test_tracking.py`` (the ``test`` extra brings wandb, mlflow and tensorboard).
"""

from __future__ import annotations

import importlib.util
import json
import struct
import sys
import time
from pathlib import Path

import pytest
import torch

from atrv_warp.integrations.video import EvalVideo, read_video
from atrv_warp.rl.command_line import load_train_config
from atrv_warp.rl.config import flat_config
from atrv_warp.task.terms import REWARD_TERMS

needs = {name: pytest.mark.skipif(importlib.util.find_spec(name) is None, reason=f"needs {name}: pip install -e '.[test]'")
         for name in ("wandb", "mlflow", "tensorboard")}


@pytest.fixture(scope="module")
def nav_videos(tmp_path_factory):
    """Four episodes of the shipped nav policy (terrain, obstacles, scan), recorded twice in one evaluation:
    the whole arena (written), and following each rover over 8 m of ground."""
    from atrv_warp import ATRVjrEnv, load_policy
    from atrv_warp.policy import pretrained_nav_policy_path
    from atrv_warp.task.evaluation import evaluate

    env = ATRVjrEnv(8, task="nav", seed=0)
    video, followed = EvalVideo(env, episodes=4, panel=128), EvalVideo(env, episodes=4, panel=128, follow=8.0)
    hooks = video.env_hook(), followed.env_hook()
    evaluate(load_policy(pretrained_nav_policy_path()), num_episodes=8, env=env,
             on_step=lambda e, td: [hook(e, td) for hook in hooks])
    return video, video.write(tmp_path_factory.mktemp("video") / "nav.mp4", gif=True), followed


@pytest.fixture(scope="module")
def nav_video(nav_videos):
    return nav_videos[:2]


def test_following_video_keeps_the_rover_large_and_centred(nav_videos):
    import numpy as np

    from atrv_warp.integrations.video import _ROVER

    video, _, followed = nav_videos
    whole, close = next(iter(video.frames())), next(iter(followed.frames()))
    assert close.shape == whole.shape == (256, 256, 3)

    def rover_pixels(frame):  # world 0's panel: the top-left 128 px
        return np.argwhere((frame[:128, :128] == _ROVER).all(-1))

    far, near = rover_pixels(whole), rover_pixels(close)
    # 128 px over 8 m instead of 31 m: the footprint (0.64 x 0.39 m) covers ~15x the pixels
    assert len(far) > 0 and len(near) > 10 * len(far), (len(far), len(near))
    assert np.abs(near.mean(0) - 64).max() < 4  # centred in its panel


def test_video_decodes_to_the_frames_drawn(nav_video):
    video, written = nav_video
    assert all(video.reason), video.reason  # every recorded episode ended
    assert video.steps == max(video.end_step) + 1  # recorded until the last of them ended
    expected = len(range(0, video.steps, video.every)) + (1 if (video.steps - 1) % video.every else 0)
    assert written.frames == expected and (written.width, written.height) == (256, 256) and written.fps == 10
    assert read_video(written.path) == (expected, 256, 256)  # it plays: every frame decodes
    assert written.gif[:6] == b"GIF89a"
    first, last = next(iter(video.frames())), list(video.frames())[-1]
    assert first.shape == (256, 256, 3) and not (first == last).all()  # the rovers moved
    assert len({tuple(c) for c in first.reshape(-1, 3)[::7]}) > 50  # terrain shading, not a flat fill


def test_evaluate_cli_writes_a_video_and_refuses_a_bad_path(tmp_path, capsys):
    from atrv_warp.cli.evaluate import main

    out = tmp_path / "new" / "folder" / "eval.mp4"  # a folder that does not exist yet is created
    assert main(["--episodes", "4", "--video", str(out), "--video-episodes", "2"]) == 0
    printed = capsys.readouterr().out
    frames, width, height = read_video(out)
    assert f"video: {out} ({frames} frames, {width}x{height}, 2 episodes" in printed
    assert (width, height) == (512, 256) and frames > 5
    blocker = tmp_path / "file"
    blocker.write_text("")
    for bad, why in ((tmp_path / "eval.avi", "must end in .mp4"), (blocker / "eval.mp4", "cannot create its folder")):
        assert main(["--episodes", "4", "--video", str(bad)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and why in err[0] and str(bad) in err[0], err
        assert not bad.exists()


def wandb_records(run_dir: Path) -> list:
    """Every record of a W&B run file (``run-<id>.wandb``): a 7-byte header, then LevelDB-log records
    (32 KiB blocks; per chunk a 7-byte header: CRC32C, length, type 1 full, 2 first, 3 middle, 4 last)
    whose payloads are ``wandb_internal_pb2.Record`` messages."""
    from wandb.proto import wandb_internal_pb2

    (path,) = run_dir.glob("run-*.wandb")
    data = path.read_bytes()
    assert data[:4] == b":W&B", data[:8]
    records, pending, pos, block = [], b"", 7, 32768
    while pos + 7 <= len(data):
        if block - pos % block < 7:  # a block's tail too short for a header is padding
            pos += block - pos % block
            continue
        _, length, kind = struct.unpack("<IHB", data[pos:pos + 7])
        if kind == 0 or pos + 7 + length > len(data):  # padding, or a chunk still being written
            break
        pending += data[pos + 7:pos + 7 + length]
        pos += 7 + length
        if kind in (1, 4):
            record = wandb_internal_pb2.Record()
            record.ParseFromString(pending)
            records.append(record)
            pending = b""
    return records


def tracked_config(tmp_path, backend: str, **overrides):
    return load_train_config("smoke", {"out_dir": str(tmp_path), "logger": backend, "total_frames": "4096",
                                       "eval_episodes": "8", "final_eval_episodes": "8", "video_episodes": "2",
                                       **overrides})


@needs["wandb"]
def test_wandb_offline_run_folder_holds_config_scalars_and_video(tmp_path, nav_video):
    from atrv_warp.rl.reporting import make_loggers

    _, video = nav_video
    cfg = tracked_config(tmp_path, "wandb")
    run_dir = tmp_path / "smoke"
    loggers = make_loggers(cfg, run_dir, resume=False)
    run_id = loggers.tracking_id
    loggers.log_hparams(flat_config(cfg))
    for step in (2048, 4096):
        loggers.log("eval_success_rate", step / 8192, step=step)
        for term in REWARD_TERMS:
            loggers.log(f"train_reward_{term}", 0.5, step=step)
    assert loggers.log_video("eval_video", video, 4096) == ["WandbLogger"]
    loggers.close()
    (folder,) = (run_dir / "logs" / "wandb").glob(f"offline-run-*-{run_id}")
    # W&B's writer process puts the records on disk a moment after finish() returns (about 0.1 s here; the file
    # held only its header in about one run in four): wait for the run's exit record
    deadline = time.monotonic() + 30.0
    records = wandb_records(folder)
    while not any(r.HasField("exit") for r in records) and time.monotonic() < deadline:
        time.sleep(0.1)
        records = wandb_records(folder)
    key = lambda item: item.key or "/".join(item.nested_key)
    # the configuration is a config record, or folded into the run record when it reaches W&B's writer first
    updates = [r.run.config.update if r.HasField("run") else r.config.update for r in records
               if r.HasField("run") or r.HasField("config")]
    config = {key(i): json.loads(i.value_json) for update in updates for i in update}
    assert (config.get("optim.lr"), config.get("env.task"), config.get("logging.logger")) == (
        cfg.optim.lr, "reach", "wandb"), sorted(config)
    rows = [{key(i): json.loads(i.value_json) for i in r.history.item} for r in records if r.HasField("history")]
    success = [(row["step"], row["eval_success_rate"]) for row in rows if "eval_success_rate" in row]
    assert success == [(2048, 0.25), (4096, 0.5)], success
    assert all(any(f"train_reward_{t}" in row for row in rows) for t in REWARD_TERMS)
    (clip,) = [row for row in rows if "eval_video/path" in row]
    assert clip["eval_video/_type"] == "video-file" and clip["step"] == 4096 and clip["eval_video/path"].endswith(".mp4")
    assert read_video(folder / "files" / clip["eval_video/path"]) == (video.frames, video.width, video.height)

    again = make_loggers(cfg, run_dir, resume=True, tracking_id=run_id)  # --resume continues the run
    assert again.tracking_id == run_id
    again.close()


@needs["mlflow"]
@pytest.mark.slow  # trains: a smoke run with logger=mlflow and its resume, read back from MLflow's store
def test_mlflow_training_run_is_read_back_from_its_local_store(tmp_path):
    """A training run with logger=mlflow, then --resume: one MLflow run with the hyperparameters, every
    reward term, the evaluation figures, and one decodable video per evaluation."""
    import mlflow

    from atrv_warp.rl.loop import train

    cfg = tracked_config(tmp_path, "mlflow")
    run_dir = train(cfg)
    state = torch.load(run_dir / "checkpoint.pt", weights_only=True)
    client = mlflow.MlflowClient(f"sqlite:///{(run_dir / 'logs' / 'mlflow.db').resolve()}")
    run = client.get_run(state["tracking_id"])
    assert run.info.status == "FINISHED" and run.info.run_name == "smoke"
    assert run.data.params["optim.lr"] == str(cfg.optim.lr) and run.data.params["logging.video_episodes"] == "2"
    metrics = run.data.metrics
    assert {f"train_reward_{t}" for t in REWARD_TERMS} <= metrics.keys()
    assert {"eval_success_rate", "eval_mean_return", "final_eval_success_rate", "video_render_s"} <= metrics.keys()
    evals = [m.step for m in client.get_metric_history(run.info.run_id, "eval_success_rate")]
    assert evals == [2048, 4096], evals
    videos = sorted(a.path for a in client.list_artifacts(run.info.run_id, "videos"))
    assert videos == ["videos/eval_00000002048.mp4", "videos/eval_00000004096.mp4"], videos
    local = Path(client.download_artifacts(run.info.run_id, videos[-1], str(tmp_path / "download")))
    assert read_video(local) == read_video(run_dir / "videos" / "eval_00000004096.mp4")

    train(load_train_config(str(run_dir / "config.toml"), {"total_frames": "6144", "out_dir": str(tmp_path)}),
          resume=True)
    assert [r.info.run_id for r in client.search_runs([run.info.experiment_id])] == [run.info.run_id]
    assert [m.step for m in client.get_metric_history(run.info.run_id, "eval_success_rate")] == [2048, 4096, 6144]
    assert client.get_run(run.info.run_id).data.tags["resumed.run.total_frames"] == "6144"


@needs["tensorboard"]
def test_tensorboard_gets_the_video_as_an_animated_gif(tmp_path, nav_video):
    import av
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    from atrv_warp.rl.reporting import make_loggers

    _, video = nav_video
    loggers = make_loggers(tracked_config(tmp_path, "tensorboard"), tmp_path / "run", resume=False)
    assert loggers.wants_gif and loggers.log_video("eval_video", video, 4096) == ["TensorboardLogger"]
    events = EventAccumulator(str(tmp_path / "run" / "logs"), size_guidance={"images": 0})
    events.Reload()
    (image,) = events.Images("eval_video")
    assert image.step == 4096 and (image.width, image.height) == (video.width // 2, video.height // 2)
    path = tmp_path / "eval.gif"
    path.write_bytes(image.encoded_image_string)
    with av.open(str(path)) as gif:
        assert sum(1 for _ in gif.decode(video=0)) == video.frames


def test_rerun_logger_takes_the_video_as_an_asset(tmp_path, nav_video):
    from rerun.chunk import RrdReader

    from atrv_warp.integrations.rerun_logger import RerunLogger

    _, video = nav_video
    logger = RerunLogger("train", path=tmp_path / "train.rrd")
    logger.log_video("eval_video", video.path, step=4096)
    logger.experiment.flush()
    logger.experiment.disconnect()
    entity = "/train/videos/eval_video/4096"
    columns = {}
    for chunk in RrdReader(str(tmp_path / "train.rrd")).stream().to_chunks():
        if chunk.entity_path == entity:
            batch = chunk.to_record_batch()
            columns.update({name: batch.column(name) for name in batch.schema.names})
    blob = next(c for name, c in columns.items() if name.endswith("blob"))
    assert blob.to_pylist()[0][0] == list(video.path.read_bytes())  # the MP4 itself
    stamps = next(c for name, c in columns.items() if "timestamp" in name.lower())
    assert len(stamps) == video.frames  # a frame reference per frame


def test_missing_extra_and_unknown_backend_are_one_line(tmp_path, capsys, monkeypatch):
    from atrv_warp.cli.train import main

    assert main(["--config", "smoke", f"out_dir={tmp_path}", "logger=neptune"]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "invalid choice 'neptune'" in line and "'wandb', 'mlflow'" in line, line
    assert main(["--config", "smoke", f"out_dir={tmp_path}", "algo=dqn"]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "invalid choice 'dqn'" in line and "('sac', 'ppo')" in line, line
    monkeypatch.setitem(sys.modules, "wandb", None)  # as if not installed: find_spec('wandb') is None
    assert main(["--config", "smoke", "logger=wandb", f"out_dir={tmp_path}"]) == 2
    expected = 'python -m atrv_warp.train: error: logger=wandb needs wandb, the optional extra [track]: pip install -e ".[track]"'
    assert capsys.readouterr().err.strip().splitlines() == [expected]
    assert not any(tmp_path.iterdir())
