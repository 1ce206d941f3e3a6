"""Collection on Ray that survives losing a collector (``collector=ray``): :class:`RayCollection`.

``num_collectors`` Ray actors (:class:`~atrv_warp.rl.collectors.RayWorker`, TorchRL's single-process
``Collector``) collect batches; the learner takes them first ready, first served. Each request for
a batch carries the learner's current weights through Ray's object store (one ``ray.put`` of a
few hundred kB per batch): the collector that delivered a batch gets the weights of the moment
the loop body that used it is done, and no other channel (process group, port) is involved.

A collector whose process dies (a node lost, an out-of-memory kill, ``kill -9``) raises Ray's
``RayActorError`` where its batch was awaited. That batch is dropped, one line says so, and a new
actor takes the collector's place, with the learner's current weights and a new seed stream; a
second line says when it delivers again (the recovery time). The other collectors collect on
meanwhile, and their batches in flight are kept. A collector lost ``max_restarts`` times is given
up: the run continues on the rest and says so in one line; with none left it stops with an error.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator

from tensordict import TensorDict, TensorDictBase

__all__ = ["MAX_RESTARTS", "RayCollection"]

MAX_RESTARTS = 3
"""Times one collector is replaced before the run goes on without it."""


class RayCollection:
    """Batches from Ray actors; a lost actor costs its batch in flight, and is replaced.

    Args:
        make_worker: ``make_worker(index, generation)``: a new collector actor for slot ``index``
            (``generation`` counts its replacements: a new seed stream for each).
        num_workers: Collector actors.
        actor: The learner's policy; its weights (parameters and buffers) go with every request.
        total_frames: Frames after which the iterator stops.
        started_ray: This collection started (or joined) Ray and :meth:`shutdown` stops (or leaves) it.
        max_restarts: Replacements of one collector before the run goes on without it.
        say: Where the one-line reports go (``print``).
    """

    def __init__(self, make_worker: Callable, num_workers: int, actor, *, total_frames: int, started_ray: bool,
                 max_restarts: int = MAX_RESTARTS, say: Callable[[str], None] = print):
        self.make_worker, self.actor, self.total_frames = make_worker, actor, total_frames
        self.started_ray, self.max_restarts, self.say = started_ray, max_restarts, say
        self.workers: list = [make_worker(i, 0) for i in range(num_workers)]
        """The actor of each slot; ``None`` where a collector was given up."""
        self.restarts = [0] * num_workers
        self.lost_at: dict[int, float] = {}
        """Slots being replaced, and when the loss was seen (``time.monotonic()``)."""
        self.recoveries: list[dict] = []
        """One entry per replacement that delivered again: slot, error, seconds from the loss to its first batch."""
        self.collected = 0
        self.pending: dict = {}

    def weights(self) -> TensorDictBase:
        """A copy of the learner's current weights, as each request carries them."""
        return TensorDict.from_module(self.actor).data.clone()

    def _request(self, index: int, weights_ref) -> None:
        self.pending[self.workers[index].collect.remote(weights_ref)] = index

    def __iter__(self) -> Iterator[TensorDictBase]:
        import ray

        first = ray.put(self.weights())
        for i in range(len(self.workers)):
            self._request(i, first)
        while self.collected < self.total_frames:
            if not self.pending:
                raise RuntimeError(f"every ray collector was lost (each replaced {self.max_restarts} times)")
            (ref,), _ = ray.wait(list(self.pending), num_returns=1)
            index = self.pending.pop(ref)
            try:
                data = ray.get(ref)
            except ray.exceptions.RayActorError as err:
                self._replace(index, err)
                continue
            if index in self.lost_at:
                seconds = time.monotonic() - self.lost_at.pop(index)
                self.recoveries.append({"collector": index, "seconds": seconds})
                self.say(f"ray collector {index} is back: its replacement delivered {seconds:.1f} s after the loss")
            self.collected += data.numel()
            yield data
            self._request(index, ray.put(self.weights()))  # the weights of the moment the loop body is done

    def _replace(self, index: int, err: Exception) -> None:
        """Drop slot ``index``'s batch in flight and start a new actor there (or give the slot up)."""
        import ray

        reason = str(err).strip().splitlines()[0][:120] if str(err).strip() else ""
        ray.kill(self.workers[index], no_restart=True)
        self.lost_at.setdefault(index, time.monotonic())
        if self.restarts[index] >= self.max_restarts:
            self.workers[index] = None
            self.lost_at.pop(index)
            left = sum(w is not None for w in self.workers)
            self.say(f"ray collector {index} lost again ({type(err).__name__}), after {self.max_restarts} "
                     f"replacements: the run continues on the other {left}")
            return
        self.restarts[index] += 1
        self.say(f"ray collector {index} lost ({type(err).__name__}: {reason}): its batch in flight is dropped; "
                 f"starting a replacement ({self.restarts[index]} of at most {self.max_restarts})")
        self.workers[index] = self.make_worker(index, self.restarts[index])
        self._request(index, ray.put(self.weights()))

    def map_fn(self, name: str) -> list:
        """Call the method ``name`` of every live collector actor; their results, in slot order."""
        import ray

        return ray.get([getattr(w, name).remote() for w in self.workers if w is not None])

    def shutdown(self) -> None:
        """Kill the collector actors; stop the Ray this collection started (or leave the cluster it joined)."""
        import ray

        if not ray.is_initialized():
            return
        for worker in self.workers:
            if worker is not None:
                ray.kill(worker, no_restart=True)
        self.workers = [None] * len(self.workers)
        self.pending.clear()
        if self.started_ray:
            ray.shutdown()
