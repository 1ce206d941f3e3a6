"""The reward as a table: every shipped term's torch twin gives the environment's column, a weight of 0 skips a term,
the terms and the config's weights are one declaration, and a term from outside the package trains."""

from __future__ import annotations

import json
import math
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import torch

from atrv_warp.task.env import ATRVjrEnv
from atrv_warp.task.registry import TASKS, resolve_task
from atrv_warp.task.reward import TorchRollout, progress_reward, term_values
from atrv_warp.task.spec import EndReason
from atrv_warp.task.terms import REFERENCE_TERMS

ROOT = Path(__file__).resolve().parent.parent


def _record(env: ATRVjrEnv, steps: int, seed: int = 0) -> tuple[TorchRollout, dict[str, torch.Tensor], torch.Tensor]:
    """``steps`` seeded random actions from a reset: the rollout as the twins read it, the env's reward-term columns
    (T, N) by name, and its rewards."""
    g = torch.Generator().manual_seed(seed)
    td = env.reset()
    first = (env.sim.obstacles.kind.clone(), env.sim.obstacles.pose.clone(), env.sim.obstacles.size.clone())
    poses, actions, torque, speed, reasons, rewards = [env.sim.root_pose.clone()], [], [], [], [], []
    columns = {name: [] for name in env.task.term_names}
    for _ in range(steps):
        action = torch.rand(env.num_envs, 2, generator=g) * 2 - 1
        td = env.step(td.set("action", action))
        nxt = td["next"]
        poses.append(env.sim.root_pose.clone())
        actions.append(action)
        torque.append(env.sim.wheel_torque.clone())
        speed.append(env.sim.wheel_speed.clone())
        reasons.append(nxt["end_reason"][:, 0].clone())
        rewards.append(nxt["reward"][:, 0].clone())
        for name, column in columns.items():
            column.append(nxt["reward_terms", name][:, 0].clone())
        td = td["next"].exclude("reward", "done", "terminated", "truncated")
    rollout = TorchRollout(poses=torch.stack(poses), targets=env.target.clone(), config=env.task_cfg,
                           actions=torch.stack(actions), obstacles=first, wheel_torque=torch.stack(torque),
                           wheel_speed=torch.stack(speed), end_reason=torch.stack(reasons),
                           step_dt=env.sim.sim_cfg.step_dt)
    return rollout, {k: torch.stack(v) for k, v in columns.items()}, torch.stack(rewards)


def test_every_shipped_terms_torch_twin_is_the_environments_column():
    """nav with every term weighted (the clearance over 3 m, so that obstacles count): each term's twin, weighted, is
    its column step by step, and the columns sum to the reward; one episode, no world ended."""
    env = ATRVjrEnv(8, task="nav", seed=3, max_steps=1000, action_rate_weight=0.2, energy_weight=0.01,
                    clearance_radius=3.0)
    rollout, columns, rewards = _record(env, 30)
    assert not rollout.end_reason.any(), "the window should not end an episode"
    twins = term_values(env.task, rollout)
    assert set(twins) == set(env.task.term_names)  # every term has its twin
    for name, twin in twins.items():
        env_column = columns[name]
        assert name in ("success", "failure") or env_column.abs().max() > 0, f"{name}: the rollout should exercise it"
        np.testing.assert_allclose(twin.numpy(), env_column.numpy(), rtol=2e-4, atol=2e-5, err_msg=name)
    np.testing.assert_allclose(sum(columns.values()).numpy(), rewards.numpy(), rtol=1e-5, atol=1e-6)


def test_the_event_terms_count_on_their_ends():
    """A rollout whose episodes reach the goal and collide: success and failure columns are their weights exactly on
    those steps (the twins' events), and 0 elsewhere; the running terms are 0 on them."""
    data = np.load(Path(__file__).parent / "data" / "nav_rollout.npz")  # columns: progress … clearance
    reasons = torch.as_tensor(data["end_reason"][..., 0])
    terms = torch.as_tensor(data["reward_terms"])
    task = resolve_task("nav")
    rollout = TorchRollout(poses=torch.zeros(reasons.shape[0] + 1, reasons.shape[1], 7), targets=torch.zeros(32, 2),
                           config=task.config, end_reason=reasons)
    events = {t.name: t for t in task.terms if t.when != "running"}
    for column, name in enumerate(task.term_names[:6]):
        if name in events:
            want = events[name].weight_of(task.config) * events[name].torch(rollout)
            assert torch.equal(terms[..., column], want.to(terms.dtype)), name
    ended = (reasons == int(EndReason.SUCCESS)) | (reasons == int(EndReason.OBSTACLE))
    assert ended.any() and (terms[..., :3][ended] == 0).all()


def test_a_weight_of_zero_skips_its_term_and_the_table_is_the_configs():
    """A term weighted 0 is not computed (its column stays 0, even where its value would not be finite); the shipped
    tasks' tables are the reference's, each weight a config field; the torch reward is the table's."""
    reach = resolve_task("reach")
    assert reach.term_names == tuple(t.name for t in REFERENCE_TERMS)
    assert {t.weight for t in reach.terms} <= {f.name for f in __import__("dataclasses").fields(reach.config)}
    assert all(TASKS[name].terms == REFERENCE_TERMS for name in ("reach", "nav", "nav_deploy"))
    env = ATRVjrEnv(4, task="reach", seed=1, max_steps=1000)
    _, columns, _ = _record(env, 6)
    assert all((columns[name] == 0).all() for name in ("clearance", "action_rate", "energy"))
    with pytest.raises(ValueError, match=r"weighted by TaskConfig.no_such_field, which is missing"):
        from atrv_warp.task.definition import RewardTerm, Task
        from atrv_warp.task.kernels.terms import progress, within_reach

        Task("broken", reach.config, (RewardTerm("x", progress, "no_such_field"),), within_reach)
    poses = torch.zeros(4, 2, 7)
    poses[..., 6] = 1.0
    poses[:, :, 0] = torch.arange(4.0)[:, None]  # driving +x toward a target at (10, 0)
    dense = progress_reward(poses, torch.tensor([[10.0, 0.0], [10.0, 0.0]]), "reach")
    assert torch.allclose(dense, torch.full((3, 2), 1.0 - 0.03))  # 1 m of progress, no turn, the step's cost


@pytest.mark.slow  # trains
def test_a_term_from_outside_the_package_trains(tmp_path):
    """A reward term written in a file of one's own (one function, one row), on a variant of reach registered there:
    ``train --task-module`` trains with it, logs it, and writes the resolved task into the run folder."""
    module = tmp_path / "my_task.py"
    module.write_text(textwrap.dedent('''
        from dataclasses import dataclass, replace
        from typing import Any

        import warp as wp

        from atrv_warp.task import terms
        from atrv_warp.task.config import TaskConfig
        from atrv_warp.task.definition import RewardTerm, Task
        from atrv_warp.task.kernels.state import TermInputs
        from atrv_warp.task.kernels.terms import within_reach
        from atrv_warp.task.registry import register_task


        @dataclass(frozen=True)
        class ForwardConfig(TaskConfig):
            forward_weight: float = 0.05


        @wp.func
        def forward(params: Any, inputs: TermInputs, world: int) -> float:
            """The chassis' speed along its heading [m/s]."""
            rover = inputs.rover
            pose = rover.body_q[world * rover.bodies_per_world + rover.chassis_body]
            return wp.quat_rotate_inv(wp.transform_get_rotation(pose), rover.lin_vel[world])[0]


        FORWARD = RewardTerm("forward", forward, "forward_weight")
        register_task(Task("reach_forward", ForwardConfig(), (*terms.REFERENCE_TERMS, FORWARD), within_reach))
    '''))
    out = tmp_path / "runs"
    proc = subprocess.run([sys.executable, "-m", "atrv_warp.train", "--config", "smoke", f"out_dir={out}",
                           "task=reach_forward", f"task_module={module}", "env.task.forward_weight=0.1",
                           "total_frames=3072"], cwd=ROOT, capture_output=True, text=True, timeout=900, check=False)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    run = out / "smoke"
    rows = [line.split(",") for line in (run / "logs" / "scalars" / "train_reward_forward.csv").read_text().split()]
    assert rows and all(math.isfinite(float(v)) for _, v in rows) and any(float(v) != 0 for _, v in rows)
    record = json.loads((run / "task.json").read_text())
    assert record["name"] == "reach_forward" and record["config"]["forward_weight"] == 0.1
    assert record["terms"][-1] == {"name": "forward", "weight_field": "forward_weight", "weight": 0.1,
                                   "when": "running", "reads": ["state"], "function": record["terms"][-1]["function"]}
    assert "[env.task]" in (run / "config.toml").read_text() and "forward_weight = 0.1" in (run / "config.toml").read_text()


def test_the_custom_task_example_registers_builds_and_steps():
    """``examples/custom_task.py`` (the docs' "Your own task" page shows it whole): its task registers, its own
    observation kind and reward terms build, and its environment steps with finite rewards."""
    from atrv_warp.task.registry import load_task_module

    assert load_task_module(ROOT / "examples" / "custom_task.py") == ["parking"]
    env = ATRVjrEnv(4, task="parking", seed=0)
    assert env.task.term_names == ("progress", "alignment", "stopping", "posed", "step_penalty", "success", "failure")
    td = env.rollout(8)
    assert td["next", "observation"].shape == (4, 8, 6) and torch.isfinite(td["next", "reward"]).all()
    assert '--8<-- "examples/custom_task.py"' in (ROOT / "docs" / "your-own-task.md").read_text()
