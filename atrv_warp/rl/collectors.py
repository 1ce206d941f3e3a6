"""Collectors: one table (:data:`COLLECTORS`) from ``collector.kind`` to what differs between the
ways of collecting, and :func:`make_collector`, which builds the one a configuration names.

- ``async``: one worker process on the second core steps the worlds while the trainer updates on
  the first; the trainer sends it the weights after each batch's updates.
- ``sync``: collect and update in turn, in this process, with the learner's own actor (bit-reproducible).
- ``ray``: ``num_collectors`` Ray actors, on this machine or a cluster (below).

Collection on Ray (``collector=ray``): :class:`~atrv_warp.rl.ray_collector.RayCollection` over
``num_collectors`` :class:`RayWorker` actors, each stepping ``envs_per_collector`` worlds.
``python -m atrv_warp.train --config smoke collector=ray`` trains with two collectors on a local Ray;
``ray_address=auto`` joins the cluster this node belongs to (docs/training.md, 'Scale out on Ray'). Needs the
``ray`` extra: ``pip install -e ".[ray]"``.

What runs where: the learner (updates, replay buffer, evaluations) stays in the process that
runs ``atrv_warp.train``; each collector is a Ray actor holding one :class:`RoverEnv` and a copy of
the policy. The collectors deliver their batches first ready, first served; each request for a
batch carries the learner's current weights through Ray's object store, so the collector that
delivered a batch gets the weights of the moment the loop body that used it is done. A collector
whose process dies costs its batch in flight: it is replaced, and the run says so
(:mod:`atrv_warp.rl.ray_collector`).

Ray itself: an already initialised Ray is reused and left running; otherwise :func:`make_ray_collector`
starts (``ray_address`` empty) or joins (``auto``, ``HOST:PORT``) one and the collection's
``shutdown()`` stops or leaves it again, so a run leaves no Ray process behind.
"""

from __future__ import annotations

import importlib.util
import logging
import math
import os
from collections.abc import Callable
from dataclasses import dataclass

import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.collectors import Collector

from atrv_warp.rl.config import TrainConfig
from atrv_warp.rl.run import RunSpec, resolve_run
from atrv_warp.runtime import TRAINER_CORE, WORKER_CORE, pin_to_core
from atrv_warp.task.env import EnvFactory, RoverEnv

__all__ = ["COLLECTORS", "INSTALL_HINT", "OBJECT_STORE_BYTES", "WORKER_KEY", "CollectorKind", "RayWorker",
           "StampWorker", "describe_placements", "make_collector", "make_ray_collector", "pin_to_core", "placements",
           "ray_init_config", "require_ray", "worker_weights"]

INSTALL_HINT = 'collector=ray needs Ray, the optional extra [ray]: pip install -e ".[ray]"'
"""What ``collector=ray`` says, before any work, where Ray is not installed."""
OBJECT_STORE_BYTES = 256 * 1024**2
"""Object store of a local Ray [B]: it only holds the batches in flight (512 worlds x 8 steps is a
few MB), and Ray's default (30 % of the memory) is far more than a shared 2-core machine should lend."""
WORKER_KEY = ("collector", "worker")
"""Key of the index of the collector that produced each frame."""
_SEED_STRIDE = 1_000_003
"""Collector ``i`` seeds its worlds with ``seed + i * _SEED_STRIDE``: distinct episodes per collector."""


def require_ray() -> None:
    """Raise ``ModuleNotFoundError`` with :data:`INSTALL_HINT` where Ray is not installed."""
    if importlib.util.find_spec("ray") is None:
        raise ModuleNotFoundError(INSTALL_HINT)


def ray_init_config(address: str) -> dict:
    """``ray.init`` keywords for ``ray_address``: empty = a new local Ray with one CPU per core of this
    machine and no dashboard; ``auto`` or ``HOST:PORT`` = join that cluster. Used only where Ray is not
    already initialised in this process."""
    quiet = {"logging_level": logging.WARNING, "log_to_driver": True}  # workers' errors still reach the console
    if address:
        return {"address": address, **quiet}
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return {"address": "local", "num_cpus": cores, "object_store_memory": OBJECT_STORE_BYTES,
            "include_dashboard": False, **quiet}


class StampWorker:
    """Post-processing run in collector ``index``: writes its index under :data:`WORKER_KEY`, so the
    learner can count each collector's frames."""

    def __init__(self, index: int):
        self.index = index

    def __call__(self, data: TensorDictBase) -> TensorDictBase:
        data.set(WORKER_KEY, torch.full(data.shape, self.index, dtype=torch.int16))
        return data


class RayWorker(Collector):
    """One Ray collector: TorchRL's single-process :class:`Collector`, named briefly (Ray prefixes
    every line an actor prints with the actor's repr, and Collector's spans dozens of lines), with
    queries the trainer and the tests make through :meth:`~atrv_warp.rl.ray_collector.RayCollection.map_fn`, and
    :meth:`collect`, which the collection calls for every batch."""

    def __repr__(self) -> str:
        return f"RayWorker({self.worker_idx})"

    def placement(self) -> dict:
        """Where this collector runs: Ray node id and IP address, host name and process id."""
        import socket

        import ray

        context = ray.get_runtime_context()
        return {"node_id": context.get_node_id(), "node_ip": ray.util.get_node_ip_address(),
                "host": socket.gethostname(), "pid": os.getpid()}

    def policy_weights(self) -> TensorDictBase:
        """A copy of the weights (parameters and buffers) of this collector's policy."""
        return TensorDict.from_module(self.policy).data.clone()

    def collect(self, weights: TensorDictBase | None = None) -> TensorDictBase:
        """Copy ``weights`` (the learner's, as :meth:`policy_weights` gives them) into this collector's
        policy, then collect and return the next batch."""
        if weights is not None:
            TensorDict.from_module(self.policy).data.update_(weights)
        return self.next()


def make_ray_collector(cfg: TrainConfig, actor, *, total_frames: int, init_random_frames: int, env_seed: int,
                       run: RunSpec | None = None):
    """A :class:`~atrv_warp.rl.ray_collector.RayCollection` of ``cfg.collector.num_collectors`` :class:`RayWorker`
    actors, on the Ray ``cfg.collector.ray_address`` names (started or joined here unless one is running).

    Each actor needs one CPU (and one unit of ``ray_resource`` if set), builds its env with
    :class:`EnvFactory` (no core pinning: Ray places the actor; one torch thread), and starts from
    ``actor``'s weights; every request for a batch carries the learner's weights of that moment.

    Args:
        cfg: The training configuration (``collector`` group: count, worlds, address, resource).
        actor: The learner's policy; its weights are sent, it is not shared.
        total_frames: Frames after which the iterator stops.
        init_random_frames: Frames collected with random actions first, split evenly between collectors
            (a replacement collector acts with the policy from its first frame).
        env_seed: Seed of collector 0's worlds; collector ``i`` adds ``i * 1_000_003``, its ``k``-th
            replacement ``k * 7_919``.
        run: Not used: each actor resolves the config's names in its own process.

    Returns:
        The collection; its ``shutdown()`` stops the actors, and Ray if it started it.
    """
    require_ray()
    import ray

    from atrv_warp.rl.ray_collector import RayCollection

    c = cfg.collector
    remote = {"num_cpus": 1}
    if c.ray_resource:
        remote["resources"] = {c.ray_resource: 1}
    started = not ray.is_initialized()
    if started:
        ray.init(**ray_init_config(c.ray_address))
    worker_class = ray.remote(**remote)(RayWorker)

    def make_worker(index: int, generation: int):
        seed = env_seed + index * _SEED_STRIDE + generation * 7_919
        # the MLP policy is stateless: it needs no env transform (InitTracker) appended for it
        return worker_class.remote(EnvFactory(cfg.worlds_per_collector, seed=seed, env_kwargs=cfg.env.env_kwargs()),
                                   policy=actor, frames_per_batch=cfg.frames_per_batch, total_frames=-1,
                                   init_random_frames=init_random_frames // c.num_collectors if generation == 0 else 0,
                                   postproc=StampWorker(index), auto_register_policy_transforms=False,
                                   split_trajs=False, worker_idx=index)

    try:
        collection = RayCollection(make_worker, c.num_collectors, actor, total_frames=total_frames,
                                   started_ray=started)
        collection.map_fn("placement")  # every actor is up (or its error shows here, before training)
    except BaseException:
        if started:
            ray.shutdown()
        raise
    return collection


def placements(collector) -> list[dict]:
    """:meth:`RayWorker.placement` of every collector of ``collector``, in order."""
    return collector.map_fn("placement")


def describe_placements(collector) -> str:
    """One line: each collector's node IP, host, node id (first 8 hex digits) and process id."""
    return ", ".join(f"{p['node_ip']} ({p['host']}, node {p['node_id'][:8]}, pid {p['pid']})"
                     for p in placements(collector))


def worker_weights(collector) -> list[TensorDictBase]:
    """:meth:`RayWorker.policy_weights` of every collector of ``collector``, in order."""
    return collector.map_fn("policy_weights")


def make_sync_collector(cfg: TrainConfig, actor, *, total_frames: int, init_random_frames: int, env_seed: int,
                        run: RunSpec | None = None):
    """Collect in this process, stepping the learner's own ``actor``, on the run's device (``run``: ``cfg`` resolved,
    where the caller has it)."""
    # the MLP policy is stateless: it needs no env transform (InitTracker) appended for it
    env = RoverEnv(cfg.env.num_envs, seed=env_seed, device=cfg.run.device,
                   **(run or resolve_run(cfg)).env_kwargs(cfg))
    return Collector(env, actor, frames_per_batch=cfg.frames_per_batch, total_frames=total_frames,
                     init_random_frames=init_random_frames, auto_register_policy_transforms=False)


def make_async_collector(cfg: TrainConfig, actor, *, total_frames: int, init_random_frames: int, env_seed: int,
                         run: RunSpec | None = None):
    """One worker process, pinned to the second core, with a copy of ``actor`` (it resolves the run's names itself:
    ``run`` is not used)."""
    from torchrl.collectors import MultiAsyncCollector

    factory = EnvFactory(cfg.env.num_envs, seed=env_seed, core=WORKER_CORE, env_kwargs=cfg.env.env_kwargs())
    failure = None
    try:
        return MultiAsyncCollector([factory], actor, frames_per_batch=cfg.frames_per_batch, total_frames=total_frames,
                                   init_random_frames=init_random_frames)
    except Exception as err:  # noqa: BLE001 - re-raised below, once the half-built collector is gone
        failure = f"{type(err).__name__}: {err}"
    # The half-built collector dies with the exception's frames, here: torchrl 0.14's weight-sync
    # scheme shuts down in __del__, which deadlocks if it is left for interpreter exit.
    import gc

    gc.collect()
    raise RuntimeError(f"the collector's worker process failed to start: {failure}")


def _describe_local(cfg: TrainConfig) -> str:
    return f"{cfg.collector.kind} collector, {cfg.env.num_envs} worlds"


def _describe_ray(cfg: TrainConfig) -> str:
    where = f"Ray at {cfg.collector.ray_address}" if cfg.collector.ray_address else "local Ray"
    return f"{cfg.collector.num_collectors} ray collectors x {cfg.worlds_per_collector} worlds ({where})"


@dataclass(frozen=True)
class CollectorKind:
    """What differs between the ways of collecting; the trainer asks this, never the kind's name."""

    make: Callable
    """``make(cfg, actor, *, total_frames, init_random_frames, env_seed, run)``: the TorchRL collector (``run``: ``cfg``
    resolved in this process, for the envs it builds here; processes of its own resolve the names themselves)."""
    describe: Callable[[TrainConfig], str]
    """One line for the console: ``'async collector, 256 worlds'``, ``'2 ray collectors x 64 worlds (local Ray)'``."""
    push_weights: bool = False
    """The collector steps a copy of the policy, which the trainer updates after each batch's updates
    (``sync`` shares the learner's actor; Ray's collectors fetch the weights themselves)."""
    trainer_core: int | None = None
    """Pin the trainer to this core (``async``: the worker has the other one)."""
    require: Callable[[], None] | None = None
    """Raises, before any work, where what the kind needs is not installed."""
    placements: Callable | None = None
    """``placements(collector)``: one line saying where the collectors run, printed at the start."""


def make_collector(cfg: TrainConfig, actor, frames_done: int, *, run: RunSpec | None = None):
    """The collector ``cfg.collector.kind`` names (:data:`COLLECTORS`), for the frames still to collect.

    A resumed run (``frames_done`` > 0) collects only what is left, random frames included, and
    draws new episodes.
    """
    fpb = cfg.frames_per_batch
    remaining = max(cfg.run.total_frames - frames_done, 0)
    random_left = max(cfg.collector.init_random_frames - frames_done, 0)
    env_seed = cfg.run.seed + 7919 * (frames_done // fpb + 1)  # a resumed run draws new episodes
    whole_batches = max(math.ceil(remaining / fpb), 1) * fpb  # the loop stops at total_frames itself
    return COLLECTORS[cfg.collector.kind].make(cfg, actor, total_frames=whole_batches, init_random_frames=random_left,
                                               env_seed=env_seed, run=run)


COLLECTORS: dict[str, CollectorKind] = {
    "async": CollectorKind(make_async_collector, _describe_local, push_weights=True,
                           trainer_core=TRAINER_CORE),
    "sync": CollectorKind(make_sync_collector, _describe_local),
    "ray": CollectorKind(make_ray_collector, _describe_ray, require=require_ray, placements=describe_placements),
}
"""Every ``collector.kind`` (:class:`~atrv_warp.rl.config.CollectorConfig`) and what it means for the trainer."""
