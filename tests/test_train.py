"""Training entry point: smoke run end to end, config errors, resume, evaluation CLI, shipped policy."""

import json
import math
import os
from pathlib import Path

import pytest
import torch

from atrv_warp.rl.command_line import load_train_config, preset_names
from atrv_warp.rl.config import TrainConfig

ROOT = Path(__file__).resolve().parent.parent
SMOKE = "smoke"  # a preset shipped inside the package


def test_config_files_and_errors(tmp_path):
    assert {"default", "smoke"} <= set(preset_names())
    default = load_train_config("default")
    assert default == TrainConfig()  # the preset names the documented defaults
    smoke = load_train_config(SMOKE, {"width": "16"})
    assert smoke.network.width == 16 and smoke.collector.kind == "sync"
    assert load_train_config(SMOKE, {"optim.lr": "1e-3", "collector": "async"}).optim.lr == 1e-3
    mine = tmp_path / "mine.toml"
    mine.write_text('[run]\nname = "mine"\n[network]\nwidth = 64\n[optim]\nlr = 1e-3\n[logging]\nprogress = false\n')
    assert load_train_config(str(mine)) == load_train_config(None, {"name": "mine", "width": "64", "lr": "1e-3",
                                                                    "progress": "off"})
    with pytest.raises(FileNotFoundError, match=r"config 'smok' is neither a file nor a preset; presets: \["):
        load_train_config("smok")
    with pytest.raises(ValueError, match=r"unknown train config key\(s\) \['lerning_rate'\]"):
        load_train_config(None, {"lerning_rate": "1e-3"})
    with pytest.raises(ValueError, match="Error parsing --optim.batch-size: invalid literal for int.*'big'"):
        load_train_config(None, {"batch_size": "big"})
    with pytest.raises(ValueError, match=r"invalid choice 'maybe' for argument '--logging.progress'"):
        load_train_config(None, {"progress": "maybe"})
    with pytest.raises(ValueError, match="gamma must be in"):
        load_train_config(None, {"gamma": "1.5"})
    with pytest.raises(ValueError, match=r"lr_final_fraction must be in \[0, 1\], got 1.5"):
        load_train_config(None, {"lr_final_fraction": "1.5"})
    flat = tmp_path / "flat.toml"  # what run folders from before 0.2.0 hold
    flat.write_text('name = "old"\nwidth = 64\n')
    with pytest.raises(ValueError, match=r"flat keys \['name', 'width'\] are from before atrv_warp 0.2.0.*"
                                         r"write name under \[run\], width under \[network\]"):
        load_train_config(str(flat))
    bad = tmp_path / "bad.toml"
    bad.write_text("[env]\nnum_envs = 8\nnum_env = 4\n")
    with pytest.raises(ValueError, match=r"unknown train config key\(s\) \['env.num_env'\] in .*bad.toml"):
        load_train_config(str(bad))
    for name in ("../../x", "a/b", "..", ""):  # a run stays inside out_dir
        with pytest.raises(ValueError, match="name must be a folder name inside out_dir"):
            load_train_config(None, {"name": name})
    with pytest.raises(ValueError, match=f"out_dir {bad} is a file, not a folder"):
        load_train_config(None, {"out_dir": str(bad)})


def test_substeps_reach_the_training_and_evaluation_envs():
    from atrv_warp.rl.loop import Evaluator

    cfg = load_train_config(SMOKE, {"substeps": "3", "eval_episodes": "4"})
    assert dict(cfg.env.env_kwargs())["sim"].substeps == 3 and dict(TrainConfig().env.env_kwargs())["sim"].substeps == 5
    evaluator = Evaluator(cfg, actor=None)
    assert evaluator.env.sim.substeps == 3
    with pytest.raises(ValueError, match="substeps must be > 0, got 0"):
        load_train_config(None, {"substeps": "0"})


def test_a_run_is_resolved_once_per_process(tmp_path, monkeypatch):
    """Loading the config, the actor, the in-process collector's and validation's envs and the saves' record share
    one resolution: the task is fitted to the robot once and its URDF parsed once (issue 69, part 1; a robot copied
    to a new folder, so that nothing earlier in this process resolved it)."""
    import shutil

    import yourdfpy

    from atrv_warp.rl.collectors import make_collector
    from atrv_warp.rl.evaluators import make_evaluator
    from atrv_warp.rl.learner import make_run_actor
    from atrv_warp.rl.run import resolve_run
    from atrv_warp.task.definition import Task

    for suffix in (".toml", ".urdf"):
        shutil.copy(ROOT / "atrv_warp" / "robots" / f"atrvjr{suffix}", tmp_path / f"atrvjr{suffix}")
    counts = {"fitted": 0, "parsed": 0}
    fit, load = Task.for_robot, yourdfpy.URDF.load

    def counted(key, function):
        def wrapper(*args, **kwargs):
            counts[key] += 1
            return function(*args, **kwargs)
        return wrapper

    monkeypatch.setattr(Task, "for_robot", counted("fitted", fit))
    monkeypatch.setattr(yourdfpy.URDF, "load", counted("parsed", load))
    cfg = load_train_config(SMOKE, {"robot": str(tmp_path / "atrvjr.toml"), "num_envs": "4", "eval_episodes": "2",
                                    "env.task.max_steps": "150"})
    run = resolve_run(cfg)
    assert resolve_run(cfg) is run and run.task.config.max_steps == 150 and run.robot.path == str(tmp_path / "atrvjr.toml")
    actor, _ = make_run_actor(cfg, run)
    collector = make_collector(cfg, actor, 0, run=run)
    evaluator = make_evaluator(cfg, actor, run=run)
    assert evaluator.env.task is run.task and collector.env.task is run.task  # the resolved task itself
    assert run.record()["task_record"]["config"]["max_steps"] == 150
    assert counts == {"fitted": 1, "parsed": 1}, counts
    collector.shutdown()
    robot_file = tmp_path / "atrvjr.toml"  # a file the resolution read changes: it is read again
    robot_file.write_text(robot_file.read_text().replace("linear_velocity = 0.5", "linear_velocity = 0.4"))
    stat = robot_file.stat()
    os.utime(robot_file, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000))
    again = resolve_run(cfg)
    assert again is not run and again.robot.limits.linear_velocity == 0.4 and counts["fitted"] == 2


def test_cli_rejects_bad_config_before_work(tmp_path, run_module, capsys):
    proc = run_module("atrv_warp.train", "--config", SMOKE, f"out_dir={tmp_path}", "num_envs=-3", check=False)
    assert proc.returncode == 2 and "num_envs must be > 0" in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1  # one line naming the problem, no usage dump
    from atrv_warp.cli.train import main  # the same entry point, in this process (a subprocess costs ~10 s)

    assert main([f"out_dir={tmp_path}", "lerning_rate=1e-3"]) == 2
    assert "unknown train config key(s) ['lerning_rate']" in capsys.readouterr().err
    assert main([f"out_dir={tmp_path}", "--optim.batch-size", "big"]) == 2
    err = capsys.readouterr().err
    assert "--optim.batch-size" in err and "big" in err and len(err.strip().splitlines()) == 1
    assert not any(tmp_path.iterdir())  # nothing was started or written
    with pytest.raises(SystemExit) as done:
        main(["--config", SMOKE, "--help"])  # one parser: our options and the fields
    helped = capsys.readouterr().out
    assert done.value.code == 0
    assert all(f in helped for f in ("--config", "--resume", "--verbose", "--optim.lr", "--collector.kind"))
    assert "(default: smoke)" in helped  # the fields' defaults are the preset's


@pytest.mark.slow  # trains
def test_smoke_training_end_to_end(smoke_run):
    run_dir, stdout = smoke_run
    for name in ("config.toml", "checkpoint.pt", "best_policy.pt", "final_eval.json", "learning_curve.png"):
        assert (run_dir / name).is_file(), name
    assert (run_dir / "logs" / "scalars" / "eval_success_rate.csv").is_file()
    result = json.loads((run_dir / "final_eval.json").read_text())
    assert result["frames"] >= 6144 and result["updates"] > 0
    assert 0.0 <= result["final_eval"]["success_rate"] <= 1.0
    assert "best policy:" in stdout and str(run_dir) in stdout
    # a quiet console: the device once, one line per evaluation, no library chatter
    assert stdout.count("simulation on cpu") == 1
    assert "Module " not in stdout and "CUDA warning" not in stdout and "INFO" not in stdout
    assert "Warning" not in stdout, stdout
    assert sum("eval success" in line for line in stdout.splitlines()) == 3  # every 2048 of 6144 frames
    ck = torch.load(run_dir / "checkpoint.pt", weights_only=True)  # no arbitrary pickle needed
    assert ck["frames"] == result["frames"]
    # the best policy is the best evaluation's: highest success, then highest mean return
    scalars = run_dir / "logs" / "scalars"
    rows = {name: [tuple(map(float, line.split(","))) for line in (scalars / f"{name}.csv").read_text().split()]
            for name in ("eval_success_rate", "eval_mean_return")}
    evals = [(rate, ret, -frames) for (frames, rate), (_, ret) in zip(*rows.values(), strict=True)]
    meta = torch.load(run_dir / "best_policy.pt", weights_only=True)["meta"]
    assert meta["frames"] == -max(evals)[2]


@pytest.mark.slow  # trains
def test_evaluate_cli_loads_checkpoint(smoke_run, tmp_path, run_module):
    run_dir, _ = smoke_run
    out = tmp_path / "eval.json"
    proc = run_module("atrv_warp.evaluate", str(run_dir / "checkpoint.pt"), "--episodes", "16", "--json", str(out))
    assert "success" in proc.stdout
    figures = json.loads(out.read_text())
    assert figures["episodes"] == 16
    total = figures["success_rate"] + figures["wall_rate"] + figures["flip_rate"] + figures["timeout_rate"]
    assert total == pytest.approx(1.0 - figures["nonfinite_rate"])
    bad = run_module("atrv_warp.evaluate", str(tmp_path / "missing.pt"), check=False)
    assert bad.returncode == 2 and "policy file not found" in bad.stderr


@pytest.mark.slow  # trains
def test_resume_continues_step_counter(smoke_run, tmp_path, run_module):
    import shutil

    run_dir, _ = smoke_run
    copy = tmp_path / "smoke"
    shutil.copytree(run_dir, copy)
    before = torch.load(copy / "checkpoint.pt", weights_only=True)
    run_module("atrv_warp.train", "--resume", str(copy), "total_frames=10240")
    after = torch.load(copy / "checkpoint.pt", weights_only=True)
    assert after["frames"] >= 10240 > before["frames"]
    assert after["updates"] > before["updates"]
    rows = (copy / "logs" / "scalars" / "train_reward.csv").read_text().splitlines()
    steps = [int(r.split(",")[0]) for r in rows]
    assert steps == sorted(steps) and steps[-1] >= 10240  # the log continues, it does not restart
    again = run_module("atrv_warp.train", "--config", SMOKE, f"out_dir={tmp_path}", check=False)
    assert again.returncode != 0 and "already holds a run" in again.stderr


@pytest.mark.slow  # trains: a fine-tune of the shared smoke run
def test_init_from_fine_tunes_a_new_run_under_randomization(smoke_run, tmp_path, run_module):
    """``init_from=``: a new run starts from another run's networks (here continued under the ``wide``
    randomization): its first evaluation already drives like the source, and it counts its own frames."""
    run_dir, _ = smoke_run
    source = torch.load(run_dir / "checkpoint.pt", weights_only=True)
    run_module("atrv_warp.train", "--config", SMOKE, f"out_dir={tmp_path}", "name=tuned", "randomization=wide",
               f"init_from={run_dir / 'checkpoint.pt'}", "init_random_frames=0", "total_frames=1024")
    tuned = torch.load(tmp_path / "tuned" / "checkpoint.pt", weights_only=True)
    assert tuned["frames"] == 1024 and tuned["stats_ready"]
    assert tuned["config"]["env"]["randomization"] == "wide"
    norm = [k for k in source["policy"]["state_dict"] if "loc" in k or "scale" in k]
    assert norm and all(torch.equal(source["policy"]["state_dict"][k], tuned["policy"]["state_dict"][k]) for k in norm)
    bad = run_module("atrv_warp.train", "--config", SMOKE, f"out_dir={tmp_path}", "name=bad",
                     f"init_from={tmp_path / 'nope.pt'}", check=False)
    assert bad.returncode != 0 and "nope.pt" in bad.stderr and not (tmp_path / "bad" / "checkpoint.pt").exists()


def test_resume_of_a_run_with_a_flat_config_says_what_changed(tmp_path, capsys):
    """Run folders from before 0.2.0 hold a flat config.toml: --resume names the change in one line."""
    from atrv_warp.cli.train import main

    old = tmp_path / "old"
    old.mkdir()
    (old / "config.toml").write_text('name = "old"\nlr = 0.001\n[env]\nnum_envs = 64\n')
    assert main(["--resume", str(old)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    assert "are from before atrv_warp 0.2.0" in lines[0] and "lr under [optim], name under [run]" in lines[0]
    assert sorted(p.name for p in old.iterdir()) == ["config.toml"]  # nothing started


def test_shipped_policy_beats_scripted_baseline():
    from atrv_warp.policy import load_policy, pretrained_policy_path
    from atrv_warp.task.baseline import scripted_policy
    from atrv_warp.task.evaluation import evaluate

    assert pretrained_policy_path().stat().st_size < 1_000_000
    shipped = evaluate(load_policy(), num_episodes=200, seed=99)
    baseline = evaluate(scripted_policy(), num_episodes=200, seed=99)
    assert shipped.success_rate >= baseline.success_rate
    # it also earns more of the shaped reward
    assert shipped.mean_return > baseline.mean_return


def test_shipped_nav_policy_beats_scripted_driver_on_nav():
    """Learning matters on the nav task: the scripted turn-then-drive driver runs into the obstacle
    across its path; the shipped nav policy drives around it."""
    from atrv_warp.policy import load_policy, policy_task, pretrained_nav_policy_path
    from atrv_warp.task.baseline import scripted_policy
    from atrv_warp.task.evaluation import evaluate

    path = pretrained_nav_policy_path()
    assert path.stat().st_size < 1_000_000 and policy_task(path) == "nav"
    shipped = evaluate(load_policy(path), num_episodes=128, seed=99, task="nav")
    baseline = evaluate(scripted_policy(), num_episodes=128, seed=99, task="nav")
    assert shipped.success_rate >= 0.85 and baseline.success_rate < 0.3, (shipped, baseline)


@pytest.mark.slow  # trains
def test_sync_training_is_reproducible(smoke_run, tmp_path, run_module):
    """Same seed, same result: the in-process (sync) collector gives bit-identical weights."""
    run_dir, _ = smoke_run
    run_module("atrv_warp.train", "--config", SMOKE, f"out_dir={tmp_path}")
    a = torch.load(run_dir / "checkpoint.pt", weights_only=True)["policy"]["state_dict"]
    b = torch.load(tmp_path / "smoke" / "checkpoint.pt", weights_only=True)["policy"]["state_dict"]
    assert a.keys() == b.keys()
    assert all(torch.equal(a[k], b[k]) for k in a)


@pytest.mark.slow  # trains
def test_validation_in_the_background_judges_the_same_weights_alike(smoke_run, tmp_path, run_module):
    """The periodic validation in a process of its own (the default outside the smoke preset) finds what the
    in-trainer one finds, logged at the same frames, and saves the weights it judged, not the trainer's later ones:
    with the bit-reproducible sync collector, the same figures and the same best policy, byte for byte."""
    run_dir, _ = smoke_run
    run_module("atrv_warp.train", "--config", SMOKE, f"out_dir={tmp_path}", "logging.eval_in_background=true")
    background = tmp_path / "smoke"
    for name in ("eval_success_rate", "eval_mean_return", "eval_mean_steps"):
        ours = (background / "logs" / "scalars" / f"{name}.csv").read_text()
        assert ours == (run_dir / "logs" / "scalars" / f"{name}.csv").read_text(), name
    assert (background / "best_policy.pt").read_bytes() == (run_dir / "best_policy.pt").read_bytes()
    taken = dict(line.split(",") for line in (background / "logs" / "scalars" / "wall_time_s.csv").read_text().split())
    known = dict(line.split(",") for line in (background / "logs" / "scalars" / "eval_known_wall_s.csv").read_text().split())
    assert taken.keys() == known.keys() and all(float(known[f]) > float(taken[f]) for f in taken)
    assert json.loads((background / "final_eval.json").read_text())["final_eval"] == \
        json.loads((run_dir / "final_eval.json").read_text())["final_eval"]


def test_a_background_validation_that_fails_says_why():
    """A failure in the validation's process is an error in the trainer carrying its cause, not a hang."""
    from atrv_warp.rl.evaluators import BackgroundEvaluator

    evaluator = BackgroundEvaluator(load_train_config(SMOKE, {"eval_episodes": "4"}))
    try:
        evaluator.submit(2048, {"state_dict": {}})  # weights that fit no actor
        with pytest.raises(RuntimeError, match=r"the background validation failed: RuntimeError: Error\(s\) in "
                                               r"loading state_dict"):
            evaluator.poll(wait=True)
    finally:
        evaluator.close()
    assert not evaluator.process.is_alive()


class _TouchOnLoad:
    """Unpickling this creates ``path``: proof that a loader executed pickled code."""

    def __init__(self, path):
        self.path = path

    def __reduce__(self):
        return (Path.touch, (Path(self.path),))


def _damaged_files(tmp_path: Path, good: Path) -> tuple[dict[str, Path], Path]:
    import pickle
    import random

    marker = tmp_path / "unpickled.marker"
    files = {"random": tmp_path / "random.pt", "pickle": tmp_path / "objects.pkl",
             "torch_pickle": tmp_path / "objects.pt", "truncated": tmp_path / "truncated.pt"}
    files["random"].write_bytes(random.Random(0).randbytes(4096))
    files["pickle"].write_bytes(pickle.dumps({"policy": _TouchOnLoad(marker)}))
    torch.save({"policy": _TouchOnLoad(marker)}, files["torch_pickle"])
    data = good.read_bytes()
    files["truncated"].write_bytes(data[: len(data) // 2])
    return files, marker


@pytest.mark.slow  # trains
def test_evaluate_names_a_bad_file_in_one_line_and_unpickles_nothing(smoke_run, tmp_path, run_module):
    run_dir, _ = smoke_run
    files, marker = _damaged_files(tmp_path, run_dir / "checkpoint.pt")
    expected = {"random": "not a complete file written by torch.save",
                "pickle": "not a complete file written by torch.save",
                "torch_pickle": "holds Python objects other than tensors",
                "truncated": "not a complete file written by torch.save"}
    for kind in ("random", "torch_pickle", "truncated"):  # one of each kind of refusal through the CLI
        proc = run_module("atrv_warp.evaluate", str(files[kind]), "--episodes", "2", check=False)
        lines = proc.stderr.strip().splitlines()
        assert proc.returncode == 2 and len(lines) == 1, (kind, proc.stderr)
        assert str(files[kind]) in lines[0] and expected[kind] in lines[0], lines[0]
        assert "Traceback" not in proc.stderr
    from atrv_warp.policy import load_policy
    from atrv_warp.storage import FileFormatError

    for kind, path in files.items():
        with pytest.raises(FileFormatError, match=expected[kind]):
            load_policy(path)
    assert not marker.exists()  # nothing was unpickled
    tensor = tmp_path / "tensor.pt"
    torch.save(torch.zeros(3), tensor)
    with pytest.raises(FileFormatError, match="holds a Tensor, not a dict"):
        load_policy(tensor)
    ck = torch.load(run_dir / "checkpoint.pt", weights_only=True)
    ck["policy"]["state_dict"] = {k: v.fill_(float("nan")) if v.is_floating_point() else v
                                  for k, v in ck["policy"]["state_dict"].items()}
    torch.save(ck, tmp_path / "nan.pt")
    with pytest.raises(FileFormatError, match="non-finite values"):
        load_policy(tmp_path / "nan.pt")
    ck["policy"]["width"] = 7
    torch.save(ck, tmp_path / "shape.pt")
    with pytest.raises(FileFormatError, match="damaged atrv_warp policy"):
        load_policy(tmp_path / "shape.pt")


@pytest.mark.slow  # trains
def test_resume_refuses_a_damaged_checkpoint_and_keeps_the_run(smoke_run, tmp_path, run_module):
    import shutil

    run_dir, _ = smoke_run
    copy = tmp_path / "smoke"
    shutil.copytree(run_dir, copy)
    data = (copy / "checkpoint.pt").read_bytes()
    (copy / "checkpoint.pt").write_bytes(data[: len(data) - 100])
    # the lock names the pid of the last training that held the folder (this one's, refused): not the run's data
    before = {p: p.read_bytes() for p in copy.rglob("*") if p.is_file() and p.name != "training.lock"}
    proc = run_module("atrv_warp.train", "--resume", str(copy), "total_frames=10240", check=False)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert str(copy / "checkpoint.pt") in lines[0] and "training checkpoint" in lines[0]
    after = {p: p.read_bytes() for p in copy.rglob("*") if p.is_file() and p.name != "training.lock"}
    assert after == before  # nothing rewritten, nothing added


def _fixed_batch(n: int = 256):
    from tensordict import TensorDict

    g = torch.Generator().manual_seed(0)
    return TensorDict({"observation": torch.randn(n, 10, generator=g), "action": torch.rand(n, 2, generator=g) * 2 - 1,
                       ("next", "done"): torch.zeros(n, 1, dtype=torch.bool),
                       ("next", "terminated"): torch.zeros(n, 1, dtype=torch.bool),
                       ("next", "reward"): torch.randn(n, 1, generator=g),
                       ("next", "observation"): torch.randn(n, 10, generator=g)}, [n])


@pytest.mark.slow  # trains
def test_learning_rate_anneals_with_the_frames(tmp_path, run_module):
    """``lr_final_fraction``: every optimiser's rate falls linearly from ``lr`` to ``lr x fraction`` at
    ``total_frames``; the logged rate follows the frames, and the checkpoint's optimisers end at the floor."""
    from atrv_warp.rl.learner import annealed_lr

    run_module("atrv_warp.train", "--config", SMOKE, f"out_dir={tmp_path}", "lr=1e-3", "lr_final_fraction=0.1")
    cfg = load_train_config(SMOKE, {"lr": "1e-3", "lr_final_fraction": "0.1"})
    assert annealed_lr(cfg, 0) == 1e-3 and annealed_lr(cfg, 10 * cfg.run.total_frames) == pytest.approx(1e-4)
    assert annealed_lr(cfg, cfg.run.total_frames // 2) == pytest.approx(5.5e-4)
    logged = [tuple(map(float, line.split(","))) for line in
              (tmp_path / "smoke" / "logs" / "scalars" / "lr.csv").read_text().split()]
    assert len(logged) == 3 and all(lr == pytest.approx(annealed_lr(cfg, int(f))) for f, lr in logged)
    assert [lr for _, lr in logged] == sorted((lr for _, lr in logged), reverse=True)
    ck = torch.load(tmp_path / "smoke" / "checkpoint.pt", weights_only=True)
    rates = [group["lr"] for opt in ck["opts"].values() for group in opt["param_groups"]]
    assert len(rates) == 3 and all(rate == pytest.approx(1e-4) for rate in rates)  # actor, critics, temperature


@pytest.mark.parametrize("loss", ["sac", "crossq", "redq"])
def test_each_loss_learns_and_its_state_round_trips(loss):
    """``loss=`` switches TorchRL's SAC, CrossQ or REDQ loss: each fits its critics on a fixed batch,
    CrossQ without target networks, and a learner rebuilt from the state dict takes the same step."""
    from atrv_warp.policy import Normalize, make_actor
    from atrv_warp.rl.learner import REPLAY_KEYS, Learner

    cfg = load_train_config(SMOKE, {"loss": loss})
    torch.manual_seed(0)
    learner = Learner(cfg, make_actor(32, 2, normalize=Normalize()), Normalize())
    assert (learner.target_update is None) == (loss == "crossq")
    assert type(learner.loss).__name__ == {"sac": "SACLoss", "crossq": "CrossQLoss", "redq": "REDQLoss"}[loss]
    batch = _fixed_batch()
    assert set(batch.keys(True, True)) <= set(REPLAY_KEYS)  # the loss learns from what the replay buffer keeps
    first = [float(learner.update(batch.clone())["loss_qvalue"]) for _ in range(3)]
    for _ in range(150):
        out = learner.update(batch.clone())
    assert all(torch.isfinite(out[k]).all() for k in ("loss_actor", "loss_qvalue", "loss_alpha", "entropy"))
    assert float(out["loss_qvalue"]) < 0.5 * min(first)

    twin = Learner(cfg, make_actor(32, 2, normalize=Normalize()), Normalize())
    twin.load_state_dict(learner.state_dict())
    torch.manual_seed(1)
    a = learner.update(batch.clone())
    torch.manual_seed(1)
    b = twin.update(batch.clone())
    assert float(a["loss_qvalue"]) == float(b["loss_qvalue"]) and float(a["loss_actor"]) == float(b["loss_actor"])


@pytest.mark.slow  # trains
def test_crossq_trains_from_the_command_line(tmp_path, run_module):
    proc = run_module("atrv_warp.train", "--config", SMOKE, f"out_dir={tmp_path}", "loss=crossq", "total_frames=4096")
    assert "best policy, final evaluation" in proc.stdout
    assert (tmp_path / "smoke" / "logs" / "scalars" / "eval_success_rate.csv").read_text().strip()
    ck = torch.load(tmp_path / "smoke" / "checkpoint.pt", weights_only=True)
    assert ck["updates"] > 0 and any("running_mean" in k for k in ck["loss"])  # batch-renormalised critics
    assert 'loss = "crossq"' in (tmp_path / "smoke" / "config.toml").read_text()


PPO_TINY = {"num_envs": "64", "init_random_frames": "1024", "minibatch_size": "256", "total_frames": "5120",
            "eval_every_frames": "2048", "eval_episodes": "16", "final_eval_episodes": "32", "width": "32",
            "buffer_size": "2048", "progress": "false", "video_episodes": "0"}
"""The ``ppo`` preset shrunk to seconds: 64 worlds x 16 steps per batch, the first batch random."""


def test_ppo_learner_fits_its_value_and_its_state_round_trips():
    """``algo=ppo``: TorchRL's ClipPPOLoss on GAE advantages of a collected batch; the value loss falls
    over passes on one batch, and a learner rebuilt from the state dict takes the same steps."""
    from atrv_warp.policy import Normalize, make_actor
    from atrv_warp.rl.collectors import make_collector
    from atrv_warp.rl.learner import ALGOS, make_learner
    from atrv_warp.rl.ppo import PPOLearner

    # gamma 0.5, lambda 1: the value targets are (nearly) the discounted rewards, which the value does not move
    cfg = load_train_config("ppo", {**PPO_TINY, "init_random_frames": "0", "epochs": "1", "gamma": "0.5",
                                    "gae_lambda": "1.0", "lr": "3e-3"})
    assert ALGOS[cfg.optim.algo].on_policy and cfg.optim.algo == "ppo"
    torch.manual_seed(0)
    actor = make_actor(32, 2, normalize=Normalize(), return_log_prob=True)
    collector = make_collector(cfg, actor, 0)
    batch = next(iter(collector))
    collector.shutdown()
    assert batch.shape == (64, 16) and batch.get("action_log_prob", None) is not None
    learner = make_learner(cfg, actor, Normalize())
    assert isinstance(learner, PPOLearner) and type(learner.loss).__name__ == "ClipPPOLoss"
    twin_actor = make_actor(32, 2, normalize=Normalize(), return_log_prob=True)
    twin_actor.load_state_dict(actor.state_dict())
    twin = make_learner(cfg, twin_actor, Normalize())
    twin.load_state_dict(learner.state_dict())
    torch.manual_seed(1)
    a = [float(out["loss_objective"]) for out in learner.learn_batch(batch.clone())]
    torch.manual_seed(1)
    b = [float(out["loss_objective"]) for out in twin.learn_batch(batch.clone())]
    assert len(a) == 4 and a == b  # 1,024 frames in minibatches of 256, one pass; the same steps
    critic = [float(out["loss_critic"]) for _ in range(20) for out in learner.learn_batch(batch.clone())]
    assert all(map(math.isfinite, critic)) and min(critic[-4:]) < 0.5 * max(critic[:4]), critic


@pytest.mark.slow  # trains
def test_ppo_trains_resumes_and_exports(tmp_path, run_module):
    """The ``ppo`` preset end to end (shrunk): it learns only from the policy's batches, a resumed run
    continues it, the same seed gives the same weights, and its policy exports."""
    args = [f"{k}={v}" for k, v in PPO_TINY.items()]
    proc = run_module("atrv_warp.train", "--config", "ppo", f"out_dir={tmp_path}", *args)
    run_dir = tmp_path / "ppo"
    assert "(ppo, sync collector, 64 worlds, batch 1024 frames" in proc.stdout
    ck = torch.load(run_dir / "checkpoint.pt", weights_only=True)
    # 5 batches: the first of random actions sets the statistics; 4 x (1,024 / 256 minibatches x 4 epochs)
    assert ck["frames"] == 5120 and ck["updates"] == 64
    scalars = run_dir / "logs" / "scalars"
    assert all((scalars / f"{k}.csv").is_file() for k in ("loss_objective", "loss_critic", "kl_approx", "clip_fraction"))
    run_module("atrv_warp.train", "--resume", str(run_dir), "total_frames=7168")
    after = torch.load(run_dir / "checkpoint.pt", weights_only=True)
    assert after["frames"] == 7168 and after["updates"] == 96 and set(after["opts"]) == {"ppo"}
    again = tmp_path / "again"
    run_module("atrv_warp.train", "--config", "ppo", f"out_dir={again}", *args)
    first, second = ck["policy"]["state_dict"], torch.load(again / "ppo" / "checkpoint.pt", weights_only=True)["policy"]["state_dict"]
    assert first.keys() == second.keys() and all(torch.equal(first[k], second[k]) for k in first)  # same seed, same weights
    from atrv_warp.rl.export import load_exported

    out = tmp_path / "ppo.pt2"
    run_module("atrv_warp.export", str(run_dir / "best_policy.pt"), str(out))
    module, spec = load_exported(out)
    assert module(torch.zeros(3, 10)).shape == (3, 2) and spec["policy_meta"]["task"] == "reach"


@pytest.mark.slow  # trains
def test_train_around_a_calibrated_rover_from_the_command_line(tmp_path, run_module):
    """``train --sim-config F randomization=around``: the run trains on draws around the file's values and its
    folder records the resolved ranges; a file that lacks a drawn parameter stops before any work, in one line."""
    calibrated = tmp_path / "calibrated.toml"
    calibrated.write_text("[rover]\ntorque_scale = 0.8\npayload_mass = 12.0\nwheel_radius = 0.125\n"
                          "[contact]\nfriction = 0.5\n[calibration.standard_error]\npayload_mass = 1.5\n")
    run_module("atrv_warp.train", "--config", SMOKE, f"out_dir={tmp_path}", "name=around", "--sim-config",
               str(calibrated), "randomization=around", "total_frames=2048", "init_random_frames=1024",
               "eval_every_frames=1024", "final_eval_episodes=16")
    run_dir = tmp_path / "around"
    assert (run_dir / "best_policy.pt").is_file()
    saved = json.loads((run_dir / "randomization.json").read_text())
    assert saved["randomization"] == "around" and saved["sim_config"] == str(calibrated)
    resolved = saved["resolved"]
    assert resolved["payload_mass"]["low"] == pytest.approx(9.0) and resolved["payload_mass"]["high"] == pytest.approx(15.0)
    assert resolved["friction"]["low"] == pytest.approx(0.45) and resolved["friction"]["high"] == pytest.approx(0.55)
    assert resolved["stiffness"] is None and resolved["latency"] == [0, 1]
    lacking = tmp_path / "lacking.toml"
    lacking.write_text("[contact]\nfriction = 0.5\n")
    bad = run_module("atrv_warp.train", "--config", SMOKE, f"out_dir={tmp_path}", "name=bad", "--sim-config",
                     str(lacking), "randomization=around", check=False)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1
    assert str(lacking) in bad.stderr and "payload_mass" in bad.stderr and not (tmp_path / "bad").exists()


@pytest.mark.parametrize(("token", "message"), [
    ("max_minutes=nan", "run.max_minutes must be a finite number, got nan"),
    ("lr=inf", "optim.lr must be a finite number, got inf"),
    ("env.task.max_steps=-3", "TaskConfig.max_steps must be >= 0, got -3"),
    ("env.task.reach_radius=0", "TaskConfig.reach_radius must be > 0"),
    ("total_frames=1e30", "run.total_frames must be a whole number, got 1e30"),
    ("total_frames=2.5", "run.total_frames must be a whole number, got 2.5"),
    ("run.device=cpu:1", "device must be cpu (one device, whatever its cores)"),
    ("num_envs=10_000_000", "(env.num_envs alone"),
    ("buffer_size=2_000_000_000", "(optim.buffer_size alone"),
    ("steps_per_batch=100_000_000", "lower env.num_envs or env.steps_per_batch"),
])
def test_a_bad_number_or_size_is_refused_by_name_before_any_work(token, message):
    """Issue 70: numbers that are not finite, counts below zero or not whole, a CPU index, and a run that would not
    fit in memory (estimated before anything is allocated) are one line naming the field; 1e6 is a whole number."""
    from atrv_warp.rl.command_line import parse_command

    with pytest.raises(ValueError) as err:
        parse_command(["--config", "smoke", token])
    assert message in str(err.value) and "\n" not in str(err.value), str(err.value)


def test_whole_numbers_in_float_form_and_text_without_control_characters(tmp_path):
    from atrv_warp.rl.command_line import load_train_config, parse_command

    assert parse_command(["--config", "smoke", "total_frames=1e6"]).train.run.total_frames == 1_000_000
    assert load_train_config("smoke", {"total_frames": "2.0e4"}).run.total_frames == 20_000
    config = tmp_path / "nul.toml"
    config.write_text('[run]\nname = "a\\u0000b"\n')
    with pytest.raises(ValueError, match=r"run.name holds a control character: 'a\\x00b'"):
        load_train_config(str(config))
