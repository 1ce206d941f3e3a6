"""A training run resolved once: the robot, its nominal rover, the task fitted to it and the randomizations, from a
:class:`~atrv_warp.rl.config.TrainConfig`'s names (:func:`resolve_run`).

The trainer's process resolves its run once and passes the :class:`RunSpec` down (the learner's networks, the
checkpoint's records, the envs it builds itself); processes of its own (collectors, a background validation) get
the config's names, which are picklable, and resolve them once each.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import tomllib
import typing
from dataclasses import dataclass
from pathlib import Path

__all__ = ["TASK_MODULE_RECORD", "RunSpec", "check_resumed_task_module", "resolve_run", "task_field_values",
           "task_module_record", "toml_value"]


@dataclass(frozen=True)
class RunSpec:
    """What a run's names resolve to."""

    robot: object
    """The robot (:class:`~atrv_warp.core.robot.Robot`), from ``env.robot``."""
    rover: object
    """Its nominal rover (:class:`~atrv_warp.sim.config.RoverConfig`): what an env of the run simulates."""
    task: object
    """The task (:class:`~atrv_warp.task.definition.Task`): ``env.task`` (from ``env.task_module`` where set) fitted
    to the robot, ``env.task_fields`` applied."""
    randomization: object
    """The training envs' randomization in absolute ranges
    (:class:`~atrv_warp.task.randomization.RandomizationConfig`; ``around`` resolved against ``env.sim_config``)."""
    eval_randomization: object
    """The evaluations' (``env.eval_randomization``; the training's where that is empty)."""
    maps: tuple = ()
    """The sites (:class:`~atrv_warp.world.OccupancyMap`), from ``env.map``, each read once."""
    map_entries: tuple = ()
    """``env.map`` as the config gives it: map files and procedural entries (``building:32``)."""

    def record(self) -> dict:
        """The task and the robot as a saved policy and a checkpoint keep them (:func:`atrv_warp.policy.run_record`):
        what an export or an evaluation reads, not today's code; and the sites it trained in
        (:meth:`sites_record`), where it has maps."""
        from atrv_warp.policy import run_record

        return run_record(self.task, self.robot, self.sites_record())

    def sites_record(self) -> dict | None:
        """The maps the run trains in: ``env.map``'s entries, the generator of its procedural places (drawn for the
        robot's width, the robot record's) and each map (:meth:`~atrv_warp.world.OccupancyMap.record`); ``None``
        without maps."""
        if not self.maps:
            return None
        return {"entries": [str(e) for e in self.map_entries], "generator": "atrv_warp.world.places",
                "maps": [m.record() for m in self.maps]}

    def env_kwargs(self, cfg, *, judged: bool = False) -> dict:
        """:class:`~atrv_warp.task.env.RoverEnv` keyword arguments of an env of the run built in this process:
        ``cfg.env``'s (:meth:`~atrv_warp.rl.config.EnvConfig.env_kwargs`) with this spec's task, rover and
        randomization (``judged``: the evaluations') in place of the names they resolve."""
        named = {"robot", "task", "task_module", "randomization", "maps", *(name for name, _ in cfg.env.task_fields)}
        kept = {k: v for k, v in cfg.env.env_kwargs() if k not in named}
        return {**kept, "task": self.task, "rover": self.rover, "maps": self.maps,
                "randomization": self.eval_randomization if judged else self.randomization}


def resolve_run(cfg) -> RunSpec:
    """The run ``cfg`` (a :class:`~atrv_warp.rl.config.TrainConfig`) names, resolved: the robot file and its URDF read,
    the task module loaded, the task fitted and its fields checked, the randomizations resolved. A process resolves
    each env config once (the answer is kept for the next call with the same ``cfg.env``, while the files it read
    are unchanged: the robot file and its URDF, the sim config, the task module).

    Raises:
        ValueError: One line, ``train config: ...``: an unknown task or field, a bad value, a randomization that does
            not resolve (its key named), a sim config file that does not read.
        FileNotFoundError: A missing ``task_module`` (as a ValueError, named).
    """
    return _resolve(cfg.env, _files_read(cfg.env))


def _files_read(env) -> tuple:
    """Each file a resolution of ``env`` reads, with its modification time (``None``: not there, or not found yet; the
    resolution names what is wrong): a file changed since the last call is read again."""
    from atrv_warp.core.robot import load_robot

    paths = [Path(p) for p in (env.sim_config, env.task_module, *env.map) if p]  # a procedural entry: not a file
    try:
        robot = load_robot(env.robot)
        paths += [Path(robot.path), Path(robot.urdf)]
    except ValueError:  # an unknown robot or a bad file (RobotFileError): the resolution raises it, named
        pass
    return tuple((str(p), p.stat().st_mtime_ns if p.is_file() else None) for p in paths)


@functools.lru_cache(maxsize=8)
def _resolve(env, _files: tuple) -> RunSpec:
    from atrv_warp.sim.config import nominal_rover_config
    from atrv_warp.sim.config_file import load_sim_config
    from atrv_warp.sim.urdf import footprint_radii, load_rover
    from atrv_warp.task.randomization import get_randomization
    from atrv_warp.task.registry import load_task_module, resolve_task
    from atrv_warp.task.scaling import fit_task
    from atrv_warp.world import resolve_sites

    try:  # loads task_module, names the known tasks if this one is not, checks every task field
        if env.task_module:
            load_task_module(env.task_module)
        rover = nominal_rover_config(env.robot)
        task = fit_task(resolve_task(env.task), rover).with_config(**task_field_values(env))
    except (ValueError, FileNotFoundError) as err:
        raise ValueError(f"train config: {' '.join(str(err).split())}") from None
    if env.sim_config:
        load_sim_config(env.sim_config)  # names the file and the key that is wrong

    def randomization(key: str):
        try:
            return get_randomization(getattr(env, key), sim_config=env.sim_config or None, rover=rover)
        except ValueError as err:
            raise ValueError(f"train config: {key}: {err}") from None

    shift = randomization("randomization")
    judged = randomization("eval_randomization") if env.eval_randomization else shift
    try:  # the robot's width sizes the procedural places
        maps = tuple(resolve_sites(env.map, 2 * footprint_radii(load_rover(rover), rover)[0])) if env.map else ()
    except ValueError as err:  # MapError: the file and the problem named
        raise ValueError(f"train config: env.map: {err}") from None
    return RunSpec(robot=rover.robot_spec, rover=rover, task=task, randomization=shift, eval_randomization=judged,
                   maps=maps, map_entries=tuple(env.map))


TASK_MODULE_RECORD = "task_module.json"
"""The run folder's record of the task module a run used: its ``path`` and its ``sha256``."""


def task_module_record(path: str | Path) -> dict[str, str]:
    """What a run folder records of its task module ``path`` (:data:`TASK_MODULE_RECORD`)."""
    from atrv_warp.storage import file_sha256

    return {"path": str(Path(path).resolve()), "sha256": file_sha256(path)}


def check_resumed_task_module(run_dir: Path, used: str, given: str) -> None:
    """A resume names the task module itself: a run folder never makes a command import code. ``used``: the module
    the run's ``config.toml`` names (not imported); ``given``: ``env.task_module`` on the command line.

    Raises:
        ValueError: One line: no module given for a run that used one, a missing file, or a file whose sha256 is not
            the one the run recorded (both named).
    """
    from atrv_warp.storage import file_sha256

    if not given:
        raise ValueError(f"--resume {run_dir}: the run used the task module {used}; a run folder runs no code, so name "
                         f"it on the command line: env.task_module={used}")
    if not Path(given).is_file():
        raise ValueError(f"--resume {run_dir}: task module not found: {given}")
    try:
        recorded = json.loads((run_dir / TASK_MODULE_RECORD).read_text())["sha256"]
    except (OSError, ValueError, KeyError, TypeError):
        return  # a run folder from before the record: the module named on the command line is taken as it is
    now = file_sha256(given)
    if now != recorded:
        raise ValueError(f"--resume {run_dir}: the task module {given} is not the one the run trained with (sha256 "
                         f"{now[:12]}…, the run recorded {recorded[:12]}… for {used}): resume with that file, or "
                         "train a new run")


def task_field_values(env) -> dict[str, object]:
    """``env.task_fields`` as the task config's values, each of its field's type (a whole number for a float field
    is a float; a list for a pair is a tuple).

    Raises:
        ValueError: A field the task's config does not have (the known ones named), or a value of another type.
    """
    from atrv_warp.task.registry import load_task_module, resolve_task

    if not env.task_fields:
        return {}
    if env.task_module:
        load_task_module(env.task_module)
    config = resolve_task(env.task).config
    hints, fields = typing.get_type_hints(type(config)), {f.name for f in dataclasses.fields(config)}
    out = {}
    for name, text in env.task_fields:
        if name not in fields:
            raise ValueError(f"env.task.{name}: task {env.task!r} ({type(config).__name__}) has no field {name!r}; "
                             f"its fields: {sorted(fields)}")
        value, kind = toml_value(text), hints[name]
        optional = type(None) in typing.get_args(kind)
        base = next((k for k in typing.get_args(kind) if k is not type(None)), kind) if optional else kind
        origin = typing.get_origin(base) or base
        if origin is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        elif origin is tuple and isinstance(value, list):
            value = tuple(float(v) if isinstance(v, int) and not isinstance(v, bool) else v for v in value)
        ok = isinstance(value, origin) and not (origin in (int, float) and isinstance(value, bool))
        if not ok:
            raise ValueError(f"env.task.{name} must be {getattr(origin, '__name__', origin)}, got {text!r}")
        out[name] = value
    return out


def toml_value(text: str):
    """A value written as TOML (``0.5``, ``[5.0, 8.0]``, ``"rolling"``, ``true``), or the text itself where it is no
    TOML value (a bare word on the command line: ``rolling``)."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text
