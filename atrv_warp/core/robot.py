"""A robot is one file: a TOML file beside its URDF that holds everything that is the robot's and not the world's
or the task's.

The package ships one per robot in ``atrv_warp/robots/`` (:data:`ROBOTS`: ``atrvjr``, the default, ``jackal`` and
``husky``); :func:`load_robot` takes a shipped robot's name or the path of a file of your own. A file reads::

    name = "atrvjr"                      # how commands and saved policies call it
    title = "iRobot ATRV-Jr"
    urdf = "atrvjr.urdf"                 # relative to this file

    [links]
    chassis = "center_link"              # any link of the tree; links fixed to it are one body with it
    left_wheels = ["left_front_wheel_link", "left_rear_wheel_link"]   # or leave both lists out: every joint
    right_wheels = ["right_front_wheel_link", "right_rear_wheel_link"] # about a lateral axis, by its side
    imu = "cbimu_frame"                  # the IMU's frame, fixed to the chassis
    laser = "lrf_frame"                  # the laser scanner's frame, fixed to the chassis
    frames = ["novatel"]                 # other frames that must exist (optional)

    [wheels]                             # the contact cylinder that replaces the URDF's wheel geometry
    radius = 0.125                       # [m]
    width = 0.075                        # [m]
    offset = 0.03                        # cylinder centre outward from the wheel joint, along the axle [m]

    [motor]
    torque_limit = 20.0                  # per wheel [N·m]
    no_load_speed = 50.0                 # [rad/s]

    [driver]                             # written by `python -m atrv_warp.robot check FILE --write`
    kp = 3.0                             # wheel-speed PI [N·m per rad/s]
    ki = 30.0                            # [N·m per rad]
    effective_track_factor = 1.56        # effective track / wheel track, measured on our physics

    [limits]                             # the robot's published diff_drive_controller limits
    linear_velocity = 0.5                # [m/s]
    angular_velocity = 1.0               # [rad/s]
    linear_acceleration = 0.7            # [m/s²] (optional)
    angular_acceleration = 1.0           # [rad/s²] (optional)

    [sources]                            # where each value comes from, by its dotted name
    "limits.linear_velocity" = "owner/repo@commit:path L12"

    [[sensors]]                          # more sensors than links.laser's scanner (optional, any number)
    kind = "laser"                       # a kind atrv_warp.task.sensors knows (it checks the other keys)
    name = "rear_scan"                   # its step entry and its observed fields' prefix
    frame = "rear_laser"                 # fixed to the chassis

    [deploy]                             # how atrv-deploy runs on it (optional; the file's last table)
    scan_topic = "sensors/lidar2d_0/scan"  # any of the node's topic, frame and command-type parameters
    tf_in_namespace = true               # its stack keeps /tf and /tf_static in the robot's namespace

Any other key is refused by name. The ``[deploy]`` table says where the robot runs, not what it is: it is no part of
the robot's identity (:class:`Robot` equality, a saved policy's record, :func:`robot_file_sha256`). The
``[[sensors]]`` list says what it carries: no part of :class:`Robot` equality either, but a saved policy's record
keeps it and the file's hash covers it (it changes what a policy observes). This module reads only the TOML file (standard library), so code on a robot's
computer can load it; :mod:`atrv_warp.sim` checks it against its URDF (``python -m atrv_warp.robot check``).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import math
import os
import re
import sys
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

from atrv_warp.core.inputs import InputFileError, read_input

if sys.version_info >= (3, 11):  # noqa: UP036 (the slim install runs on 3.10)
    import tomllib
else:  # Python 3.10 (ROS 2 Humble's): the same parser from PyPI, which the slim install requires there
    import tomli as tomllib

__all__ = [
    "DEFAULT_ROBOT",
    "FIELDS",
    "PHYSICAL_RANGE",
    "ROBOTS",
    "ROBOT_NAME",
    "SENSOR_KEYS",
    "Robot",
    "RobotFileError",
    "RobotLimits",
    "load_robot",
    "robot_file",
    "robot_file_sha256",
    "robot_from_record",
    "robot_record",
    "robot_spec",
]

DEFAULT_ROBOT = "atrvjr"
MAX_WHEELS = 8
"""Driven wheels a skid-steer rover may have: 2 to 8, as many on the left as on the right (the encoders' loops have
this fixed length; the friction solve is built for each count)."""
"""The robot everything uses unless told otherwise."""


class RobotFileError(ValueError):
    """A robot file that cannot be read, or a value in it that is missing or wrong (the message names the file and
    the field)."""


def _shipped_folder() -> Path:
    return Path(str(resources.files("atrv_warp").joinpath("robots")))


def _shipped() -> tuple[str, ...]:
    folder = _shipped_folder()
    return tuple(sorted(p.stem for p in folder.glob("*.toml"))) if folder.is_dir() else ()


ROBOTS: tuple[str, ...] = _shipped()
"""The shipped robots' names (one ``atrv_warp/robots/<name>.toml`` each)."""


@dataclass(frozen=True)
class RobotLimits:
    """A robot's velocity and acceleration limits: its ``diff_drive_controller``'s ``linear.x.max_velocity``,
    ``angular.z.max_velocity``, ``linear.x.max_acceleration`` and ``angular.z.max_acceleration``."""

    linear_velocity: float
    """[m/s]"""
    angular_velocity: float
    """[rad/s]"""
    linear_acceleration: float | None = None
    """[m/s²]; ``None``: none published."""
    angular_acceleration: float | None = None
    """[rad/s²]; ``None``: none published."""


@dataclass(frozen=True)
class Robot:
    """One robot, as its file declares it. Every length in metres, every angle in radians."""

    name: str
    """How commands, configs and saved policies call it."""
    title: str
    """A human name ("Clearpath Jackal J100")."""
    path: str = field(compare=False)
    """The robot file it was read from (or the record it came from); two robots of the same values are equal
    wherever they were read."""
    urdf: str = field(compare=False)
    """The URDF's path (the file gives it relative to itself); where it lies does not make the robot, its text does
    (:attr:`urdf_sha256`)."""
    urdf_sha256: str
    """The SHA-256 of the URDF's bytes ("" where it cannot be read): two robots are the same robot wherever their
    files lie, as long as the values and the URDF's text agree."""
    chassis: str
    """The link the free joint holds: any link of the tree."""
    left_wheels: tuple[str, ...]
    """Wheel links driven by the left command; empty with :attr:`right_wheels`: every revolute or continuous joint
    from the chassis about a lateral axis, left or right by the side it sits on."""
    right_wheels: tuple[str, ...]
    imu_frame: str
    """The IMU's frame (a link fixed to the chassis)."""
    laser_frame: str
    """The laser scanner's frame (a link fixed to the chassis)."""
    frames: tuple[str, ...]
    """Other frames that must exist, fixed to the chassis."""
    wheel_radius: float
    """The contact cylinder's radius [m]."""
    wheel_width: float
    """The contact cylinder's width [m]."""
    wheel_offset: float
    """The cylinder's centre outward from the wheel joint along the axle [m]."""
    torque_limit: float
    """Each wheel motor's torque limit [N·m]."""
    no_load_speed: float
    """The motor's no-load wheel speed [rad/s]: drive torque tapers from full at 80 % of it to zero at it."""
    kp: float
    """The driver's wheel-speed PI proportional gain [N·m per rad/s]."""
    ki: float
    """The driver's PI integral gain [N·m per rad]."""
    effective_track_factor: float
    """Effective track / wheel track on our physics [-] (skid steering turns slower than the wheel track says)."""
    limits: RobotLimits
    motor_per_side: bool = False
    """One motor per side drives that side's wheels through a chain or gears (Clearpath's A200 and J100), so they
    turn at one speed; ``False``: each wheel turns freely on its own joint under its side's torque (the reference's
    ATRV-Jr model). Uncoupled, a wheel that lifts off spins up and the side's mean speed, which the driver holds, no
    longer drives the wheels still on the ground."""
    sources: dict[str, str] = field(default_factory=dict, compare=False)
    """Where each value comes from, by dotted name (``"limits.linear_velocity"``)."""
    deploy: dict[str, str | bool] = field(default_factory=dict, compare=False)
    """The file's ``[deploy]`` table: the deploy node's parameters on this robot's stack (its topics, frames and
    command type, relative to the robot's namespace; :mod:`atrv_warp.deploy.parameters` declares and checks them) and
    ``tf_in_namespace``; empty where the file has none. Not the robot's identity: where it runs, not what it is."""
    sensors: tuple[dict, ...] = field(default=(), compare=False)
    """The file's ``[[sensors]]``: the sensors it carries beside :attr:`laser_frame`'s scanner, each a table with
    ``kind``, ``name`` and ``frame`` (and its kind's own keys, which :mod:`atrv_warp.task.sensors` checks). Not the
    robot's identity (a saved policy records them beside it)."""

    @property
    def sensor_frames(self) -> tuple[str, ...]:
        """The IMU's, the laser's, the other frames and the sensors': every link the robot needs fixed to its chassis."""
        return tuple(dict.fromkeys((self.imu_frame, self.laser_frame, *self.frames,
                                    *(s["frame"] for s in self.sensors))))

    @property
    def top_speed(self) -> float:
        """The motor's top rim speed [m/s]: ``no_load_speed x wheel_radius``."""
        return self.no_load_speed * self.wheel_radius

    def summary(self) -> str:
        """One line: the robot and its limits."""
        lim = self.limits
        acc = "" if lim.linear_acceleration is None else f", {lim.linear_acceleration:g} m/s²"
        return (f"{self.name} ({self.title}): up to {lim.linear_velocity:g} m/s{acc} and {lim.angular_velocity:g} "
                "rad/s")


_SCHEMA: dict[str, dict[str, tuple[type, bool]]] = {
    "": {"name": (str, True), "title": (str, True), "urdf": (str, True)},
    "links": {"chassis": (str, True), "left_wheels": (list, False), "right_wheels": (list, False),
              "imu": (str, True), "laser": (str, True), "frames": (list, False)},
    "wheels": {"radius": (float, True), "width": (float, True), "offset": (float, True)},
    "motor": {"torque_limit": (float, True), "no_load_speed": (float, True), "per_side": (bool, False)},
    "driver": {"kp": (float, True), "ki": (float, True), "effective_track_factor": (float, True)},
    "limits": {"linear_velocity": (float, True), "angular_velocity": (float, True),
               "linear_acceleration": (float, False), "angular_acceleration": (float, False)},
}
"""Each table's keys: (type, required). ``[sources]`` maps any of their dotted names to text."""

PHYSICAL_RANGE: dict[str, tuple[float, float]] = {
    "wheels.radius": (0.01, 2.0), "wheels.width": (0.005, 2.0), "wheels.offset": (0.0, 2.0),
    "motor.torque_limit": (0.01, 1e4), "motor.no_load_speed": (0.1, 1e3),
    "driver.kp": (1e-6, 1e4), "driver.ki": (0.0, 1e5), "driver.effective_track_factor": (0.5, 20.0),
    "limits.linear_velocity": (0.01, 50.0), "limits.angular_velocity": (0.01, 50.0),
    "limits.linear_acceleration": (0.01, 1e3), "limits.angular_acceleration": (0.01, 1e3),
}
"""Each number's range [its unit], beyond which no skid-steer rover lies: a wheel of 1 cm to 2 m, a motor of up to
10 kN·m and 1,000 rad/s, a track factor of 0.5-20 (MuJoCo's turn needs 2.6, PhysX's up to 13.6), limits up to
50 m/s. It keeps a mistyped value (``torque_limit = 1e30`` stepped the physics to NaN) out of the simulator, named;
a value inside it is the robot's to set."""

FIELDS: tuple[str, ...] = tuple(f"{t}.{k}" if t else k for t, keys in _SCHEMA.items() for k in keys)
"""Every key of a robot file, dotted (``"limits.linear_velocity"``)."""


def robot_file(spec: str | os.PathLike) -> Path:
    """The robot file ``spec`` names: a shipped robot's name (:data:`ROBOTS`) or a path to a ``.toml`` file."""
    text = os.fspath(spec)
    if not isinstance(text, str) or not text:
        raise RobotFileError(f"a robot is a shipped robot's name ({', '.join(ROBOTS)}) or a robot file's path, got "
                             f"{spec!r}")
    if text in ROBOTS:
        return _shipped_folder() / f"{text}.toml"
    path = Path(text).expanduser()
    if path.suffix == ".toml" or os.sep in text or "/" in text:
        if not path.exists():
            raise RobotFileError(f"robot file not found: {path}")
        return path.resolve()
    raise RobotFileError(f"unknown robot {text!r}; shipped robots: {', '.join(ROBOTS)} (or give the path of a robot "
                         "file, see docs/your-own-robot.md)")


def load_robot(spec: str | os.PathLike | Robot = DEFAULT_ROBOT) -> Robot:
    """The :class:`Robot` that ``spec`` names (a shipped robot's name or a robot file's path; a :class:`Robot` is
    returned as is).

    Raises:
        RobotFileError: an unknown name (the message lists the shipped ones), a missing or malformed file, or a
            missing, mistyped, out-of-range or unknown key (named with its table).
    """
    if isinstance(spec, Robot):
        return spec
    path = robot_file(spec)
    robot = _load(str(path), path.stat().st_mtime_ns)
    digest = _file_digest(robot.urdf)  # the URDF may have changed since its robot file was read
    return robot if digest == robot.urdf_sha256 else dataclasses.replace(robot, urdf_sha256=digest)


@functools.lru_cache(maxsize=32)
def _load(path: str, _mtime: int) -> Robot:
    try:
        data = tomllib.loads(read_input(path, "robot file").decode("utf-8"))
    except tomllib.TOMLDecodeError as err:
        raise RobotFileError(f"{path}: not valid TOML: {err}") from None
    except UnicodeDecodeError as err:
        raise RobotFileError(f"{path}: not UTF-8 text (a TOML file must be): byte {err.start} is "
                             f"{err.object[err.start:err.start + 1]!r}") from None
    except InputFileError as err:
        raise RobotFileError(str(err)) from None
    except OSError as err:
        raise RobotFileError(f"{path}: cannot read: {err}") from None
    return _from_table(path, data)


@functools.lru_cache(maxsize=32)
def _cached_digest(path: str, _mtime: int) -> str:
    return hashlib.sha256(read_input(path, "URDF")).hexdigest()


def _file_digest(path: str | os.PathLike) -> str:
    """The SHA-256 of the file at ``path`` (a URDF), or "" where it cannot be read (a missing file, or one that is not
    a regular file of bounded size: its reader names why)."""
    try:
        return _cached_digest(os.fspath(path), os.stat(path).st_mtime_ns)
    except (OSError, InputFileError):
        return ""


def _from_table(path: str, data: dict, urdf_sha256: str | None = None) -> Robot:
    """``urdf_sha256``: a record's (whose URDF may lie on another machine); None: the URDF's, read now."""

    def fail(message: str):
        raise RobotFileError(f"{path}: {message}")

    deploy = data.pop("deploy", {})  # its keys are the deploy node's parameters: atrv_warp.deploy checks their names
    if not isinstance(deploy, dict) or not all(isinstance(v, bool) or (isinstance(v, str) and v)
                                               for v in deploy.values()):
        fail(f"[deploy] must be a table of names (non-empty text) and switches (true or false), got {deploy!r}")
    sensors = _sensors(data.pop("sensors", []), fail)
    sources = data.pop("sources", {})
    if not isinstance(sources, dict) or not all(isinstance(v, str) for v in sources.values()):
        fail("[sources] must map dotted field names to text")
    unknown_sources = sorted(set(sources) - set(FIELDS))
    if unknown_sources:
        fail(f"[sources] names unknown field(s) {unknown_sources}; known: {', '.join(FIELDS)}")
    values: dict[str, object] = {}
    for table, keys in _SCHEMA.items():
        where = data if not table else data.get(table, {})
        if not isinstance(where, dict):
            fail(f"[{table}] must be a table")
        for key, (kind, required) in keys.items():
            name = f"{table}.{key}" if table else key
            if key not in where:
                if required:
                    fail(f"missing {name}" + (f" (in [{table}])" if table else ""))
                continue
            value = where[key]
            if kind is float:
                if not (isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)):
                    fail(f"{name} must be a finite number, got {value!r}")
                if value < 0 or (value == 0 and name not in ("driver.ki", "wheels.offset")):
                    fail(f"{name} must be > 0, got {value!r}")
                low, high = PHYSICAL_RANGE[name]
                if not low <= value <= high:
                    fail(f"{name} = {value!r} is outside the range a skid-steer rover's lies in, [{low:g}, {high:g}] "
                         f"(PHYSICAL_RANGE): a mistyped value?")
                value = float(value)
            elif kind is bool:
                if not isinstance(value, bool):
                    fail(f"{name} must be true or false, got {value!r}")
            elif kind is list:
                if not (isinstance(value, list) and all(isinstance(v, str) and v for v in value)):
                    fail(f"{name} must be a list of link names, got {value!r}")
                value = tuple(value)
            elif not (isinstance(value, str) and value):
                fail(f"{name} must be a non-empty string, got {value!r}")
            values[name] = value
    unknown = sorted({k for k, v in data.items() if not isinstance(v, dict) and k not in _SCHEMA[""]}
                     | {f"[{k}]" for k, v in data.items() if isinstance(v, dict) and k not in _SCHEMA}
                     | {f"{k}.{key}" for k, v in data.items() if isinstance(v, dict) and k in _SCHEMA
                        for key in v if key not in _SCHEMA[k]})
    if unknown:
        fail(f"unknown field(s) {unknown}; known: {', '.join(FIELDS)}")
    left, right = values.get("links.left_wheels", ()), values.get("links.right_wheels", ())
    if bool(left) != bool(right):
        fail("links.left_wheels and links.right_wheels name the wheels of both sides, or neither (the rule finds "
             "them)")
    if set(left) & set(right):
        fail(f"links: wheel(s) {sorted(set(left) & set(right))} on both sides")
    if left and (len(left) != len(right) or len(left) + len(right) > MAX_WHEELS):
        fail(f"links: {len(left)} left and {len(right)} right wheels; a skid-steer rover has as many on each side, "
             f"{MAX_WHEELS} at most")
    if not ROBOT_NAME.fullmatch(values["name"]):
        fail(f"name must be letters, digits, '_' and '-' (it names the robot's policies and files), got "
             f"{values['name']!r}")
    urdf = Path(values["urdf"]).expanduser()
    urdf = urdf if urdf.is_absolute() else Path(path).parent / urdf
    return Robot(
        name=values["name"], title=values["title"], path=path, urdf=str(urdf),
        urdf_sha256=_file_digest(urdf) if urdf_sha256 is None else urdf_sha256, chassis=values["links.chassis"],
        left_wheels=left, right_wheels=right, imu_frame=values["links.imu"], laser_frame=values["links.laser"],
        frames=values.get("links.frames", ()), wheel_radius=values["wheels.radius"],
        wheel_width=values["wheels.width"], wheel_offset=values["wheels.offset"],
        torque_limit=values["motor.torque_limit"], no_load_speed=values["motor.no_load_speed"],
        kp=values["driver.kp"], ki=values["driver.ki"],
        effective_track_factor=values["driver.effective_track_factor"],
        limits=RobotLimits(values["limits.linear_velocity"], values["limits.angular_velocity"],
                           values.get("limits.linear_acceleration"), values.get("limits.angular_acceleration")),
        motor_per_side=values.get("motor.per_side", False), sources=dict(sources),
        deploy=dict(deploy), sensors=sensors)


ROBOT_NAME = re.compile(r"[A-Za-z0-9_-]+")
"""What a robot's ``name`` may be: it names the robot's policies (``nav_deploy_<name>``), files and ROS parameters."""
SENSOR_KEYS = ("kind", "name", "frame")
"""The keys every ``[[sensors]]`` entry has (text each); the rest are its kind's (:mod:`atrv_warp.task.sensors`)."""


def _sensors(entries, fail) -> tuple[dict, ...]:
    """The ``[[sensors]]`` list, checked for what every sensor has: a kind, a name (a Python identifier, unique,
    not ``scan``: the laser of ``links.laser``) and a frame; its other keys must be text, numbers or switches."""
    if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
        fail(f"[[sensors]] must be a list of tables, got {entries!r:.80}")
    names = {"scan"}
    for i, entry in enumerate(entries):
        for key in SENSOR_KEYS:
            if not (isinstance(entry.get(key), str) and entry[key]):
                fail(f"[[sensors]] entry {i + 1}: {key} must be a non-empty string, got {entry.get(key)!r}")
        name = entry["name"]
        if not name.isidentifier() or name in names:
            fail(f"[[sensors]] entry {i + 1}: name {name!r} must be a Python identifier used once (scan is "
                 "links.laser's)")
        names.add(name)
        bad = sorted(k for k, v in entry.items() if not isinstance(v, str | bool | int | float))
        if bad:
            fail(f"[[sensors]] {name}: {', '.join(bad)} must be text, a number or a switch")
    return tuple(dict(e) for e in entries)


def robot_record(robot: Robot) -> dict:
    """``robot`` as its file's tables (the URDF's path resolved, its text's SHA-256 beside it): what a checkpoint and a saved policy keep, and what
    :func:`robot_from_record` reads back."""
    lim = robot.limits
    limits = {"linear_velocity": lim.linear_velocity, "angular_velocity": lim.angular_velocity}
    limits.update({k: v for k, v in (("linear_acceleration", lim.linear_acceleration),
                                     ("angular_acceleration", lim.angular_acceleration)) if v is not None})
    links = {"chassis": robot.chassis, "imu": robot.imu_frame, "laser": robot.laser_frame, "frames": list(robot.frames)}
    if robot.left_wheels:
        links.update(left_wheels=list(robot.left_wheels), right_wheels=list(robot.right_wheels))
    motor = {"torque_limit": robot.torque_limit, "no_load_speed": robot.no_load_speed}
    if robot.motor_per_side:  # written only where set: a record made before the key reads the same
        motor["per_side"] = True
    record = {"name": robot.name, "title": robot.title, "urdf": robot.urdf, "urdf_sha256": robot.urdf_sha256,
              "links": links,
              "wheels": {"radius": robot.wheel_radius, "width": robot.wheel_width, "offset": robot.wheel_offset},
              "motor": motor,
              "driver": {"kp": robot.kp, "ki": robot.ki, "effective_track_factor": robot.effective_track_factor},
              "limits": limits, "sources": dict(robot.sources)}
    if robot.sensors:  # written only where there are some: a record made before the list reads the same
        record["sensors"] = [dict(s) for s in robot.sensors]
    return record


def robot_spec(robot: Robot) -> str | None:
    """The shipped robot's name that loads ``robot`` (a recorded one) again, or ``None``: a robot of one's own (a
    record keeps its values, not where its file was), or a shipped one whose file has changed since."""
    return robot.name if robot.name in ROBOTS and load_robot(robot.name) == robot else None


def robot_file_sha256(path: str | os.PathLike) -> str:
    """The SHA-256 of a robot file's identity: its bytes less its ``[deploy]`` table (from its header to the next
    table or the end, with the blank lines before it), which says where the robot runs, not what it is. A file
    without one hashes as its bytes. Results files record it (``benchmarks/_common.provenance``)."""
    text = read_input(path, "robot file")
    lines = text.splitlines(keepends=True)
    start = next((i for i, line in enumerate(lines) if line.strip() == b"[deploy]"), None)
    if start is None:
        return hashlib.sha256(text).hexdigest()
    end = next((i for i in range(start + 1, len(lines)) if lines[i].lstrip().startswith(b"[")), len(lines))
    while start > 0 and not lines[start - 1].strip():
        start -= 1
    return hashlib.sha256(b"".join(lines[:start] + lines[end:])).hexdigest()


def robot_from_record(record: dict, where: str) -> Robot:
    """The :class:`Robot` a :func:`robot_record` holds (``where`` names the file it came from in errors)."""
    if not isinstance(record, dict):
        raise RobotFileError(f"{where}: a robot record is a table, got {type(record).__name__}")
    copy = {k: dict(v) if isinstance(v, dict) else v for k, v in record.items()}
    if isinstance(copy.get("sensors"), list):
        copy["sensors"] = [dict(s) if isinstance(s, dict) else s for s in copy["sensors"]]
    digest = copy.pop("urdf_sha256", "")  # a record from before it was kept: never the same as a file's robot
    if not isinstance(digest, str):
        raise RobotFileError(f"{where}: urdf_sha256 must be text, got {digest!r}")
    return _from_table(where, copy, digest)
