"""The contact model a simulator launches: the rover's shapes, the scene (arena planes, terrain,
obstacles) and the law.

:class:`ContactModel` turns the configs and the built Newton model into the structs the
Hunt–Crossley kernel (:mod:`atrv_warp.sim.kernels.contact`) and the wheels' Coulomb friction solver
(:mod:`atrv_warp.sim.kernels.friction`) read, once per simulator, and launches them.
:class:`~atrv_warp.sim.RoverSim` and :class:`~atrv_warp.sim.diff.DiffRollout` both step through it, so
there is one contact model to change.
"""

from __future__ import annotations

import math

import newton
import numpy as np
import torch
import warp as wp

from atrv_warp.core.geometry import quat_to_matrix
from atrv_warp.sim.config import ArenaConfig, ContactConfig, ObstacleConfig, RoverConfig
from atrv_warp.sim.kernels.contact import (
    ARENA_PLANES,
    ArenaPlanes,
    ContactParams,
    RoverShapes,
    Scene,
    compute_contact_forces,
)
from atrv_warp.sim.kernels.friction import RoverInertia, WheelSlots, friction_kernels
from atrv_warp.sim.kernels.obstacles import OBSTACLE_BOX, OBSTACLE_CYLINDER, OBSTACLE_NONE, ObstacleSet
from atrv_warp.sim.kernels.params import MassProperties, WorldPhysics
from atrv_warp.sim.kernels.terrain import TerrainGrid
from atrv_warp.sim.maps import GridWorlds
from atrv_warp.sim.model import BuiltModel
from atrv_warp.sim.terrain import HeightGrid

__all__ = ["OBSTACLE_KINDS", "ContactModel", "Obstacles", "Terrain", "rover_inertia"]

OBSTACLE_KINDS = {"none": int(OBSTACLE_NONE), "box": int(OBSTACLE_BOX), "cylinder": int(OBSTACLE_CYLINDER)}
"""Codes of :attr:`Obstacles.kind`."""


def _law(cfg: ContactConfig, sim_dt: float, m_share: float) -> ContactParams:
    """The kernel's law; ``m_share`` [kg] is the rover's mass per wheel (the damping ceiling's ``m_eff``)."""
    p = ContactParams()
    p.stiffness = cfg.stiffness
    p.damping = cfg.damping
    p.exponent = cfg.exponent
    p.linear_region = cfg.linear_region
    p.linear_coeff = cfg.linear_region ** (cfg.exponent - 1.0)
    p.wheel_solver = int(cfg.friction_law == "coulomb")
    p.dt = sim_dt
    p.damping_cap = math.inf if cfg.damping_limit is None else cfg.damping_limit * m_share / sim_dt
    p.patch = cfg.patch
    return p


class Terrain:
    """Each world's ground: the height grids and which tile each world drives on.

    Attributes:
        grid: the :class:`~atrv_warp.sim.terrain.HeightGrid` (``None`` on the flat arena).
        tile: (N,) int32 torch view of each world's tile; write it before a reset to move a world
            to another tile (values in [0, tiles)).
        kernel: the :class:`~atrv_warp.sim.kernels.terrain.TerrainGrid` kernels read.
    """

    def __init__(self, grid: HeightGrid | None, num_worlds: int, arena: ArenaConfig, device):
        self.grid = grid
        k = TerrainGrid()
        k.enabled = int(grid is not None)
        heights = grid.heights if grid is not None else np.zeros((1, 2, 2), dtype=np.float32)
        k.heights = wp.array(heights, dtype=float, device=device)
        tiles = heights.shape[0]
        k.tile = wp.array(np.arange(num_worlds) % tiles, dtype=wp.int32, device=device)
        k.low = wp.array(heights.reshape(tiles, -1).min(1) + arena.ground_top, dtype=float, device=device)
        k.high = wp.array(heights.reshape(tiles, -1).max(1) + arena.ground_top, dtype=float, device=device)
        k.origin = -grid.half_size if grid is not None else -arena.half_size
        k.inv_resolution = 1.0 / grid.resolution if grid is not None else 1.0
        k.base = arena.ground_top
        self.kernel = k
        self.base = arena.ground_top
        self.tile = wp.to_torch(k.tile)

    @property
    def enabled(self) -> bool:
        return self.grid is not None

    def height(self, x, y, worlds=None) -> np.ndarray:
        """Absolute ground height [m] under (x, y) [m] in each world (or the given ``worlds``)."""
        tiles = self.tile.cpu().numpy() if worlds is None else self.tile.cpu().numpy()[np.asarray(worlds)]
        if self.grid is None:
            return np.full(np.broadcast(np.asarray(x), tiles).shape, self.base)
        return self.base + self.grid.height(tiles, x, y)


class Obstacles:
    """Every world's static obstacles (``ObstacleConfig.slots`` per world).

    Attributes (torch views the contact and scan kernels read; write them before a reset or
    through :meth:`set`):
        kind: (N, slots) int32, :data:`OBSTACLE_KINDS` (0 = empty slot).
        pose: (N, slots, 3) centre x [m], y [m], yaw [rad].
        size: (N, slots, 2) box half extents x, y [m]; cylinder (radius [m], 0).
        kernel: the :class:`~atrv_warp.sim.kernels.obstacles.ObstacleSet` kernels read.
    """

    def __init__(self, cfg: ObstacleConfig | None, num_worlds: int, arena: ArenaConfig, device):
        self.cfg = cfg
        slots = cfg.slots if cfg is not None else 0
        if slots < 0 or (cfg is not None and cfg.height <= 0):
            raise ValueError(f"ObstacleConfig needs slots >= 0 and height > 0, got {cfg}")
        k = ObstacleSet()
        k.count = slots
        shape = (num_worlds, max(slots, 1))
        k.kind = wp.zeros(shape, dtype=wp.int32, device=device)
        k.pose = wp.zeros(shape, dtype=wp.vec3, device=device)
        k.size = wp.zeros(shape, dtype=wp.vec2, device=device)
        k.top = arena.ground_top + (cfg.height if cfg is not None else 0.0)
        k.height = wp.full(shape, k.top, dtype=float, device=device)
        self.kernel = k
        self.slots = slots
        self.kind = wp.to_torch(k.kind)
        self.pose = wp.to_torch(k.pose)
        self.size = wp.to_torch(k.size)
        self.height = wp.to_torch(k.height)
        self._half = arena.half_size
        self._ground = arena.ground_top

    def set(self, world: int, layout) -> None:
        """Replace one world's obstacles by ``layout``: a sequence of ``("box", x, y, yaw, hx, hy)``
        and ``("cylinder", x, y, radius)`` [m, rad], each with its height above the ground [m] last where it is
        not the config's (``("box", x, y, yaw, hx, hy, 0.2)``: a low box, under a laser mounted higher). Checked:
        kinds, sizes and heights > 0, inside the arena."""
        kind, pose, size, height = self.layout(layout)
        self.kind[world] = kind.to(self.kind.device)
        self.pose[world] = pose.to(self.pose.device)
        self.size[world] = size.to(self.size.device)
        self.height[world] = height.to(self.height.device)

    def layout(self, layout) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """``layout`` (as :meth:`set` takes it) checked, as one world's slots: kind (slots,), pose (slots, 3), size
        (slots, 2), top (slots,) [m, absolute]."""
        if len(layout) > self.slots:
            raise ValueError(f"{len(layout)} obstacles do not fit the {self.slots} slots (ObstacleConfig.slots)")
        width = max(self.slots, 1)  # as the kernels' arrays (a world without slots has one, always empty)
        kind = torch.zeros(width, dtype=torch.int32)
        pose, size = torch.zeros(width, 3), torch.zeros(width, 2)
        top = torch.full((width,), float(self.kernel.top))
        for i, item in enumerate(layout):
            name, *values = item
            given = {"box": 5, "cylinder": 3}.get(name)
            if given is None or len(values) not in (given, given + 1):
                raise ValueError(f"obstacle {i}: {item!r} is neither ('box', x, y, yaw, hx, hy[, height]) nor "
                                 "('cylinder', x, y, radius[, height])")
            if len(values) > given:
                height = float(values[given])
                if not (math.isfinite(height) and height > 0):
                    raise ValueError(f"obstacle {i}: {item!r} needs a height above the ground > 0")
                top[i] = self._ground + height
            if name == "box":
                pose[i] = torch.tensor(values[:3])
                size[i] = torch.tensor(values[3:5])
            else:
                pose[i, :2] = torch.tensor(values[:2])
                size[i, 0] = values[2]
            if not (size[i, 0] > 0 and (name == "cylinder" or size[i, 1] > 0)) or not torch.isfinite(pose[i]).all():
                raise ValueError(f"obstacle {i}: {item!r} needs positive sizes and a finite pose")
            if pose[i, :2].abs().max() >= self._half:
                raise ValueError(f"obstacle {i}: centre ({float(pose[i, 0]):g}, {float(pose[i, 1]):g}) m is outside "
                                 f"the arena (|x|, |y| < {self._half:g} m)")
            kind[i] = OBSTACLE_KINDS[name]
        return kind, pose, size, top


def _planes(arena: ArenaConfig, device) -> ArenaPlanes:
    """Ground and the four walls as half-spaces ``n·x >= offset`` (inner faces)."""
    half_spaces = arena.planes()
    if len(half_spaces) != ARENA_PLANES:
        raise ValueError(f"the contact kernel tests {ARENA_PLANES} arena planes (ground, four walls), the arena "
                         f"has {len(half_spaces)}")
    planes = ArenaPlanes()
    planes.normal = wp.array([n for n, _ in half_spaces], dtype=wp.vec3, device=device)
    planes.offset = wp.array([o for _, o in half_spaces], dtype=float, device=device)
    return planes


def _shapes(built: BuiltModel, rover: RoverConfig, cfg: ContactConfig, sim_dt: float, device) -> RoverShapes:
    """The template rover's cylinders and boxes, with each contact's friction slope.

    Effective mass seen by friction at a shape's contact: a quarter of the rover sideways; along
    the rolling direction, that in series with the wheel's spin inertia.
    """
    rb, desc = built.rover_builder, built.description
    m_share = desc.total_mass / max(len(desc.wheels), 1)
    wheel_of_body = dict(zip(built.wheel_bodies, desc.wheels))
    body, kind, is_wheel, xform, size, slope_lon, slope_lat = [], [], [], [], [], [], []
    for s in built.rover_shapes:
        b, gtype, scale = rb.shape_body[s], rb.shape_type[s], rb.shape_scale[s]
        if gtype == newton.GeoType.CYLINDER:
            kind.append(0)
            size.append(wp.vec3(scale[0], scale[1], 0.0))
        elif gtype == newton.GeoType.BOX:
            kind.append(1)
            size.append(wp.vec3(*scale))
        else:
            raise ValueError(f"contact kernel handles cylinders and boxes, got {gtype!r}")
        body.append(b)
        xform.append(rb.shape_transform[s])
        w = wheel_of_body.get(b)
        m_lon = m_share
        if w is not None:
            i_axial = float(w.axis @ w.inertial.inertia @ w.axis)
            r = rover.wheel_radius
            m_lon = 1.0 / (1.0 / m_share + r * r / i_axial)
        is_wheel.append(int(w is not None))
        slope_lon.append(cfg.friction_slope_fraction * m_lon / sim_dt)
        slope_lat.append(cfg.friction_slope_fraction * m_share / sim_dt)
    sh = RoverShapes()
    sh.count = len(body)
    sh.body = wp.array(body, dtype=int, device=device)
    sh.kind = wp.array(kind, dtype=int, device=device)
    sh.is_wheel = wp.array(is_wheel, dtype=int, device=device)
    sh.xform = wp.array(xform, dtype=wp.transform, device=device)
    sh.size = wp.array(size, dtype=wp.vec3, device=device)
    sh.slope_lon = wp.array(slope_lon, dtype=float, device=device)
    sh.slope_lat = wp.array(slope_lat, dtype=float, device=device)
    return sh


def rover_inertia(model: newton.Model, bodies_per_world: int, chassis: int) -> tuple[float, np.ndarray, np.ndarray]:
    """World 0's rover as one rigid body, from the model's masses and its joints at zero: (mass [kg],
    centre of mass [m] and inertia about it [kg·m²], both in the chassis body frame)."""
    state = model.state()
    newton.eval_fk(model, model.joint_q, model.joint_qd, state)
    q = state.body_q.numpy()[:bodies_per_world].astype(np.float64)
    mass = model.body_mass.numpy()[:bodies_per_world].astype(np.float64)
    inertia = model.body_inertia.numpy()[:bodies_per_world].astype(np.float64)
    com = model.body_com.numpy()[:bodies_per_world].astype(np.float64)

    def rotation(quat) -> np.ndarray:  # (x, y, z, w) -> 3x3, in float64
        return quat_to_matrix(torch.from_numpy(quat)).numpy()

    r_c = rotation(q[chassis, 3:])
    # each body's rotation and COM in the chassis frame
    rots = [r_c.T @ rotation(q[b, 3:]) for b in range(bodies_per_world)]
    coms = [r_c.T @ (q[b, :3] + rotation(q[b, 3:]) @ com[b] - q[chassis, :3]) for b in range(bodies_per_world)]
    total = float(mass.sum())
    centre = sum(m * c for m, c in zip(mass, coms)) / total
    tensor = np.zeros((3, 3))
    for m, rot, i_b, c in zip(mass, rots, inertia, coms):
        d = c - centre
        tensor += rot @ i_b @ rot.T + m * (d @ d * np.eye(3) - np.outer(d, d))
    return total, centre, tensor


def _wheel_slots(built: BuiltModel, wheel_dofs: list[int], dofs_per_world: int, device) -> WheelSlots:
    """The wheels' cylinders, joints, spin inertias and sides (each side's spin inertia for a solve that turns a
    geared side as one, :attr:`~atrv_warp.sim.config.ContactConfig.solve_geared_sides`), in the description's wheel
    order."""
    rb, desc = built.rover_builder, built.description
    shape, axis, inv_spin = [], [], []
    inertia = built.model.body_inertia.numpy()
    for body, wheel in zip(built.wheel_bodies, desc.wheels):
        cylinders = [s for s in built.rover_shapes
                     if rb.shape_body[s] == body and rb.shape_type[s] == newton.GeoType.CYLINDER]
        if len(cylinders) != 1:
            raise ValueError(f"wheel {wheel.link!r} needs exactly one collision cylinder, has {len(cylinders)}")
        shape.append(built.rover_shapes.index(cylinders[0]))
        a = np.asarray(wheel.axis, dtype=np.float64)
        axis.append(wp.vec3(*a))
        inv_spin.append(1.0 / float(a @ inertia[body] @ a))
    slots = WheelSlots()
    slots.count = len(desc.wheels)
    side_inertia = [sum(1.0 / i for i, w in zip(inv_spin, desc.wheels) if w.side == q) for q in (0, 1)]
    slots.side_inertia = wp.vec2(*side_inertia)
    slots.side = wp.array([w.side for w in desc.wheels], dtype=int, device=device)
    slots.sign = wp.array([float(w.drive_sign) for w in desc.wheels], dtype=float, device=device)
    slots.chassis = built.chassis_body
    slots.dofs_per_world = dofs_per_world
    slots.shape = wp.array(shape, dtype=int, device=device)
    slots.dof = wp.array(wheel_dofs, dtype=int, device=device)
    slots.axis = wp.array(axis, dtype=wp.vec3, device=device)
    slots.inv_spin_inertia = wp.array(inv_spin, dtype=float, device=device)
    return slots


class ContactModel:
    """Hunt–Crossley contact of every world's rover against the arena, ready to launch.

    Attributes (read-only; the kernels' inputs):
        params: the law (:class:`~atrv_warp.sim.kernels.contact.ContactParams`).
        shapes: the template rover's shapes (:class:`~atrv_warp.sim.kernels.contact.RoverShapes`).
        planes: ground and walls (:class:`~atrv_warp.sim.kernels.contact.ArenaPlanes`).
        terrain: each world's ground (:class:`Terrain`); obstacles: each world's (:class:`Obstacles`).
        maps: each world's map (:class:`~atrv_warp.sim.maps.GridWorlds`; none by default): walls the laser sees and
            the rover meets.
        scene: planes, terrain, obstacles and maps as the kernel's struct.
        wheels: the wheels the Coulomb friction solver handles
            (:class:`~atrv_warp.sim.kernels.friction.WheelSlots`; ``None`` under the viscous law).
        inertia: each world's rover as one rigid body, the solver's model of it
            (:class:`~atrv_warp.sim.kernels.friction.RoverInertia`), which a payload changes.
        nominal_rover: the rover without payload as one rigid body
            (:class:`~atrv_warp.sim.kernels.params.MassProperties`, chassis frame).
    """

    def __init__(self, built: BuiltModel, *, rover: RoverConfig, contact: ContactConfig, arena: ArenaConfig,
                 sim_dt: float, gravity: float, device, terrain: HeightGrid | None = None,
                 obstacles: ObstacleConfig | None = None, implicit_drive: bool = False,
                 maps: GridWorlds | None = None):
        self.num_worlds = built.num_worlds
        rb = built.rover_builder
        self.bodies_per_world = rb.body_count
        self.device = device
        desc = built.description
        self.params = _law(contact, sim_dt, desc.total_mass / max(len(desc.wheels), 1))
        self.shapes = _shapes(built, rover, contact, sim_dt, device)
        self.planes = _planes(arena, device)
        self.terrain = Terrain(terrain, self.num_worlds, arena, device)
        self.obstacles = Obstacles(obstacles, self.num_worlds, arena, device)
        self.maps = maps if maps is not None else GridWorlds([], [-1] * self.num_worlds, device)
        scene = Scene()
        scene.planes, scene.terrain, scene.obstacles = self.planes, self.terrain.kernel, self.obstacles.kernel
        scene.grids = self.maps.struct
        self.scene = scene
        self.gravity = wp.vec3(0.0, 0.0, gravity)
        self.wheels: WheelSlots | None = None
        geared = contact.friction_law == "coulomb" and contact.solve_geared_sides and rover.robot_spec.motor_per_side
        if contact.friction_law == "coulomb":
            self.wheels = _wheel_slots(built, [rb.joint_qd_start[j] for j in built.wheel_joints], rb.joint_dof_count,
                                       device)
        mass, com, tensor = rover_inertia(built.model, self.bodies_per_world, built.chassis_body)
        n = self.num_worlds
        inertia = RoverInertia()
        grad = built.model.requires_grad  # a tape differentiates through a payload's effect on this model
        inertia.inv_mass = wp.array(np.full(n, 1.0 / mass), dtype=float, device=device, requires_grad=grad)
        inertia.com = wp.array(np.tile(com, (n, 1)), dtype=wp.vec3, device=device, requires_grad=grad)
        inertia.inv_inertia = wp.array(np.tile(np.linalg.inv(tensor), (n, 1, 1)), dtype=wp.mat33, device=device,
                                       requires_grad=grad)
        self.inertia = inertia
        nominal = MassProperties()
        nominal.mass, nominal.com, nominal.inertia = mass, wp.vec3(*com), wp.mat33(*tensor.flatten())
        nominal.inv_mass = inertia.inv_mass.numpy()[0]
        nominal.inv_inertia = wp.mat33(*inertia.inv_inertia.numpy()[0].flatten())
        self.nominal_rover = nominal
        self.wheel_count = len(desc.wheels)
        self._solve, self._clear = friction_kernels(self.wheel_count, geared, implicit_drive)
        self.impulses = wp.zeros(self.num_worlds * self.wheel_count, dtype=wp.vec3, device=device)
        """(N x wheels) each wheel's last friction impulse [N·s], world frame: where the next substep's
        sweeps start (the Coulomb law's warm start)."""

    def apply(self, state: newton.State, body_com: wp.array, joint_f: wp.array, damping: wp.array, torque_cap: wp.array,
              flags: wp.array, physics: WorldPhysics, warm_start: wp.array | None = None,
              impulses: wp.array | None = None) -> None:
        """Add every contact wrench to ``state.body_f`` and OR the contact bits into ``flags``.

        ``joint_f`` holds this substep's drive torques (the friction solver predicts the wheels'
        spin with them), ``damping`` (N, W) how each falls with its wheel's speed change (an implicit driver's),
        ``torque_cap`` (N, W) each wheel's motor torque at the loop's limit (the drive's ``torque_cap``);
        ``physics`` each world's mu, stiffness and wheel radius
        (:class:`~atrv_warp.sim.params.WorldParams`, or a tape's own with differentiable arrays).
        ``warm_start`` and ``impulses`` (N x wheels ``wp.vec3``) replace :attr:`impulses` as the previous
        substep's friction impulses and this one's (a tape needs one array per substep).
        """
        wp.launch(compute_contact_forces, dim=self.num_worlds,
                  inputs=[self.bodies_per_world, self.shapes, self.scene, self.params, physics, state.body_q,
                          state.body_qd, body_com],
                  outputs=[state.body_f, flags], device=self.device)
        if self.wheels is not None:
            wp.launch(self._solve, dim=self.num_worlds,
                      inputs=[self.bodies_per_world, self.shapes, self.wheels, self.inertia, self.scene, self.params,
                              self.gravity, physics, state.body_q, state.body_qd, body_com, joint_f, damping,
                              torque_cap, self.impulses if warm_start is None else warm_start],
                      outputs=[state.body_f, self.impulses if impulses is None else impulses], device=self.device)

    def reset(self, mask: wp.array) -> None:
        """Forget the masked worlds' friction impulses (a reset rover starts unloaded)."""
        wp.launch(self._clear, dim=self.num_worlds, inputs=[mask, self.wheel_count], outputs=[self.impulses],
                  device=self.device)
