"""Robot files: list the shipped ones, start one from a URDF, check and measure one.

    python -m atrv_warp.robot list
    python -m atrv_warp.robot new my_rover.urdf --name my_rover     # writes my_rover.toml beside the URDF
    python -m atrv_warp.robot check my_rover.toml [--write] [--json report.json]

``check`` reads the file and its URDF (one named error per problem: the file's field and the link or joint), then
drives the robot in the simulator and prints its mass, wheel radius, track, wheelbase, effective track factor (steady
turns to the robot's limits at µ 0.3 and 0.8, and each one's ``/cmd_vel`` yaw error with it), top speed under full
torque and the ``/cmd_vel`` step response through its driver, judged: exit 1 where it does not settle within 0.5 s.
``--write`` puts the measured factor and the rule's driver gains into the file. The robot file's format is
:mod:`atrv_warp.core.robot`'s; docs/your-own-robot.md walks through it.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import re
import sys
from pathlib import Path

__all__ = ["build_parser", "format_check", "main", "starter_file", "write_measured"]

AGREEMENT = 0.02
"""A file's factor or gains within this share of the measured ones agree (a re-measure of an unchanged robot does)."""


def build_parser() -> argparse.ArgumentParser:
    """The command line's parser (the docs' command table reads it too)."""
    p = argparse.ArgumentParser(prog="python -m atrv_warp.robot", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)
    sub.add_parser("list", help="the shipped robots and their limits")
    new = sub.add_parser("new", help="write a starter robot file for a URDF (then check it)")
    new.add_argument("urdf", help="the robot's URDF")
    new.add_argument("--name", required=True, help="the robot's name (how commands and saved policies call it)")
    new.add_argument("--out", help="the robot file to write (default: NAME.toml beside the URDF)")
    new.add_argument("--force", action="store_true", help="overwrite an existing file")
    check = sub.add_parser("check", help="check a robot file against its URDF and measure it in the simulator")
    check.add_argument("robot", help="a shipped robot's name or a robot file's path")
    check.add_argument("--write", action="store_true",
                       help="write the measured effective track factor and the rule's gains into the file")
    check.add_argument("--json", metavar="FILE", help="also write the report as JSON")
    check.add_argument("--static", action="store_true", help="only check the file and its URDF (no driving)")
    return p


def _list() -> int:
    from atrv_warp.core.robot import ROBOTS, load_robot

    for name in ROBOTS:
        robot = load_robot(name)
        print(f"{robot.summary()}\n    {robot.path}")
    return 0


def format_check(report: dict) -> str:
    """The check's report (:meth:`~atrv_warp.sim.robot_check.RobotCheck.as_dict`) as the command prints it."""
    from atrv_warp.sim.robot_check import SETTLE_TARGET

    f, g = report["file"], report["gains"]
    lines = [
        f"{report['robot']} ({report['title']})",
        (f"  mass {report['mass']:.2f} kg, wheel radius {report['wheel_radius']:.4g} m, track {report['track']:.3f} m, "
         f"wheelbase {report['wheelbase']:.3f} m, reach {report['reach']:.2f} m"),
        (f"  driver gains by the rule (wheel inertia {report['wheel_inertia']:.4g} kg·m²): kp {g['kp']:g}, "
         f"ki {g['ki']:g}   file: {f['kp']:g}, {f['ki']:g}{_agree(g['kp'], f['kp'])}"),
    ]
    by_mu: dict[float, list[float]] = {}
    for t in report["turns"]:
        by_mu.setdefault(t["friction"], []).append(t["chi"])
    spread = ", ".join(f"µ {mu:g}: {min(c):.2f}-{max(c):.2f}" for mu, c in by_mu.items())
    lines.append(f"  effective track factor {report['effective_track_factor']:.3f} (chi {spread}; least squared "
                 f"/cmd_vel yaw error within the grip)   file: "
                 f"{f['effective_track_factor']:g}{_agree(report['effective_track_factor'], f['effective_track_factor'])}")
    lines += _turn_table(report["turns"])
    capped = report.get("top_speed_measured", report["top_speed"]) > 1.005 * report["top_speed"]
    lines.append(f"  top speed under full torque ({f['torque_limit']:g} N·m, µ 0.8): {report['top_speed']:.2f} m/s"
                 + (f" (the motor's no-load speed at the rim; measured {report['top_speed_measured']:.2f})" if capped
                    else "") + f" (limit {f['limits']['linear_velocity']:g} m/s)")
    lines.append("  drivetrain: " + ("one motor per side, its wheels geared to one speed (motor.per_side)"
                                     if f.get("motor_per_side") else "each wheel free under its side's torque"))
    lines.append("  /cmd_vel steps from rest, settled (yaw rate within 10 % to the end) / overshoot:")
    cases = sorted({(s["linear"], s["angular"]) for s in report["steps"]}, key=lambda c: (c[0], -c[1]))
    mus = sorted({s["friction"] for s in report["steps"]})
    lines.append("    " + f"{'command':<26}" + "".join(f"{f'µ {mu:g}':>18}" for mu in mus))
    for v, w in cases:
        label = f"in place {w:g} rad/s" if v == 0 else f"arc {v:g} m/s, {w:g} rad/s"
        cells = []
        for mu in mus:
            s = next(x for x in report["steps"] if (x["linear"], x["angular"], x["friction"]) == (v, w, mu))
            settle = "never" if not math.isfinite(s["settle"]) else f"{s['settle']:.2f} s"
            cells.append(f"{settle} / {100 * s['overshoot']:+.0f} %")
        lines.append("    " + f"{label:<26}" + "".join(f"{c:>18}" for c in cells))
    misses = report.get("settle_misses", [])
    lines.append(f"  settling (in place and the 0.3 m/s arc, target {SETTLE_TARGET:g} s): "
                 + ("met" if not misses else "MISSED: " + "; ".join(misses)))
    return "\n".join(lines)


def _turn_table(turns: list[dict]) -> list[str]:
    """Each steady turn's /cmd_vel yaw error and odometry error through the driver with the chosen factor."""
    if not turns or "yaw_error" not in turns[0]:
        return []
    mus = sorted({t["friction"] for t in turns})
    from atrv_warp.sim.robot_check import within_grip

    lines = [("  steady turns through the driver: yaw rate / command - 1, odometry's yaw / true - 1 (* at the grip "
              "limit, not fitted):"),
             "    " + f"{'command':<26}" + "".join(f"{f'µ {mu:g}':>18}" for mu in mus)]
    for v, w in dict.fromkeys((t["linear"], t["angular"]) for t in turns):
        label = f"in place {w:g} rad/s" if v == 0 else f"arc {v:g} m/s, {w:g} rad/s"
        cells = [f"{'*' if not within_grip(t) else ''}{100 * t['yaw_error']:+.0f} %, {100 * t['odometry_error']:+.0f} %"
                 for mu in mus
                 for t in turns if (t["linear"], t["angular"], t["friction"]) == (v, w, mu)]
        lines.append("    " + f"{label:<26}" + "".join(f"{c:>18}" for c in cells))
    return lines


def _agree(measured: float, declared: float) -> str:
    if abs(measured - declared) <= AGREEMENT * abs(measured):
        return " (agrees)"
    return " (differs: --write puts the measured value in the file)"


def write_measured(path: str | Path, report: dict) -> list[str]:
    """Put the report's gains and effective track factor into the robot file at ``path`` (its ``[driver]`` table and
    their ``[sources]`` lines), keeping everything else as written. Returns the changed keys."""
    path = Path(path)
    text = path.read_text(encoding="utf-8")
    from atrv_warp.sim.robot_check import gain_rule_source

    day = datetime.date.today().isoformat()
    values = {"kp": report["gains"]["kp"], "ki": report["gains"]["ki"],
              "effective_track_factor": round(report["effective_track_factor"], 2)}
    source = {"kp": gain_rule_source(report["wheel_inertia"], report["loaded_inertia"], values["kp"], day),
              "ki": f"the rule: ki = 10 kp, {day}",
              "effective_track_factor": "measured by `python -m atrv_warp.robot check`: the least squared "
                                        "/cmd_vel yaw error over the turns within the grip of "
                                        f"{len(report['turns'])} steady turns to the robot's limits at µ 0.3 and "
                                        f"0.8, {day}"}
    changed = [k for k, v in values.items() if report["file"].get(k) != v]
    for key, value in values.items():
        text = _set_key(text, "driver", key, repr(float(value)))
        text = _set_key(text, "sources", f'"driver.{key}"', json.dumps(source[key], ensure_ascii=False))
    from atrv_warp.storage import atomic_write_text

    atomic_write_text(path, text)
    return changed


def _set_key(text: str, table: str, key: str, value: str) -> str:
    """``text`` with ``key = value`` in ``[table]``: the existing line replaced, else added at the table's end (the
    table appended where there is none)."""
    lines = text.splitlines()
    start = next((i for i, line in enumerate(lines) if line.split("#")[0].strip() == f"[{table}]"), None)
    if start is None:
        return text.rstrip("\n") + f"\n\n[{table}]\n{key} = {value}\n"
    end = next((i for i in range(start + 1, len(lines)) if lines[i].lstrip().startswith("[")), len(lines))
    pattern = re.compile(rf"^\s*{re.escape(key)}\s*=")
    for i in range(start + 1, end):
        if pattern.match(lines[i]):
            lines[i] = f"{key} = {value}"
            return "\n".join(lines) + "\n"
    while end > start + 1 and not lines[end - 1].strip():
        end -= 1
    lines.insert(end, f"{key} = {value}")
    return "\n".join(lines) + "\n"


_IMU = re.compile(r"imu", re.IGNORECASE)
_LASER = re.compile(r"laser|lidar|lrf|scan|hokuyo|sick|lms", re.IGNORECASE)


def _wheel_geometry(urdf: Path, links: dict, wheels: list) -> tuple[float, float, float]:
    """The starter's wheel: the first wheel cylinder's radius and width [m], and the least axial inertia of the wheel
    links [kg·m²] (the driver's gains come from it)."""
    import numpy as np

    from atrv_warp.core.robot import RobotFileError

    radius = width = None
    for j in wheels:
        for geoms in (links[j.child].collisions, links[j.child].visuals):
            for g in geoms or ():
                if radius is None and g.geometry is not None and g.geometry.cylinder is not None:
                    radius, width = float(g.geometry.cylinder.radius), float(g.geometry.cylinder.length)
    if radius is None:
        raise RobotFileError(f"{urdf}: the wheels have no cylinder geometry; write wheels.radius and wheels.width "
                             "by hand")
    weighed = [j for j in wheels if links[j.child].inertial is not None and links[j.child].inertial.inertia is not None]
    if not weighed:
        raise RobotFileError(f"{urdf}: the wheel links ({', '.join(j.child for j in wheels)}) have no <inertial>: the "
                             "driver's gains come from a wheel's inertia; give each wheel link its mass and inertia")
    inertia = min(float(np.asarray(j.axis, dtype=float) @ np.asarray(links[j.child].inertial.inertia, dtype=float)
                        @ np.asarray(j.axis, dtype=float)) / float(np.dot(j.axis, j.axis)) for j in weighed)
    return radius, width, inertia


def starter_file(urdf: str | Path, name: str) -> str:
    """A robot file for ``urdf`` as far as the URDF tells: the chassis (the wheels' parent), the wheels found by the
    rule, an IMU and a laser frame fixed to the chassis (by their names), the wheel cylinder, the rule's gains, and a
    torque limit by the shipped robots' rule. Every field a robot file has is written (the optional ones as comments);
    the motor's and the limits are placeholders, their ``[sources]`` say so: set your robot's."""
    from atrv_warp.core.robot import RobotFileError
    from atrv_warp.sim.urdf import read_urdf, rigid_group

    urdf = Path(urdf).resolve()
    links, joints = read_urdf(urdf)
    wheels = [j for j in joints if j.type in ("revolute", "continuous")]
    if not wheels:
        raise RobotFileError(f"{urdf}: no revolute or continuous joint: no wheels to drive")
    parents = [j.parent for j in wheels]
    chassis = max(set(parents), key=parents.count)
    group = rigid_group(chassis, links, joints)
    imu = [n for n in group if _IMU.search(n)]
    laser = [n for n in group if _LASER.search(n)]
    missing = [what for what, found in (("an IMU frame (a link named *imu*)", imu),
                                        ("a laser frame (a link named *laser*, *lidar*, *scan* ...)", laser)) if not found]
    if missing:
        raise RobotFileError(f"{urdf}: no {' and no '.join(missing)} fixed to the chassis {chassis!r}; add one to the "
                             "URDF (a fixed joint with the chassis' axes) or write links.imu and links.laser by hand")
    mass = sum(float(link.inertial.mass) for link in links.values()
               if link.inertial is not None and link.inertial.mass is not None)
    radius, width, inertia = _wheel_geometry(urdf, links, wheels)
    from atrv_warp.sim.robot_check import gain_rule_source, rule_gains

    loaded = inertia + mass / len(wheels) * radius ** 2
    kp, ki = rule_gains(inertia, loaded)
    kp_source = gain_rule_source(inertia, loaded, kp, datetime.date.today().isoformat())
    torque = float(f"{1.125 * mass * 9.81 * radius / len(wheels):.2g}")
    try:
        rel = urdf.relative_to(Path.cwd())
    except ValueError:
        rel = urdf
    return f"""# {name}: written by `python -m atrv_warp.robot new {rel} --name {name}`.
# Check and measure it: `python -m atrv_warp.robot check {name}.toml --write` (docs/your-own-robot.md).
name = "{name}"
title = "{name}"
urdf = "{urdf.name}"

[links]
chassis = "{chassis}"
imu = "{imu[0]}"
laser = "{laser[0]}"
# left_wheels = [...]          # name the wheels (both lists) where the rule would take a joint that is not one
# right_wheels = [...]
# frames = [...]               # other frames that must exist, fixed to the chassis

[wheels]
radius = {radius!r}
width = {width!r}
offset = 0.0

[motor]
torque_limit = {torque!r}   # set your motor's; this slips a wheel at µ 1.125 under a {len(wheels)}th of {mass:.1f} kg
no_load_speed = 20.0        # [rad/s] set your motor's no-load wheel speed
per_side = false            # true: one motor per side drives its wheels through a chain or gears

[driver]
kp = {kp!r}
ki = {ki!r}
effective_track_factor = 1.5   # `check --write` measures it

[limits]                       # set your robot's diff_drive_controller limits
linear_velocity = 1.0          # [m/s] linear.x.max_velocity
angular_velocity = 1.0         # [rad/s] angular.z.max_velocity
linear_acceleration = 1.0      # [m/s²] linear.x.max_acceleration (optional: leave it out for none)
angular_acceleration = 1.0     # [rad/s²] angular.z.max_acceleration (optional)

[sources]                      # where each value comes from: a datasheet, a config file at its commit, or "not published"
"links.chassis" = "{urdf.name}: the wheels' parent"
"wheels.radius" = "{urdf.name}: the wheel cylinder"
"wheels.width" = "{urdf.name}: the wheel cylinder"
"motor.torque_limit" = "not published: the starter's rule, the torque that slips a wheel at µ 1.125 under its share"
"motor.no_load_speed" = "not published: the starter's placeholder"
"motor.per_side" = "not published: the starter's placeholder"
"driver.kp" = {json.dumps(kp_source, ensure_ascii=False)}
"driver.ki" = "the rule: ki = 10 kp"
"limits.linear_velocity" = "not published: the starter's placeholder"
"limits.angular_velocity" = "not published: the starter's placeholder"
"limits.linear_acceleration" = "not published: the starter's placeholder"
"limits.angular_acceleration" = "not published: the starter's placeholder"
"""


def _new(args) -> int:
    from atrv_warp.core.files import OutputPathError, check_output_path
    from atrv_warp.core.robot import ROBOT_NAME, RobotFileError
    from atrv_warp.sim.urdf import URDFError

    if not ROBOT_NAME.fullmatch(args.name):
        print(f"error: --name must be letters, digits, '_' and '-' (it names the robot's policies and files), got "
              f"{args.name!r}", file=sys.stderr)
        return 2
    out = Path(args.out) if args.out else Path(args.urdf).resolve().with_name(f"{args.name}.toml")
    if out.exists() and not args.force:
        print(f"error: {out} exists (--force overwrites it)", file=sys.stderr)
        return 2
    try:
        check_output_path(out, "robot file")
    except OutputPathError as err:
        print(f"error: --out {err}", file=sys.stderr)
        return 2
    try:
        text = starter_file(args.urdf, args.name)
    except (RobotFileError, URDFError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    if Path(args.urdf).resolve().parent != out.resolve().parent:
        text = text.replace(f'urdf = "{Path(args.urdf).name}"', f'urdf = "{Path(args.urdf).resolve()}"')
    out.write_text(text, encoding="utf-8")
    print(f"wrote {out}: set its [motor] and [limits] to your robot's, then: python -m atrv_warp.robot check {out} "
          "--write")
    return 0


def _check(args) -> int:
    from atrv_warp.core.files import OutputPathError, check_output_path
    from atrv_warp.core.robot import RobotFileError
    from atrv_warp.sim.robot_check import SETTLE_TARGET, check_robot, measure_robot

    if args.json:  # before the measured drive, which takes minutes
        try:
            check_output_path(args.json, "report")
        except OutputPathError as err:
            print(f"error: --json {err}", file=sys.stderr)
            return 2
    try:
        if args.static:
            robot, description = check_robot(args.robot)
            more = "".join(f", {s['kind']} {s['name']} at {s['frame']}" for s in robot.sensors)
            print(f"{robot.path}: ok ({robot.name}: chassis {robot.chassis}, {len(description.wheels)} wheels, IMU "
                  f"{robot.imu_frame}, laser {robot.laser_frame}{more})")
            return 0
        report = measure_robot(args.robot, progress=lambda line: print(f"... {line}", flush=True)).as_dict()
    except RobotFileError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(format_check(report))
    if args.json:
        from atrv_warp.storage import atomic_write_text

        atomic_write_text(Path(args.json), json.dumps(report, indent=2) + "\n")
        print(f"wrote {args.json}")
    if args.write:
        from atrv_warp.core.robot import load_robot

        path = load_robot(args.robot).path
        changed = write_measured(path, report)
        print(f"wrote {path}: " + (", ".join(changed) if changed else "its values already agreed"))
    if report["settle_misses"]:
        print(f"error: {args.robot}: the driver does not settle within {SETTLE_TARGET:g} s: "
              + "; ".join(report["settle_misses"]), file=sys.stderr)
        return 1
    return 0


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.command == "list":
        return _list()
    if args.command == "new":
        return _new(args)
    return _check(args)


if __name__ == "__main__":
    sys.exit(main())
