"""Build the Newton model: rover from a checked URDF description, replicated into N worlds,
inside the reference arena; print the model as the reference does.

``python -m atrv_warp.model [--urdf PATH] [--variant NAME]`` prints the body tree
(body, parent, joint type) and the body table (joint type, degrees of freedom).
"""

from __future__ import annotations

from dataclasses import dataclass

import newton
import numpy as np
import warp as wp

from atrv_warp.sim.config import ArenaConfig, RoverConfig, SimConfig
from atrv_warp.sim.urdf import RoverDescription, load_rover

__all__ = ["BuiltModel", "build_model", "format_table", "format_tree"]

_JOINT_DOFS = {"free": 6, "floating": 6, "revolute": 1, "continuous": 1, "prismatic": 1, "fixed": 0, "planar": 2}


def _transform(mat: np.ndarray) -> wp.transform:
    """4x4 homogeneous matrix to a Warp transform."""
    rot = wp.mat33(*np.asarray(mat[:3, :3], dtype=float).flatten().tolist())
    return wp.transform(wp.vec3(*mat[:3, 3].tolist()), wp.quat_from_matrix(rot))


def _quat_z_to(direction: np.ndarray) -> wp.quat:
    """Rotation taking +z onto ``direction`` (a cylinder's axis)."""
    d = direction / np.linalg.norm(direction)
    if d[2] < -1.0 + 1e-9:
        return wp.quat_from_axis_angle(wp.vec3(1.0, 0.0, 0.0), wp.pi)
    return wp.quat_between_vectors(wp.vec3(0.0, 0.0, 1.0), wp.vec3(*d.tolist()))


@dataclass(frozen=True)
class BuiltModel:
    """A finalised Newton model plus what the simulator needs to index it."""

    model: newton.Model
    description: RoverDescription
    num_worlds: int
    rover_builder: newton.ModelBuilder
    """The single-rover template that was replicated (local indices are world indices)."""
    chassis_body: int
    wheel_bodies: tuple[int, ...]
    wheel_joints: tuple[int, ...]
    rover_shapes: tuple[int, ...]
    """Shape indices in ``rover_builder``: chassis box first if any, then wheel cylinders."""


def _build_rover(desc: RoverDescription, rover: RoverConfig) -> tuple[newton.ModelBuilder, dict]:
    b = newton.ModelBuilder()
    # Shapes carry no mass: mass properties come from the URDF inertials alone.
    shape_cfg = newton.ModelBuilder.ShapeConfig(density=0.0)
    ci = desc.chassis_inertial
    chassis = b.add_link(com=wp.vec3(*ci.com.tolist()), inertia=wp.mat33(*ci.inertia.flatten().tolist()),
                         mass=ci.mass, label=desc.chassis, lock_inertia=True)
    joints = [b.add_joint_free(chassis, label="root_joint")]
    shapes = []
    if desc.chassis_box is not None:
        pose, half = desc.chassis_box
        shapes.append(b.add_shape_box(chassis, xform=_transform(pose), hx=float(half[0]), hy=float(half[1]),
                                      hz=float(half[2]), cfg=shape_cfg, label=f"{desc.chassis}/box"))
    wheel_bodies = []
    for w in desc.wheels:
        wi = w.inertial
        body = b.add_link(com=wp.vec3(*wi.com.tolist()), inertia=wp.mat33(*wi.inertia.flatten().tolist()),
                          mass=wi.mass, label=w.link, lock_inertia=True)
        joints.append(b.add_joint_revolute(chassis, body, parent_xform=_transform(w.origin),
                                           axis=wp.vec3(*w.axis.tolist()), label=w.joint))
        # The URDF's collision geometry is dropped: each wheel gets the spec's cylinder,
        # its axis on the axle, its centre ``wheel_offset`` outward from the joint.
        centre = w.outward * rover.wheel_offset
        xf = wp.transform(wp.vec3(*centre.tolist()), _quat_z_to(w.outward))
        shapes.append(b.add_shape_cylinder(body, xform=xf, radius=rover.wheel_radius,
                                           half_height=0.5 * rover.wheel_length, cfg=shape_cfg,
                                           label=f"{w.link}/cylinder"))
        wheel_bodies.append(body)
    b.add_articulation(joints, label=desc.name)
    return b, {"chassis": chassis, "wheel_bodies": tuple(wheel_bodies), "wheel_joints": tuple(joints[1:]),
               "shapes": tuple(shapes)}


def _add_arena(b: newton.ModelBuilder, arena: ArenaConfig) -> None:
    """Ground box and walls as static shapes shared by all worlds (drawn, and mirrored
    analytically by the contact kernel's half-spaces)."""
    cfg = newton.ModelBuilder.ShapeConfig(density=0.0)
    for label, (x, y, z), (hx, hy, hz) in arena.boxes():
        b.add_shape_box(-1, xform=wp.transform(wp.vec3(x, y, z), wp.quat_identity()), hx=hx, hy=hy, hz=hz, cfg=cfg,
                        label=label)


def build_model(
    num_worlds: int,
    *,
    rover: RoverConfig | None = None,
    arena: ArenaConfig | None = None,
    sim: SimConfig | None = None,
    device: str | None = None,
    requires_grad: bool = False,
) -> BuiltModel:
    """Load the URDF and build ``num_worlds`` independent rovers in one Newton model."""
    if not isinstance(num_worlds, int) or num_worlds < 1:
        raise ValueError(f"num_worlds must be a positive int, got {num_worlds!r}")
    rover = rover or RoverConfig()
    arena = arena or ArenaConfig()
    sim = sim or SimConfig()
    desc = load_rover(rover)
    rover_builder, idx = _build_rover(desc, rover)
    builder = newton.ModelBuilder(gravity=(0.0, 0.0, sim.gravity))
    builder.replicate(rover_builder, num_worlds)
    _add_arena(builder, arena)
    model = builder.finalize(device=device, requires_grad=requires_grad)
    bpw = rover_builder.body_count
    body_world = model.body_world.numpy()
    if model.body_count != bpw * num_worlds or not np.array_equal(body_world, np.repeat(np.arange(num_worlds), bpw)):
        raise RuntimeError("replicated bodies are not laid out world by world; the kernels' indexing needs that")
    return BuiltModel(model, desc, num_worlds, rover_builder, idx["chassis"], idx["wheel_bodies"],
                      idx["wheel_joints"], idx["shapes"])


def format_tree(desc: RoverDescription) -> str:
    """The URDF body tree, one line per body: ``body  <- parent  (joint type)``, indented by depth."""
    children: dict[str, list[tuple[str, str]]] = {}
    for body, parent, _joint, jtype in desc.tree:
        children.setdefault(parent, []).append((body, jtype))
    lines: list[str] = []

    def walk(parent: str, depth: int) -> None:
        for body, jtype in children.get(parent, []):
            lines.append(f"{'  ' * depth}{body}  <- {parent}  ({jtype})")
            walk(body, depth + 1)

    walk("world", 0)
    return "\n".join(lines)


def format_table(desc: RoverDescription) -> str:
    """A table of bodies: parent, joint name, joint type, DOFs, and how the simulator keeps each."""
    frames = {f.name for f in desc.frames}
    wheels = {w.link for w in desc.wheels}
    rows = [("body", "parent", "joint", "type", "dofs", "simulated as")]
    total = 0
    for body, parent, joint, jtype in desc.tree:
        dofs = _JOINT_DOFS.get(jtype, 0)
        total += dofs
        role = ("chassis body" if body == desc.chassis else "wheel body" if body in wheels
                else f"frame on {desc.chassis}" if body in frames else "ignored")
        rows.append((body, parent, joint, jtype, str(dofs), role))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    out = ["  ".join(c.ljust(wd) for c, wd in zip(r, widths)).rstrip() for r in rows]
    out.insert(1, "  ".join("-" * wd for wd in widths))
    out.append(f"{len(desc.tree)} bodies, {total} degrees of freedom; "
               f"mass {desc.total_mass:.2f} kg (chassis {desc.chassis_inertial.mass:.2f} kg)")
    return "\n".join(out)
