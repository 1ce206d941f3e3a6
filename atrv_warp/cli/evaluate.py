"""Evaluate a saved policy on seeded episodes: ``python -m atrv_warp.evaluate [CHECKPOINT]``.

CHECKPOINT is a ``best_policy.pt``, a training ``checkpoint.pt``, or omitted for the policy
shipped with the package. Reports success rate, mean return, mean steps and the failure
breakdown (wall, flip, timeout, obstacle), optionally as JSON.

Examples::

    python -m atrv_warp.evaluate                          # the shipped policy, 1000 episodes
    python -m atrv_warp.evaluate runs/default/best_policy.pt --episodes 200 --seed 7
    python -m atrv_warp.evaluate --baseline               # the scripted driver, for comparison (atrv-baseline)
    python -m atrv_warp.evaluate --task nav               # the shipped navigation policy
    python -m atrv_warp.evaluate nav_plain                # a shipped policy by name (atrv_warp.policy.SHIPPED_POLICIES)
    python -m atrv_warp.evaluate --task nav --randomization wide   # under shift: per-world physics, noise, latency
    python -m atrv_warp.evaluate run/best_policy.pt --sim-config calibrated.toml --randomization around
                                                          # on the calibrated rover, then across the spread around it
    python -m atrv_warp.evaluate --task nav --baseline --episodes 8 --rerun nav.rrd
    python -m atrv_warp.evaluate --episodes 8 --rerun eval.rrd      # record 4 worlds; view: rerun eval.rrd
    python -m atrv_warp.evaluate --episodes 4 --serve --real-time   # live web viewer on 127.0.0.1
    python -m atrv_warp.evaluate --task nav --episodes 64 --video nav.mp4   # the first 4 episodes, top down
    python -m atrv_warp.evaluate --task nav --episodes 4 --video nav.mp4 --video-follow 10   # a camera on each rover
    python -m atrv_warp.evaluate nav_deploy --engine mujoco --episodes 20   # the same episodes in the MuJoCo twin
    python -m atrv_warp.evaluate run.pt2 --engine mujoco --friction 0.8     # an exported policy, the twin at µ 0.8

``--engine mujoco`` (the ``mujoco`` extra) drives a deployable policy (``/cmd_vel`` actions from the robot
observation) through ``atrv_warp.integrations.mujoco``'s twin of each episode's world: the same worlds, starts and
goals, the observation built by the light core's ``RobotObservation`` as on a robot, the base configured for the
radius the twin's tyres roll on (``integrations.mujoco.twin.rolling_radius``). The library function is
:func:`evaluate_policy`.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from atrv_warp.runtime import add_verbose_argument, device_summary, error_line, set_verbose

__all__ = ["ENGINES", "Evaluation", "baseline_main", "build_parser", "evaluate_around", "evaluate_policy", "main"]

ENGINES = ("ours", "mujoco")
"""Engines an evaluation runs on: ``ours`` (the simulator that trains the policies) and ``mujoco`` (the MuJoCo
twin of the nav world, ``atrv_warp.integrations.mujoco``; the ``mujoco`` extra)."""
MUJOCO_EXTRA = "pip install 'atrv_warp[mujoco]'"
"""How to install what ``--engine mujoco`` needs."""


@dataclass(frozen=True)
class Evaluation:
    """What :func:`evaluate_policy` measured."""

    name: str
    """The policy's file or shipped name (or the scripted baseline's label)."""
    task: str
    seed: int
    engine: str
    record: object
    """Each episode's end (:class:`~atrv_warp.task.evaluation.EpisodeRecord`)."""
    extra: dict = field(default_factory=dict)
    """Figures beside the summary, as the JSON gets them (the randomization, the ranges it drew from and its
    success-by-bin table; the twin's engine and friction)."""

    @property
    def result(self):
        """The summary (:class:`~atrv_warp.task.evaluation.EvalResult`)."""
        return self.record.summary()


def evaluate_policy(policy: str | None = None, *, engine: str = "ours", task: str | None = None,
                    episodes: int = 1000, seed: int | None = None, baseline: bool = False,
                    randomization: str = "none", friction: float | None = None, sim_config: str | None = None,
                    device: str = "cpu", attach: Callable | None = None, driver=None,
                    task_module: str | None = None, robot: str | None = None,
                    allow_other_robot: bool = False, maps: Sequence[str] = ()) -> Evaluation:
    """Run a policy once on each of the first ``episodes`` episodes of evaluation set ``seed``.

    Args:
        policy: A policy file (``.pt``, a training ``checkpoint.pt``, an exported ``.pt2``) or a shipped policy's
            name; ``None``: ``robot``'s shipped policy for the task where one ships (``nav_deploy_husky``), else the
            task's (``reach``; ``nav_deploy`` on ``mujoco``).
        engine: One of :data:`ENGINES`.
        task: The task (default: the policy's own; ``reach`` for the baseline).
        episodes: How many episodes (one world each on ``ours``).
        seed: The evaluation set (default :data:`~atrv_warp.task.evaluation.EVAL_SEED`, the test set).
        baseline: Evaluate the scripted baseline instead (``ours`` only).
        randomization: A randomization preset (``ours`` only); ``around`` is centred on ``sim_config``.
        friction: The twin's Coulomb µ (``mujoco`` only; default the nominal µ).
        sim_config: A simulator-config TOML (``ours`` only).
        device: The simulation device (``ours``).
        attach: ``attach(env)`` returns an ``on_step(env, tensordict)`` callback or ``None`` (recorders; ``ours``).
        driver: The base's motor driver (:class:`~atrv_warp.sim.driver.DriverConfig`, e.g. a calibrated wheel radius
            or an accelerometer-aided odometry) that velocity actions go through, on either engine; the task's limits
            fill in those it leaves unset (default: the task's base).
        task_module: A Python file that registers a task of your own (loaded first; never from a policy file).
        robot: The robot to run on (a shipped robot's name or a robot file's path); ``None``: the policy's own (the
            one its file records; the ATRV-Jr for the baseline). A policy runs its recorded task, fitted to the robot
            it was trained on, never today's declaration of it.
        allow_other_robot: Run a policy on another robot than its own on purpose (a study); without it, that is
            refused naming both.
        maps: Nav2 ``map_server`` YAML files to drive in (``ours`` only): episode ``k`` in map ``k % len(maps)``,
            its start and goal in the map's free space (:class:`~atrv_warp.task.env.RoverEnv`); the JSON records
            each map (its file and sha256), each episode's and the success in each.

    Raises:
        ValueError: One line naming the problem: an unknown engine, task or preset; a policy that cannot be loaded
            (a missing file, or a shipped policy not trained yet: naming the command that trains it) or does not fit
            the task; an option the engine does not take; a policy the twin cannot drive (not deployable); MuJoCo
            not installed for ``mujoco``; a randomization centred on a ``sim_config`` that is missing or does not set
            a parameter it draws.
    """
    from atrv_warp.task.evaluation import EVAL_SEED
    from atrv_warp.task.registry import load_task_module, resolve_task

    if engine not in ENGINES:
        raise ValueError(f"unknown engine {engine!r}; known: {', '.join(ENGINES)}")
    if task_module:
        try:
            load_task_module(task_module)
        except FileNotFoundError as err:
            raise ValueError(str(err)) from None
    if task is not None:
        resolve_task(task)  # an unknown one is named, with the known ones
    if episodes < 1:
        raise ValueError(f"need at least 1 episode, got {episodes}")
    seed = EVAL_SEED if seed is None else seed
    if robot is not None:
        from atrv_warp.core.robot import load_robot

        load_robot(robot)  # an unknown one is named, with the shipped ones
    from atrv_warp.world.places import read_map_files

    site_maps = read_map_files(maps)  # a bad map file stops here; a place is drawn by the env for its robot
    if engine == "mujoco":
        if site_maps:
            raise ValueError("engine mujoco drives the twin's flat arena; maps are for engine ours")
        return _evaluate_twin(policy, task=task, episodes=episodes, seed=seed, friction=friction,
                              baseline=baseline, randomization=randomization, sim_config=sim_config, driver=driver,
                              robot=robot, allow_other_robot=allow_other_robot)
    if friction is not None:
        raise ValueError("friction sets the MuJoCo twin's µ (engine mujoco); our simulator's comes from the rover "
                         "config or the randomization")
    return _evaluate_ours(policy, task=task, episodes=episodes, seed=seed, baseline=baseline,
                          randomization=randomization, sim_config=sim_config, device=device, attach=attach,
                          driver=driver, robot=robot, allow_other_robot=allow_other_robot, maps=site_maps)


def _map_figures(maps: Sequence, record, num_worlds: int) -> dict:
    """The JSON's record of the maps: each one's file and sha256, each episode's map and the success in each."""
    import torch

    from atrv_warp.sim.maps import round_robin

    episode_map = round_robin(num_worlds, len(maps))
    success = record.success.float()
    return {"maps": [{**m.record(), "episodes": episode_map.count(k),
                      "success": float(success[torch.tensor(episode_map) == k].mean())}
                     for k, m in enumerate(maps)],
            "episode_map": episode_map}


def evaluate_around(policy: str | None = None, *, sim_config: str, randomization: str = "around",
                    **kwargs) -> tuple[Evaluation, Evaluation]:
    """The policy on the rover ``sim_config`` describes (e.g. a calibrated one), then across the spread around it:
    :func:`evaluate_policy` on the same episodes without randomization and under ``randomization`` (a randomization
    centred on ``sim_config``, :data:`~atrv_warp.task.randomization.AROUND_PRESETS`).

    Args:
        policy: As :func:`evaluate_policy`'s.
        sim_config: The simulator-config TOML file.
        randomization: A name in :data:`~atrv_warp.task.randomization.AROUND_PRESETS`.
        **kwargs: :func:`evaluate_policy`'s other keyword arguments (``attach`` goes to the second run only).

    Raises:
        ValueError: As :func:`evaluate_policy`, before either run; a ``randomization`` not centred on a config.
    """
    from atrv_warp.task.randomization import AROUND_PRESETS, get_randomization

    if randomization not in AROUND_PRESETS:
        raise ValueError(f"randomization {randomization!r} is not centred on a simulator config; known: "
                         f"{sorted(AROUND_PRESETS)}")
    get_randomization(randomization, sim_config=sim_config)  # a file that cannot centre it stops before any run
    attach = kwargs.pop("attach", None)
    on = evaluate_policy(policy, sim_config=sim_config, **kwargs)
    return on, evaluate_policy(policy, sim_config=sim_config, randomization=randomization, attach=attach, **kwargs)


def _load(path: str, task: str | None):
    """(policy module, trained-on task name, :class:`~atrv_warp.policy.PolicyRecord`) of a saved policy, or of an
    exported one (its program: what a robot runs), refused when it does not fit ``task``."""
    from atrv_warp.policy import load_policy, policy_record, policy_task

    if str(path).endswith(".pt2"):
        return _load_exported(path, task)
    try:
        trained_on = policy_task(path)
        # a policy that commands or observes another kind than the task's is refused first, naming both
        module = load_policy(path, task=task or trained_on)
        record = policy_record(path)
    except (FileNotFoundError, ValueError) as err:  # FileFormatError is a ValueError
        raise ValueError(f"cannot load policy: {err}") from None
    if task is not None and task != trained_on:
        raise ValueError(f"{path} was trained on task {trained_on!r}, not {task!r}")
    return module, trained_on, record


def _load_exported(path: str, task: str | None):
    """:func:`_load` for an exported program (``.pt2``), with the task and robot its contract keeps."""
    from tensordict.nn import TensorDictModule

    from atrv_warp.core.contract import read_exported
    from atrv_warp.policy import exported_policy_record

    try:
        program, contract = read_exported(path)  # checked first: nothing in the file can run code
        record = exported_policy_record(path, contract)
    except (FileNotFoundError, ValueError) as err:  # ExportedFileError and FileFormatError are ValueErrors
        raise ValueError(f"cannot load policy: {err}") from None
    trained_on = record.task.name
    if task is not None and task != trained_on:
        raise ValueError(f"{path} was trained on task {trained_on!r}, not {task!r}")
    return TensorDictModule(program.module(), in_keys=["observation"], out_keys=["action"]), trained_on, record


def _robot_of_old_export(name: str, robot: str | None, allow: bool, source) -> tuple[str, str | None]:
    """:func:`_robot_to_run` for a file exported before exported files kept their records: its robot's ``name``
    alone, which must be a shipped robot's."""
    from atrv_warp.core.robot import ROBOTS, load_robot
    from atrv_warp.policy import PolicyRecord

    if name not in ROBOTS:
        raise ValueError(f"{source} was exported before exported policies kept their robot, and {name!r} is not a "
                         "shipped robot: export it again (python -m atrv_warp.export POLICY OUT.pt2)")
    if robot is None:
        return name, None
    return _robot_to_run(PolicyRecord(None, load_robot(name), False), robot, allow, source)


def _robot_to_run(record, robot: str | None, allow: bool, source) -> tuple[str, str | None]:
    """(the robot to build the environment on, a line to warn with) for a policy of ``record`` asked to run on
    ``robot`` (``None``: its own)."""
    from atrv_warp.core.robot import load_robot, robot_spec
    from atrv_warp.policy import PolicyRobotMismatch, check_policy_robot

    if robot is None:
        own = record.robot
        spec = robot_spec(own)
        if spec is not None:
            return spec, None
        raise ValueError(f"{source} was trained on robot {own.name!r} ({own.title}), which is not a shipped robot "
                         "(or has changed since): give its robot file with --robot FILE")
    try:
        warning = check_policy_robot(record, load_robot(robot), source=source, allow=allow)
    except PolicyRobotMismatch as err:
        raise ValueError(str(err)) from None
    return robot, warning


def _baseline(env):
    """The scripted baseline of ``env``'s task: Nav2's Regulated Pure Pursuit for a task that follows a plan, else
    the heading driver."""
    if env.task_cfg.observation == "path":
        from atrv_warp.task.pursuit import pursuit_policy

        return pursuit_policy(env.task_cfg, env.robot), "regulated pure pursuit"
    from atrv_warp.task.baseline import scripted_policy

    return scripted_policy(), "scripted baseline"


def _evaluate_ours(policy, *, task, episodes, seed, baseline, randomization, sim_config, device, attach,
                   driver, robot=None, allow_other_robot=False, maps=()) -> Evaluation:
    from atrv_warp.policy import shipped_policy_for
    from atrv_warp.task.evaluation import range_bins, run_episodes, success_by_bin
    from atrv_warp.task.randomization import AROUND_PRESETS, get_randomization

    if sim_config:
        from atrv_warp.sim.config_file import load_sim_config

        load_sim_config(sim_config)  # a bad file stops here, before the simulator is built
    if baseline:  # built for the env below: a plan's follower reads the observation of the robot's sensors
        task = task or "reach"
        module, name, env_task = None, f"scripted baseline ({task})", task
    else:
        name = policy or shipped_policy_for(task or "reach", robot)  # the robot's shipped policy, else the task's
        module, task, record = _load(name, task)
        env_task = record.task  # the task it trained on, fitted to its robot: not today's declaration
        robot, warning = _robot_to_run(record, robot, allow_other_robot, name)
        if warning:
            print(f"warning: {warning} (--allow-other-robot)", file=sys.stderr)
    from atrv_warp.sim.config import nominal_rover_config
    from atrv_warp.task.env import RoverEnv

    # `around` resolved against sim_config; a preset fitted to the robot
    shift = get_randomization(randomization, sim_config=sim_config, rover=nominal_rover_config(robot))
    env = RoverEnv(episodes, device=device, task=env_task, randomization=shift, sim_config=sim_config,
                   driver=driver, robot=robot, maps=maps)
    if baseline:
        module, kind = _baseline(env)
        name = f"{kind} ({task})"
    module = module.to(env.device)  # loaded on the CPU; the env's observations live on its device
    record = run_episodes(module, env, seed=seed, on_step=attach(env) if attach is not None else None)
    extra = {}
    if shift.enabled:
        around = randomization in AROUND_PRESETS  # its ranges are narrow: bins across them, not SHIFT_BINS
        extra = {"randomization": randomization,
                 "ranges": {k: [d.low, d.high] for k, d in shift.physics.items()} | {"latency": list(shift.latency)},
                 "success_by_bin": success_by_bin(record, range_bins(shift)) if around else success_by_bin(record)}
    if maps:
        extra |= _map_figures(env.sim.maps.maps, record, episodes)
    if record.path_ratio is not None:
        extra |= _path_figures(record, env.sim.sim_cfg.step_dt)
    return Evaluation(str(name), task, seed, "ours", record, extra)


def _path_figures(record, step_dt: float) -> dict:
    """A path task's episodes, each: how it ended, its time [s], the distance driven over its first plan's length,
    its least clearance [m]; and the successful episodes' medians."""
    from atrv_warp.task.spec import END_REASONS

    done = record.success
    median = (lambda x: float(x[done].median())) if bool(done.any()) else (lambda x: None)
    return {"episodes_path": {"end": [END_REASONS[int(r)] for r in record.end_reason],
                              "seconds": [round(float(s) * step_dt, 3) for s in record.steps],
                              "path_ratio": [round(float(r), 4) for r in record.path_ratio],
                              "least_clearance_m": [round(float(c), 4) for c in record.least_clearance]},
            "success_median_path_ratio": median(record.path_ratio),
            "success_median_least_clearance_m": median(record.least_clearance)}


def _evaluate_twin(policy, *, task, episodes, seed, friction, baseline, randomization, sim_config,
                   driver, robot=None, allow_other_robot=False) -> Evaluation:
    for option, given in (("baseline", baseline), ("randomization", randomization != "none"),
                          ("sim_config", sim_config)):
        if given:
            raise ValueError(f"engine mujoco drives a deployable policy on the nominal twin; {option} is for engine "
                             "ours")
    try:
        from atrv_warp.integrations.mujoco import DeployablePolicy, draw_episodes, run_twin_episodes
    except ImportError as err:
        raise ValueError(f"engine mujoco needs MuJoCo ({err.name} is not installed): {MUJOCO_EXTRA}") from None
    from atrv_warp.policy import shipped_policy_for

    name = policy or shipped_policy_for(task or "nav_deploy", robot)
    try:
        deployable = DeployablePolicy.load(name)
    except FileNotFoundError as err:
        raise ValueError(f"cannot load policy: {err}") from None
    trained_on = getattr(deployable.task, "name", deployable.task)
    if task is not None and task != trained_on:
        raise ValueError(f"{name} was trained on task {trained_on!r}, not {task!r}")
    if deployable.record is not None:
        robot, warning = _robot_to_run(deployable.record, robot, allow_other_robot, name)
    else:
        robot, warning = _robot_of_old_export(deployable.robot, robot, allow_other_robot, name)
    if warning:
        print(f"warning: {warning} (--allow-other-robot)", file=sys.stderr)
    record = run_twin_episodes(deployable, draw_episodes(deployable.task, episodes, seed=seed, robot=robot),
                               friction=friction, driver=driver)
    mu = float(record.params["friction"][0])
    return Evaluation(str(name), trained_on, seed, "mujoco", record, {"engine": "mujoco", "friction": mu,
                                                                     "robot": robot})


def build_parser() -> argparse.ArgumentParser:
    """The command line's parser (the docs' command table reads it too)."""
    parser = argparse.ArgumentParser(prog="python -m atrv_warp.evaluate", description=__doc__.splitlines()[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    parser.add_argument("checkpoint", nargs="?", default=None, help="policy or checkpoint file, or a shipped policy's name (reach, nav, nav_plain, nav_deploy, "
                             "nav_deploy_<robot>, follow_path_<robot>; default: the task's shipped one)")
    parser.add_argument("--engine", default="ours", help=f"simulator: {' | '.join(ENGINES)} (mujoco: the MuJoCo twin "
                        "of the nav world, for a deployable policy; the mujoco extra)")
    parser.add_argument("--friction", type=float, default=None, metavar="MU",
                        help="the MuJoCo twin's Coulomb µ (--engine mujoco; default: the nominal µ)")
    parser.add_argument("--odometry-accel-time", type=float, default=None, metavar="S",
                        help="the base's fused odometry blends in the IMU's accelerometer with this time constant [s] "
                             "(DriverConfig.odometry_accel_time; default: the encoders alone)")
    parser.add_argument("--robot", default=None,
                        help="the robot to run on: a shipped robot's name or a robot file's path (default: the "
                             "policy's own, as its file records; the ATRV-Jr for --baseline)")
    parser.add_argument("--allow-other-robot", action="store_true",
                        help="run a policy on another robot than its own on purpose (a study); refused without it")
    parser.add_argument("--episodes", type=int, default=1000, help="number of seeded episodes (one world each)")
    parser.add_argument("--seed", type=int, default=None, help="evaluation-set seed (default: the standard set)")
    parser.add_argument("--baseline", action="store_true", help="evaluate the scripted baseline instead (Nav2's "
                        "Regulated Pure Pursuit on a task that follows a plan)")
    parser.add_argument("--task", default=None,
                        help="task: reach | nav | nav_deploy | follow_path, or yours (--task-module) (default: the policy's own; reach "
                             "for the baseline)")
    parser.add_argument("--task-module", metavar="FILE.py", default=None,
                        help="a Python file that registers a task of your own (docs/your-own-task.md)")
    parser.add_argument("--randomization", default="none", metavar="PRESET",
                        help="evaluate under domain randomization: none | mild | wide | wide_slip | wide_slip_gain (each world draws its physics, "
                             "sensor noise and latency from the evaluation seed); prints success by parameter bin. "
                             "around (with --sim-config): on the config's rover, then across the spread around it, "
                             "two rows")
    parser.add_argument("--sim-config", metavar="FILE",
                        help="simulator-config TOML, e.g. atrv-calibrate's fit of a real rover (docs/calibration.md)")
    parser.add_argument("--device", default="cpu", help="simulation device")
    parser.add_argument("--map", nargs="+", metavar="MAP.yaml",
                        help="drive in Nav2 map_server maps or procedural places (building:100@1000: 100 buildings "
                             "from seed 1000), episode k in map k %% N, starts and goals in their free space")
    parser.add_argument("--json", metavar="FILE", help="also write the figures to FILE")
    parser.add_argument("--rerun", metavar="FILE.rrd", help="record the episodes to a Rerun file")
    parser.add_argument("--serve", action="store_true", help="serve a live Rerun web viewer on 127.0.0.1")
    parser.add_argument("--real-time", action="store_true", help="slow the simulation to real time")
    parser.add_argument("--worlds", type=int, nargs="+", default=None,
                        help="worlds (episodes) to record (default: the first 4)")
    parser.add_argument("--video", metavar="FILE.mp4", help="draw the first episodes top down into an MP4")
    parser.add_argument("--video-episodes", type=int, default=4, help="episodes in the video (default: 4)")
    parser.add_argument("--video-follow", type=float, default=None, metavar="METRES",
                        help="each panel follows its rover over this much ground (default: the whole arena)")
    add_verbose_argument(parser)
    return parser


def _check_outputs(args) -> str | None:
    """Why the recording, video or engine options cannot be served (``None``: they can); files' folders are
    created now, before any work."""
    if args.engine == "mujoco" and (args.rerun or args.serve or args.real_time or args.video):
        return "--rerun, --serve, --real-time and --video record our simulator; drop them with --engine mujoco"
    if args.video:
        from atrv_warp.integrations.video import check_video_path

        try:  # its folder is created now, before any work; a path that cannot be written stops here
            check_video_path(args.video)
        except ValueError as err:
            return f"--{err}"
    if args.rerun:
        from atrv_warp.integrations.recorder import check_recording_path

        try:  # as --video: a recording that cannot be written stops here, before the simulator is built
            check_recording_path(args.rerun)
        except ValueError as err:
            return f"--rerun: {err}"
    return None


class _Viewers:
    """The recorder and the video the command line attaches to our env (``attach``), closed after the run."""

    def __init__(self, args):
        self.args, self.recorder, self.video = args, None, None

    def __call__(self, env):
        args, on_step = self.args, None
        if args.rerun or args.serve or args.real_time:
            from atrv_warp.integrations.recorder import RerunRecorder

            self.recorder = RerunRecorder(env.sim, path=args.rerun, serve=args.serve, worlds=args.worlds,
                                          real_time=args.real_time)
            on_step = self.recorder.env_hook()
        if args.video:
            from atrv_warp.integrations.video import EvalVideo

            self.video = EvalVideo(env, episodes=args.video_episodes, follow=args.video_follow)
            draw, rerun_step = self.video.env_hook(), on_step
            on_step = draw if rerun_step is None else (lambda e, td: (rerun_step(e, td), draw(e, td)))
        return on_step

    def close(self) -> None:
        if self.recorder is not None:
            self.recorder.close()


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.episodes < 1:
        parser.error("--episodes must be >= 1")
    if args.video_episodes < 1:
        parser.error("--video-episodes must be >= 1")
    if args.video_follow is not None and not args.video_follow > 0:
        parser.error("--video-follow must be > 0 metres")
    if args.engine not in ENGINES:
        return error_line(parser.prog, f"unknown --engine {args.engine!r}; known: {', '.join(ENGINES)}")
    if (problem := _check_outputs(args)) is not None:
        return error_line(parser.prog, problem)
    from atrv_warp.task.randomization import AROUND_PRESETS

    around = args.randomization in AROUND_PRESETS and args.engine == "ours"
    if around and not args.sim_config:
        return error_line(parser.prog, f"--randomization {args.randomization} is centred on a simulator config: give "
                          "it with --sim-config FILE")
    if args.verbose:
        set_verbose()
    from atrv_warp.task.evaluation import format_bins, format_result, write_result

    if args.engine == "ours":
        try:
            print(device_summary(args.device))
        except (RuntimeError, ValueError) as err:
            return error_line(parser.prog, f"--device {args.device!r}: {err}")
    driver = None
    if args.odometry_accel_time is not None:
        from atrv_warp.sim.driver import DriverConfig

        try:
            driver = DriverConfig(odometry_accel_time=args.odometry_accel_time)
        except ValueError as err:
            return error_line(parser.prog, f"--odometry-accel-time: {err}")
    viewers = _Viewers(args)
    options = {"engine": args.engine, "task": args.task, "episodes": args.episodes, "seed": args.seed,
               "baseline": args.baseline, "friction": args.friction, "device": args.device, "attach": viewers,
               "driver": driver, "task_module": args.task_module, "robot": args.robot,
               "allow_other_robot": args.allow_other_robot, "maps": args.map or ()}
    on = None
    try:
        if around:  # the config's rover itself, then across the spread around it
            on, run = evaluate_around(args.checkpoint, sim_config=args.sim_config, randomization=args.randomization,
                                      **options)
        else:
            run = evaluate_policy(args.checkpoint, randomization=args.randomization, sim_config=args.sim_config,
                                  **options)
    except ValueError as err:
        return error_line(parser.prog, _option_named(err))
    finally:
        viewers.close()
    result, extra = run.result, run.extra
    tail = f" | randomization {extra['randomization']}" if "randomization" in extra else " | nominal"
    tail += f" MuJoCo twin, µ {extra['friction']:g}" if run.engine == "mujoco" else ""
    if on is not None:
        print(format_result(f"{run.name} on {args.sim_config}", on.result))
        print(format_result(f"{run.name} around {args.sim_config}", result) + tail)
        extra = {**extra, "on_sim_config": on.result.as_dict()}
    else:
        print(format_result(run.name, result) + tail)
    if "success_by_bin" in extra:
        print(format_bins(extra["success_by_bin"]))
    if 1 < len(extra.get("maps", ())) <= 8:
        print("  success by map: " + " | ".join(f"{m['name']}: {100 * m['success']:.1f}% ({m['episodes']})"
                                                for m in extra["maps"]))
    if extra.get("success_median_path_ratio") is not None:
        print(f"  successful episodes (median): drove {extra['success_median_path_ratio']:.2f}x the plan's length, "
              f"least clearance {extra['success_median_least_clearance_m']:.2f} m")
    if args.rerun:
        print(f"recording: {args.rerun}  (view with: rerun {args.rerun})")
    if viewers.video is not None:
        written = viewers.video.write(args.video)
        print(f"video: {written.path} ({written.frames} frames, {written.width}x{written.height}, "
              f"{len(viewers.video.worlds)} episodes; drawn and encoded in {written.render_s:.2f} s)")
    if args.serve and sys.stdin.isatty():
        input("viewer running; press Enter to stop ...")
    if args.json:
        write_result(args.json, run.name, run.task, run.seed, result, **extra)
    return 0


def _option_named(err: Exception) -> str:
    """The library's message as the command line words it (its options by their flags)."""
    text = str(err)
    for word, flag in (("unknown engine", "unknown --engine"), ("unknown task", "unknown --task"),
                       ("unknown randomization preset", "--randomization: unknown randomization preset")):
        if text.startswith(word):
            return flag + text[len(word):]
    if text.startswith("sim config"):
        return f"--sim-config: {text}"
    return text


def baseline_main(argv: list[str] | None = None) -> int:
    """``atrv-baseline [--task nav] [--json F] …``: ``evaluate --baseline``, the scripted driver on the
    standard evaluation set."""
    return main(["--baseline", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":
    sys.exit(main())
