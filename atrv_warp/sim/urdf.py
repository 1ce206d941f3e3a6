"""Read a skid-steer rover URDF with yourdfpy, check it, and describe it for model building.

The description is what the reference simulation keeps after editing its imported
model: one chassis on a free joint, revolute wheels with their axes and drive signs,
sensor frames fixed to the chassis (their masses, if any, lumped into the chassis), and
the geometry needed to replace the URDF's collision meshes by wheel cylinders.
"""

from __future__ import annotations

import functools
import hashlib
import os
from dataclasses import dataclass

import numpy as np

from atrv_warp.core.inputs import InputFileError, read_input
from atrv_warp.core.robot import MAX_WHEELS
from atrv_warp.sim.config import InertialOverride, RoverConfig, default_urdf_path

__all__ = ["URDF_RANGE", "Frame", "Inertial", "RoverDescription", "URDFError", "Wheel", "check_numbers", "check_tree",
           "footprint_points", "footprint_radii", "load_rover", "read_urdf", "rigid_group"]


class URDFError(ValueError):
    """A URDF file that cannot be read or does not describe a skid-steer rover.

    ``field`` names the :class:`~atrv_warp.sim.config.RoverConfig` field the problem is about (``"chassis_link"``,
    ``"left_wheels"``, ``"sensor_frames"``, ``"urdf"`` …) and ``subject`` the link or joint, where there is one: a
    robot check (``python -m atrv_warp.robot check``) names the robot file's field from them."""

    def __init__(self, message: str, *, field: str = "urdf", subject: str | None = None):
        super().__init__(message)
        self.field, self.subject = field, subject


@dataclass(frozen=True)
class Inertial:
    """Mass properties of one body in its link frame."""

    mass: float
    """[kg]"""
    com: np.ndarray
    """Centre of mass in the link frame [m], shape (3,)."""
    inertia: np.ndarray
    """Inertia tensor about the COM, in link-frame axes [kg·m²], shape (3, 3)."""


@dataclass(frozen=True)
class Wheel:
    """One driven wheel."""

    link: str
    joint: str
    side: int
    """0 for left (first command), 1 for right (second command)."""
    origin: np.ndarray
    """Joint frame in the chassis link frame, 4x4 homogeneous transform."""
    axis: np.ndarray
    """Unit joint axis in the wheel link frame, shape (3,)."""
    drive_sign: float
    """+1 if a positive joint torque drives the rover forward (+x), else -1."""
    outward: np.ndarray
    """Unit axle direction in the wheel link frame that points away from the chassis centre."""
    inertial: Inertial
    radius: float | None = None
    """The radius of the wheel's cylinder in the URDF (collision geometry before visual) [m]; None where it gives
    none (the model replaces the wheel's geometry by :attr:`~atrv_warp.sim.config.RoverConfig.wheel_radius`'s
    cylinder either way)."""
    width: float | None = None
    """The length of that cylinder [m]; None where the URDF gives none."""


@dataclass(frozen=True)
class Frame:
    """A link fixed to the chassis, kept as a named frame."""

    name: str
    transform: np.ndarray
    """Pose in the chassis link frame, 4x4 homogeneous transform."""


@dataclass(frozen=True)
class RoverDescription:
    """A checked rover: what :func:`atrv_warp.model.build_model` needs from the URDF."""

    path: str
    name: str
    chassis: str
    chassis_inertial: Inertial
    """Chassis mass properties with the fixed frames' masses lumped in."""
    chassis_box: tuple[np.ndarray, np.ndarray] | None
    """(4x4 pose in the chassis frame, half extents [m]) of the chassis collision box, taken
    from a URDF box collision (or box visual); ``None`` if the URDF gives neither."""
    wheels: tuple[Wheel, ...]
    frames: tuple[Frame, ...]
    tree: tuple[tuple[str, str, str, str], ...]
    """(body, parent, joint name, joint type) of every URDF link, root first."""

    @property
    def total_mass(self) -> float:
        """Chassis plus wheels [kg]."""
        return self.chassis_inertial.mass + sum(w.inertial.mass for w in self.wheels)

    @property
    def wheel_radius(self) -> float | None:
        """The wheels' radius in the URDF [m] (the largest of their cylinders), or None where it gives none."""
        radii = [w.radius for w in self.wheels if w.radius is not None]
        return max(radii) if radii else None

    @property
    def reach(self) -> float:
        """Half the chassis box's diagonal, from the chassis' centre of mass to the box's farthest corner [m] (or to
        the farthest wheel joint where the URDF gives no box): how far the rover's body extends."""
        com = self.chassis_inertial.com
        if self.chassis_box is not None:
            pose, half = self.chassis_box
            corners = [pose[:3, :3] @ (half * np.array(s)) + pose[:3, 3]
                       for s in np.array(np.meshgrid(*[[-1, 1]] * 3)).T.reshape(-1, 3)]
            return float(max(np.linalg.norm(c - com) for c in corners))
        return float(max(np.linalg.norm(w.origin[:3, 3] - com) for w in self.wheels))


def footprint_points(description: RoverDescription, rover) -> np.ndarray:
    """(P, 2) the rover's outline seen from above, about its chassis origin [m]: its chassis box's corners and the
    corners of its wheels' contact cylinders (``rover``: its :class:`~atrv_warp.sim.config.RoverConfig`, whose
    cylinder the model uses: radius, length, offset outward)."""
    points = []
    if description.chassis_box is not None:
        pose, half = description.chassis_box
        for corner in np.array(np.meshgrid(*[[-1.0, 1.0]] * 3)).T.reshape(-1, 3):
            points.append((pose[:3, :3] @ (half * corner) + pose[:3, 3])[:2])
    for wheel in description.wheels:
        out = wheel.origin[:3, :3] @ wheel.outward
        centre = wheel.origin[:3, 3] + out * rover.wheel_offset
        for side in (-0.5, 0.5):
            for along in (-1.0, 1.0):
                points.append((centre + out * side * rover.wheel_length + np.array([along * rover.wheel_radius, 0, 0]))
                              [:2])
    return np.array(points)


def footprint_radii(description: RoverDescription, rover) -> tuple[float, float]:
    """(inscribed, circumscribed) radius [m] of :func:`footprint_points` about the chassis origin (the pose an
    episode starts at): the nearest side of its bounding rectangle, and its farthest point (the task's
    ``footprint_radius``). Nav2's footprint radii: a planner keeps the inscribed one from walls, a spawn the
    circumscribed one."""
    points = footprint_points(description, rover)
    return float(np.abs(points).max(axis=0).min()), float(np.linalg.norm(points, axis=1).max())


def _inertial_of(link) -> Inertial:
    if link.inertial is None or link.inertial.mass is None:
        return Inertial(0.0, np.zeros(3), np.zeros((3, 3)))
    origin = np.eye(4) if link.inertial.origin is None else np.asarray(link.inertial.origin, dtype=float)
    rot = origin[:3, :3]
    inertia = np.zeros((3, 3)) if link.inertial.inertia is None else np.asarray(link.inertial.inertia, dtype=float)
    return Inertial(float(link.inertial.mass), origin[:3, 3].copy(), rot @ inertia @ rot.T)


def _lump(parts: list[tuple[Inertial, np.ndarray]]) -> Inertial:
    """Combine inertials given with the 4x4 pose of their link in a common frame."""
    mass = sum(p.mass for p, _ in parts)
    if mass <= 0.0:
        return Inertial(0.0, np.zeros(3), np.zeros((3, 3)))
    coms = [(tf[:3, :3] @ p.com + tf[:3, 3]) for p, tf in parts]
    com = sum(p.mass * c for (p, _), c in zip(parts, coms)) / mass
    inertia = np.zeros((3, 3))
    for (p, tf), c in zip(parts, coms):
        r = c - com
        rot = tf[:3, :3]
        # parallel-axis theorem
        inertia += rot @ p.inertia @ rot.T + p.mass * (np.dot(r, r) * np.eye(3) - np.outer(r, r))
    return Inertial(mass, com, inertia)


def _apply_override(inertial: Inertial, ov: InertialOverride) -> Inertial:
    if ov.mass <= 0.0:
        raise URDFError(f"inertial override for {ov.link!r}: mass must be > 0, got {ov.mass}")
    if ov.inertia_diag is not None:
        inertia = np.diag(np.asarray(ov.inertia_diag, dtype=float))
    elif inertial.mass > 0.0:
        inertia = inertial.inertia * (ov.mass / inertial.mass)
    else:
        raise URDFError(f"inertial override for {ov.link!r} needs inertia_diag: the URDF link has no inertia")
    return Inertial(ov.mass, inertial.com, inertia)


def _check_inertial(path: str, name: str, inertial: Inertial) -> None:
    if inertial.mass <= 0.0:
        raise URDFError(f"{path}: link {name!r} needs a positive <inertial><mass>, got {inertial.mass}", subject=name)
    eig = np.linalg.eigvalsh(0.5 * (inertial.inertia + inertial.inertia.T))
    if eig.min() <= 0.0 or eig[0] + eig[1] < eig[2] * (1.0 - 1e-6):
        raise URDFError(
            f"{path}: link {name!r} has an unphysical inertia tensor (principal moments {eig.round(6).tolist()} kg·m²)",
            subject=name)


def _parse(path: str):
    """The URDF's robot, or a URDFError naming the file and what is wrong with it. A process parses each file once
    while its bytes stay the same (the robot is read, never changed, by its callers)."""
    try:
        data = read_input(path, "URDF")  # a regular file of bounded size, before any parser sees it
    except FileNotFoundError:
        raise URDFError(f"URDF file not found: {path}") from None
    except InputFileError as err:
        raise URDFError(str(err)) from None
    return _parse_file(path, hashlib.sha256(data).hexdigest())


@functools.lru_cache(maxsize=16)
def _parse_file(path: str, digest: str):
    """:func:`_parse` of the file at ``path`` whose bytes hash to ``digest`` (the cache's key)."""
    import yourdfpy
    from lxml import etree

    try:  # yourdfpy silently recovers from broken XML; refuse it instead
        etree.parse(path, etree.XMLParser(recover=False))
    except etree.XMLSyntaxError as err:
        raise URDFError(f"{path}: malformed URDF (XML): {err}") from None
    try:
        urdf = yourdfpy.URDF.load(
            path,
            build_scene_graph=False,
            build_collision_scene_graph=False,
            load_meshes=False,
            load_collision_meshes=False,
        )
    except Exception as err:  # noqa: BLE001 - yourdfpy raises assorted types for schema problems
        raise URDFError(f"{path}: malformed URDF: {err}") from None
    return urdf.robot


def read_urdf(path) -> tuple[dict, list]:
    """The URDF's links by name and its joints (yourdfpy's objects), checked to be one tree (:func:`check_tree`), or a
    :class:`URDFError` naming the file."""
    path = os.fspath(path)
    robot = _parse(path)
    links, joints = {link.name: link for link in robot.links}, list(robot.joints)
    check_tree(path, links, joints)
    check_numbers(path, links, joints)
    return links, joints


URDF_RANGE = {"mass": 1e4, "inertia": 1e4, "distance": 100.0}
"""The largest link mass [kg], inertia tensor entry [kg·m²] and origin offset [m] a rover's URDF may hold: a value past
them (a ``1e400`` that XML reads as inf, a mistyped exponent) is refused, named, before it reaches the physics."""


def check_numbers(path: str, links: dict, joints) -> None:
    """Every number the simulator takes from the URDF is finite and within :data:`URDF_RANGE`: each link's mass (>= 0),
    inertia tensor and inertial origin, each joint's origin, and each joint's axis (not zero).

    Raises:
        URDFError: the first bad number, named with its link or joint.
    """
    def bad(values, limit: float) -> bool:
        array = np.asarray(values, dtype=float)
        return not (np.isfinite(array).all() and (np.abs(array) <= limit).all())

    for name, link in links.items():
        inertial = link.inertial
        if inertial is None:
            continue
        mass = inertial.mass if inertial.mass is not None else 0.0
        if bad(mass, URDF_RANGE["mass"]) or mass < 0:
            raise URDFError(f"{path}: link {name!r}: <mass> {mass!r} must be a finite number in [0, "
                            f"{URDF_RANGE['mass']:g}] kg", subject=name)
        if inertial.inertia is not None and bad(inertial.inertia, URDF_RANGE["inertia"]):
            raise URDFError(f"{path}: link {name!r}: <inertia> must be finite numbers of at most "
                            f"{URDF_RANGE['inertia']:g} kg·m², got {np.asarray(inertial.inertia).tolist()}",
                            subject=name)
        if inertial.origin is not None and bad(np.asarray(inertial.origin)[:3, 3], URDF_RANGE["distance"]):
            raise URDFError(f"{path}: link {name!r}: the <inertial> <origin> must be finite and within "
                            f"{URDF_RANGE['distance']:g} m", subject=name)
    for j in joints:
        origin = _origin(j)
        if not np.isfinite(origin).all() or bad(origin[:3, 3], URDF_RANGE["distance"]):
            raise URDFError(f"{path}: joint {j.name!r}: its <origin> must be finite and within "
                            f"{URDF_RANGE['distance']:g} m, got xyz {origin[:3, 3].tolist()}", subject=j.name)
        if j.axis is not None:
            axis = np.asarray(j.axis, dtype=float)
            if not np.isfinite(axis).all() or np.linalg.norm(axis) < 1e-9:
                raise URDFError(f"{path}: joint {j.name!r}: its <axis> {axis.tolist()} must be a finite, non-zero "
                                "vector", subject=j.name)


def check_tree(path: str, links: dict, joints) -> None:
    """The links and joints make one tree, before anything walks them (a walk up a loop would never end): every joint's
    ends exist, no link is the child of two joints, one link is no joint's child (the root), and every link hangs from
    it (a link in a loop of joints does not).

    Raises:
        URDFError: the first problem, named with its links or joints.
    """
    parent: dict[str, str] = {}
    for j in joints:
        for end in (j.parent, j.child):
            if end not in links:
                raise URDFError(f"{path}: joint {j.name!r} refers to missing link {end!r}", subject=j.name)
        if j.child in parent:
            raise URDFError(f"{path}: link {j.child!r} is the child of two joints ({parent[j.child]!r} and {j.name!r}); "
                            "a URDF is a tree", subject=j.child)
        parent[j.child] = j.name
    roots = [name for name in links if name not in parent]
    if len(roots) != 1:
        raise URDFError(f"{path}: a URDF has one root link (no joint's child), this one has "
                        f"{len(roots)}: {roots[:8]}" + (" (a loop of joints leaves none)" if not roots else ""),
                        subject=roots[0] if roots else None)
    children: dict[str, list[str]] = {}
    for j in joints:
        children.setdefault(j.parent, []).append(j.child)
    reached, todo = {roots[0]}, [roots[0]]
    while todo:
        for child in children.get(todo.pop(), []):
            if child not in reached:
                reached.add(child)
                todo.append(child)
    lost = [name for name in links if name not in reached]
    if lost:
        raise URDFError(f"{path}: link(s) {lost[:8]} do not hang from the root {roots[0]!r}: a loop of joints",
                        subject=lost[0])


def rigid_group(chassis: str, links: dict, joints) -> dict[str, np.ndarray]:
    """Every link joined to ``chassis`` by fixed joints alone (above it in the tree or below), with its pose in the
    chassis frame (4x4): the one body they make."""
    return _rigid_group(chassis, links, joints)


def _check_links(path: str, rover: RoverConfig, links: dict, joints) -> None:
    """Every joint's ends exist, and every role's link."""
    for j in joints:
        for end in (j.parent, j.child):
            if end not in links:
                raise URDFError(f"{path}: joint {j.name!r} refers to missing link {end!r}", subject=j.name)
    required = [(rover.chassis_link, "chassis", "chassis_link")]
    required += [(n, "wheel", "left_wheels") for n in rover.left_wheels]
    required += [(n, "wheel", "right_wheels") for n in rover.right_wheels]
    required += [(n, "sensor frame", "sensor_frames") for n in rover.sensor_frames]
    for name, role, field in required:
        if name not in links:
            raise URDFError(f"{path}: required {role} link {name!r} not found; links present: {sorted(links)}",
                            field=field, subject=name)
    unknown = sorted({ov.link for ov in rover.inertial_overrides} - set(links))
    if unknown:
        raise URDFError(f"{path}: inertial overrides name unknown link(s) {unknown}", field="inertial_overrides",
                        subject=unknown[0])


def _origin(j) -> np.ndarray:
    return np.eye(4) if j.origin is None else np.asarray(j.origin, dtype=float)


def _rigid_group(chassis: str, links: dict, joints) -> dict[str, np.ndarray]:
    """Every link joined to ``chassis`` by fixed joints alone (above it in the tree or below), with its pose in the
    chassis frame (4x4), in the URDF's link order: the one body they make. Time linear in the joints (each link's
    fixed joints gathered once), so a URDF of many fixed frames merges in seconds."""
    fixed: dict[str, list] = {}
    for j in joints:
        if j.type == "fixed":
            fixed.setdefault(j.parent, []).append(j)
            fixed.setdefault(j.child, []).append(j)
    poses, todo = {chassis: np.eye(4)}, [chassis]
    while todo:
        name = todo.pop()
        for j in fixed.get(name, []):  # in the URDF's joint order, as a scan of every joint finds them
            if j.parent == name and j.child not in poses:  # down the tree
                poses[j.child] = poses[name] @ _origin(j)
                todo.append(j.child)
            elif j.child == name and j.parent not in poses:  # up it
                poses[j.parent] = poses[name] @ np.linalg.inv(_origin(j))
                todo.append(j.parent)
    return {name: poses[name] for name in links if name in poses}


def _frames(path: str, rover: RoverConfig, group: dict[str, np.ndarray], wheel_names: set[str]) -> list[Frame]:
    """The rigid group's links (not the chassis, not a wheel) become named frames."""
    frames = [Frame(name, pose) for name, pose in group.items() if name != rover.chassis_link and name not in wheel_names]
    missing = [n for n in rover.sensor_frames if n not in group]
    if missing:
        raise URDFError(f"{path}: sensor frame {missing[0]!r} must be fixed to {rover.chassis_link!r} (through fixed "
                        "joints only)", field="sensor_frames", subject=missing[0])
    return frames


def _wheel_joints(path: str, rover: RoverConfig, group: dict[str, np.ndarray], joints) -> list[tuple[str, object]]:
    """(link, joint) of each wheel: the named ones (``left_wheels``, ``right_wheels``), or where none are named, every
    revolute or continuous joint hanging from the chassis' rigid group about a lateral axis."""
    named = tuple(rover.left_wheels) + tuple(rover.right_wheels)
    by_child = {j.child: j for j in joints}
    if named:
        return [(name, by_child.get(name)) for name in named]
    found = []
    for j in joints:
        if j.type in ("revolute", "continuous") and j.parent in group:
            axis = np.asarray(j.axis if j.axis is not None else (1.0, 0.0, 0.0), dtype=float)
            lateral = (group[j.parent] @ _origin(j))[:3, :3] @ (axis / np.linalg.norm(axis))
            if abs(lateral[1]) >= 0.9:
                found.append((j.child, j))
    if len(found) < 2:
        raise URDFError(f"{path}: found {len(found)} wheel joint(s) (revolute or continuous joints from "
                        f"{rover.chassis_link!r} or a link fixed to it, about a lateral axis); a skid-steer rover needs "
                        "wheels on both sides (or name them: left_wheels, right_wheels)", field="left_wheels")
    return found


def _wheel(path: str, rover: RoverConfig, name: str, j, group: dict[str, np.ndarray], inertial: Inertial,
           link) -> Wheel:
    """A wheel on a revolute joint from the chassis (or a link fixed to it), about a lateral axis (+y or -y of the
    chassis, however its link is turned: the ATRV-Jr's turn their z to the side, ROS robots turn about +y)."""
    if j is None or j.type not in ("revolute", "continuous") or j.parent not in group:
        kind = "no joint" if j is None else f"a {j.type} joint to {j.parent!r}"
        raise URDFError(f"{path}: wheel {name!r} must hang on a revolute/continuous joint from "
                        f"{rover.chassis_link!r} (or a link fixed to it), found {kind}", field=_side_field(rover, name),
                        subject=name)
    origin = group[j.parent] @ _origin(j)  # the joint frame in the chassis frame
    axis = np.asarray(j.axis if j.axis is not None else (1.0, 0.0, 0.0), dtype=float)
    axis = axis / np.linalg.norm(axis)
    axis_chassis = origin[:3, :3] @ axis
    if abs(axis_chassis[1]) < 0.9:
        raise URDFError(f"{path}: wheel joint {j.name!r} axis {axis_chassis.round(3).tolist()} (chassis frame) "
                        "is not lateral; a skid-steer wheel turns about the chassis y axis",
                        field=_side_field(rover, name), subject=j.name)
    # Rolling forward (+x) is a positive rotation about chassis +y.
    drive_sign = 1.0 if axis_chassis[1] > 0.0 else -1.0
    lateral = 1.0 if origin[1, 3] >= 0.0 else -1.0
    outward = axis * (1.0 if axis_chassis[1] * lateral > 0.0 else -1.0)
    try:
        _check_inertial(path, name, inertial)
    except URDFError as err:
        raise URDFError(str(err), field=_side_field(rover, name), subject=name) from None
    named = tuple(rover.left_wheels) + tuple(rover.right_wheels)
    side = (0 if name in rover.left_wheels else 1) if named else (0 if lateral > 0 else 1)
    return Wheel(name, j.name, side, origin, axis, drive_sign, outward, inertial, *_cylinder(link))


def _side_field(rover: RoverConfig, wheel: str) -> str:
    """The field that names ``wheel`` (``left_wheels`` where the wheels are found by the rule)."""
    return "right_wheels" if wheel in rover.right_wheels else "left_wheels"


def _cylinder(link) -> tuple[float | None, float | None]:
    """The radius and length of the link's first cylinder, collision geometry before visual [m]."""
    for geom_list in (link.collisions, link.visuals):
        for g in geom_list or ():
            if g.geometry is not None and g.geometry.cylinder is not None:
                return float(g.geometry.cylinder.radius), float(g.geometry.cylinder.length)
    return None, None


def _chassis_box(chassis: str, links: dict, group: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray] | None:
    """(pose in the chassis frame, half extents) of the chassis' first box (collision geometry before visual), or of
    the first box of a link fixed to it."""
    for name in [chassis, *(n for n in group if n != chassis)]:
        link = links[name]
        for geom_list in (link.collisions, link.visuals):
            for g in geom_list or ():
                if g.geometry is not None and g.geometry.box is not None:
                    pose = np.eye(4) if g.origin is None else np.asarray(g.origin, dtype=float)
                    return group[name] @ pose, 0.5 * np.asarray(g.geometry.box.size, dtype=float)
    return None


def load_rover(rover: RoverConfig | None = None) -> RoverDescription:
    """Load, check and describe the rover URDF named by ``rover.urdf``.

    The chassis (``rover.chassis_link``) may be any link of the tree: the links joined to it by fixed joints alone,
    above it (a massless ``base_link`` root, a ``base_footprint``) or below it (an ``inertial_link`` holding the mass,
    sensor frames), are one body with it, their masses merged and each kept as a named frame. The wheels are the
    named links (``left_wheels``, ``right_wheels``), or where none are named, every revolute or continuous joint from
    that body about a lateral axis, left or right by the side of the chassis they sit on.

    Raises:
        URDFError: the file is missing or malformed, a required link is absent, a wheel is
            not on a revolute/continuous joint to the chassis or about a lateral axis, the wheels
            are on one side only, or a sensor frame is not fixed to it.
    """
    rover = rover or RoverConfig()
    path = os.fspath(rover.urdf or default_urdf_path())
    robot = _parse(path)
    links = {link.name: link for link in robot.links}
    check_tree(path, links, robot.joints)
    check_numbers(path, links, robot.joints)
    _check_links(path, rover, links, robot.joints)
    overrides = {ov.link: ov for ov in rover.inertial_overrides}

    def inertial(name: str) -> Inertial:
        base = _inertial_of(links[name])
        return _apply_override(base, overrides[name]) if name in overrides else base

    group = _rigid_group(rover.chassis_link, links, robot.joints)
    wheel_joints = _wheel_joints(path, rover, group, robot.joints)
    wheels = [_wheel(path, rover, name, j, group, inertial(name), links[name]) for name, j in wheel_joints]
    if not tuple(rover.left_wheels) + tuple(rover.right_wheels):  # found by the rule: left first, front first
        wheels.sort(key=lambda w: (w.side, -float(w.origin[0, 3])))
    if {w.side for w in wheels} != {0, 1}:
        raise URDFError(f"{path}: wheels on one side only ({', '.join(w.link for w in wheels)}); a skid-steer rover "
                        "drives a left and a right side", field="left_wheels" if wheels[0].side else "right_wheels")
    left = sum(w.side == 0 for w in wheels)
    if left != len(wheels) - left or len(wheels) > MAX_WHEELS:
        raise URDFError(f"{path}: {left} left and {len(wheels) - left} right wheels "
                        f"({', '.join(w.link for w in wheels)}); a skid-steer rover has as many on each side, "
                        f"{MAX_WHEELS} at most", field="left_wheels")
    frames = _frames(path, rover, group, {w.link for w in wheels})
    parts = [(inertial(rover.chassis_link), np.eye(4))] + [(inertial(f.name), f.transform) for f in frames]
    chassis_inertial = _lump(parts)
    try:
        _check_inertial(path, rover.chassis_link, chassis_inertial)
    except URDFError as err:
        raise URDFError(str(err), field="chassis_link", subject=rover.chassis_link) from None
    return RoverDescription(path, robot.name, rover.chassis_link, chassis_inertial,
                            _chassis_box(rover.chassis_link, links, group), tuple(wheels), tuple(frames),
                            _tree(rover.chassis_link, links, robot.joints))


def _tree(chassis: str, links: dict, joints) -> tuple[tuple[str, str, str, str], ...]:
    """(body, the link it is joined to, joint name, joint type) of every URDF link, the chassis first (on the free
    root joint): a link above the chassis in the URDF names the link below it that it is joined to."""
    by_child = {j.child: j for j in joints}
    by_parent: dict[str, list] = {}
    for j in joints:
        by_parent.setdefault(j.parent, []).append(j)
    tree = [(chassis, "world", "root_joint", "free")]
    for name in links:
        if name == chassis:
            continue
        j = by_child.get(name)
        if j is not None and not _above(name, chassis, by_child):
            tree.append((name, j.parent, j.name, j.type))
        else:  # above the chassis: joined to its child on the chassis' side
            down = next(c for c in by_parent.get(name, []) if c.child == chassis or _above(c.child, chassis, by_child))
            tree.append((name, down.child, down.name, down.type))
    return tuple(tree)


def _above(name: str, chassis: str, by_child: dict) -> bool:
    """Whether ``name`` is an ancestor of the chassis in the URDF tree."""
    node = chassis
    while node in by_child:
        node = by_child[node].parent
        if node == name:
            return True
    return False
