"""The collectors' correlated exploration noise (atrv_warp.rl.exploration): the actor's distribution at every
step, correlated across steps, and nothing else changed."""

from __future__ import annotations

import pickle

import pytest
import torch
from tensordict import TensorDict
from torchrl.envs.utils import ExplorationType, set_exploration_type

from atrv_warp.policy import make_actor
from atrv_warp.rl.command_line import load_train_config
from atrv_warp.rl.exploration import CorrelatedExploration, collection_policy


def _actions(policy, steps: int = 60, worlds: int = 2048) -> torch.Tensor:
    torch.manual_seed(0)
    obs = TensorDict({"observation": torch.randn(worlds, 10)}, [worlds])
    with set_exploration_type(ExplorationType.RANDOM), torch.no_grad():
        return torch.stack([policy(obs.clone())["action"] for _ in range(steps)])


def _lag1(actions: torch.Tensor) -> float:
    return float(torch.corrcoef(torch.stack([actions[:-1].flatten(), actions[1:].flatten()]))[0, 1])


def test_correlated_noise_keeps_the_actors_distribution_and_correlates_its_steps():
    torch.manual_seed(1)
    actor = make_actor(obs_dim=10)
    white, colored = _actions(actor), _actions(CorrelatedExploration(actor, 0.9, seed=3))
    # the same marginal distribution at each step (tanh of the actor's Gaussian) ...
    assert abs(float(white.mean()) - float(colored.mean())) < 0.02
    assert abs(float(white.std()) - float(colored.std())) < 0.02
    # ... but successive actions agree
    assert abs(_lag1(white)) < 0.05 and _lag1(colored) > 0.8


def test_it_is_the_actor_outside_exploration_and_shares_its_weights():
    actor = make_actor(obs_dim=10)
    policy = CorrelatedExploration(actor, 0.9, seed=3)
    obs = TensorDict({"observation": torch.randn(8, 10)}, [8])
    with set_exploration_type(ExplorationType.DETERMINISTIC):
        assert torch.equal(policy(obs.clone())["action"], actor(obs.clone())["action"])
    weights = TensorDict.from_module(policy)
    assert set(weights["actor"].keys(True, True)) == set(TensorDict.from_module(actor).keys(True, True))
    assert collection_policy(actor, 0.0, seed=0) is actor


def test_a_copy_draws_the_same_stream_from_its_seed():
    actor = make_actor(obs_dim=10)
    policy = CorrelatedExploration(actor, 0.5, seed=11)
    _actions(policy, steps=3)
    copy = pickle.loads(pickle.dumps(policy))  # what a collector's worker process gets
    assert copy.noise is None
    assert torch.equal(_actions(copy, steps=5), _actions(CorrelatedExploration(actor, 0.5, seed=11), steps=5))


def test_bad_correlation_is_refused():
    with pytest.raises(ValueError, match="correlation must be in"):
        CorrelatedExploration(make_actor(obs_dim=10), 1.0)
    with pytest.raises(ValueError, match="noise_correlation must be in"):
        load_train_config(None, {"noise_correlation": "-0.1"})
    with pytest.raises(ValueError, match="noise_correlation is for SAC"):
        load_train_config(None, {"noise_correlation": "0.9", "algo": "ppo"})
