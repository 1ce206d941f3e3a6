"""Training on a device (issue 60): ``run.device``, the GPU recipe's structure run on the CPU, the update built once
(``optim.compile``), and the first compile of the simulator's kernels (done ahead, in parallel, said once)."""

import io
import json

import pytest
import torch

from atrv_warp.rl.command_line import load_train_config

GPU_PRESET = "nav_deploy_gpu"


def _on_cpu(tmp_path, **extra):
    """The GPU preset shrunk to a few worlds on the CPU: the same structure (sync collector, buffer and networks on
    the run's device, validation in the trainer, several updates per env step), minutes cut to seconds."""
    overrides = {"run.device": "cpu", "optim.compile": "off", "run.out_dir": str(tmp_path), "env.num_envs": 16,
                 "env.steps_per_batch": 4, "run.total_frames": 1024, "collector.init_random_frames": 256,
                 "optim.batch_size": 64, "optim.buffer_size": 4096, "logging.eval_every_frames": 512,
                 "logging.eval_episodes": 8, "logging.final_eval_episodes": 8, "logging.progress": False,
                 "network.width": 32}
    return load_train_config(GPU_PRESET, {**overrides, **extra})


def test_the_gpu_preset_names_its_device_and_refuses_a_machine_without_one():
    cfg = load_train_config(GPU_PRESET, {"run.device": "cpu", "optim.compile": "off"})
    assert cfg.collector.kind == "sync" and cfg.env.task == "nav_deploy" and cfg.env.randomization == "wide"
    if torch.cuda.is_available():
        cfg = load_train_config(GPU_PRESET)
        assert cfg.run.device == "cuda:0" and cfg.optim.compile == "cudagraphs"
        return
    with pytest.raises(ValueError, match=r"device=cuda:0 but this torch .* sees no CUDA device"):
        load_train_config(GPU_PRESET)


@pytest.mark.parametrize(("overrides", "message"), [
    ({"run.device": "tpu"}, "device must be cpu or a CUDA device"),
    ({"run.device": "cuda:zero"}, "device must be cpu or a CUDA device"),
    ({"optim.compile": "cudagraphs"}, "compile=cudagraphs captures CUDA graphs: it needs device=cuda"),
    ({"optim.algo": "ppo", "optim.compile": "compile", "collector.noise_correlation": 0.0},
     "compile=compile builds SAC's update"),
])
def test_a_bad_device_or_compile_setting_is_named(overrides, message):
    with pytest.raises(ValueError, match=message):
        load_train_config("smoke", overrides)


@pytest.mark.slow  # trains
def test_the_gpu_recipe_trains_on_the_cpu(tmp_path, capsys):
    """The recipe's loop, on a few worlds of the CPU: it trains, validates in the trainer, saves and evaluates."""
    from atrv_warp.rl.evaluators import Evaluator, make_evaluator
    from atrv_warp.rl.learner import make_buffer, make_run_actor, replay_frames
    from atrv_warp.rl.loop import train

    cfg = _on_cpu(tmp_path)
    actor, _ = make_run_actor(cfg)
    evaluator = make_evaluator(cfg, actor)
    assert isinstance(evaluator, Evaluator)  # in the trainer, as on a GPU
    evaluator.close()
    assert make_buffer(cfg).storage.device == torch.device("cpu")
    run_dir = train(cfg)
    out = capsys.readouterr().out
    result = json.loads((run_dir / "final_eval.json").read_text())
    # one update per 256 frames once learning starts (four per env step of the recipe's 1,024 worlds)
    assert result["frames"] == 1024 and result["updates"] == (1024 - 256) // 256
    assert "simulation on cpu" in out and (run_dir / "best_policy.pt").is_file()
    batch = torch.zeros(3, 2)
    from tensordict import TensorDict

    td = TensorDict({"observation": torch.zeros(3, 2, 4), "action": batch.expand(2, 3, 2).transpose(0, 1)}, [3, 2])
    assert replay_frames(td).batch_size == torch.Size([6])


def test_a_compiled_update_learns_as_the_eager_one():
    """``optim.compile=compile``: the same update (losses to float rounding, the same parameters after a few steps),
    built once by ``torch.compile``, its learning rate changed between updates as the annealing does."""
    from tensordict import TensorDict

    from atrv_warp.rl.learner import Learner, make_run_actor

    def batch(n, obs_dim, g):
        flags = torch.zeros(n, 1, dtype=torch.bool)
        return TensorDict({"observation": torch.randn(n, obs_dim, generator=g),
                           "action": torch.rand(n, 2, generator=g) * 2 - 1,
                           ("next", "observation"): torch.randn(n, obs_dim, generator=g),
                           ("next", "reward"): torch.randn(n, 1, generator=g),
                           ("next", "done"): flags, ("next", "terminated"): flags, ("next", "truncated"): flags}, [n])

    from atrv_warp.rl.learner import set_lr

    runs = {}
    for how in ("off", "compile"):
        cfg = load_train_config("smoke", {"optim.compile": how, "env.task": "nav_deploy"})
        torch.manual_seed(0)
        actor, normalize = make_run_actor(cfg)
        learner = Learner(cfg, actor, normalize)
        g = torch.Generator().manual_seed(1)
        losses = []
        for lr in (1e-3, 1e-3, 5e-4, 2e-4):  # the annealing changes the rate between updates
            set_lr(learner, lr)
            losses.append(learner.update(batch(64, normalize.loc.numel(), g))["loss_qvalue"])
        runs[how] = torch.stack(losses), [p.detach().clone() for p in learner.loss.parameters()]
    torch.testing.assert_close(runs["compile"][0], runs["off"][0], rtol=1e-4, atol=1e-5)
    for a, b in zip(runs["compile"][1], runs["off"][1], strict=True):
        torch.testing.assert_close(a, b, rtol=1e-3, atol=1e-4)


def test_the_first_compile_is_done_ahead_and_names_every_module_a_step_loads():
    """:data:`STEP_MODULES` covers every Warp module that building a simulator and stepping the nav world loads (a
    task's own term and end kernels aside), and kernels compile without adjoints unless gradients are asked for. In a
    fresh process: other tests in this one load other modules and switch the adjoints on."""
    import subprocess
    import sys

    from atrv_warp.sim import kernel_cache

    probe = """
import json, torch, warp
from atrv_warp.sim import kernel_cache
from atrv_warp.task.env import RoverEnv
off = warp.config.enable_backward
env = RoverEnv(2, task="nav_deploy")
td = env.reset()
td["action"] = torch.zeros(2, 2)
env.step(td)
from warp._src.context import user_modules
loaded = sorted(name for name, module in user_modules.items() if module.execs)
listed = kernel_cache.step_modules()
from atrv_warp.sim import RoverSim
RoverSim(1, requires_grad=True)
print(json.dumps([off, warp.config.enable_backward, loaded, listed]))
"""
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True).stdout
    off, on, loaded, listed = json.loads(out.splitlines()[-1])
    assert (off, on) == (False, True)  # no adjoints until a simulator asks for gradients
    own = {name for name in loaded if name.startswith(("make_term_kernel_", "make_ends_kernel_"))}
    assert own and set(loaded) - own <= set(listed), set(loaded) - own - set(listed)
    out = io.StringIO()
    kernel_cache.precompile("cpu", out=out)  # this process's modules: compiled or cached, at most one line each way
    assert kernel_cache.precompile("cpu", out=out) == 0.0  # done once per process


@pytest.mark.slow  # compiles in a fresh cache, trains
def test_the_gpu_check_runs_every_part(tmp_path):
    """``benchmarks/perf/gpu_check.py``, which a GPU machine runs blind, runs every part (small, on the CPU)
    and writes each part's figures with the results file's provenance."""
    import subprocess
    import sys
    from pathlib import Path

    out, root = tmp_path / "gpu_check.json", Path(__file__).resolve().parent.parent
    proc = subprocess.run([sys.executable, "-m", "benchmarks.perf.gpu_check", "--device", "cpu", "--quick", "--seeds", "0",
                           "--out", str(out), "--runs", str(tmp_path)], cwd=root, capture_output=True, text=True,
                          timeout=600, check=False)
    assert proc.returncode == 0, proc.stderr[-3000:]
    result = json.loads(out.read_text())
    assert {"compile", "tiers", "updates", "train", "provenance"} <= result.keys()
    assert result["compile"]["cold"]["first_step_s"] > result["compile"]["warm"]["first_step_s"]
    assert [row["worlds"] for row in result["tiers"]["rows"]] == [16, 32]
    assert all(row["env in maps"]["env_steps_per_s"] > 0 for row in result["tiers"]["rows"])
    assert set(result["updates"]["updates_per_s"]) == {"off", "compile"}
    assert result["train"]["seeds"][0]["frames"] >= 2048 and result["provenance"]["task"]
