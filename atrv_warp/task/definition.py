"""What a task is: :class:`Task` (a config, a table of :class:`RewardTerm`, a success test, an observation kind) and
its reward terms. A task is declared in one module (``atrv_warp/task/tasks/nav.py``; your own file, registered with
:func:`atrv_warp.task.registry.register_task`); the environment builds its kernels from the declaration.

A reward term is a row: a name, a ``@wp.func`` of ``(params, inputs, world) -> float`` (the task config's values,
:class:`~atrv_warp.task.kernels.state.TermInputs`, the world), its weight (a config field's name, so that it is
set like any other field: ``env.task.heading_weight=2``), when it counts (``running``, ``success`` or ``failure``),
what it reads, and its torch twin (the same value from a rollout's tensors: :mod:`atrv_warp.task.twins`). The
logged per-term rewards, the TensorDict's ``reward_terms`` and the docs' list come from the table.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

__all__ = ["PHASES", "READS", "RewardTerm", "Task"]

PHASES = {"running": 0, "success": 1, "failure": 2}
"""When a reward term counts (its ``when``), and the number the step kernels give that phase: on a step that did not
end the episode (a truncated one included), on the step that reached the goal, or on one that failed (a wall, the
chassis, an obstacle, a flip)."""

READS = ("state", "action", "previous action", "scan", "obstacles", "wheels", "events", "path")
"""What a term may read: the chassis' state and the target, this step's action, the one before, the scan, the
obstacles, the wheels' torques and speeds, the step's end, the plan and where the robot is on it (documentation, and
checked: a term that reads the scan needs a task with a scanner)."""


@dataclass(frozen=True)
class RewardTerm:
    """One row of a task's reward table."""

    name: str
    """The term's name: its column of ``reward_terms`` and its logged scalar (``train_reward_<name>``)."""
    warp: object
    """Its value before the weight: a ``@wp.func`` ``(params: Any, inputs: TermInputs, world: int) -> float``."""
    weight: str
    """The task config's field that weights it (a weight of 0 skips the term: it is not computed, its column 0)."""
    when: str = "running"
    """``running``: on every step that did not end the episode (a truncated one included); ``success``: on the
    step that reached the goal; ``failure``: on one that failed (a wall, the chassis, an obstacle, a flip)."""
    reads: tuple[str, ...] = ("state",)
    """What it reads, of :data:`READS`."""
    torch: Callable | None = None
    """Its torch twin, ``(rollout: TorchRollout) -> (steps, N)`` (:mod:`atrv_warp.task.twins`): the same value from
    a rollout's poses, actions and what else it reads; ``tests/test_task_terms.py`` holds every shipped term's twin to
    the environment's."""
    description: str = ""

    def __post_init__(self):
        if self.when not in PHASES:
            raise ValueError(f"reward term {self.name!r}: when={self.when!r}; known: {sorted(PHASES)}")
        unknown = sorted(set(self.reads) - set(READS))
        if unknown:
            raise ValueError(f"reward term {self.name!r} reads {unknown}; known: {list(READS)}")
        if not isinstance(self.weight, str):
            raise TypeError(f"reward term {self.name!r}: weight names a task config field (a string), got "
                            f"{self.weight!r}")

    def weight_of(self, config) -> float:
        """This term's weight in the task config ``config``.

        Raises:
            ValueError: The config has no such field, or it is not a number.
        """
        value = getattr(config, self.weight, None)
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"reward term {self.name!r} is weighted by {type(config).__name__}.{self.weight}, "  # noqa: TRY004
                             f"which is {'missing' if value is None else f'not a number ({value!r})'}")
        return float(value)


@dataclass(frozen=True)
class Task:
    """A task in one place: its config (the scene, the limits, the weights), its reward table, its success test and
    its observation (the config's ``observation`` kind: ``arena``, ``robot``, or one a task module registers with
    :func:`atrv_warp.task.spec.register_observation`)."""

    name: str
    config: object
    """A :class:`~atrv_warp.task.config.TaskConfig` (or a dataclass deriving from it, with the task's own fields)."""
    terms: tuple[RewardTerm, ...]
    """The reward table, in column order."""
    success: object
    """The success test: a ``@wp.func`` ``(params: Any, inputs: TermInputs, world: int) -> bool`` (the shipped tasks':
    :func:`atrv_warp.task.kernels.terms.within_reach`)."""
    description: str = ""
    source: str = ""
    """Where it was declared (a module's file)."""
    scale: Callable | None = None
    """How the task follows the robot it runs on: ``(config, robot, footprint) -> config`` (a
    :class:`~atrv_warp.core.robot.Robot`, its footprint radius [m]); ``None``: the shipped rule,
    :func:`atrv_warp.task.scaling.scale_to_robot` (the robot's limits and torque, a control period for its speed, radii
    for its footprint). A task that must not change with the robot passes ``lambda config, robot, footprint:
    config``."""
    robot: str | None = None
    """The robot the config was fitted to (:meth:`for_robot`), or ``None``: as declared."""

    def __post_init__(self):
        names = [t.name for t in self.terms]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise ValueError(f"task {self.name!r}: reward term(s) {twice} declared twice")
        for term in self.terms:
            term.weight_of(self.config)  # each weight names a number of the config
        if "scan" in {r for t in self.terms for r in t.reads} and not getattr(self.config, "scan_beams", 0):
            raise ValueError(f"task {self.name!r}: a reward term reads the scan, but the task has no scanner "
                             "(scan_beams=0)")

    def record(self) -> dict:
        """The task as plain values (JSON-ready): its name, description and source, every config field, and its
        reward table (each term's name, weight field and value, when it counts, what it reads) and success test."""
        config = {f.name: getattr(self.config, f.name) for f in dataclasses.fields(self.config)}
        return {"name": self.name, "description": self.description, "source": self.source, "robot": self.robot,
                "config_class": f"{type(self.config).__module__}.{type(self.config).__qualname__}", "config": config,
                "terms": [{"name": t.name, "weight_field": t.weight, "weight": t.weight_of(self.config),
                           "when": t.when, "reads": list(t.reads), "function": getattr(t.warp, "key", str(t.warp))}
                          for t in self.terms],
                "success": getattr(self.success, "key", str(self.success))}

    @property
    def term_names(self) -> tuple[str, ...]:
        """The reward terms' names, in column order."""
        return tuple(t.name for t in self.terms)

    def for_robot(self, robot, footprint: float) -> Task:
        """This task fitted to ``robot`` (a :class:`~atrv_warp.core.robot.Robot`, whose footprint radius is
        ``footprint`` [m]) by :attr:`scale`; a task fitted already is returned as it is."""
        if self.robot is not None:
            return self
        from atrv_warp.task.scaling import scale_to_robot

        config = (self.scale or scale_to_robot)(self.config, robot, footprint)
        return dataclasses.replace(self, config=config, robot=robot.name)

    def with_config(self, **changes) -> Task:
        """This task with config fields changed (checked by name: an unknown one is a ``ValueError`` naming the known
        ones)."""
        from atrv_warp.sim.config import replace_checked

        return dataclasses.replace(self, config=replace_checked(self.config, **changes)) if changes else self
