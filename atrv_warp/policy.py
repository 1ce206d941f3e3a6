"""Saved policies: the actor network, its file format, and the policies that ship.

This module sits below training and the integrations: :mod:`atrv_warp.cli.evaluate`, the ROS node
and the exporter load a policy from here without importing the trainer (:mod:`atrv_warp.rl`).

Observation normalisation lives *inside* the networks (:class:`Normalize`, statistics as
buffers): it is saved with the policy, frozen for evaluation, and a saved policy runs on raw
``RoverEnv`` observations with no transform to rebuild.

A saved policy records what it commands and observes (``action``: ``torque`` | ``twist``; ``observation``:
``arena`` | ``robot``; files from before mean ``torque`` and ``arena``), and :func:`load_policy` refuses, naming
both, a policy whose kinds are not its task's. The shipped policies are loaded by name (:data:`SHIPPED_POLICIES`):
``load_policy("nav")``.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import torch
from tensordict.nn import NormalParamExtractor, TensorDictModule, TensorDictSequential
from torch import nn
from torchrl.modules import MLP, ProbabilisticActor, TanhNormal

from atrv_warp.storage import FileFormatError, atomic_save, load_weights
from atrv_warp.task.spec import ACTION_DIM, OBS_DIM, observation_fields

__all__ = ["OLD_KINDS", "POLICY_FORMAT", "READ_FORMATS", "ROBOT_POLICY_ARGUMENTS", "SHIPPED_POLICIES", "Normalize",
           "PolicyRecord", "PolicyRobotMismatch", "PolicyTaskMismatch", "ShippedPolicy", "check_policy_robot",
           "check_policy_task", "exported_policy_record", "load_policy", "make_actor", "policy_kinds", "policy_path",
           "policy_payload", "policy_record", "policy_task", "pretrained_nav_policy_path", "pretrained_policy_path",
           "run_record", "save_policy", "shipped_policy_for", "shipped_policy_path"]

POLICY_FORMAT = "atrv_warp.policy/2"
"""Format tag of a saved policy (``save_policy``, and the ``policy`` entry of a training checkpoint). 2: it records
the task and the robot it was trained with, every field (``task_record``, ``robot``); a policy of format 1 (before
issue 59) is read as what it was: its task as its module declared it then, on the ATRV-Jr."""
READ_FORMATS = ("atrv_warp.policy/1", POLICY_FORMAT)
"""The formats :func:`load_policy` reads."""

OLD_KINDS = ("torque", "arena")
"""(action, observation) of a saved policy that records neither: every policy saved before twist actions and robot
observations existed."""


@dataclass(frozen=True)
class ShippedPolicy:
    """A policy that ships inside the package (``atrv_warp/assets/``)."""

    file: str
    """Its file name in ``atrv_warp/assets/``."""
    task: str
    """The registered task it was trained on."""
    train: str
    """The command that trains it (its ``best_policy.pt`` is then copied to ``atrv_warp/assets/<file>``)."""


ROBOT_POLICY_ARGUMENTS: dict[str, str] = {"husky": "run.total_frames=3000000"}
"""Training arguments beyond ``--config nav_deploy env.robot=<robot>`` that a shipped robot's policy needed, by robot
(none for most): the Husky's command anneals over 3 M frames (its free-wheeled predecessor still improved at
nav_deploy's 1.4 M); the 30-minute budget of the benchmark stops it first on 2 cores."""


def _robot_policies() -> dict[str, ShippedPolicy]:
    """Each shipped robot's deployable policy, ``nav_deploy_<robot>``, from the robots folder: at its own limits, seed
    0 of ``benchmarks/training/train_to_success.py`` with the same arguments (its results file:
    ``train_to_success_nav_deploy_<robot>.json``; ``benchmarks/robots/robot_policies.py`` evaluates them)."""
    from atrv_warp.core.robot import ROBOTS

    return {f"nav_deploy_{robot}": ShippedPolicy(
        f"nav_deploy_{robot}_policy.pt", "nav_deploy",
        " ".join(("python -m atrv_warp.train --config nav_deploy", f"env.robot={robot}",
                  *filter(None, [ROBOT_POLICY_ARGUMENTS.get(robot)]))))
        for robot in ROBOTS}


def _path_policies() -> dict[str, ShippedPolicy]:
    """Each shipped robot's policy that follows Nav2's plan, ``follow_path_<robot>``: at Nav2's controller speeds (its
    own limits where lower), trained by the ``follow_path`` preset in procedural buildings and yards
    (``benchmarks/training/follow_path_policies.py`` evaluates them, and reads their training from the run folders)."""
    from atrv_warp.core.robot import ROBOTS

    return {f"follow_path_{robot}": ShippedPolicy(
        f"follow_path_{robot}_policy.pt", "follow_path",
        f"python -m atrv_warp.train --config follow_path env.robot={robot} run.name=follow_path_{robot}")
        for robot in ROBOTS}


SHIPPED_POLICIES: dict[str, ShippedPolicy] = {
    "reach": ShippedPolicy("pretrained_policy.pt", "reach", "python -m atrv_warp.train"),
    "nav": ShippedPolicy("nav_policy.pt", "nav", "python -m atrv_warp.train --config nav randomization=wide"),
    "nav_plain": ShippedPolicy("nav_policy_plain.pt", "nav", "python -m atrv_warp.train --config nav"),
    **_robot_policies(),  # a robot shipped in the robots folder ships its policy under this name
    **_path_policies(),  # and its policy as Nav2's controller
    # the two 2 m/s studies: trained before robots had files (the ATRV-Jr's body at the Jackal's speed, a 1 m/s² base)
    # and before nav_deploy.toml's batch went from 512 to 256; the deploy and MuJoCo figures of the docs cite them
    "nav_deploy": ShippedPolicy("nav_deploy_policy.pt", "nav_deploy",
                                "python -m atrv_warp.train --config nav_deploy batch_size=512"),
    "nav_deploy_plain": ShippedPolicy("nav_deploy_policy_plain.pt", "nav_deploy",
                                      "python -m atrv_warp.train --config nav_deploy randomization=none batch_size=512"),
}
"""The shipped policies by name: ``reach`` (the reference task), ``nav`` (navigation, trained under the ``wide``
domain randomization), ``nav_plain`` (navigation on the nominal rover with perfect sensors),
``nav_deploy_<robot>`` for every robot of the robots folder (its navigation policy: ``/cmd_vel`` commands at its own
limits from the robot observation, trained under ``wide``; a robot shipped without it names the command that trains
it), ``follow_path_<robot>`` for every robot of the robots folder (its policy as Nav2's controller: following the
plan in buildings and yards, :mod:`atrv_warp.task.tasks.follow_path`), ``nav_deploy`` (the 2 m/s study it grew
from: the ATRV-Jr at the Jackal's speed, the task as declared),
``nav_deploy_plain`` (the same study trained on the nominal rover, without randomization: the MuJoCo twin's
comparison)."""


class PolicyTaskMismatch(FileFormatError):
    """A saved policy commands or observes another kind than its task's (it cannot drive that task)."""


class PolicyRobotMismatch(ValueError):
    """A saved policy is asked to drive another robot than the one it was trained on."""


@dataclass(frozen=True)
class PolicyRecord:
    """What a saved policy was trained with (:func:`policy_record`)."""

    task: object
    """The task (:class:`~atrv_warp.task.definition.Task`): the registered one's reward table and success test, with
    the config the policy trained on, fitted to its robot."""
    robot: object
    """The robot (:class:`~atrv_warp.core.robot.Robot`), every field as it was."""
    recorded: bool
    """Whether the file records them (format 2), or they are what a format-1 file meant: the task as its module
    declares it, on the ATRV-Jr."""
    sites: dict | None = None
    """The maps it trained in, as its run recorded them (:meth:`~atrv_warp.rl.run.RunSpec.sites_record`: the run's
    ``env.map`` entries, the places' generator, each map's name, file and sha256); ``None``: none recorded (the
    arena, or a policy saved before policies recorded them)."""


def run_record(task, robot, sites: dict | None = None) -> dict:
    """The ``task_record`` and ``robot`` entries a saved policy keeps (``task``: a
    :class:`~atrv_warp.task.definition.Task`, fitted; ``robot``: a :class:`~atrv_warp.core.robot.Robot`), and
    ``sites``, where given: the maps it trained in (:meth:`~atrv_warp.rl.run.RunSpec.sites_record`)."""
    from atrv_warp.core.robot import robot_record

    return {"task_record": task.record(), "robot": robot_record(robot)} | ({"sites": sites} if sites else {})


class Normalize(nn.Module):
    """``(x - loc) / scale`` with frozen statistics stored as buffers."""

    def __init__(self, dim: int = OBS_DIM):
        super().__init__()
        self.register_buffer("loc", torch.zeros(dim))
        self.register_buffer("scale", torch.ones(dim))

    def set_stats(self, loc: torch.Tensor, scale: torch.Tensor) -> None:
        self.loc.copy_(loc)
        self.scale.copy_(scale.clamp(min=1e-3))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return (x - self.loc) / self.scale


def make_actor(width: int = 128, depth: int = 2, normalize: Normalize | None = None, *,
               obs_dim: int = OBS_DIM, return_log_prob: bool = False) -> ProbabilisticActor:
    """Tanh-Gaussian actor ``observation`` (``obs_dim``: the task's) ``-> action`` in [-1, 1]².

    ``return_log_prob``: also write the sampled action's log-probability (``action_log_prob``), as
    PPO's collection needs; the weights, and so the saved policy, are the same.
    """
    net = nn.Sequential(
        normalize if normalize is not None else Normalize(obs_dim),
        MLP(in_features=obs_dim, out_features=2 * ACTION_DIM, num_cells=[width] * depth, activation_class=nn.ReLU),
        NormalParamExtractor(),
    )
    module = TensorDictModule(net, in_keys=["observation"], out_keys=["loc", "scale"])
    return ProbabilisticActor(module, in_keys=["loc", "scale"], out_keys=["action"], distribution_class=TanhNormal,
                              distribution_kwargs={"low": -1.0, "high": 1.0}, return_log_prob=return_log_prob)


def save_policy(actor: ProbabilisticActor, path: str | Path, *, width: int, depth: int, meta: dict | None = None,
                task=None):
    """Write the actor's weights (normalisation included) atomically, loadable with weights_only.
    ``meta["task"]`` names the task the policy observes (``reach`` if absent); ``task`` (a name or
    :class:`~atrv_warp.task.config.TaskConfig`, default ``meta["task"]``): whose action and observation kinds
    the file records."""
    atomic_save(policy_payload(actor, width=width, depth=depth, meta=meta, task=task), path)


def policy_payload(actor: ProbabilisticActor, *, width: int, depth: int, meta: dict | None = None,
                   task=None, record: dict | None = None) -> dict:
    """The saved form of a policy (``POLICY_FORMAT``), as :func:`load_policy` reads it: weights, sizes, ``meta``,
    the ``action`` and ``observation`` kinds of ``task`` (default: ``meta["task"]``, ``reach`` if absent), and
    ``record`` (:func:`run_record`: the task and robot it trained with; default: ``task`` as declared, on the
    ATRV-Jr)."""
    from atrv_warp.core.robot import DEFAULT_ROBOT, load_robot
    from atrv_warp.task.definition import Task
    from atrv_warp.task.registry import resolve_task

    meta = meta or {}
    resolved = task if isinstance(task, Task) else resolve_task(task if task is not None else meta.get("task", "reach"))
    config = resolved.config
    if record is None:
        record = run_record(resolved, load_robot(DEFAULT_ROBOT))
    sd = {k: v.detach().cpu().clone() for k, v in actor.state_dict().items()}  # a copy: the actor trains on
    obs_dim = next(v.numel() for k, v in sd.items() if k.endswith("loc") and v.ndim == 1)
    return {"format": POLICY_FORMAT, "width": width, "depth": depth, "obs_dim": obs_dim, "state_dict": sd,
            "meta": meta, "action": config.action, "observation": config.observation, **record}


def _read(path: Path) -> dict:
    payload = load_weights(path, "policy file")
    return payload["policy"] if isinstance(payload.get("policy"), dict) else payload  # a training checkpoint's


def policy_task(path: str | Path) -> str:
    """The task a saved policy (a file or a shipped name) was trained on (``meta["task"]``; ``reach`` for older
    files)."""
    return str(_read(policy_path(path)).get("meta", {}).get("task", "reach"))


def policy_record(path_or_payload, *, where: str = "the policy") -> PolicyRecord:
    """The task and robot a saved policy (a file, a shipped name, or a loaded payload: ``where`` names it in errors)
    was trained with: as it records them (format 2), or for a format-1 file what it meant (its task as the module
    declares it, on the ATRV-Jr).

    Raises:
        FileFormatError: a record that does not read back (named), or a task no longer registered.
    """
    from atrv_warp.core.robot import DEFAULT_ROBOT, RobotFileError, load_robot, robot_from_record
    from atrv_warp.task.registry import resolve_task

    if isinstance(path_or_payload, dict):
        payload = path_or_payload
    else:
        where = str(policy_path(path_or_payload))
        payload = _read(Path(where))
    name = str(payload.get("meta", {}).get("task", "reach"))
    registered = resolve_task(name)
    if "task_record" not in payload:
        import dataclasses

        return PolicyRecord(dataclasses.replace(registered, robot=DEFAULT_ROBOT), load_robot(DEFAULT_ROBOT), False)
    try:
        robot = robot_from_record(payload["robot"], f"{where} (its robot record)")
        fields = payload["task_record"]["config"]
        config_class = type(registered.config)
        config = config_class(**{k: tuple(tuple(x) if isinstance(x, list) else x for x in v) if isinstance(v, list)
                                 else v for k, v in fields.items()})
    except (RobotFileError, KeyError, TypeError, ValueError) as err:
        raise FileFormatError(f"{where}: its task or robot record does not read back ({err})") from None
    import dataclasses

    task = dataclasses.replace(registered, config=config, robot=payload["task_record"].get("robot") or robot.name)
    return PolicyRecord(task, robot, True, payload.get("sites"))


def exported_policy_record(path: str | Path, contract: dict) -> PolicyRecord:
    """The task and robot an exported policy (``path``, its ``contract``) was trained with: its ``trained_with``
    entry, read as :func:`policy_record` reads a policy file's.

    Raises:
        FileFormatError: a file exported before the contract kept them (naming the policy file it came from and the
            command that exports it again), or a record that does not read back.
    """
    entry = contract.get("trained_with")
    if not isinstance(entry, dict):
        raise FileFormatError(f"{path}: exported before exported policies kept the task and robot they were trained "
                              f"with: evaluate the policy file it came from ({contract.get('source')}), or export it "
                              "again (python -m atrv_warp.export POLICY OUT.pt2)")
    try:
        return policy_record(entry, where=str(path))
    except ValueError as err:  # an unknown task
        raise FileFormatError(f"{path}: {err}") from None


def check_policy_robot(record: PolicyRecord, robot, *, source, allow: bool = False,
                       allow_with: str = "--allow-other-robot") -> str | None:
    """Refuse a policy trained on another robot than ``robot`` (a :class:`~atrv_warp.core.robot.Robot`), naming both
    and how to allow it (``allow_with``: the command's flag, or a node's parameter); with ``allow``, return the line to
    warn with instead. ``None`` where they are the same.

    Raises:
        PolicyRobotMismatch: e.g. ``policy nav_deploy_husky was trained on husky (Clearpath Husky A200) but this is
            jackal (Clearpath Jackal J100)``.
    """
    if record.robot == robot:
        return None
    line = (f"policy {source} was trained on {record.robot.name} ({record.robot.title}) but this is {robot.name} "
            f"({robot.title})")
    if allow:
        return line
    raise PolicyRobotMismatch(f"{line}: evaluate or deploy it on its own robot, or allow another on purpose "
                              f"({allow_with})")


def policy_kinds(path: str | Path) -> tuple[str, str]:
    """(action, observation) kinds a saved policy (a file or a shipped name) commands and observes
    (:data:`OLD_KINDS` for files from before they were recorded)."""
    return _kinds(_read(policy_path(path)))


def _kinds(payload: dict) -> tuple[str, str]:
    return str(payload.get("action", OLD_KINDS[0])), str(payload.get("observation", OLD_KINDS[1]))


def check_policy_task(payload: dict, task, *, source: str | Path) -> None:
    """Refuse a saved policy (``payload``, as :func:`policy_payload` writes it or a checkpoint's ``policy``
    entry) that commands or observes another kind than ``task`` (a name, a
    :class:`~atrv_warp.task.definition.Task` or a :class:`~atrv_warp.task.config.TaskConfig`), in one line naming
    both.

    Raises:
        PolicyTaskMismatch: e.g. ``policy nav_deploy_policy.pt commands twist but task 'nav' takes torque``.
    """
    from atrv_warp.task.definition import Task
    from atrv_warp.task.registry import get_task

    config = task.config if isinstance(task, Task) else get_task(task)
    action, observation = _kinds(payload)
    name = f"task {task.name!r}" if isinstance(task, Task) else f"task {task!r}" if isinstance(task, str) else "the task"
    if action != config.action:
        raise PolicyTaskMismatch(f"policy {source} commands {action} but {name} takes {config.action}")
    if observation != config.observation:
        raise PolicyTaskMismatch(f"policy {source} observes the {observation} observation but {name} gives the "
                                 f"{config.observation} one")


def shipped_policy_for(task: str, robot: str | None = None) -> str:
    """The name of the shipped policy that drives ``task`` on ``robot`` (a shipped robot's name): the robot's own
    (``nav_deploy_husky``) where one ships, else the task's, else the default robot's (``follow_path_atrvjr``),
    else ``reach``'s."""
    from atrv_warp.core.robot import DEFAULT_ROBOT

    for name in (f"{task}_{robot}" if robot else None, task, f"{task}_{DEFAULT_ROBOT}"):
        if name in SHIPPED_POLICIES and SHIPPED_POLICIES[name].task == task:
            return name
    return "reach"


def shipped_policy_path(name: str) -> Path:
    """The file of the shipped policy called ``name`` (:data:`SHIPPED_POLICIES`).

    Raises:
        ValueError: No shipped policy has that name (the known ones are listed).
        FileNotFoundError: It is registered but not trained yet; the message names the command that trains it.
    """
    try:
        shipped = SHIPPED_POLICIES[name]
    except KeyError:
        raise ValueError(f"no shipped policy is called {name!r}; known: {sorted(SHIPPED_POLICIES)}") from None
    path = Path(str(resources.files("atrv_warp").joinpath(f"assets/{shipped.file}")))
    if not path.is_file():
        raise FileNotFoundError(f"the shipped policy {name!r} ({path}) is not trained yet: train it with "
                                f"`{shipped.train}` and copy the run's best_policy.pt to atrv_warp/assets/{shipped.file}")
    return path


def policy_path(path: str | Path | None) -> Path:
    """The file of ``path``: a shipped policy's name (a ``str`` key of :data:`SHIPPED_POLICIES`; ``None``:
    ``reach``; see :func:`shipped_policy_path`), or a file's path as given."""
    if path is None or (isinstance(path, str) and path in SHIPPED_POLICIES):
        return shipped_policy_path(path or "reach")
    return Path(path)


def pretrained_nav_policy_path(randomized: bool = True) -> Path:
    """The navigation policy shipped inside the package, trained by ``python -m atrv_warp.train --config nav``
    under the ``wide`` domain randomization (the default); ``randomized=False``: the earlier one, trained on the
    nominal rover with perfect sensors (``nav_policy_plain.pt``)."""
    return shipped_policy_path("nav" if randomized else "nav_plain")


def pretrained_policy_path() -> Path:
    """The policy shipped inside the package (trained by ``python -m atrv_warp.train``)."""
    return shipped_policy_path("reach")


def load_policy(path: str | Path | None = None, *, deterministic: bool = True, task=None,
                device: str | torch.device = "cpu") -> TensorDictSequential:
    """Load a saved policy as a TorchRL policy module: ``path`` is a file, or the name of a shipped policy
    (:data:`SHIPPED_POLICIES`: ``"reach"``, ``"nav"``, ``"nav_plain"``, ``"nav_deploy"``; ``None``: ``reach``; a file
    called like one is ``./nav``).

    The module reads raw ``observation`` from :class:`~atrv_warp.task.env.RoverEnv` and writes
    ``action``; with ``deterministic=True`` it returns the distribution's mode. ``task`` (a task name or
    :class:`~atrv_warp.task.config.TaskConfig`): the policy must command that task's action kind and observe its
    observation.

    Raises ``FileNotFoundError`` (for a shipped policy not trained yet, naming the command that trains it),
    ``ValueError`` for an unknown shipped name, or :class:`~atrv_warp.storage.FileFormatError` naming the file
    and the problem for anything that is not a complete policy (nothing is unpickled), or for a policy
    that observes another observation than ``task``'s (:class:`PolicyTaskMismatch` when it commands or observes
    another kind, naming both). ``device``: where the weights go; the env's
    (``env.device``) for an :class:`~atrv_warp.task.env.RoverEnv` on a GPU.
    """
    label = path if isinstance(path, str) and path in SHIPPED_POLICIES else None
    path = policy_path(path)
    payload = _read(path)  # a training checkpoint: its policy
    if payload.get("format") not in READ_FORMATS:
        raise FileFormatError(f"{path}: not an atrv_warp policy (format {payload.get('format')!r}, "
                              f"expected one of {list(READ_FORMATS)})")
    if task is not None:
        check_policy_task(payload, task, source=label or path)
        _check_observes(path, int(payload.get("obs_dim", OBS_DIM)), task, payload.get("robot"))
    try:
        actor = make_actor(int(payload["width"]), int(payload["depth"]), obs_dim=int(payload.get("obs_dim", OBS_DIM)))
        actor.load_state_dict(payload["state_dict"])
    except (KeyError, TypeError, ValueError, RuntimeError) as err:
        detail = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise FileFormatError(f"{path}: damaged atrv_warp policy ({detail[:200]})") from None
    bad = [k for k, v in actor.state_dict().items() if v.is_floating_point() and not torch.isfinite(v).all()]
    if bad:
        raise FileFormatError(f"{path}: damaged atrv_warp policy (non-finite values in {bad[:3]})")
    actor.to(device).eval()
    if not deterministic:
        return actor
    from torchrl.envs.utils import ExplorationType

    return _Deterministic(actor, ExplorationType.DETERMINISTIC)


def _check_observes(path: Path, obs_dim: int, task, robot_record=None) -> None:
    """``robot_record``: the policy's, whose ``[[sensors]]`` it observed beside the task's scan."""
    from atrv_warp.task.registry import get_task

    config = get_task(task)
    sensors = None
    if isinstance(robot_record, dict) and robot_record.get("sensors"):
        from atrv_warp.core.robot import RobotFileError, robot_from_record
        from atrv_warp.task.sensors import sensor_fields

        try:
            sensors = sensor_fields(config, robot_from_record(robot_record, f"{path} (its robot record)"))
        except (RobotFileError, ValueError) as err:
            raise FileFormatError(f"{path}: its robot's sensors do not read back ({err})") from None
    fields = observation_fields(config, sensors)
    if obs_dim != len(fields):
        name = f"task {task!r}" if isinstance(task, str) else "the task"
        raise FileFormatError(
            f"{path}: the policy observes {obs_dim} values, {name} observes {len(fields)} "
            f"({fields[0].name} … {fields[-1].name}); it was trained on another version of the task: train it again")


class _Deterministic(TensorDictSequential):
    """Runs the wrapped actor under a fixed exploration type."""

    def __init__(self, actor, exploration_type):
        super().__init__(actor)
        self._exploration_type = exploration_type

    def forward(self, tensordict, *args, **kwargs):
        from torchrl.envs.utils import set_exploration_type

        with set_exploration_type(self._exploration_type), torch.no_grad():
            return super().forward(tensordict, *args, **kwargs)
