"""A robot file checked against its URDF and measured in the simulator: what ``python -m atrv_warp.robot check``
prints and ``benchmarks/robots/robot_check.py`` keeps.

:func:`check_robot` reads the file and its URDF and raises one :class:`~atrv_warp.core.robot.RobotFileError` per
problem, naming the file's field and the link or joint. :func:`measure_robot` drives the robot: its effective track
factor in steady turns, its top speed under full torque, and its driver's ``/cmd_vel`` step response.
:func:`driver_gains` is the rule that picks the driver's PI gains for the wheel and its share of the robot.
"""

from __future__ import annotations

import math
import statistics
from dataclasses import dataclass

import numpy as np
import torch

from atrv_warp.core.robot import Robot, RobotFileError, load_robot
from atrv_warp.sim.config import ContactConfig, RoverConfig, SimConfig
from atrv_warp.sim.urdf import RoverDescription, URDFError, load_rover

__all__ = [
    "ARC_SHARES",
    "FACTOR_RULE",
    "GAIN_RATIO",
    "GRIP_SHARE",
    "IMPLICIT_GAIN_CAP",
    "INTEGRAL_RATIO",
    "IN_PLACE_SHARES",
    "LOOP_TIME",
    "SETTLE_TARGET",
    "STEP_CASES",
    "TURN_FRICTIONS",
    "RobotCheck",
    "check_robot",
    "driver_gains",
    "gain_rule_source",
    "loaded_inertia",
    "measure_robot",
    "rule_gains",
    "settle_misses",
    "track_factor_rule",
    "turn_commands",
    "wheel_inertia",
    "within_grip",
]

GAIN_RATIO = 1.536
"""The driver's rule: ``kp x sim_dt / J = GAIN_RATIO`` for the wheel's axial inertia ``J`` [kg·m²]: the ATRV-Jr's
tuned 3.0 N·m per rad/s on its 0.01953 kg·m² wheel at the 0.01 s substep (``benchmarks/physics/driver_response.py`` chose it:
the fastest pair whose yaw rate overshoots by at most 10 % at µ 0.2-1.0). The loop runs every substep, and a
slipping wheel (its own inertia alone) goes unstable where the ratio reaches 2."""
INTEGRAL_RATIO = 10.0
"""The rule's ``ki / kp`` [1/s] (the ATRV-Jr's 30 / 3)."""
LOOP_TIME = 0.05
"""The implicit loop's rule (:attr:`~atrv_warp.sim.driver.DriverConfig.implicit_speed_loop`): ``kp = J_loaded /
LOOP_TIME`` [s] for a wheel loaded with its share of the robot, ``J_loaded = J + (mass / wheels) r²``, so that every
robot's loaded wheel answers as fast (the ATRV-Jr's tuned 3.0 is 0.082 s, the Jackal's bounded 0.369 is 0.126 s;
``benchmarks/robots/implicit_driver.py`` measures every robot's settling under both loops), at most
:data:`IMPLICIT_GAIN_CAP`."""
IMPLICIT_GAIN_CAP = 4.0
"""The implicit rule's ``kp x sim_dt / J`` at most. It was set when the loop's damping switched off at the torque limit
and, above about 6, flipped every substep on a slipping light wheel (the Jackal at µ 0.3); the friction solve now
holds a wheel at its limit with the damping on (:func:`~atrv_warp.sim.kernels.friction.relax_drive`), and the cap
binds none of the shipped or test robots."""
IN_PLACE_SHARES: tuple[float, ...] = (0.125, 0.25, 0.5, 1.0)
"""Steady turns in place at these shares of the robot's angular limit."""
ARC_SHARES: tuple[tuple[float, float], ...] = ((0.5, 0.25), (0.5, -0.5), (1.0, 0.25), (1.0, 0.5))
"""Steady arcs at these (linear, angular) shares of the robot's limits: at half and all of its linear limit."""
GRIP_SHARE = 0.25
"""A turn whose lateral acceleration (linear x angular) exceeds this share of µ g is past the turns a track factor
serves: the robot slides outward, and how far it turns is set by how it slides. Its error is reported, not fitted.
A quarter, not a half: with each side's wheels geared as one (``ContactConfig.solve_geared_sides``) the Jackal's chi
falls from 1.45 in place to 1.35 at 0.13 µ g, 1.09-1.19 at 0.25 µ g and 1.0 at 0.34 µ g, and a factor fitted over
those turns (1.30 at a half) leaves its turns in place 10 % short of every command."""
FACTOR_RULE = ("the factor with the least mean squared /cmd_vel yaw error over the turns within the tyres' grip "
               f"(lateral acceleration <= {GRIP_SHARE:g} µ g): a driver of factor f turns a robot of chi at f / chi of "
               "the command, so f = sum(1 / chi) / sum(1 / chi^2)")
"""How :func:`measure_robot` picks the effective track factor from the turns' chi (:func:`track_factor_rule`)."""
TURN_FRICTIONS: tuple[float, ...] = (0.3, 0.8)
"""Coulomb µ of the turns and the step response."""
STEP_CASES: tuple[tuple[float, float], ...] = ((0.0, 0.5), (0.3, 0.3), (1.0, 0.2))
"""``/cmd_vel`` steps from rest: in place at 0.5 rad/s, an arc at 0.3 m/s and 0.3 rad/s, and the ATRV-Jr's slow
1 m/s, 0.2 rad/s arc."""
SETTLE_TARGET = 0.5
"""The first two step cases (the judged ones) settle within this [s]."""
LEVEL_TOLERANCE = math.radians(3.0)
"""How far a laser's or an IMU's axes may turn from the chassis' [rad]."""
SIZE_TOLERANCE = 0.02
"""How far the file's wheel radius and width may differ from the URDF's wheel cylinder [share]."""


def _field_of(robot: Robot, err: URDFError) -> str:
    """The robot file's field that a :class:`URDFError` is about."""
    if err.field == "sensor_frames":
        if err.subject == robot.imu_frame:
            return "links.imu"
        if err.subject == robot.laser_frame:
            return "links.laser"
        sensor = next((s for s in robot.sensors if s["frame"] == err.subject), None)
        return "links.frames" if sensor is None else f"[[sensors]] {sensor['name']}.frame"
    return {"chassis_link": "links.chassis", "left_wheels": "links.left_wheels", "right_wheels": "links.right_wheels",
            "urdf": "urdf"}.get(err.field, err.field)


def check_robot(spec) -> tuple[Robot, RoverDescription]:
    """Read the robot file ``spec`` (a shipped robot's name or a path) and its URDF, and check them against each
    other: every named link exists, the wheels hang on lateral joints on both sides with positive masses and
    inertias, the IMU and the laser are fixed to the chassis with their axes the chassis' (the observation reads
    the IMU in the chassis' axes; the scan is a horizontal plane; another laser of ``[[sensors]]`` may be turned about
    z only), and the file's wheel size is the URDF's cylinder.

    Raises:
        RobotFileError: the first problem, naming the file's field and the link or joint.
    """
    robot = load_robot(spec)
    try:
        description = load_rover(RoverConfig(robot=robot.path))
    except URDFError as err:
        where = f" ({err.subject})" if err.subject else ""
        raise RobotFileError(f"{robot.path}: {_field_of(robot, err)}{where}: {err}") from None
    frames = {f.name: f.transform for f in description.frames}
    for field, name in (("links.imu", robot.imu_frame), ("links.laser", robot.laser_frame)):
        rotation = np.asarray(frames[name])[:3, :3]
        angle = math.acos(max(-1.0, min(1.0, (float(np.trace(rotation)) - 1.0) / 2.0)))
        if angle > LEVEL_TOLERANCE:
            raise RobotFileError(
                f"{robot.path}: {field} ({name}): the frame is turned {math.degrees(angle):.1f} deg from the chassis "
                f"{robot.chassis!r}; the {'IMU is read in the chassis axes' if field == 'links.imu' else 'scan is a horizontal plane looking forward'}: "
                "mount a frame with the chassis' axes (a fixed joint with rpy 0 0 0) and name it")
    for sensor in robot.sensors:  # another laser may look any way, but its scan too is a horizontal plane
        if sensor["kind"] == "laser":
            tilt = math.acos(max(-1.0, min(1.0, float(np.asarray(frames[sensor["frame"]])[2, 2]))))
            if tilt > LEVEL_TOLERANCE:
                raise RobotFileError(
                    f"{robot.path}: [[sensors]] {sensor['name']}.frame ({sensor['frame']}): the frame's z is tilted "
                    f"{math.degrees(tilt):.1f} deg from the chassis' and the scan is a horizontal plane: mount it "
                    "level (a fixed joint with rpy 0 0 yaw)")
    for wheel in description.wheels:
        for field, mine, urdf in (("wheels.radius", robot.wheel_radius, wheel.radius),
                                  ("wheels.width", robot.wheel_width, wheel.width)):
            if urdf is not None and abs(mine - urdf) > SIZE_TOLERANCE * urdf:
                raise RobotFileError(f"{robot.path}: {field} ({wheel.link}): the file says {mine:g} m, the URDF's "
                                     f"wheel cylinder {urdf:g} m")
    return robot, description


def turn_commands(robot: Robot) -> tuple[tuple[float, float], ...]:
    """(linear [m/s], angular [rad/s]) steady turns over ``robot``'s range: :data:`IN_PLACE_SHARES` and
    :data:`ARC_SHARES` of its limits."""
    v, w = robot.limits.linear_velocity, robot.limits.angular_velocity
    return (tuple((0.0, round(a * w, 4)) for a in IN_PLACE_SHARES)
            + tuple((round(a * v, 4), round(b * w, 4)) for a, b in ARC_SHARES))


def within_grip(turn: dict) -> bool:
    """Whether a turn (``linear`` [m/s], ``angular`` [rad/s], ``friction``) is within :data:`GRIP_SHARE` of the grip."""
    return abs(turn["linear"] * turn["angular"]) <= GRIP_SHARE * turn["friction"] * -SimConfig().gravity


def track_factor_rule(turns: list[dict]) -> float:
    """The effective track factor by :data:`FACTOR_RULE` from the ``turns`` (each with its ``chi``)."""
    inverse = [1.0 / float(t["chi"]) for t in turns if within_grip(t)]
    if not inverse:
        raise ValueError("no turn within the tyres' grip to fit the effective track factor on")
    return sum(inverse) / sum(x * x for x in inverse)


def settle_misses(steps: list[dict], target: float = SETTLE_TARGET) -> list[str]:
    """The judged step cases (the first two of :data:`STEP_CASES`) that settle later than ``target`` [s] or never,
    each as "in place 0.5 rad/s at µ 0.8: 0.65 s"."""
    misses = []
    for s in steps:
        if (s["linear"], s["angular"]) in STEP_CASES[:2] and not s["settle"] <= target:
            label = (f"in place {s['angular']:g} rad/s" if s["linear"] == 0 else
                     f"arc {s['linear']:g} m/s, {s['angular']:g} rad/s")
            took = "never" if not math.isfinite(s["settle"]) else f"{s['settle']:.2f} s"
            misses.append(f"{label} at µ {s['friction']:g}: {took}")
    return misses


def wheel_inertia(description: RoverDescription) -> float:
    """The wheels' smallest moment of inertia about their axle [kg·m²]."""
    return min(float(w.axis @ w.inertial.inertia @ w.axis) for w in description.wheels)


def rule_gains(inertia: float, loaded_inertia: float, sim_dt: float | None = None, *, implicit: bool = True
               ) -> tuple[float, float]:
    """(kp [N·m per rad/s], ki [N·m per rad]) by the rule, for a wheel of axial ``inertia`` [kg·m²] that carries its
    share of the robot as ``loaded_inertia`` (``J + (mass / wheels) r²``): for the implicit loop (the default driver's,
    :attr:`~atrv_warp.sim.driver.DriverConfig.implicit_speed_loop`) :data:`LOOP_TIME` within
    :data:`IMPLICIT_GAIN_CAP`, for the explicit one :data:`GAIN_RATIO` at the substep ``sim_dt`` (default
    :class:`~atrv_warp.sim.config.SimConfig`'s); ``ki = INTEGRAL_RATIO x kp``; three significant figures."""
    dt = SimConfig().sim_dt if sim_dt is None else sim_dt
    kp = min(loaded_inertia / LOOP_TIME, IMPLICIT_GAIN_CAP * inertia / dt) if implicit else GAIN_RATIO * inertia / dt
    kp = float(f"{kp:.3g}")
    return kp, float(f"{INTEGRAL_RATIO * kp:.3g}")


def gain_rule_source(inertia: float, loaded_inertia: float, kp: float, day: str) -> str:
    """A robot file's ``[sources]`` line for the rule's ``driver.kp`` (:func:`rule_gains`, the implicit loop's)."""
    capped = kp < float(f"{loaded_inertia / LOOP_TIME:.3g}")
    bound = f", capped at kp x sim_dt / J = {IMPLICIT_GAIN_CAP:g}" if capped else ""
    return (f"the rule of `python -m atrv_warp.robot check` (kp = J_loaded / {LOOP_TIME:g} s for the wheel loaded "
            f"with its share of the robot, J_loaded = {loaded_inertia:.4g} kg m², axial J = {inertia:.4g} kg m²"
            f"{bound}), {day}")


def driver_gains(description: RoverDescription, sim_dt: float | None = None, *, implicit: bool = True,
                 wheel_radius: float | None = None) -> tuple[float, float]:
    """:func:`rule_gains` for a robot's wheels (:func:`wheel_inertia`, :func:`loaded_inertia` at ``wheel_radius``)."""
    return rule_gains(wheel_inertia(description), loaded_inertia(description, wheel_radius), sim_dt,
                      implicit=implicit)


def loaded_inertia(description: RoverDescription, wheel_radius: float | None = None) -> float:
    """A wheel's axial inertia with its share of the robot's mass at the rim, ``J + (mass / wheels) r²`` [kg·m²],
    at ``wheel_radius`` [m] (default: the URDF's)."""
    radius = description.wheel_radius if wheel_radius is None else wheel_radius
    if radius is None:
        raise ValueError("the gain rule needs the wheel radius: the URDF gives none, pass wheel_radius")
    return wheel_inertia(description) + description.total_mass / len(description.wheels) * radius ** 2


@dataclass
class RobotCheck:
    """What :func:`measure_robot` measured."""

    robot: str
    title: str
    mass: float
    """[kg]"""
    wheel_radius: float
    """[m]"""
    track: float
    """Between the left and right wheels' contact centres [m]."""
    wheelbase: float
    """Between the front and rear wheel joints [m]."""
    reach: float
    """From the chassis' centre of mass to its farthest corner [m]."""
    wheel_inertia: float
    """[kg·m²]"""
    loaded_inertia: float
    """A wheel with its share of the robot at the rim (:func:`loaded_inertia`) [kg·m²]."""
    gains: dict
    """``{"kp", "ki"}`` by the rule (the file's are in ``file``)."""
    effective_track_factor: float
    """By :data:`FACTOR_RULE` over the turns and frictions [-]."""
    turns: list
    """Each turn over the robot's range (:func:`turn_commands`): command, µ, ``chi`` (through a differential drive's
    wheel targets), and through the driver with :attr:`effective_track_factor` the ``yaw_error`` (yaw rate over the
    command, less 1) and the ``odometry_error`` (the wheel odometry's yaw rate over the true one, less 1)."""
    top_speed: float
    """Under full torque on both sides at µ 0.8, the mean over the last half second of three [m/s], at most the
    motor's no-load speed at the rim (:attr:`top_speed_measured` is the simulator's figure)."""
    top_speed_measured: float
    """[m/s]"""
    steps: list
    """Each ``/cmd_vel`` step: command, µ, ``settle`` [s], ``overshoot`` [-]."""
    settle_misses: list
    """The judged steps that miss :data:`SETTLE_TARGET` (:func:`settle_misses`); empty: the robot settles."""
    file: dict
    """The file's own gains, factor and limits."""

    def as_dict(self) -> dict:
        from dataclasses import asdict

        return asdict(self)


def _turns(rover: RoverConfig, description: RoverDescription, commands, frictions, seconds: float
           ) -> tuple[list[dict], float]:
    """Each steady turn's chi through a differential drive's wheel targets; then, through the driver with the factor
    :func:`track_factor_rule` picks from them, its yaw and odometry errors. Returns (the turns, the factor)."""
    from atrv_warp.core.kinematics import track_width
    from atrv_warp.sim.driver import DriverConfig
    from atrv_warp.sim.protocols import turning_response

    r, track = rover.wheel_radius, track_width(description, rover)

    def drive(factor: float, mu: float) -> list[dict]:
        return turning_response(commands, driver=DriverConfig(wheel_radius=r, track_width=track,
                                                              effective_track_factor=factor),
                                contact=ContactConfig(friction=mu), rover=rover, seconds=seconds,
                                average=min(4.0, seconds / 2))

    rows = [{"linear": row["linear"], "angular": row["angular"], "friction": mu,
             "chi": r * (row["wheel_right"] - row["wheel_left"]) / (row["yaw_rate"] * track)}
            for mu in frictions for row in drive(1.0, mu)]
    factor = track_factor_rule(rows)
    driven = [row for mu in frictions for row in drive(factor, mu)]
    for t, row in zip(rows, driven, strict=True):
        t["yaw_error"] = row["yaw_rate"] / row["angular"] - 1.0
        odometry = r * (row["wheel_right"] - row["wheel_left"]) / (factor * track)
        t["odometry_error"] = odometry / row["yaw_rate"] - 1.0
    return rows, factor


def _top_speed(rover: RoverConfig, torque: float, seconds: float = 3.0) -> float:
    """Full ``torque`` on both sides from rest at µ 0.8 for ``seconds``, from one end of the standard arena (Newton's
    floating base keeps its velocity at the world origin: far from it, float32 rounding feeds a fast rover energy,
    so the run stays in the arena): the mean speed over the last half second [m/s]."""
    from atrv_warp.sim.simulator import RoverSim

    sim = RoverSim(1, rover=rover, contact=ContactConfig(friction=0.8))
    sim.reset(poses=[[-0.45 * sim.arena_cfg.size, 0.0, 0.0]])
    dt = sim.sim_cfg.step_dt
    speeds = []
    for _ in range(round(seconds / dt)):
        sim.set_commands(torch.tensor([[torque, torque]]))
        sim.step()
        speeds.append(float(sim.lin_vel[0, :2].norm()))
    return statistics.fmean(speeds[-round(0.5 / dt):])


def measure_robot(spec, *, frictions=TURN_FRICTIONS, turn_seconds: float = 15.0, step_seconds: float = 5.0,
                  progress=None) -> RobotCheck:
    """Check ``spec`` (:func:`check_robot`), then drive it: the effective track factor (steady turns over the robot's
    range, :func:`turn_commands` at each µ of ``frictions``, through a differential drive's wheel targets; ``chi = r
    (w_right - w_left) / (yaw rate x track)``; the factor by :data:`FACTOR_RULE`, and each turn's yaw and odometry
    errors through the driver with it), the top speed under full torque, and the ``/cmd_vel`` step response of its
    driver with the rule's gains and that factor (:data:`STEP_CASES`, no limits; the time after which the yaw rate
    stays within 10 % of the command to the end of ``step_seconds``), judged against :data:`SETTLE_TARGET`.
    ``progress``: called with a line before each part."""
    from atrv_warp.core.kinematics import track_width
    from atrv_warp.sim.driver import DriverConfig
    from atrv_warp.sim.protocols import step_response

    say = progress or (lambda _line: None)
    robot, description = check_robot(spec)
    rover = RoverConfig(robot=robot.path)
    kp, ki = driver_gains(description, wheel_radius=robot.wheel_radius)
    say("steady turns over the robot's range (effective track factor, then /cmd_vel yaw error)")
    turns, factor = _turns(rover, description, turn_commands(robot), frictions, turn_seconds)
    say("full torque (top speed)")
    top = _top_speed(rover, robot.torque_limit)
    say("/cmd_vel steps (driver response)")
    steps = step_response(STEP_CASES, frictions, seconds=step_seconds, rover=rover,
                          driver=DriverConfig(kp=kp, ki=ki, effective_track_factor=round(factor, 2)))
    xs = [float(w.origin[0, 3]) for w in description.wheels]
    lim = robot.limits
    return RobotCheck(
        robot=robot.name, title=robot.title, mass=description.total_mass, wheel_radius=robot.wheel_radius,
        track=track_width(description, rover), wheelbase=max(xs) - min(xs), reach=description.reach,
        wheel_inertia=wheel_inertia(description), loaded_inertia=loaded_inertia(description, robot.wheel_radius),
        gains={"kp": kp, "ki": ki},
        effective_track_factor=factor, turns=turns, top_speed=min(top, robot.top_speed), top_speed_measured=top,
        steps=[{k: s[k] for k in ("linear", "angular", "friction", "settle", "overshoot")} for s in steps],
        settle_misses=settle_misses(steps),
        file={"kp": robot.kp, "ki": robot.ki, "effective_track_factor": robot.effective_track_factor,
              "torque_limit": robot.torque_limit, "motor_per_side": robot.motor_per_side,
              "limits": {"linear_velocity": lim.linear_velocity, "angular_velocity": lim.angular_velocity}})
