"""Sensors as units: what a rover carries besides its chassis' own state, each one object the environment drives.

A sensor reads every world's rover after a reset (the reset worlds) and after a step (all of them), writes its
columns of the observation (after the task's leading fields, before the last actions), reports its full reading as
a step entry under its name, and keeps its noise stream's position in the environment's snapshot. The environment
(:class:`~atrv_warp.task.env.RoverEnv`) holds a tuple of them and knows no sensor by name.

Where they come from: the robot's ``links.laser`` is the laser ``scan`` (the task's ``scan_*`` fields set its beams
and observed sectors; a task without ``scan_beams`` has none), and its file's ``[[sensors]]`` list adds more, each
of a kind registered here (``laser``, or one of yours: :func:`register_sensor`)::

    [[sensors]]
    kind = "laser"
    name = "rear_scan"      # the step's ``rear_scan`` entry; observed as rear_scan_0 … rear_scan_{S-1}
    frame = "rear_laser"    # a frame of the URDF, fixed to the chassis

A second laser takes the task's geometry (``scan_beams``, ``scan_fov``, ``scan_sectors``, ``scan_clip``) and the
randomization's scan noise, with a noise stream of its own. :func:`sensor_fields` gives a robot's observed fields
for a task without building anything, so a trainer sizes its network and a loaded policy is checked against it.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import ClassVar, Protocol

import torch
import warp as wp
from torchrl.data import Bounded, TensorSpec

from atrv_warp.core.robot import SENSOR_KEYS
from atrv_warp.task.kernels.observe import ScanReading, write_scan_observation
from atrv_warp.task.spec import ObservationField, laser_fields, scan_sectors

__all__ = ["SENSOR_KINDS", "LaserSensor", "Sensor", "build_sensors", "register_sensor", "robot_sensors",
           "sensor_fields"]

RESERVED = frozenset({"observation", "reward", "done", "terminated", "truncated", "end_reason", "distance",
                      "reward_terms", "action", "next", "_reset"})
"""Step entries of the environment's own, which no sensor may be called."""


class Sensor(Protocol):
    """What the environment asks of a sensor. Built once per environment by its kind
    (``kind(sim, task, declaration, noise, index)``: ``declaration`` is its ``[[sensors]]`` table, ``index`` its place
    among the rover's sensors)."""

    kind: ClassVar[str]
    name: str
    """Its step entry and the prefix of its observed fields."""
    fields: tuple[ObservationField, ...]
    """Its columns of the observation, in order (:meth:`fields_of`)."""

    @classmethod
    def active(cls, task) -> bool:
        """Whether ``task`` (a :class:`~atrv_warp.task.config.TaskConfig`) uses sensors of this kind at all."""

    @classmethod
    def fields_of(cls, task, declaration: Mapping) -> tuple[ObservationField, ...]:
        """The observed fields of the sensor ``declaration`` describes, under ``task``, without building it."""

    def spec(self, n: int, device: torch.device) -> TensorSpec | None:
        """The spec of its step entry (None: it reports none)."""

    def read(self, mask: wp.array | None = None) -> None:
        """Take a reading of the worlds ``mask`` sets (None: all), from the simulator's current state."""

    def observe(self, obs: wp.array, column: int, nonfinite: wp.array) -> None:
        """Write its fields into ``obs`` (N, D) from ``column`` on (a non-finite world's neutral values)."""

    def reading(self) -> torch.Tensor | None:
        """Its step entry (N, ...): a view the environment clones."""

    def reseed(self, seed: int) -> None:
        """Restart its noise stream for the environment's ``seed``."""

    def state(self) -> dict[str, torch.Tensor]:
        """What a snapshot keeps of it (its noise stream's position), by key."""

    def load_state(self, state: Mapping[str, torch.Tensor]) -> None:
        """Restore :meth:`state` (the environment has reseeded it first)."""


class LaserSensor:
    """A 2-D laser scanner (:class:`~atrv_warp.sim.scanner.LaserScanner`) at its declaration's frame, with the
    task's beams, field of view, sectors and clip and the randomization's range noise and dropout."""

    kind: ClassVar[str] = "laser"

    def __init__(self, sim, task, declaration: Mapping, noise, index: int):
        from atrv_warp.sim.scanner import LaserScanner, ScannerConfig

        unknown = sorted(set(declaration) - set(SENSOR_KEYS))
        if unknown:
            raise ValueError(f"laser {declaration['name']!r}: unknown key(s) {unknown}; a laser takes "
                             f"{', '.join(SENSOR_KEYS)} (its geometry is the task's scan_* fields)")
        self.name, self.index = declaration["name"], index
        geometry = {"beams": task.scan_beams, "fov": task.scan_fov, "frame": declaration["frame"]}
        cfg = ScannerConfig(**geometry) if noise is None else ScannerConfig(
            **geometry, noise_std=noise.scan_range, dropout=noise.scan_dropout)
        self.scanner = LaserScanner(sim, cfg)
        """The simulated scanner (its ``ranges`` are the step entry)."""
        self.fields = self.fields_of(task, declaration)
        self._reading = None
        sectors = scan_sectors(task)
        if sectors is not None:
            bounds = sectors.beam_bounds(torch.as_tensor(cfg.angles)).to(torch.int32)
            reading = ScanReading()
            reading.first = wp.array(bounds[:, 0].numpy(), dtype=wp.int32, device=sim.device)
            reading.end = wp.array(bounds[:, 1].numpy(), dtype=wp.int32, device=sim.device)
            reading.clip, reading.range_min, reading.range_max = task.scan_clip, cfg.min_range, cfg.max_range
            self._reading = reading

    @classmethod
    def active(cls, task) -> bool:
        return bool(getattr(task, "scan_beams", 0))

    @classmethod
    def fields_of(cls, task, declaration: Mapping) -> tuple[ObservationField, ...]:
        if declaration["name"] == "scan":  # the robot's links.laser: the fields every scan policy observes
            return laser_fields(task)
        return laser_fields(task, declaration["name"], f"scanner ({declaration['frame']})")

    def spec(self, n: int, device: torch.device) -> TensorSpec:
        c = self.scanner.cfg
        return Bounded(c.min_range, c.max_range, shape=(n, c.beams), dtype=torch.float32, device=device)

    def read(self, mask: wp.array | None = None) -> None:
        self.scanner.scan(mask)

    def observe(self, obs: wp.array, column: int, nonfinite: wp.array) -> None:
        if self._reading is not None:
            wp.launch(write_scan_observation, dim=(obs.shape[0], len(self.fields)),
                      inputs=[self.scanner.buffer, nonfinite, column, self._reading], outputs=[obs],
                      device=obs.device)

    def reading(self) -> torch.Tensor:
        return self.scanner.ranges

    def reseed(self, seed: int) -> None:
        # the first laser's stream is the environment's seed; another's is offset from it (independent noise)
        self.scanner.reseed(seed + self.index * 0x9E3779B1)

    def state(self) -> dict[str, torch.Tensor]:
        return {f"{self.name}_count": torch.tensor(self.scanner.count)}

    def load_state(self, state: Mapping[str, torch.Tensor]) -> None:
        self.scanner.count = int(state[f"{self.name}_count"])


SENSOR_KINDS: dict[str, type] = {"laser": LaserSensor}
"""The sensor kinds a robot file's ``[[sensors]]`` may name, by ``kind``."""


def register_sensor(kind: type) -> type:
    """Register a sensor kind (a class with the :class:`Sensor` protocol, named by its ``kind``); usable as a class
    decorator. A robot file's ``[[sensors]]`` entry of that kind then builds it in every environment of that robot.

    Raises:
        ValueError: A kind without a name, or one already registered by another class.
    """
    name = getattr(kind, "kind", None)
    if not (isinstance(name, str) and name):
        raise ValueError(f"a sensor kind needs a class attribute kind (its name), got {name!r}")
    if SENSOR_KINDS.get(name, kind) is not kind:
        raise ValueError(f"sensor kind {name!r} is already registered ({SENSOR_KINDS[name].__qualname__})")
    SENSOR_KINDS[name] = kind
    return kind


def robot_sensors(robot) -> tuple[dict, ...]:
    """The sensors ``robot`` (a :class:`~atrv_warp.core.robot.Robot`) carries, in order: its ``links.laser``'s laser
    ``scan``, then its file's ``[[sensors]]``."""
    return ({"kind": "laser", "name": "scan", "frame": robot.laser_frame}, *robot.sensors)


def _kinds(task, robot) -> list[tuple[type, dict]]:
    """(kind, declaration) of each of ``robot``'s sensors that ``task`` uses (an unknown kind or name named)."""
    used = []
    for decl in robot_sensors(robot):
        kind = SENSOR_KINDS.get(decl["kind"])
        if kind is None:
            raise ValueError(f"{robot.path}: [[sensors]] {decl['name']}: unknown kind {decl['kind']!r}; known: "
                             f"{', '.join(sorted(SENSOR_KINDS))} (atrv_warp.task.sensors.register_sensor adds one)")
        if decl["name"] in RESERVED:
            raise ValueError(f"{robot.path}: [[sensors]] {decl['name']}: the environment's own step entry; rename it")
        if kind.active(task):
            used.append((kind, decl))
    return used


def sensor_fields(task, robot) -> tuple[ObservationField, ...]:
    """Every observed field of ``robot``'s sensors under ``task`` (a :class:`~atrv_warp.task.config.TaskConfig`), in
    order: what :func:`~atrv_warp.task.spec.observation_fields` takes as ``sensors``."""
    return tuple(f for kind, decl in _kinds(task, robot) for f in kind.fields_of(task, decl))


def build_sensors(sim, task, robot, noise) -> tuple:
    """The sensors of ``robot`` that ``task`` uses, built on ``sim`` (a :class:`~atrv_warp.sim.simulator.RoverSim`)
    with the randomization's ``noise`` (a :class:`~atrv_warp.sim.config.SensorNoise` or None)."""
    return tuple(kind(sim, task, decl, noise, i) for i, (kind, decl) in enumerate(_kinds(task, robot)))
