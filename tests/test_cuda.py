"""The same code on CUDA: the simulator, the environment, its snapshot and the gradients on a GPU, each held to
what the CPU gives for the same inputs.

Skipped where Warp finds no CUDA device (CI has none). On a GPU machine: ``python -m pytest tests/test_cuda.py``.
"""

from __future__ import annotations

import pytest
import torch
import warp as wp

from atrv_warp import ATRVjrEnv, RoverSim  # the simulator's import initialises Warp quietly
from atrv_warp.sim.diff import DiffRollout
from atrv_warp.task.baseline import scripted_policy

pytestmark = pytest.mark.skipif(wp.get_cuda_device_count() == 0, reason="no CUDA device")

CUDA = "cuda:0"


def _commands(steps: int, n: int, seed: int) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return (torch.rand(steps, n, 2, generator=g) * 2 - 1) * 20


def _drive(device: str, poses: torch.Tensor, cmds: torch.Tensor) -> torch.Tensor:
    sim = RoverSim(poses.shape[0], device=device)
    sim.reset(poses=poses)
    for c in cmds:
        sim.step(c)
    assert sim.root_pose.device.type == torch.device(device).type
    return torch.cat([sim.root_pose, sim.lin_vel, sim.wheel_speed], -1).cpu()


def test_the_simulator_on_cuda_drives_as_on_the_cpu():
    """Forty steps (2 s) of random wheel torques on four worlds: the GPU's state follows the CPU's (float32
    sums in another order, so close, not equal)."""
    poses = torch.tensor([[0.0, 0.0, 0.3], [5.0, -3.0, -1.0], [-8.0, 2.0, 2.5], [3.0, 7.0, 0.0]])
    cmds = _commands(40, 4, 0)
    cpu, gpu = _drive("cpu", poses, cmds), _drive(CUDA, poses, cmds)
    assert torch.isfinite(gpu).all()
    torch.testing.assert_close(gpu, cpu, atol=5e-3, rtol=1e-3)
    assert (cpu[:, :2] - poses[:, :2]).norm(dim=1).min() > 0.1  # the rovers moved


def test_same_inputs_same_state_on_cuda():
    """Same seed, same result on the GPU too: two runs of the same inputs agree bit for bit."""
    poses = torch.tensor([[0.0, 0.0, 0.3], [5.0, -3.0, -1.0]])
    cmds = _commands(40, 2, 1)
    assert torch.equal(_drive(CUDA, poses, cmds), _drive(CUDA, poses, cmds))


def _rollout(env: ATRVjrEnv, actions: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Every observation (the reset's first) and every reward of ``actions``, on the CPU."""
    td = env.reset()
    obs, rewards = [td["observation"].cpu()], []
    for act in actions:
        td, td_next = env.step_and_maybe_reset(td.set("action", act.to(env.device)))
        obs.append(td["next", "observation"].cpu())
        rewards.append(td["next", "reward"].cpu())
        td = td_next
    return torch.stack(obs), torch.stack(rewards)


@pytest.mark.parametrize("task", ["reach", "nav"])
def test_the_environment_on_cuda_gives_the_cpus_episodes(task):
    """The env on the GPU: TorchRL's spec check passes, its tensors live on the GPU, the same seed draws the
    same episodes as on the CPU (terrain, obstacles, starts and goals), and the first steps follow the CPU's."""
    from torchrl.envs.utils import check_env_specs

    env = ATRVjrEnv(8, device=CUDA, seed=3, task=task)
    check_env_specs(env)
    assert env.reset()["observation"].device.type == torch.device(CUDA).type
    actions = torch.rand(10, 8, 2, generator=torch.Generator().manual_seed(4)) * 2 - 1
    (gpu, gpu_reward), (cpu, cpu_reward) = (_rollout(ATRVjrEnv(8, device=device, seed=3, task=task), actions)
                                            for device in (CUDA, "cpu"))
    assert torch.isfinite(gpu).all() and torch.isfinite(gpu_reward).all()
    torch.testing.assert_close(gpu[0], cpu[0], atol=1e-5, rtol=1e-5)  # the same episodes
    torch.testing.assert_close(gpu, cpu, atol=2e-2, rtol=1e-2)
    torch.testing.assert_close(gpu_reward, cpu_reward, atol=2e-2, rtol=1e-2)


def test_a_snapshot_on_cuda_restores_exactly():
    """Restoring a GPU env's snapshot and stepping on gives, bit for bit, what the original gave (under 'wide':
    per-world physics, delay, motor lag, sensor noise)."""
    actions = torch.rand(30, 8, 2, generator=torch.Generator().manual_seed(5)) * 2 - 1
    env = ATRVjrEnv(8, device=CUDA, seed=7, task="nav", randomization="wide")
    td = env.reset()
    for act in actions[:15]:
        td = env.step_and_maybe_reset(td.set("action", act.to(env.device)))[1]
    saved, saved_td = env.state_dict(), td.clone()

    def go_on(td):
        seq = []
        for act in actions[15:]:
            td, td_next = env.step_and_maybe_reset(td.set("action", act.to(env.device)))
            seq.append(torch.cat([td["next", "observation"], td["next", "reward"]], -1).clone())
            td = td_next
        return torch.stack(seq)

    original = go_on(td)
    env.load_state_dict(saved)
    assert torch.equal(go_on(saved_td.clone()), original)


def test_a_nonfinite_world_on_cuda_is_contained():
    env = ATRVjrEnv(3, device=CUDA, seed=3)
    td = env.reset()
    qd = wp.to_torch(env.sim.state_0.joint_qd).view(3, -1)
    qd[1, 0] = float("nan")  # world 1 blows up
    td, _ = env.step_and_maybe_reset(td.set("action", torch.full((3, 2), 0.5, device=env.device)))
    assert torch.isfinite(td["next", "observation"]).all()
    assert td["next", "terminated"][1].item() and not td["next", "terminated"][[0, 2]].any()
    assert torch.isfinite(wp.to_torch(env.sim.state_0.joint_qd)).all() and env.nonfinite_count == 1


def test_a_collector_gathers_from_the_env_on_cuda():
    from torchrl.collectors import Collector

    env = ATRVjrEnv(8, device=CUDA, seed=0, max_steps=4)
    collector = Collector(env, scripted_policy(), frames_per_batch=80, total_frames=160)
    batches = list(collector)
    collector.shutdown()
    assert [b.numel() for b in batches] == [80, 80]
    assert batches[0]["next", "observation"].device.type == torch.device(CUDA).type
    assert batches[0]["next", "truncated"][:, 3].all()


def test_gradients_through_the_simulator_on_cuda_match_the_cpus():
    """d x_final / d actions and d x_final / d mu over 0.5 s, on the GPU's tape and the CPU's."""
    grads = {}
    for device in ("cpu", CUDA):
        roll = DiffRollout(1, steps=10, device=device)
        state = roll.initial_state()
        a = torch.full((10, 1, 2), 0.3, requires_grad=True)
        mu = torch.tensor(0.3, requires_grad=True)
        roll(a, state, mu)[-1, 0, 0].backward()
        grads[device] = torch.cat([a.grad.flatten(), mu.grad.reshape(1)]).cpu()
    assert torch.isfinite(grads[CUDA]).all() and grads["cpu"].abs().max() > 0.01
    torch.testing.assert_close(grads[CUDA], grads["cpu"], rtol=1e-2, atol=1e-4)


@pytest.mark.parametrize("build", ["off", "cudagraphs"])
def test_training_runs_on_cuda(tmp_path, build):
    """The GPU recipe's loop, small: the worlds, the buffer, the networks and the updates on the GPU (eager, and the
    update captured in a CUDA graph), then a saved policy that loads on the CPU."""
    import json

    from atrv_warp.policy import load_policy
    from atrv_warp.rl.command_line import load_train_config
    from atrv_warp.rl.learner import make_buffer
    from atrv_warp.rl.loop import train

    cfg = load_train_config("nav_deploy_gpu", {
        "run.out_dir": str(tmp_path), "optim.compile": build, "env.num_envs": 64, "env.steps_per_batch": 4,
        "run.total_frames": 8192, "collector.init_random_frames": 1024, "optim.batch_size": 256,
        "logging.eval_every_frames": 4096, "logging.eval_episodes": 16, "logging.final_eval_episodes": 16,
        "logging.progress": False})
    assert make_buffer(cfg).storage.device == torch.device(CUDA)
    run_dir = train(cfg)
    result = json.loads((run_dir / "final_eval.json").read_text())
    assert result["frames"] == 8192 and result["updates"] == (8192 - 1024) // 256
    policy = load_policy(run_dir / "best_policy.pt")  # on the CPU
    assert next(policy.parameters()).device.type == "cpu"
    ck = torch.load(run_dir / "checkpoint.pt", weights_only=True)  # tensors come back where they were saved
    assert all(t.device.type == "cpu" for t in ck["loss"].values())  # on the CPU: any machine reads it
