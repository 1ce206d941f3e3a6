"""Fit the simulator to a drive recorded on a rover: ``python -m atrv_warp.calibrate BAG [--out calibrated.toml]``.

The bag (MCAP; ``ros2 bag record -s mcap /cmd_vel /joint_states /ground_truth/odom``) needs the wheel joint
states and a reference pose, and the velocity commands or the wheel efforts. The fit replays segments of it
in many worlds at once and adjusts friction, motor torque scale, payload and wheel radius (``--params``)
by Levenberg-Marquardt on the replays' errors. The velocity commands go through a driver configured as the robot's is
(``--driver-wheel-radius``, ``--driver-track-width``; default the nominal rover's): a worn tyre is then a
physical radius the fit finds. It writes:

- ``--out`` (``calibrated.toml``): the fitted values, for ``--sim-config`` of ``python -m atrv_warp.train``,
  ``RoverSim(sim_config=...)``, ``RoverEnv(sim_config=...)`` and the ROS node (``-p sim_config:=...``);
- a report (``<out>.report.json``): each value with its spread over the starts, and each segment's position
  error before and after, on the training and the held-out segments;
- a plot (``<out>.png``): recorded against simulated paths of held-out segments.

A bad bag is one line naming the file and the problem (exit 2), and nothing is written. A fit that does not
converge says so and writes no calibration file (exit 1).

``--record-example OUT.mcap`` records a bag to try it on: the simulator node driven over ROS 2 by a scripted
driver (needs the ``ros`` extra), or with ``--engine mujoco`` the MuJoCo twin (the ``mujoco`` extra), a rover
whose contact is not ours; ``--truth FILE`` gives that rover a simulator config the fit is not told.
docs/calibration.md walks through both.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from pathlib import Path

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The command line's parser (the docs' command table reads it too)."""
    from atrv_warp.sim.sysid.config import COMMAND_SOURCES, DEFAULT_FIT, FIT_PARAMETERS, CalibrationConfig
    from atrv_warp.sim.sysid.log import Topics

    d = CalibrationConfig()
    nominal = d.driver()  # the nominal rover's radius and track
    p = argparse.ArgumentParser(prog="python -m atrv_warp.calibrate", description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog="docs/calibration.md: how to record a bag on a real rover, and a worked example.")
    p.add_argument("bag", nargs="?", help="the MCAP bag to fit to")
    p.add_argument("--out", default="calibrated.toml", help="simulator config to write (default %(default)s)")
    p.add_argument("--report", help="JSON report (default: <out>.report.json)")
    p.add_argument("--plot", help="PNG of recorded and simulated paths (default: <out>.png)")
    p.add_argument("--force", action="store_true",
                   help="overwrite --out, --report, --plot or --record-example where they exist (without it, an "
                        "existing file is refused before any work)")
    p.add_argument("--pose-topic", default=Topics.pose,
                   help="reference pose, nav_msgs/Odometry or geometry_msgs/PoseStamped (default %(default)s)")
    p.add_argument("--cmd-vel-topic", default=Topics.cmd_vel, help="velocity commands (default %(default)s)")
    p.add_argument("--joint-states-topic", default=Topics.joint_states, help="wheel joints (default %(default)s)")
    p.add_argument("--params", default=",".join(DEFAULT_FIT),
                   help=f"parameters to fit, comma-separated, from {','.join(FIT_PARAMETERS)} (default %(default)s)")
    p.add_argument("--command", choices=COMMAND_SOURCES, default=d.command,
                   help="replay the velocity commands through the base's PI controller, or the wheel efforts")
    p.add_argument("--robot", default=d.robot,
                   help="the robot the bag was recorded on: a shipped robot's name or a robot file's path (%(default)s); "
                        "its wheel joints, nominal rover and driver gains")
    p.add_argument("--sim-config", help="the rover to start from (default: the robot's nominal rover)")
    p.add_argument("--segment", type=float, default=d.segment_seconds, help="segment length [s] (%(default)s)")
    p.add_argument("--duration", type=float, metavar="S",
                   help="fit only the drive's first S seconds (default: all of it)")
    p.add_argument("--starts", type=int, default=d.starts, help="starting points (%(default)s)")
    p.add_argument("--iterations", type=int, default=d.iterations,
                   help="Levenberg-Marquardt iterations at most, every start at once (%(default)s)")
    p.add_argument("--tolerance", type=float, default=d.tolerance,
                   help="settled: a Gauss-Newton step moves no parameter more than this share of its range "
                        "(%(default)s)")
    p.add_argument("--robust", type=float, default=d.robust,
                   help="each segment's loss counts as robust*log(1 + loss/robust) (%(default)s; 0: as it is)")
    p.add_argument("--pose-smoothing", type=float, default=d.pose_smoothing,
                   help="centred moving average over the reference poses [s] (%(default)s; 0: none)")
    p.add_argument("--seed", type=int, default=d.seed)
    p.add_argument("--wheel-kp", type=float, default=d.kp,
                   help="the base's wheel-speed PI gains (the node's; default: the robot's)")
    p.add_argument("--wheel-ki", type=float, default=d.ki)
    p.add_argument("--effective-track-factor", type=float, default=d.effective_track_factor,
                   help="the driver's effective track / wheel track (default: the robot's)")
    p.add_argument("--driver-wheel-radius", type=float, metavar="M",
                   help="the wheel radius the robot's driver is configured with [m]; /cmd_vel is replayed through it "
                        f"(default: the nominal rover's, {nominal.wheel_radius:g}; the physical radius is fitted)")
    p.add_argument("--driver-track-width", type=float, metavar="M",
                   help=f"the wheel track the robot's driver is configured with [m] (default: the nominal rover's, "
                        f"{nominal.track_width:g})")
    p.add_argument("--latency", type=float, metavar="S",
                   help=("how long after its stamp a /cmd_vel reaches the driver [s] (default: fitted, in whole "
                         "0.05 s steps up to 0.2 s; 0: none)"))
    p.add_argument("--record-example", metavar="OUT.mcap",
                   help="record a bag to try this on: the simulator node, driven over ROS 2 (needs the ros extra)")
    p.add_argument("--engine", default="ours", choices=("ours", "mujoco"),
                   help=("--record-example: the rover's simulator: ours (the simulator node over ROS 2) or mujoco "
                         "(the MuJoCo twin on flat ground, another engine's contact; the mujoco extra) (%(default)s)"))
    p.add_argument("--minutes", type=float, default=5.0, help="--record-example: sim minutes (%(default)s)")
    p.add_argument("--truth", help="--record-example: the recorded rover's simulator config (hidden from the fit)")
    p.add_argument("--noise", type=float, default=0.01,
                   help="--record-example: reference position noise [m] (yaw: noise / 0.5 m) (%(default)s)")
    p.add_argument("-p", "--node-param", action="append", default=[], metavar="NAME:=VALUE",
                   help=("--record-example: another simulator-node parameter (python -m atrv_warp.ros --help), e.g. "
                         "-p cmd_vel_delay:=0.1 -p motor_lag:=0.1 -p terrain:=slope: what the fit does not model"))
    return p


def _node_params(items: list[str]) -> dict[str, float | int | bool | str] | str:
    """``-p NAME:=VALUE`` options as node parameters, each checked as the node checks it, or an error line."""
    from atrv_warp.core.parameters import ParameterError
    from atrv_warp.integrations.ros.parameters import PARAMETER_BY_NAME

    out = {}
    for item in items:
        name, sep, text = item.partition(":=")
        if not sep or name not in PARAMETER_BY_NAME:
            return (f"error: -p {item!r}: not NAME:=VALUE with a simulator-node parameter; known: "
                    f"{sorted(PARAMETER_BY_NAME)}")
        parameter = PARAMETER_BY_NAME[name]
        value: object = text
        if parameter.kind == "switch":
            value = {"true": True, "false": False}.get(text.lower(), text)
        elif parameter.kind in ("number", "integer"):
            try:
                value = float(text)
            except ValueError:
                pass  # the check names it
        try:
            out[name] = parameter.check(value)
        except ParameterError as err:
            return f"error: -p {item!r}: {err}"
    return out


def _unwritable(paths, force: bool) -> str | None:
    """The first output that cannot be written, or exists without ``--force``, as an error line."""
    from atrv_warp.core.files import OutputPathError, check_output_path

    for path in paths:
        try:
            check_output_path(path)
        except OutputPathError as err:
            return f"error: {err}"
        if Path(path).exists() and not force:
            return f"error: {path} exists: pass --force to overwrite it, or name another file"
    return None


def _robot_argument(robot: str) -> str:
    """``--robot`` as the simulator node takes it: a shipped robot's name as it is, a robot file's path absolute."""
    return str(Path(robot).resolve()) if robot.endswith(".toml") or "/" in robot else robot


def _record(args) -> int:
    bad = _unwritable([args.record_example], args.force)
    if bad:
        print(bad, file=sys.stderr)
        return 2
    Path(args.record_example).unlink(missing_ok=True)  # --force: the recorder writes a new file, never onto one
    if args.engine == "mujoco":
        return _record_twin(args)
    try:
        from atrv_warp.integrations.ros.drive import record_drive_bag
    except ImportError:
        from atrv_warp.integrations.ros import MISSING_ROS_MESSAGE

        print(MISSING_ROS_MESSAGE, file=sys.stderr)
        return 2
    # the node's driver is configured as the nominal rover unless told otherwise, whatever --truth's wheel: a base
    # whose tyre wore still runs the radius it was set up with
    params = {"robot": _robot_argument(args.robot), "truth_noise": args.noise, "truth_yaw_noise": args.noise / 0.5,
              "wheel_radius": args.driver_wheel_radius or 0.0, "track_width": args.driver_track_width or 0.0}
    extra = _node_params(args.node_param)
    if isinstance(extra, str):
        print(extra, file=sys.stderr)
        return 2
    params.update(extra)
    if args.truth:
        from atrv_warp.sim.config_file import load_sim_config

        try:
            load_sim_config(args.truth)
        except ValueError as err:
            print(f"error: --truth: {err}", file=sys.stderr)
            return 2
        params["sim_config"] = str(Path(args.truth).resolve())
    t0 = time.perf_counter()
    print(f"recording {args.minutes:g} min of scripted driving to {args.record_example} …", flush=True)
    record_drive_bag(args.record_example, args.minutes, seed=args.seed, parameters=params)
    print(f"wrote {args.record_example} ({Path(args.record_example).stat().st_size / 1e6:.1f} MB) in "
          f"{time.perf_counter() - t0:.0f} s")
    return 0


def _record_twin(args) -> int:
    """``--record-example --engine mujoco``: the bag from the MuJoCo twin of ``--truth``'s rover."""
    from atrv_warp.cli.evaluate import MUJOCO_EXTRA

    if args.node_param:
        print(f"error: -p {args.node_param[0]}: simulator-node parameters are for --engine ours", file=sys.stderr)
        return 2
    try:
        from atrv_warp.integrations.mujoco.record import record_twin_bag
    except ImportError as err:
        print(f"error: --engine mujoco needs MuJoCo ({err.name} is not installed): {MUJOCO_EXTRA}", file=sys.stderr)
        return 2
    from atrv_warp.sim.config import ContactConfig, nominal_rover_config
    from atrv_warp.sim.config_file import load_sim_config
    from atrv_warp.sim.driver import DriverConfig

    rover, friction = nominal_rover_config(args.robot), None  # the robot the bag is of, as the fit will read it
    if args.truth:
        try:
            rover, contact = load_sim_config(args.truth, rover=rover)
        except ValueError as err:
            print(f"error: --truth: {err}", file=sys.stderr)
            return 2
        other = [f.name for f in dataclasses.fields(contact) if f.name != "friction"
                 and getattr(contact, f.name) != getattr(ContactConfig(), f.name)]
        if other:
            print(f"error: --truth: [contact] {', '.join(other)} is our contact model's; the MuJoCo twin takes its "
                  "friction only", file=sys.stderr)
            return 2
        friction = contact.friction
    driver = DriverConfig(wheel_radius=args.driver_wheel_radius, track_width=args.driver_track_width)
    t0 = time.perf_counter()
    print(f"recording {args.minutes:g} min of scripted driving in the MuJoCo twin to {args.record_example} …",
          flush=True)
    try:
        record_twin_bag(args.record_example, args.minutes, seed=args.seed, rover=rover, friction=friction,
                        driver=driver, truth_noise=args.noise, truth_yaw_noise=args.noise / 0.5,
                        progress=lambda t: print(f"  {t:.0f} s", flush=True) if round(t) % 60 == 0 else None)
    except (OSError, ValueError) as err:
        print(f"error: {args.record_example}: {err}", file=sys.stderr)
        return 2
    print(f"wrote {args.record_example} ({Path(args.record_example).stat().st_size / 1e6:.1f} MB) in "
          f"{time.perf_counter() - t0:.0f} s")
    return 0


def _bad_driver(args) -> str | None:
    """The first ``--driver-*`` value that no driver can be configured with, as an error line."""
    for option, value in (("--driver-wheel-radius", args.driver_wheel_radius),
                          ("--driver-track-width", args.driver_track_width)):
        if value is not None and not (math.isfinite(value) and value > 0):
            return f"error: {option} must be a finite number > 0 [m], got {value:g}"
    return None


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    bad = _bad_driver(args)
    if bad:
        print(bad, file=sys.stderr)
        return 2
    if args.record_example:
        return _record(args)
    if not args.bag:
        build_parser().error("give a BAG to fit to (or --record-example OUT.mcap)")
    from atrv_warp.sim.config_file import load_sim_config
    from atrv_warp.sim.sysid import (
        BagError,
        CalibrationConfig,
        CalibrationError,
        Topics,
        calibrate,
        read_drive_log,
    )
    from atrv_warp.sim.sysid.output import format_report, plot_paths, write_report, write_sim_config
    from atrv_warp.sim.urdf import load_rover

    out = Path(args.out)
    report = Path(args.report) if args.report else out.with_suffix(".report.json")
    plot = Path(args.plot) if args.plot else out.with_suffix(".png")
    bad = _unwritable((out, report, plot), args.force)  # before the fit: a long fit never ends in a traceback
    if bad:
        print(bad, file=sys.stderr)
        return 2
    try:
        cfg = CalibrationConfig(robot=args.robot, params=tuple(p.strip() for p in args.params.split(",") if p.strip()),
                                command=args.command, segment_seconds=args.segment, duration=args.duration,
                                starts=args.starts,
                                iterations=args.iterations, tolerance=args.tolerance, robust=args.robust or None,
                                pose_smoothing=args.pose_smoothing, seed=args.seed, kp=args.wheel_kp,
                                ki=args.wheel_ki, effective_track_factor=args.effective_track_factor,
                                driver_wheel_radius=args.driver_wheel_radius,
                                driver_track_width=args.driver_track_width, latency=args.latency)
        nominal_rover = cfg.nominal_rover()
        rover, contact = (load_sim_config(args.sim_config, nominal_rover) if args.sim_config
                          else (nominal_rover, None))
        wheels = {w.joint: (w.side, w.drive_sign) for w in load_rover(rover).wheels}
        t0 = time.perf_counter()
        log = read_drive_log(args.bag, wheels, Topics(cmd_vel=args.cmd_vel_topic,
                                                       joint_states=args.joint_states_topic, pose=args.pose_topic))
        print(f"{args.bag}: {log.duration:.1f} s of drive, {len(log.pose_time)} poses on {args.pose_topic}, "
              f"{len(log.joint_time)} joint states, {len(log.cmd_time)} commands "
              f"(read in {time.perf_counter() - t0:.1f} s)", flush=True)
        result = calibrate(log, cfg, rover=rover, contact=contact, progress=lambda s: print(s, flush=True))
    except (BagError, CalibrationError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(format_report(result))
    print(f"fit {result.seconds:.1f} s (+ {result.compile_seconds:.1f} s building the rollout and compiling "
          "its kernels on first use)")
    write_report(report, result, args.bag)
    plot_paths(plot, result, args.bag)
    if not result.converged:
        advice = ("The model check flags a misfit (above): more iterations will not fix what the model lacks"
                  if result.misfit and result.misfit["flagged"] else
                  "Try more --iterations or --starts, or a longer drive with more turns and accelerations")
        print(f"{result.reason}; wrote no calibration (report {report}, plot {plot}). {advice}.", file=sys.stderr)
        return 1
    write_sim_config(out, result, args.bag)
    if result.misfit and result.misfit["flagged"]:
        print(f"wrote {out} all the same: it beats the nominal rover on the held-out segments, but see the misfit "
              "above", file=sys.stderr)
    spread_note = "" if not any(math.isnan(v) for v in result.spread.values()) else " (one converged start: no spread)"
    print(f"wrote {out}{spread_note}, {report} and {plot}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
