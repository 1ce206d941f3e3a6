"""MJCF text of the nav world, written from our own descriptions so that the twin cannot drift from them.

- the rover from the URDF's :class:`~atrv_warp.sim.urdf.RoverDescription` (chassis mass, centre of mass and
  inertia with the sensor frames lumped in, the chassis box, each wheel's joint frame, axis and inertial) and
  :class:`~atrv_warp.sim.config.RoverConfig` (the wheel cylinder, its offset along the axle);
- the arena's walls from :meth:`~atrv_warp.sim.config.ArenaConfig.boxes`; the ground as a plane at
  ``ArenaConfig.ground_top``, or one tile of a :class:`~atrv_warp.sim.terrain.HeightGrid` as a height field;
- each episode's obstacles (:class:`Obstacle`) from below the ground up to ``ObstacleSet.top``;
- :class:`~atrv_warp.sim.config.SimConfig`'s substep and gravity, and the Coulomb µ.

What MuJoCo does its own way, on purpose: the contact (soft constraints, an elliptic friction cone) in place of our
Hunt–Crossley law and velocity-level Coulomb solve, and the height field's triangles in place of our bilinear
patches. The soft constraint's compliance (:class:`MujocoContact`) is the tyre's: a wheel sinks at rest as far as
ours does (``benchmarks/transfer/mujoco_turning_study.py`` says why MuJoCo's stiff default makes a skid-steer rover hop).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from atrv_warp.sim.config import ArenaConfig, RoverConfig, SimConfig
from atrv_warp.sim.terrain import HeightGrid
from atrv_warp.sim.urdf import Inertial, RoverDescription

__all__ = ["MUJOCO_DEFAULT_CONTACT", "ROVER_GROUP", "SCENE_GROUP", "MujocoContact", "Obstacle", "inertial_xml", "number",
           "pose_xml", "quat_wxyz", "rover_xml", "vector", "wheel_geom_name", "with_payload", "world_xml"]

SCENE_GROUP = 0
"""Geom group of the scene (ground, walls, obstacles): what the scanner's rays see."""
ROVER_GROUP = 1
"""Geom group of the rover's own shapes, which the scanner's rays skip."""
BURY = 0.5
"""How far the height field's base and the obstacles reach below the lowest ground [m]."""


@dataclass(frozen=True)
class MujocoContact:
    """MuJoCo's own contact settings for the twin (MuJoCo's names and units).

    The default gives MuJoCo's soft contact the tyre's static compliance: under the rover's weight a wheel sinks
    12.7 mm, as our Hunt–Crossley law sinks it (12.6 mm, ``(load / kp)^(1/n)`` with the nominal
    :class:`~atrv_warp.sim.config.ContactConfig`), critically damped as MuJoCo's default is. Not a turning figure.

    MuJoCo's default (:data:`MUJOCO_DEFAULT_CONTACT`, a 0.15 mm sink) makes a skid-steer rover hop. Its soft
    constraint pushes a sliding contact's bodies apart by a distance that grows with the slip speed and with how
    fast the friction's reference pulls the slip to zero; once that exceeds the static sink the contact breaks. In
    a turn every wheel slides, so with MuJoCo's default the wheels leave the ground one substep in five or six,
    spin up in the air under the driver's torque, are slammed back on landing, and the rover turns at a fifth to
    two thirds of the Coulomb rate. With the tyre's sink no wheel leaves the ground in the agreement benchmark's
    turns (0.5 rad/s), the sliding wheels' friction is µ times their load as Coulomb's law has it, chi is within
    10 % of our Coulomb solve's at µ 0.3 and 0.8 whatever the impedance (0.3 to 0.7) or the step, and on the
    ``hills`` terrain the twin turns as ours does. In the nav task's fastest turns (2 rad/s) at µ 0.8 the wheels
    still hop on flat ground. A slower friction reference at the wheels (:attr:`solreffriction`) with a harder
    friction (:attr:`impratio`) stops that on flat ground, but on the height field the twin then turns at half our
    rate; damping the tyre as lightly as ours makes the friction viscous (``benchmarks/transfer/mujoco_turning_study.py``)."""

    solref: tuple[float, float] = (0.087, 1.0)
    """(time constant [s], damping ratio [-]) of every contact: the time constant that gives, with
    :attr:`solimp`, the tyre's static sink (the rest-height row of ``benchmarks/transfer/mujoco_agreement.py``);
    MuJoCo's default damping ratio."""
    solimp: tuple[float, float, float] = (0.5, 0.5, 0.001)
    """(dmin [-], dmax [-], width [m]): a constant impedance of 0.5, the middle of the range (0.3 to 0.7) over
    which the study finds the turn independent of it. MuJoCo's default (0.9 to 0.95) needs a 0.27 s time constant
    for the tyre's sink, and its turns at µ 0.8 still hop."""
    solreffriction: tuple[float, float] | None = None
    """(time constant [s], damping ratio [-]) of the friction at the wheels' ground contacts, on a ``<pair>`` per
    wheel; ``None`` (the default): no pairs, the friction takes :attr:`solref`, as in MuJoCo."""
    cone: str = "elliptic"
    """Friction cone: ``"elliptic"`` (Coulomb's circle) or ``"pyramidal"``."""
    impratio: float = 1.0
    """Ratio of the frictional to the normal constraint's impedance [-] (MuJoCo's default)."""
    noslip_iterations: int = 0
    """Iterations of MuJoCo's noslip post-solve of the friction forces (0: off, its default)."""
    integrator: str = "Euler"
    """MuJoCo's integrator: ``"Euler"`` (its default, semi-implicit) or ``"implicitfast"``."""
    wheel: str = "cylinder"
    """The wheel's collision shape: ``"cylinder"`` (the URDF's; two rim contacts on flat ground) or
    ``"sphere"`` of the wheel's radius (one contact, as ours)."""
    steps_per_substep: int = 1
    """MuJoCo steps per driver substep (``SimConfig.sim_dt``): MuJoCo's timestep is ``sim_dt`` over this."""

    def __post_init__(self):
        if self.cone not in ("elliptic", "pyramidal"):
            raise ValueError(f"MujocoContact.cone must be 'elliptic' or 'pyramidal', got {self.cone!r}")
        if self.integrator not in ("Euler", "implicitfast"):
            raise ValueError(f"MujocoContact.integrator must be 'Euler' or 'implicitfast', got {self.integrator!r}")
        if self.wheel not in ("cylinder", "sphere"):
            raise ValueError(f"MujocoContact.wheel must be 'cylinder' or 'sphere', got {self.wheel!r}")
        if self.steps_per_substep < 1:
            raise ValueError(f"MujocoContact.steps_per_substep must be >= 1, got {self.steps_per_substep!r}")


MUJOCO_DEFAULT_CONTACT = MujocoContact(solref=(0.02, 1.0), solimp=(0.9, 0.95, 0.001))
"""MuJoCo's own defaults (the twin's contact before the tyre's compliance; the study's baseline)."""


@dataclass(frozen=True)
class Obstacle:
    """One upright obstacle of an episode, as :class:`~atrv_warp.sim.contact.Obstacles` holds it."""

    kind: str
    """``"box"`` or ``"cylinder"``."""
    x: float
    """Centre x [m] (world)."""
    y: float
    """Centre y [m] (world)."""
    yaw: float
    """Heading of a box's x axis [rad] (0 for a cylinder)."""
    size: tuple[float, float]
    """A box's half extents (x, y) [m]; a cylinder's (radius [m], 0)."""


def number(x: float) -> str:
    """A number as MJCF text: up to 9 significant digits, no trailing zeros, no '-0'."""
    s = f"{float(x):.9g}"
    return "0" if s in ("-0", "0") else s


def vector(xs) -> str:
    """Numbers as one MJCF attribute value."""
    return " ".join(number(x) for x in xs)


def quat_wxyz(rot: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z), MuJoCo's order, of a 3x3 rotation matrix (w >= 0)."""
    m = np.asarray(rot, dtype=float)
    tr = np.trace(m)
    if tr > 0.0:
        s = 2.0 * math.sqrt(tr + 1.0)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    else:
        i = int(np.argmax(np.diag(m)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * math.sqrt(1.0 + m[i, i] - m[j, j] - m[k, k])
        q = [0.0] * 4
        q[0] = (m[k, j] - m[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (m[j, i] + m[i, j]) / s
        q[1 + k] = (m[k, i] + m[i, k]) / s
    q = np.asarray(q)
    q /= np.linalg.norm(q)
    return q if q[0] >= 0.0 else -q


def pose_xml(tf: np.ndarray) -> str:
    """``pos``/``quat`` attributes of a 4x4 transform (``quat`` left out when it is the identity)."""
    q = quat_wxyz(tf[:3, :3])
    out = f'pos="{vector(tf[:3, 3])}"'
    if not np.allclose(q, (1.0, 0.0, 0.0, 0.0), atol=1e-12):
        out += f' quat="{vector(q)}"'
    return out


def inertial_xml(inertial: Inertial) -> str:
    """An ``<inertial>`` element: mass [kg], centre of mass [m] and the full inertia tensor [kg·m²]."""
    i = inertial.inertia
    full = (i[0, 0], i[1, 1], i[2, 2], i[0, 1], i[0, 2], i[1, 2])
    return f'<inertial pos="{vector(inertial.com)}" mass="{number(inertial.mass)}" fullinertia="{vector(full)}"/>'


def with_payload(inertial: Inertial, mass: float, offset) -> Inertial:
    """``inertial`` with a point ``mass`` [kg] at ``offset`` [m] from its centre of mass (its frame's axes) added,
    as the simulator puts a payload on the chassis (``add_point_mass`` in :mod:`atrv_warp.sim.kernels.params`)."""
    if mass == 0.0:
        return inertial
    point = inertial.com + np.asarray(offset, dtype=np.float64)
    total = inertial.mass + mass
    com = inertial.com + (mass / total) * (point - inertial.com)

    def parallel_axis(m: float, r: np.ndarray) -> np.ndarray:
        return m * (float(r @ r) * np.eye(3) - np.outer(r, r))

    inertia = inertial.inertia + parallel_axis(inertial.mass, inertial.com - com) + parallel_axis(mass, point - com)
    return Inertial(total, com, inertia)


def wheel_geom_name(link: str, wheel: str = "cylinder") -> str:
    """The name of a wheel link's collision geom (``wheel``: its shape) in :func:`rover_xml`."""
    return f"{link}/{wheel}"


def rover_xml(desc: RoverDescription, rover: RoverConfig, *, pos=(0.0, 0.0, 0.0), indent: str = "    ",
              shape_attributes: str = "", wheel: str = "cylinder", wheel_attributes: str | None = None) -> list[str]:
    """The rover's body tree as MJCF lines: the chassis on a free joint named ``root_joint`` (its box collision;
    the rover's payload in its mass properties), and each wheel on a hinge (its cylinder, ``wheel_offset`` outward of the joint; or a sphere of its radius
    there, ``wheel="sphere"``). ``shape_attributes`` is added to every collision geom (contact bits, group);
    ``wheel_attributes``, if given, to the wheels' in its place."""
    extra = f" {shape_attributes}" if shape_attributes else ""
    wheel_extra = extra if wheel_attributes is None else f" {wheel_attributes}"
    lines = [f'{indent}<body name="{desc.chassis}" pos="{vector(pos)}">',
             f'{indent}  <freejoint name="root_joint"/>',
             f"{indent}  {inertial_xml(with_payload(desc.chassis_inertial, rover.payload_mass, rover.payload_offset))}"]
    if desc.chassis_box is not None:
        pose, half = desc.chassis_box
        lines.append(f'{indent}  <geom name="{desc.chassis}/box" type="box" {pose_xml(pose)} size="{vector(half)}"'
                     f"{extra}/>")
    for w in desc.wheels:
        centre = w.outward * rover.wheel_offset
        name = wheel_geom_name(w.link, wheel)
        if wheel == "sphere":
            shape = (f'<geom name="{name}" type="sphere" pos="{vector(centre)}" '
                     f'size="{number(rover.wheel_radius)}"{wheel_extra}/>')
        else:
            shape = (f'<geom name="{name}" type="cylinder" pos="{vector(centre)}" '
                     f'zaxis="{vector(w.outward)}" size="{number(rover.wheel_radius)} {number(0.5 * rover.wheel_length)}"'
                     f"{wheel_extra}/>")
        lines += [
            f'{indent}  <body name="{w.link}" {pose_xml(w.origin)}>',
            f'{indent}    <joint name="{w.joint}" type="hinge" axis="{vector(w.axis)}"/>',
            f"{indent}    {inertial_xml(w.inertial)}",
            f"{indent}    {shape}",
            f"{indent}  </body>",
        ]
    lines.append(f"{indent}</body>")
    return lines


def world_xml(desc: RoverDescription, rover: RoverConfig, *, arena: ArenaConfig, sim: SimConfig, friction: float,
              torque_limit: float, obstacle_top: float, terrain: HeightGrid | None = None, tile: int = 0,
              obstacles: tuple[Obstacle, ...] = (), contact: MujocoContact | None = None) -> str:
    """The MJCF text of one episode's world: the rover (at the origin; its free joint places it), the arena, the
    ground (a plane, or ``terrain``'s ``tile`` as a height field), the ``obstacles`` (standing to ``obstacle_top``
    [m], absolute), one torque motor per wheel (``gear`` its drive sign, so that a positive control drives forward;
    a robot with one motor per side (:attr:`~atrv_warp.core.robot.Robot.motor_per_side`) has its side's wheels held to
    one forward speed by joint equalities;
    within ``torque_limit`` [N·m], times the rover's ``torque_scale`` where that exceeds 1), contact at Coulomb ``friction`` [-] with MuJoCo's settings ``contact``
    (default :class:`MujocoContact`: the tyre's compliance).

    The scene's geoms are in :data:`SCENE_GROUP` and collide with the rover's only; the rover's are in
    :data:`ROVER_GROUP` and collide with the scene's only (the wheels never touch the chassis or each other, as in
    our simulator). With ``contact.solreffriction`` each wheel meets the ground through a ``<pair>`` of its own
    (its contact bit is one the ground lacks), and the walls and obstacles through MuJoCo's defaults."""
    c = contact or MujocoContact()
    h = arena.half_size
    scene = f'contype="0" conaffinity="1" group="{SCENE_GROUP}"'
    # with pairs, the wheels' own bit (2) is one the walls and obstacles have and the ground lacks
    solid = f'contype="0" conaffinity="{1 if c.solreffriction is None else 3}" group="{SCENE_GROUP}"'
    lines = [
        "<!-- Generated by atrv_warp.integrations.mujoco from atrv_warp's URDF description and configs;",
        "     SI units: m, kg, s, rad, N·m. -->",
        f'<mujoco model="{desc.name}_nav_twin">',
        '  <compiler angle="radian" autolimits="true"/>',
        (f'  <option timestep="{number(sim.sim_dt / c.steps_per_substep)}" gravity="0 0 {number(sim.gravity)}" '
         f'integrator="{c.integrator}" cone="{c.cone}" impratio="{number(c.impratio)}" '
         f'noslip_iterations="{c.noslip_iterations}"/>'),
        "  <default>",
        # condim 3: sliding friction only, Coulomb coefficient mu (torsional and rolling friction unused); solref and
        # solimp: the tyre's compliance (MujocoContact says why)
        (f'    <geom condim="3" friction="{number(friction)} 0 0" solref="{vector(c.solref)}" '
         f'solimp="{vector(c.solimp)}"/>'),
        "  </default>",
    ]
    bottom = arena.ground_top - BURY
    if terrain is not None:
        heights = np.asarray(terrain.heights[tile], dtype=np.float64)
        low, high = float(heights.min()), float(heights.max())
        span = max(high - low, 1e-6)
        n = heights.shape[0]
        # MuJoCo's rows run along y and its columns along x (ours index x first: the transpose), and it stores the
        # rows of ``elevation`` last first (its first row is the +y edge): normalised to [0, 1]
        elevation = vector(((heights.T[::-1] - low) / span).ravel())
        lines += ["  <asset>",
                  (f'    <hfield name="terrain" nrow="{n}" ncol="{n}" size="{number(terrain.half_size)} '
                   f'{number(terrain.half_size)} {number(span)} {number(BURY)}" elevation="{elevation}"/>'),
                  "  </asset>"]
        bottom = arena.ground_top + low - BURY
    lines.append("  <worldbody>")
    if terrain is not None:
        lines.append(f'    <geom name="ground" type="hfield" hfield="terrain" pos="0 0 {number(arena.ground_top + low)}" '
                     f"{scene}/>")
    else:
        lines.append(f'    <geom name="ground" type="plane" pos="0 0 {number(arena.ground_top)}" '
                     f'size="{number(h)} {number(h)} 0.1" {scene}/>')
    for label, centre, half in arena.boxes():
        if label != "ground":  # the ground is the plane or height field above
            lines.append(f'    <geom name="{label}" type="box" pos="{vector(centre)}" size="{vector(half)}" {solid}/>')
    zc, hz = 0.5 * (obstacle_top + bottom), 0.5 * (obstacle_top - bottom)
    for i, o in enumerate(obstacles):
        if o.kind == "box":
            quat = vector((math.cos(0.5 * o.yaw), 0.0, 0.0, math.sin(0.5 * o.yaw)))
            lines.append(f'    <geom name="obstacle_{i}" type="box" pos="{vector((o.x, o.y, zc))}" quat="{quat}" '
                         f'size="{vector((*o.size, hz))}" {solid}/>')
        elif o.kind == "cylinder":
            lines.append(f'    <geom name="obstacle_{i}" type="cylinder" pos="{vector((o.x, o.y, zc))}" '
                         f'size="{number(o.size[0])} {number(hz)}" {solid}/>')
        else:
            raise ValueError(f"obstacle {i}: kind {o.kind!r} is neither 'box' nor 'cylinder'")
    wheel_bits = None if c.solreffriction is None else f'contype="2" conaffinity="0" group="{ROVER_GROUP}"'
    lines += rover_xml(desc, rover, shape_attributes=f'contype="1" conaffinity="0" group="{ROVER_GROUP}"',
                       wheel=c.wheel, wheel_attributes=wheel_bits)
    lines.append("  </worldbody>")
    if c.solreffriction is not None:
        lines.append("  <contact>")
        for w in desc.wheels:
            lines.append(f'    <pair geom1="{wheel_geom_name(w.link, c.wheel)}" geom2="ground" condim="3" '
                         f'friction="{number(friction)} {number(friction)} 0 0 0" solref="{vector(c.solref)}" '
                         f'solimp="{vector(c.solimp)}" solreffriction="{vector(c.solreffriction)}"/>')
        lines.append("  </contact>")
    if rover.robot_spec.motor_per_side:  # one motor per side: the side's wheels geared to one forward speed
        lines.append("  <equality>")
        for side in (0, 1):
            first, *others = [w for w in desc.wheels if w.side == side]
            for w in others:
                lines.append(f'    <joint joint1="{w.joint}" joint2="{first.joint}" '
                             f'polycoef="0 {number(w.drive_sign * first.drive_sign)} 0 0 0"/>')
        lines.append("  </equality>")
    lines.append("  <actuator>")
    torque_limit *= max(1.0, rover.torque_scale)  # the driver's torque times the motor's strength
    for w in desc.wheels:
        lines.append(f'    <motor name="{w.joint}/motor" joint="{w.joint}" gear="{number(w.drive_sign)}" '
                     f'ctrlrange="{number(-torque_limit)} {number(torque_limit)}"/>')
    lines += ["  </actuator>", "</mujoco>", ""]
    return "\n".join(lines)
