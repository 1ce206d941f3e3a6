"""Configuration of the simulator: the rover (and its registered variants), the contact law,
the arena and the integrator. A simulator-config file of them is :mod:`atrv_warp.sim.config_file`'s.

Every physical quantity carries its SI unit. Configs are frozen dataclasses: derive a
variant with :func:`dataclasses.replace`, never mutate a shared default.
"""

from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass

from atrv_warp.core.robot import DEFAULT_ROBOT, Robot, load_robot

__all__ = [
    "FAST_SIM_DT",
    "FRICTION_LAWS",
    "NO_WALL",
    "REFERENCE_SIM_DT",
    "SENSOR_NOISE",
    "VARIANTS",
    "ArenaConfig",
    "ContactConfig",
    "InertialOverride",
    "ObstacleConfig",
    "RoverConfig",
    "SensorNoise",
    "SimConfig",
    "default_urdf_path",
    "get_variant",
    "nominal_rover_config",
    "replace_checked",
]


def default_urdf_path() -> str:
    """Path of the default robot's URDF (the ATRV-Jr's, shipped inside the package)."""
    return load_robot(DEFAULT_ROBOT).urdf


def _is_number(value) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _check_types(cfg, defaults: dict | None = None) -> None:
    """Each field of a config dataclass of the type its default has (a number, a string, a tuple of strings or of
    numbers of the default's length), a list taken as a tuple; raise a ``TypeError`` naming the field. ``defaults``
    stands in for the defaults of fields whose default is ``None`` (a robot's values)."""
    for f in dataclasses.fields(cfg):
        value, default = getattr(cfg, f.name), (defaults or {}).get(f.name, f.default)
        if isinstance(value, list):
            value = tuple(value)
            object.__setattr__(cfg, f.name, value)
        where = f"{type(cfg).__name__}.{f.name}"
        if (value is None and "None" in str(f.type)) or default is None or f.name == "inertial_overrides":
            continue  # optional fields and the overrides' own checks
        if _is_number(default) and not _is_number(value):
            raise TypeError(f"{where} must be a number, got {value!r} ({type(value).__name__})")
        if isinstance(default, str) and not isinstance(value, str):
            raise TypeError(f"{where} must be a string, got {value!r} ({type(value).__name__})")
        if isinstance(default, tuple):
            kind = "a number" if default and all(map(_is_number, default)) else "a string"
            ok = isinstance(value, tuple) and all(_is_number(v) if kind == "a number" else isinstance(v, str)
                                                 for v in value)
            if not ok or (kind == "a number" and len(value) != len(default)):
                size = f"{len(default)} numbers" if kind == "a number" else "names (strings)"
                raise TypeError(f"{where} must be a list of {size}, got {value!r}")


@dataclass(frozen=True)
class InertialOverride:
    """Replaces the mass properties a URDF gives one link (used by the ``reference`` variant)."""

    link: str
    """Name of the link whose inertial is replaced."""
    mass: float
    """Mass [kg]."""
    inertia_diag: tuple[float, float, float] | None = None
    """Principal moments about the link's inertial frame [kg·m²]; ``None`` keeps the
    URDF's inertia tensor scaled by the mass ratio."""

    def __post_init__(self):
        if not isinstance(self.link, str) or not self.link:
            raise TypeError(f"InertialOverride.link must name a link, got {self.link!r}")
        if not (_is_number(self.mass) and math.isfinite(self.mass) and self.mass > 0):
            raise ValueError(f"InertialOverride.mass of {self.link!r} must be a finite number > 0 [kg], got "
                             f"{self.mass!r}")
        if self.inertia_diag is not None:
            diag = tuple(self.inertia_diag) if isinstance(self.inertia_diag, list | tuple) else None
            if diag is None or len(diag) != 3 or not all(_is_number(v) and math.isfinite(v) and v > 0 for v in diag):
                raise ValueError(f"InertialOverride.inertia_diag of {self.link!r} must be three finite numbers > 0 "
                                 f"[kg·m²], got {self.inertia_diag!r}")
            object.__setattr__(self, "inertia_diag", diag)


@dataclass(frozen=True)
class RoverConfig:
    """Which robot to simulate and what differs from its file: every field left ``None`` is the robot's
    (:class:`~atrv_warp.core.robot.Robot`, filled in on construction), so ``RoverConfig()`` is the ATRV-Jr and
    ``RoverConfig(robot="jackal")`` the Jackal. To change the robot of a config, build a new one
    (:func:`replace_checked` does): ``dataclasses.replace`` would keep the old robot's filled-in fields."""

    robot: str = DEFAULT_ROBOT
    """A shipped robot's name (``atrvjr``, ``jackal``, ``husky``) or the path of a robot file."""
    urdf: str | None = None
    """Path of the URDF; ``None``: the robot's."""
    chassis_link: str | None = None
    """Link joined to the world by the free 6-DOF joint; ``None``: the robot's."""
    left_wheels: tuple[str, ...] | None = None
    """Wheel links driven by the first (left) command; ``None``: the robot's (empty: found by the rule)."""
    right_wheels: tuple[str, ...] | None = None
    """Wheel links driven by the second (right) command; ``None``: the robot's."""
    sensor_frames: tuple[str, ...] | None = None
    """Links fixed to the chassis that must exist; kept as named frames. ``None``: the robot's IMU, laser and other
    frames."""
    wheel_radius: float | None = None
    """Radius of the wheel collision cylinder [m]; ``None``: the robot's."""
    wheel_length: float | None = None
    """Length (width) of the wheel collision cylinder [m]; ``None``: the robot's."""
    wheel_offset: float | None = None
    """Offset of the cylinder centre from the wheel joint along the axle, outward [m]; ``None``: the robot's."""
    wheel_speed_limit: float | None = None
    """Motor no-load speed [rad/s] (the ATRV-Jr's 50 rad/s = 6.25 m/s at the rim); ``None``: the robot's. Drive
    torque tapers linearly from full at 80 % of this speed to zero at it, like a DC motor's back-EMF; an unbounded
    torque source otherwise spins a slipping wheel to 1000+ rad/s."""
    inertial_overrides: tuple[InertialOverride, ...] = ()
    """Mass-property replacements applied after loading the URDF."""
    torque_scale: float = 1.0
    """Torque the motors deliver per unit of commanded torque [-] (a calibrated motor's gain)."""
    payload_mass: float = 0.0
    """A point payload on the chassis [kg]."""
    payload_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Where the payload sits, from the chassis' centre of mass in the chassis frame [m]."""

    @property
    def robot_spec(self) -> Robot:
        """The :class:`~atrv_warp.core.robot.Robot` this config starts from."""
        return load_robot(self.robot)

    def __post_init__(self):
        if isinstance(self.robot, os.PathLike):
            object.__setattr__(self, "robot", os.fspath(self.robot))
        if not isinstance(self.robot, str):
            raise TypeError(f"RoverConfig.robot must be a robot's name or a robot file's path, got {self.robot!r}")
        robot = load_robot(self.robot)
        own = {"urdf": robot.urdf, "chassis_link": robot.chassis, "left_wheels": robot.left_wheels,
               "right_wheels": robot.right_wheels, "sensor_frames": robot.sensor_frames,
               "wheel_radius": robot.wheel_radius, "wheel_length": robot.wheel_width,
               "wheel_offset": robot.wheel_offset, "wheel_speed_limit": robot.no_load_speed}
        for name, value in own.items():
            if getattr(self, name) is None:
                object.__setattr__(self, name, value)
        _check_types(self, {k: v for k, v in own.items() if k != "urdf"})
        if not isinstance(self.urdf, str | os.PathLike):
            raise TypeError(f"RoverConfig.urdf must be a path, got {self.urdf!r}")
        if not isinstance(self.inertial_overrides, tuple) or not all(
                isinstance(ov, InertialOverride) for ov in self.inertial_overrides):
            raise TypeError("RoverConfig.inertial_overrides must be InertialOverride entries (in a sim config: "
                            f"tables with link, mass and inertia_diag), got {self.inertial_overrides!r}")
        for name in ("wheel_radius", "wheel_speed_limit"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"RoverConfig.{name} must be a finite number > 0, got {value!r}")
        for name in ("torque_scale", "payload_mass"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"RoverConfig.{name} must be a finite number >= 0, got {value!r}")
        if len(self.payload_offset) != 3 or not all(math.isfinite(v) for v in self.payload_offset):
            raise ValueError(f"RoverConfig.payload_offset must be three finite numbers [m], got {self.payload_offset!r}")


ROBOT_FIELDS = ("urdf", "chassis_link", "left_wheels", "right_wheels", "sensor_frames", "wheel_radius",
                "wheel_length", "wheel_offset", "wheel_speed_limit")
"""The :class:`RoverConfig` fields that are the robot's unless set."""

FRICTION_LAWS = ("coulomb", "viscous")
"""Values of :attr:`ContactConfig.friction_law`."""


@dataclass(frozen=True)
class ContactConfig:
    """Hunt–Crossley penalty contact with Coulomb friction.

    Normal force per contact point, penetration ``d`` [m] and its rate ``d_dot`` [m/s]:
    ``f_n = kp d^n + kc d^n d_dot`` (clamped at 0, no adhesion). Below ``linear_region``
    the ``d^n`` factor is replaced by its secant ``linear_region^(n-1) d`` so the stiffness
    stays finite at first touch. Defaults are the reference simulation's figures.

    Friction (:attr:`friction_law`): the wheels' ground contacts are solved together, per world and
    substep, as a velocity-level Coulomb problem (``kernels/friction.py``): a wheel sticks, with
    whatever force up to ``mu f_n`` keeps its contact point still, or slides with ``mu f_n`` against
    its slip. Every other contact (walls, obstacles, the chassis) keeps the regularised law below.
    """

    stiffness: float = 1.0e5
    """kp [N/m^n]."""
    damping: float = 2.0e4
    """kc [N·s/m^(n+1)]."""
    exponent: float = 1.5
    """n, Hertz-like exponent [-]."""
    linear_region: float = 1.0e-3
    """Penetration below which the law is linear [m]."""
    friction: float = 0.3
    """Coulomb coefficient mu [-]."""
    friction_rise: float = 0.0
    """How the wheels' sliding friction rises with slip speed [s/m]: a sliding contact's coefficient is
    ``mu (1 + friction_rise x slip)``, its slip speed [m/s] taken at the substep's start (0: Coulomb's constant
    mu). Rubber's friction can rise with sliding speed (Grosch 1963), and a contact that loses energy as its wheels
    slide harder (the MuJoCo twin's, whose wheels hop in brisk turns at high mu) resists brisk turns more than slow
    ones: a rover near its torque limit then turns at a capped rate where Coulomb's law lets it turn at any rate or
    not at all. Not drawn by the domain randomization; fitted by ``atrv-calibrate --params ...,friction_rise``
    (``docs/calibration.md``)."""
    friction_law: str = "coulomb"
    """``"coulomb"``: the wheels' ground friction is solved at velocity level (stick and slide, as a
    real tyre on firm ground). ``"viscous"``: every contact uses the regularised law of releases
    0.1.x (force proportional to slip up to ``mu f_n``, see :attr:`friction_slope_fraction`), under
    which a rover turns about five times slower than Coulomb friction allows and mu hardly matters;
    kept to reproduce those releases' rollouts (``tests/test_reference_task.py``)."""
    friction_slope_fraction: float = 0.5
    """Low-slip viscous slope of the regularised friction law as a fraction of the largest slope an
    explicit step of ``sim_dt`` stays stable with (``m_eff / sim_dt`` per contact direction).
    Friction is ``mu f_n`` once slip exceeds ``mu f_n dt / (fraction m_eff)``; below it,
    proportional to slip. Used by walls, obstacles and the chassis, and by the wheels under the
    ``"viscous"`` law."""
    damping_limit: float | None = 0.1
    """Ceiling on the damping coefficient ``kc d^n`` [N·s/m], as a fraction of the explicit
    stability limit ``m_eff / sim_dt`` (``m_eff``: a quarter of the rover). The coefficient grows
    with depth, and an explicit step integrates a damper stably only while
    ``coefficient x sim_dt / m_eff`` stays small: past that it overshoots, and a deep impact leaves
    faster than it came in. It engages only in impacts (where, ``benchmarks/physics/physics_report.py``
    prints). ``None``: the plain law."""
    patch: float = 0.0
    """On terrain, each wheel's ground is the plane of the terrain's mean over a patch (five samples, +-``patch`` x
    the wheel's radius along the rim and +-half its width across it), not the tangent plane at its deepest point: a
    tyre touches over a patch. 0 (the default): one point. The study of whether the single point makes the turn on
    uneven ground depend on the contact stiffness (``benchmarks/physics/contact_stiffness.py``)."""
    solve_geared_sides: bool = True
    """For a robot with one motor per side (``motor.per_side``): the friction solve turns each side's wheels as one
    body, the chain's coupling inside the solve, and gives each wheel the chain's torque that keeps it with its side
    within the substep (the default). ``False``: the chain's torque is the drive's, explicit (each wheel brought to the side's
    speed, friction aside), which converges only as the substep shrinks on uneven ground
    (``benchmarks/physics/contact_stiffness.py``)."""

    def __post_init__(self):
        _check_types(self)
        if self.damping_limit is not None and not _is_number(self.damping_limit):
            raise TypeError(f"ContactConfig.damping_limit must be a number or None, got {self.damping_limit!r}")
        for name in ("stiffness", "damping", "linear_region"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"ContactConfig.{name} must be a finite number >= 0, got {value!r}")
        if not (math.isfinite(self.exponent) and self.exponent >= 1):
            raise ValueError(f"ContactConfig.exponent must be a finite number >= 1, got {self.exponent!r}")
        if not (math.isfinite(self.stiffness) and self.stiffness > 0):
            raise ValueError(f"ContactConfig.stiffness must be a finite number > 0, got {self.stiffness!r}")
        if not (math.isfinite(self.friction) and self.friction > 0):
            raise ValueError(f"ContactConfig.friction must be a finite number > 0, got {self.friction!r}")
        if not (math.isfinite(self.friction_rise) and self.friction_rise >= 0):
            raise ValueError(f"ContactConfig.friction_rise must be a finite number >= 0, got {self.friction_rise!r}")
        if self.friction_law not in FRICTION_LAWS:
            raise ValueError(f"ContactConfig.friction_law must be one of {FRICTION_LAWS}, got {self.friction_law!r}")
        if not (math.isfinite(self.friction_slope_fraction) and self.friction_slope_fraction > 0):
            raise ValueError("ContactConfig.friction_slope_fraction must be a finite number > 0, got "
                             f"{self.friction_slope_fraction!r}")
        if not (math.isfinite(self.patch) and 0 <= self.patch <= 1):
            raise ValueError(f"ContactConfig.patch must be a number in [0, 1] (a share of the radius), got "
                             f"{self.patch!r}")
        if self.damping_limit is not None and not (math.isfinite(self.damping_limit) and self.damping_limit > 0):
            raise ValueError(f"ContactConfig.damping_limit must be > 0 or None (no ceiling), got {self.damping_limit!r}")


NO_WALL = 1.0e6
"""Where an arena without walls puts each wall's face [m]: beyond any rover's reach and any beam's range."""


@dataclass(frozen=True)
class ArenaConfig:
    """Ground box and four walls of the reference arena (or the ground alone: :attr:`walls`)."""

    size: float = 30.0
    """Side of the square ground [m]."""
    ground_thickness: float = 0.25
    """[m]"""
    ground_center_z: float = -0.1
    """Height of the ground box centre [m]; the top is at centre + thickness/2 = 0.025 m."""
    wall_thickness: float = 0.25
    """[m]"""
    wall_height: float = 2.5
    """[m]"""
    target_radius: float = 0.25
    """Radius of the target disc (graphics only) [m]."""
    walls: bool = True
    """The four walls around the ground; without them a rover drives on past the ground box's edge (the ground is a
    plane to the contact and the laser; a terrain's edge heights continue beyond its grid), nothing stops it and no
    beam ends on a wall: open ground, for goals farther than the arena allows."""

    @property
    def ground_top(self) -> float:
        """Height of the driving surface [m]."""
        return self.ground_center_z + 0.5 * self.ground_thickness

    @property
    def half_size(self) -> float:
        """Distance from the centre to each wall's inner face [m]."""
        return 0.5 * self.size

    def boxes(self) -> tuple[tuple[str, tuple[float, float, float], tuple[float, float, float]], ...]:
        """(label, centre [m], half extents [m]) of the ground and the four walls: what the model
        builds and the viewer draws."""
        h, t = self.half_size, 0.5 * self.wall_thickness
        zc, hz = self.ground_top + 0.5 * self.wall_height, 0.5 * self.wall_height
        ground = (("ground", (0.0, 0.0, self.ground_center_z), (h, h, 0.5 * self.ground_thickness)),)
        if not self.walls:
            return ground
        return (
            *ground,
            ("wall_+x", (h + t, 0.0, zc), (t, h + 2 * t, hz)),
            ("wall_-x", (-h - t, 0.0, zc), (t, h + 2 * t, hz)),
            ("wall_+y", (0.0, h + t, zc), (h, t, hz)),
            ("wall_-y", (0.0, -h - t, zc), (h, t, hz)),
        )

    def planes(self) -> tuple[tuple[tuple[float, float, float], float], ...]:
        """(normal, offset) of each box's inner face as a half-space ``n·x >= offset``, same order
        as :meth:`boxes`: what the contact kernel tests. Without :attr:`walls`, each wall's half-space holds every
        point a rover can reach (its face :data:`NO_WALL` away), so none is ever met."""
        h = self.half_size if self.walls else NO_WALL
        return (((0.0, 0.0, 1.0), self.ground_top), ((1.0, 0.0, 0.0), -h), ((-1.0, 0.0, 0.0), -h),
                ((0.0, 1.0, 0.0), -h), ((0.0, -1.0, 0.0), -h))


@dataclass(frozen=True)
class ObstacleConfig:
    """Room for static obstacles (upright boxes and cylinders) in every world.

    Layouts are written per world through :attr:`atrv_warp.sim.RoverSim.obstacles` (a task's sampler
    does it on reset); the slots beyond a layout stay empty.
    """

    slots: int = 8
    """Obstacles per world at most."""
    height: float = 1.0
    """Height of every obstacle above the flat ground's top [m] (taller than the rover, 0.6 m)."""


@dataclass(frozen=True)
class SensorNoise:
    """Noise of the rover's sensors, declared once: the training environment's noisy observations
    (:class:`atrv_warp.task.randomization.RandomizationConfig`) and the ROS node's topics read the same
    settings, so a policy trains with the noise it meets when deployed. Standard deviations of zero-mean
    Gaussian noise, drawn independently per reading."""

    scan_range: float = 0.01
    """Laser range noise [m] (a SICK LMS 2xx: about 0.01)."""
    scan_dropout: float = 0.0
    """Probability that a beam returns nothing (reads the maximum range) [-]."""
    velocity: float = 0.05
    """Noise of the velocity estimate (the observation's vx, vy; the odometry's twist) [m/s]."""
    gyro: float = 0.005
    """Gyroscope noise (the observation's yaw rate; /imu angular velocity) [rad/s]."""
    attitude: float = 0.005
    """Noise of the roll estimate (the observation's roll) [rad]."""
    accel: float = 0.05
    """Accelerometer noise (/imu linear acceleration) [m/s²]."""
    wheel_speed: float = 0.02
    """Wheel-encoder speed noise (/joint_states velocity) [rad/s]."""

    def __post_init__(self):
        _check_types(self)
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"SensorNoise.{f.name} must be a finite number >= 0, got {value!r}")
        if self.scan_dropout > 1:
            raise ValueError(f"SensorNoise.scan_dropout is a probability, got {self.scan_dropout!r}")


SENSOR_NOISE = SensorNoise()
"""The ATRV-Jr's sensors as the ROS node simulates them by default, and as the randomization presets
train with."""


REFERENCE_SIM_DT = 0.01
"""The reference's integration step [s] (RK4 at 0.01 s), and :class:`SimConfig`'s default: five
substeps per step. With ``ContactConfig(damping_limit=None, friction_law="viscous")`` it reproduces
the releases before issue 17 bit for bit."""

FAST_SIM_DT = 0.05 / 3
"""Three substeps per step [s]: ``SimConfig(sim_dt=FAST_SIM_DT)`` makes a step cheaper, with the physics
report's figures, non-finite checks and wall impacts validated (``benchmarks/physics/substep_study.py``). Not
the default: SAC on the reach task learns a little less per frame on it
(``benchmarks/training/substep_training.py``), and training, bound by its updates, is no quicker. The figures
are on the docs' performance page. ``EnvConfig.substeps = 3`` trains on it."""


@dataclass(frozen=True)
class SimConfig:
    """Integrator settings. Chosen by measurement (the docs' physics and performance pages)."""

    step_dt: float = 0.05
    """Simulated time of one environment step [s]."""
    sim_dt: float = REFERENCE_SIM_DT
    """Solver substep [s]: five per step, as the reference integrated. :data:`FAST_SIM_DT` is three."""
    gravity: float = -9.81
    """[m/s²] along z."""
    mass_matrix_interval: int | None = None
    """Featherstone mass-matrix refresh interval in substeps; ``None`` = once per step
    (``substeps``), aligned with step boundaries so a reset never meets a stale matrix."""
    use_tile_gemm: bool = True
    """Use Warp's tile API for the mass-matrix factorisation: 2.6x faster at N=1024 on CPU
    (69k vs 27k env-steps/s, benchmarks/perf/sim_throughput.py)."""
    fuse_cholesky: bool | None = None
    """With the tile GEMM, factorise the mass matrix in the kernel that forms it (``True``, Newton's
    default) or in a kernel of its own (``False``). ``None``: separate on the CPU, where it is about
    1.03x faster at N=1024 and bit-identical (``benchmarks/physics/solver_options.py``), fused elsewhere."""
    use_graph: bool = True
    """Record the whole step once (``wp.ScopedCapture``) and replay it."""

    def resolve_fuse_cholesky(self, on_cpu: bool) -> bool:
        """:attr:`fuse_cholesky` as set, or when ``None``: separate on the CPU, fused elsewhere."""
        return (not on_cpu) if self.fuse_cholesky is None else self.fuse_cholesky

    @property
    def substeps(self) -> int:
        """Solver substeps per environment step."""
        n = round(self.step_dt / self.sim_dt)
        if n < 1 or not math.isclose(n * self.sim_dt, self.step_dt, rel_tol=1e-9):
            raise ValueError(f"step_dt={self.step_dt} is not a whole multiple of sim_dt={self.sim_dt}")
        return n


_REFERENCE_INERTIALS = (
    InertialOverride("center_link", 50.0),
    *(
        InertialOverride(w, 1.0, (1.0, 1.0, 1.0))
        for w in ("left_front_wheel_link", "left_rear_wheel_link", "right_front_wheel_link", "right_rear_wheel_link")
    ),
)

VARIANTS: dict[str, RoverConfig] = {
    "realistic": RoverConfig(),
    "reference": RoverConfig(inertial_overrides=_REFERENCE_INERTIALS),
}
"""Registered rover variants. ``realistic``: masses and inertias from geometry (58 kg).
``reference``: the reference simulation's chassis 50 kg, wheels 1 kg with a placeholder
1 kg·m² inertia, which is why it accelerated at only ~0.4 m/s²."""


def get_variant(name: str) -> RoverConfig:
    """Return the registered :class:`RoverConfig` called ``name``."""
    try:
        return VARIANTS[name]
    except KeyError:
        raise ValueError(f"unknown rover variant {name!r}; known: {sorted(VARIANTS)}") from None


def nominal_rover_config(robot=None, variant: str = "realistic", rover: RoverConfig | None = None) -> RoverConfig:
    """The rover a simulator builds: ``rover`` where given (its robot must be ``robot``'s where both are given), else
    the registered ``variant`` of ``robot`` (a name or a robot file's path; ``None``: the ATRV-Jr)."""
    if rover is not None:
        if robot is not None and load_robot(robot).path != rover.robot_spec.path:
            raise ValueError(f"robot {robot!r} and rover config's robot {rover.robot!r} differ: give one")
        return rover
    base = get_variant(variant)
    if robot is None or load_robot(robot).path == base.robot_spec.path:
        return base
    if variant != "realistic":
        raise ValueError(f"rover variant {variant!r} is the ATRV-Jr's; robot {robot!r} has only its own file")
    return RoverConfig(robot=os.fspath(robot) if not isinstance(robot, Robot) else robot.path)


def replace_checked(cfg, **changes):
    """:func:`dataclasses.replace` that names an unknown field instead of a TypeError. A :class:`RoverConfig` given
    another ``robot`` takes the new robot's values wherever it held the old one's."""
    names = {f.name for f in dataclasses.fields(cfg)}
    unknown = sorted(set(changes) - names)
    if unknown:
        raise ValueError(f"unknown {type(cfg).__name__} key(s) {unknown}; known: {sorted(names)}")
    if isinstance(cfg, RoverConfig) and "robot" in changes and changes["robot"] != cfg.robot:
        old = RoverConfig(robot=cfg.robot)
        changes = {**{name: None for name in ROBOT_FIELDS if getattr(cfg, name) == getattr(old, name)}, **changes}
    return dataclasses.replace(cfg, **changes)

