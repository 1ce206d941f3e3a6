"""N rovers in N independent worlds, stepped by Newton's Featherstone solver.

One :meth:`RoverSim.step` advances every world by ``SimConfig.step_dt`` (0.05 s) in
``substeps`` solver steps; per substep: contact wrenches (Hunt–Crossley, our kernel),
wheel torques (motor kernel), one Featherstone step. The whole step is recorded once with
``wp.ScopedCapture`` and replayed, on CPU as on CUDA. Per-world state is exposed as torch
views of Warp arrays that the step updates in place (no copy per step).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import newton
import numpy as np
import torch
import warp as wp

from atrv_warp.core.geometry import quat_to_matrix
from atrv_warp.runtime import available_memory, enable_gradients
from atrv_warp.sim.config import (
    ArenaConfig,
    ContactConfig,
    ObstacleConfig,
    RoverConfig,
    SimConfig,
    nominal_rover_config,
)
from atrv_warp.sim.config_file import read_sim_config
from atrv_warp.sim.contact import ContactModel, Obstacles, Terrain
from atrv_warp.sim.driver import DRIVE_TORQUE, DRIVE_TWIST, SNAPSHOT_ADDED, Driver, DriverConfig
from atrv_warp.sim.kernel_cache import precompile
from atrv_warp.sim.kernels.contact import FLAG_BODY_GROUND, FLAG_OBSTACLE, FLAG_WALL
from atrv_warp.sim.kernels.driver import DriverState, drive_wheels
from atrv_warp.sim.kernels.params import MassProperties, WorldPhysics, apply_payload
from atrv_warp.sim.kernels.rover import RoverLayout, compute_rover_state, reset_worlds
from atrv_warp.sim.kernels.terrain import place_on_terrain
from atrv_warp.sim.maps import GridWorlds, arena_around, round_robin
from atrv_warp.sim.model import BuiltModel, build_model
from atrv_warp.sim.modes import DRIVE_MODE_REFERENCE_TORQUE, DRIVE_MODE_TORQUES, DriveMode
from atrv_warp.sim.params import (
    PARAMETER_KEYS,
    PARAMETERS,
    WorldParams,
    check_bounds,
    check_parameter,
    parameter_bounds,
    parameter_values,
)
from atrv_warp.sim.terrain import HeightGrid, TerrainConfig, get_terrain
from atrv_warp.sim.urdf import footprint_radii, load_rover
from atrv_warp.world import OccupancyMap, resolve_sites

__all__ = ["DRIVE_MODE_REFERENCE_TORQUE", "DRIVE_MODE_TORQUES", "DriveMode", "RoverSim", "SimBuffers"]


def _as_world_mask(mask, num_worlds: int) -> np.ndarray:
    if mask is None:
        return np.ones(num_worlds, dtype=bool)
    m = np.asarray(mask.detach().cpu() if isinstance(mask, torch.Tensor) else mask)
    if m.dtype != bool:
        if m.ndim == 1 and m.size and np.issubdtype(m.dtype, np.integer):
            idx = m
            if idx.min() < 0 or idx.max() >= num_worlds:
                raise IndexError(f"world indices must lie in [0, {num_worlds}), got {idx.tolist()}")
            m = np.zeros(num_worlds, dtype=bool)
            m[idx] = True
            return m
        raise TypeError(f"mask must be a bool array of shape ({num_worlds},) or integer world indices")
    m = m.reshape(-1)
    if m.shape != (num_worlds,):
        raise ValueError(f"mask must have shape ({num_worlds},), got {tuple(m.shape)}")
    return m


@dataclass(frozen=True)
class SimBuffers:
    """Read-only view of the Warp arrays a :class:`RoverSim` steps in place, for clients' kernels
    (the task, sensors, recorders). The arrays live as long as the simulator and are never
    reallocated. Write only ``commands``; everything else is the simulator's output.

    Per-world arrays have N = ``num_worlds`` rows; Newton's flat arrays hold
    ``layout.bodies_per_world`` bodies per world, world after world.
    """

    layout: RoverLayout
    """Where each world's rover lives in Newton's flat arrays (the kernels' struct)."""
    body_q: wp.array
    """(N·B,) ``wp.transform`` body poses, world frame (``state_0``)."""
    body_qd: wp.array
    """(N·B,) ``wp.spatial_vector`` body velocities (Newton's convention)."""
    joint_q: wp.array
    """Generalised coordinates, ``layout.coords_per_world`` per world."""
    joint_qd: wp.array
    """Generalised velocities, ``layout.dofs_per_world`` per world."""
    body_com: wp.array
    """(N·B,) ``wp.vec3`` centres of mass in body frames."""
    commands: wp.array
    """(N,) ``wp.vec2`` [left, right] wheel torque commands [N·m], read by the next step."""
    lin_vel: wp.array
    """(N,) ``wp.vec3`` chassis-origin velocity [m/s], world frame."""
    ang_vel: wp.array
    """(N,) ``wp.vec3`` chassis angular velocity [rad/s], world frame."""
    rpy: wp.array
    """(N,) ``wp.vec3`` roll, pitch, yaw [rad]."""
    wheel_speed: wp.array
    """(N, W) forward-positive wheel speeds [rad/s]."""
    wheel_torque: wp.array
    """(N, W) torques applied in the last substep [N·m]."""
    contact_flags: wp.array
    """(N,) ``int32``: bit 1 wall contact, bit 2 chassis–ground contact, bit 4 obstacle contact, since
    the last step began."""
    nonfinite: wp.array
    """(N,) ``int32``: 1 where the world's state is no longer finite (stays until reset)."""


BYTES_PER_WORLD = 32_000
"""Memory one world takes, with headroom [bytes]: about 20 kB measured on the CPU (the resident memory of
``RoverSim(4096)`` less ``RoverSim(64)``, and of the ``nav_deploy`` environment likewise)."""


def check_world_count(num_worlds, device) -> None:
    """Refuse a world count that is no positive integer (``True`` is not one world), or whose memory estimate
    (:data:`BYTES_PER_WORLD` each) exceeds what ``device`` has free, before anything is allocated.

    Raises:
        TypeError: Not an integer.
        ValueError: Below 1, or past the memory (the estimate and what is free named).
    """
    if isinstance(num_worlds, bool) or not isinstance(num_worlds, int | np.integer):
        raise TypeError(f"num_worlds must be an integer, got {num_worlds!r} ({type(num_worlds).__name__})")
    if num_worlds < 1:
        raise ValueError(f"num_worlds must be >= 1, got {num_worlds}")
    need, free = int(num_worlds) * BYTES_PER_WORLD, available_memory(str(device))
    if free is not None and need > free:
        raise ValueError(f"{num_worlds:,} worlds need about {need / 1e9:.1f} GB on {device} "
                         f"({BYTES_PER_WORLD / 1e3:.0f} kB each), more than the {free / 1e9:.1f} GB free there")


def checked_configs(rover: RoverConfig, contact: ContactConfig, sim_config: str | Path | None = None):
    """``rover`` and ``contact`` with ``sim_config``'s tables applied, and this robot's parameter bounds, each value
    checked against them (a value out of bounds is a ``ValueError`` naming the file and key it came from)."""
    read = None
    if sim_config:
        read = read_sim_config(sim_config, rover, contact)
    applied_rover, applied_contact = (read.rover, read.contact) if read is not None else (rover, contact)
    bounds = parameter_bounds(load_rover(applied_rover), rover.wheel_radius)
    for name, value in parameter_values(applied_rover, applied_contact).items():
        table, key = PARAMETER_KEYS[name]
        label = (f"sim config {read.path}: [{table}] {key}" if read is not None and read.sets(table, key) else
                 f"{'RoverConfig' if table == 'rover' else 'ContactConfig'}.{key}")
        check_bounds(bounds, name, value, label)
    return applied_rover, applied_contact, bounds


class RoverSim:
    """Batched skid-steer rover simulator (the ATRV-Jr unless told otherwise).

    Args:
        num_worlds: Number of independent worlds (one rover each), 1 … 4096 and beyond.
        robot: A shipped robot's name (``"atrvjr"``, ``"jackal"``, ``"husky"``) or a robot file's path
            (:func:`~atrv_warp.core.robot.load_robot`); ``None``: ``rover``'s robot, else the ATRV-Jr.
        variant: Registered ATRV-Jr variant (``"realistic"`` or ``"reference"``); ignored if
            ``rover`` is given.
        rover: Rover configuration (its robot, and what differs from it: URDF, link roles, payload).
        contact: Contact law.
        arena: Arena geometry.
        sim: Integrator settings.
        terrain: The ground: ``None`` or ``"flat"`` (the reference arena), a preset name of
            :data:`~atrv_warp.sim.terrain.TERRAIN_PRESETS`, a :class:`~atrv_warp.sim.terrain.TerrainConfig`
            or a :class:`~atrv_warp.sim.terrain.HeightGrid`.
        obstacles: Room for static obstacles per world (:class:`ObstacleConfig`); ``None``: none.
        device: Warp device (``"cpu"`` default, ``"cuda:0"`` …).
        requires_grad: Build the model for gradients (what :class:`~atrv_warp.sim.diff.DiffRollout` does).
        sim_config: A TOML file whose ``[rover]`` and ``[contact]`` tables change ``rover`` and
            ``contact`` (:func:`~atrv_warp.sim.config_file.load_sim_config`), e.g. the calibration that
            ``atrv-calibrate`` wrote from a recorded bag.
        driver: The base's motor driver (:class:`~atrv_warp.sim.driver.DriverConfig`; default: its defaults).
            Its radius and track default to the nominal rover's: ``rover`` before ``sim_config`` changes it; its
            gains, torque limit and track factor to the robot's.
        maps: Sites as Nav2 maps (:class:`~atrv_warp.world.OccupancyMap`, a ``map_server`` YAML's path, or procedural
            places for this robot such as ``"building:64"``: :func:`~atrv_warp.world.resolve_sites`), each held once;
            world ``w`` drives in map ``w % len(maps)``. Their walls and unknown cells (and what lies
            beyond a map's edge) stand :data:`~atrv_warp.sim.maps.DEFAULT_WALL_TOP` high: the laser reads them, and
            the rover meets them as it meets an obstacle (``FLAG_OBSTACLE``). Without an ``arena``, the arena's
            ground and walls are drawn around every map (:func:`~atrv_warp.sim.maps.arena_around`). ``()``: none.

    State views (torch tensors on the sim device, updated in place by :meth:`step`; clone to keep):
        ``root_pose`` (N, 7): chassis position [m] and quaternion (x, y, z, w), world frame.
        ``lin_vel`` (N, 3): chassis-origin velocity [m/s], world frame.
        ``ang_vel`` (N, 3): chassis angular velocity [rad/s], world frame.
        ``rpy`` (N, 3): roll, pitch, yaw [rad].
        ``wheel_speed`` (N, W): forward-positive wheel speeds [rad/s].
        ``wheel_torque`` (N, W): torques applied in the last substep [N·m].
        ``contact_flags`` (N,): bit 1 wall contact, bit 2 chassis–ground contact, since the last step began.
        ``nonfinite`` (N,): 1 where the world's state is no longer finite (stays until reset).
        ``commands`` (N, 2): [left, right] wheel torque commands [N·m], read by :meth:`step` in worlds
        driven by torque (:meth:`set_commands`).

    Worlds driven by velocity (:meth:`set_twist`) go through :attr:`driver` instead
    (:class:`~atrv_warp.sim.driver.Driver`: the motor driver's wheel-speed loop inside every substep, and the
    wheel odometry every world reports).

    The contract for code that builds on the simulator (tasks, sensors, integrations):
        :attr:`buffers` the Warp arrays behind those views (:class:`SimBuffers`), for kernels;
        :attr:`layout` where each world's rover sits in Newton's arrays;
        :meth:`reset_worlds` a masked reset from device arrays (no host round trip);
        :attr:`contact` the contact model, and :meth:`substep` one solver substep, which
        :class:`~atrv_warp.sim.diff.DiffRollout` steps through too;
        :attr:`terrain` and :attr:`obstacles` each world's ground and obstacles (write a world's tile or
        layout, then reset it); :attr:`maps` each world's map;
        :attr:`params` each world's physical parameters (:meth:`set_params`, or a kernel's writes and
        :meth:`apply_payload`).
    """

    def __init__(
        self,
        num_worlds: int = 1,
        *,
        robot: str | None = None,
        variant: str = "realistic",
        rover: RoverConfig | None = None,
        contact: ContactConfig | None = None,
        arena: ArenaConfig | None = None,
        sim: SimConfig | None = None,
        terrain: TerrainConfig | HeightGrid | str | None = None,
        obstacles: ObstacleConfig | None = None,
        device: str | None = "cpu",
        requires_grad: bool = False,
        sim_config: str | Path | None = None,
        driver: DriverConfig | None = None,
        maps: Sequence[OccupancyMap | str | Path] = (),
    ):
        self.device = wp.get_device(device)
        check_world_count(num_worlds, self.device)
        if requires_grad:
            enable_gradients()
        precompile(self.device)  # the first run on a machine compiles, in parallel, and says so
        nominal_rover = nominal_rover_config(robot, variant, rover)
        self.rover_cfg, self.contact_cfg, self.bounds = checked_configs(nominal_rover, contact or ContactConfig(),
                                                                        sim_config)
        """``bounds``: each bounded physical parameter's range for this robot
        (:func:`~atrv_warp.sim.params.parameter_bounds`): the configs' values and :meth:`set_params` are held to them."""
        width = 2 * footprint_radii(load_rover(self.rover_cfg), self.rover_cfg)[0] if maps else 0.0
        site_maps = resolve_sites(maps, width)  # procedural places drawn at the robot's width
        self.arena_cfg = arena or arena_around(site_maps)
        self.sim_cfg = sim or SimConfig()
        self.num_worlds = num_worlds
        self.substeps = self.sim_cfg.substeps
        self.built: BuiltModel = build_model(num_worlds, rover=self.rover_cfg, arena=self.arena_cfg,
                                             sim=self.sim_cfg, device=self.device, requires_grad=requires_grad)
        self.model = self.built.model
        self.description = self.built.description
        interval = self.sim_cfg.mass_matrix_interval or self.substeps
        if self.substeps % interval:
            raise ValueError(f"mass_matrix_interval={interval} must divide substeps={self.substeps}: a refresh "
                             "must fall on every step boundary so a reset never meets a stale mass matrix")
        self.solver = newton.solvers.SolverFeatherstone(
            self.model, angular_damping=0.0, update_mass_matrix_interval=interval,
            use_tile_gemm=self.sim_cfg.use_tile_gemm,
            fuse_cholesky=self.sim_cfg.resolve_fuse_cholesky(self.device.is_cpu))
        self.state_0 = self.model.state()
        self.state_1 = self.model.state()
        self.control = self.model.control()
        self._make_layout()
        if isinstance(terrain, str):
            terrain = get_terrain(terrain)
        if isinstance(terrain, TerrainConfig):
            terrain = terrain.generate(self.arena_cfg.half_size)
        driver = driver or DriverConfig()
        if driver.implicit_speed_loop and self.contact_cfg.friction_law != "coulomb":
            raise ValueError("DriverConfig.implicit_speed_loop solves the drive with the wheels' Coulomb friction; "
                             f"ContactConfig.friction_law is {self.contact_cfg.friction_law!r}")
        self.contact = ContactModel(self.built, rover=self.rover_cfg, contact=self.contact_cfg, arena=self.arena_cfg,
                                    sim_dt=self.sim_cfg.sim_dt, gravity=self.sim_cfg.gravity, device=self.device,
                                    terrain=terrain, obstacles=obstacles,
                                    implicit_drive=driver.implicit_under(self.contact_cfg.friction_law),
                                    maps=GridWorlds(site_maps, round_robin(num_worlds, len(site_maps)), self.device,
                                                    footprint=self.footprint_radii))
        """The contact model every substep launches (:class:`~atrv_warp.sim.contact.ContactModel`)."""
        self.params = WorldParams(num_worlds, rover=self.rover_cfg, contact=self.contact_cfg, device=self.device)
        """Each world's physical parameters (:class:`~atrv_warp.sim.params.WorldParams`): friction, stiffness,
        wheel radius, motor torque scale and speed limit, payload. Change them with :meth:`set_params`."""
        self.driver_cfg = dataclasses.replace(
            driver, implicit_speed_loop=driver.implicit_under(self.contact_cfg.friction_law)).resolved(
            nominal_rover.robot_spec)
        """The driver's configuration, the robot's gains, torque limit and track factor filled in."""
        self.driver = Driver(self.driver_cfg, self.driver_cfg.kinematics(self.description, nominal_rover), num_worlds,
                             self.sim_cfg.sim_dt, self.device)
        """Every world's motor driver and wheel odometry (:class:`~atrv_warp.sim.driver.Driver`)."""
        self._nominal_chassis = self._chassis_mass_properties()
        if self.rover_cfg.payload_mass:
            self.apply_payload(wp.full(num_worlds, True, dtype=bool, device=self.device))

        self._allocate_outputs()
        self.sim_time = 0.0
        """Simulated time since construction [s] (the same in every world)."""
        self._graph = None
        self.reset()

    # ------------------------------------------------------------------ build helpers
    def _allocate_outputs(self) -> None:
        """The per-world outputs the step writes (commands, velocities, attitude, wheels, flags), as Warp
        arrays and the torch views over them, and the buffers a step kernel reads."""
        n, w = self.num_worlds, len(self.description.wheels)
        dev = self.device
        self._commands = wp.zeros(n, dtype=wp.vec2, device=dev)
        self._lin_vel = wp.zeros(n, dtype=wp.vec3, device=dev)
        self._ang_vel = wp.zeros(n, dtype=wp.vec3, device=dev)
        self._rpy = wp.zeros(n, dtype=wp.vec3, device=dev)
        self._wheel_speed = wp.zeros((n, w), dtype=float, device=dev)
        self._wheel_torque = wp.zeros((n, w), dtype=float, device=dev)
        self._damping = wp.zeros((n, w), dtype=float, device=dev)
        self._torque_cap = wp.zeros((n, w), dtype=float, device=dev)
        self._contact_flags = wp.zeros(n, dtype=wp.int32, device=dev)
        self._nonfinite = wp.zeros(n, dtype=wp.int32, device=dev)
        self._reset_mask = wp.zeros(n, dtype=bool, device=dev)
        self._reset_poses = wp.zeros(n, dtype=wp.vec3, device=dev)

        self.commands = wp.to_torch(self._commands).view(n, 2)
        self.root_pose = wp.to_torch(self.state_0.body_q).view(n, self._layout.bodies_per_world, 7)[
            :, self._layout.chassis_body]
        self.lin_vel = wp.to_torch(self._lin_vel)
        self.ang_vel = wp.to_torch(self._ang_vel)
        self.rpy = wp.to_torch(self._rpy)
        self.wheel_speed = wp.to_torch(self._wheel_speed)
        self.wheel_torque = wp.to_torch(self._wheel_torque)
        self.contact_flags = wp.to_torch(self._contact_flags)
        self.nonfinite = wp.to_torch(self._nonfinite)

        s0 = self.state_0
        self._buffers = SimBuffers(
            layout=self._layout, body_q=s0.body_q, body_qd=s0.body_qd, joint_q=s0.joint_q, joint_qd=s0.joint_qd,
            body_com=self.model.body_com, commands=self._commands, lin_vel=self._lin_vel, ang_vel=self._ang_vel,
            rpy=self._rpy, wheel_speed=self._wheel_speed, wheel_torque=self._wheel_torque,
            contact_flags=self._contact_flags, nonfinite=self._nonfinite)

    def _make_layout(self) -> None:
        rb = self.built.rover_builder
        q_start = list(rb.joint_q_start) + [rb.joint_coord_count]
        qd_start = list(rb.joint_qd_start) + [rb.joint_dof_count]
        root = rb.joint_label.index("root_joint")
        layout = RoverLayout()
        layout.bodies_per_world = rb.body_count
        layout.coords_per_world = rb.joint_coord_count
        layout.dofs_per_world = rb.joint_dof_count
        layout.chassis_body = self.built.chassis_body
        layout.chassis_coord = q_start[root]
        layout.chassis_dof = qd_start[root]
        wheels = self.description.wheels
        layout.wheel_count = len(wheels)
        dev = self.device
        layout.wheel_coord = wp.array([q_start[j] for j in self.built.wheel_joints], dtype=int, device=dev)
        layout.wheel_dof = wp.array([qd_start[j] for j in self.built.wheel_joints], dtype=int, device=dev)
        layout.wheel_side = wp.array([w.side for w in wheels], dtype=int, device=dev)
        layout.wheel_sign = wp.array([w.drive_sign for w in wheels], dtype=float, device=dev)
        inertia = self.model.body_inertia.numpy()
        layout.wheel_inertia = wp.array([float(np.asarray(w.axis) @ inertia[b] @ np.asarray(w.axis))
                                         for w, b in zip(wheels, self.built.wheel_bodies)], dtype=float, device=dev)
        layout.sides_coupled = int(self.rover_cfg.robot_spec.motor_per_side)
        self._layout = layout

    def _chassis_mass_properties(self) -> MassProperties:
        """World 0's chassis as the model holds it (mass, COM, inertia, and their inverses)."""
        m, c = self.model, self._layout.chassis_body
        props = MassProperties()
        props.mass = float(m.body_mass.numpy()[c])
        props.inv_mass = float(m.body_inv_mass.numpy()[c])
        props.com = wp.vec3(*m.body_com.numpy()[c].tolist())
        props.inertia = wp.mat33(*m.body_inertia.numpy()[c].flatten().tolist())
        props.inv_inertia = wp.mat33(*m.body_inv_inertia.numpy()[c].flatten().tolist())
        return props

    # ------------------------------------------------------------------ the contract
    @property
    def layout(self) -> RoverLayout:
        """Where each world's rover lives in Newton's flat arrays (read-only)."""
        return self._layout

    @property
    def nominal_chassis(self) -> MassProperties:
        """The chassis without payload, as the model was built (:class:`~atrv_warp.sim.kernels.params.MassProperties`)."""
        return self._nominal_chassis

    @property
    def terrain(self) -> Terrain:
        """Each world's ground (:class:`~atrv_warp.sim.contact.Terrain`; disabled on the flat arena)."""
        return self.contact.terrain

    @property
    def obstacles(self) -> Obstacles:
        """Each world's obstacles (:class:`~atrv_warp.sim.contact.Obstacles`; no slots without an ObstacleConfig)."""
        return self.contact.obstacles

    @property
    def maps(self) -> GridWorlds:
        """Each world's map (:class:`~atrv_warp.sim.maps.GridWorlds`: ``maps``, ``world_map``; none by default)."""
        return self.contact.maps

    @property
    def buffers(self) -> SimBuffers:
        """The Warp arrays behind the state views, for kernels (:class:`SimBuffers`, read-only)."""
        return self._buffers

    # ------------------------------------------------------------------ per-world parameters
    def set_params(self, worlds=None, **values) -> None:
        """Set physical parameters of every world, or of the masked/indexed ``worlds``: any of
        :data:`~atrv_warp.sim.params.PARAMETERS` (``friction=0.8, payload_mass=20.0`` …), each a number
        (the same in every selected world) or one value per selected world. Checked before anything is
        written: an unknown name or a bad value is a ``ValueError`` naming it. Takes effect from the next step.
        """
        m = _as_world_mask(worlds, self.num_worlds)
        count = int(m.sum())
        staged = {}
        for name, value in values.items():
            check_parameter(name, value)
            check_bounds(self.bounds, name, value)
            v = torch.as_tensor(np.asarray(value, dtype=np.float32))
            width = (3,) if name == "payload_offset" else ()
            if v.shape not in ((*width,), (count, *width)):
                raise ValueError(f"{name} must be one value {(*width,)} or one per selected world {(count, *width)}, "
                                 f"got shape {tuple(v.shape)}")
            staged[name] = v
        sel = torch.as_tensor(m, device=self.params.friction.device)
        for name, v in staged.items():
            self.params.view(name)[sel] = v.to(self.params.friction.device)
        if {"payload_mass", "payload_offset"} & set(staged):
            self._reset_mask.assign(m)
            self.apply_payload(self._reset_mask)

    def apply_payload(self, mask: wp.array) -> None:
        """Put each masked world's payload (:attr:`params` ``payload_mass`` at ``payload_offset``) on its chassis:
        the solver's mass properties and the friction solver's model of the rover. A device-side call (no host
        round trip), for a kernel that wrote the payload arrays; from the host, use :meth:`set_params`."""
        lay, m = self._layout, self.model
        inertia = self.contact.inertia
        wp.launch(apply_payload, dim=self.num_worlds,
                  inputs=[mask, self.params.payload_mass_array, self.params.payload_offset_array, lay.bodies_per_world,
                          lay.chassis_body, self._nominal_chassis, self.contact.nominal_rover, 1],
                  outputs=[m.body_mass, m.body_inv_mass, m.body_inertia, m.body_inv_inertia, m.body_com,
                           inertia.inv_mass, inertia.com, inertia.inv_inertia], device=self.device)
        # Newton's route for runtime mass changes: the solver re-derives its spatial inertias
        self.solver.notify_model_changed(newton.ModelFlags.BODY_INERTIAL_PROPERTIES)

    # ------------------------------------------------------------------ derived figures
    @property
    def rest_height(self) -> float:
        """Chassis-origin height [m] at static equilibrium on the ground, from the contact law."""
        return float(self.rest_heights(self.rover_cfg.wheel_radius, 0.0))

    def rest_heights(self, wheel_radius, payload_mass) -> torch.Tensor:
        """Chassis-origin heights [m] at static equilibrium on flat ground of rovers with rolling radius
        ``wheel_radius`` [m] and a payload of ``payload_mass`` [kg] beyond the model's mass (each a number or one per
        rover; broadcast), from the contact law at :attr:`contact_cfg`'s stiffness: a world drawn with another radius
        or payload than the configured rover stands at its own height."""
        c = self.contact_cfg
        radius = torch.as_tensor(wheel_radius, dtype=torch.float64)
        mass = self.description.total_mass + torch.as_tensor(payload_mass, dtype=torch.float64)
        load = mass * abs(self.sim_cfg.gravity) / len(self.description.wheels)
        depth = (load / c.stiffness) ** (1.0 / c.exponent)
        linear = load / (c.stiffness * c.linear_region ** (c.exponent - 1.0))
        depth = torch.where(depth < c.linear_region, linear, depth)
        axle_z = float(np.mean([w.origin[2, 3] for w in self.description.wheels]))
        return self.arena_cfg.ground_top + radius - depth - axle_z

    @property
    def frame_names(self) -> tuple[str, ...]:
        """Sensor frames fixed to the chassis, in URDF order."""
        return tuple(f.name for f in self.description.frames)

    def frame_pose(self, name: str) -> torch.Tensor:
        """World pose (N, 4, 4) of a named sensor frame, from the chassis pose."""
        frames = {f.name: f.transform for f in self.description.frames}
        if name not in frames:
            raise KeyError(f"unknown frame {name!r}; known: {sorted(frames)}")
        pose = self.root_pose.detach().to(torch.float64).cpu()
        rot = quat_to_matrix(pose[:, 3:7])
        chassis = torch.eye(4, dtype=torch.float64).repeat(self.num_worlds, 1, 1)
        chassis[:, :3, :3] = rot
        chassis[:, :3, 3] = pose[:, :3]
        return chassis @ torch.as_tensor(frames[name])

    # ------------------------------------------------------------------ stepping
    def substep(self, s_in: newton.State, s_out: newton.State, control: newton.Control, commands: wp.array, *,
                physics: WorldPhysics | None = None, flags: wp.array | None = None, torque: wp.array | None = None,
                solver_in: newton.State | None = None, warm_start: wp.array | None = None,
                impulses: wp.array | None = None, twist: wp.array | None = None,
                driver_in: DriverState | None = None, driver_out: DriverState | None = None,
                mode: wp.array | None = None, damping: wp.array | None = None, cap: wp.array | None = None) -> None:
        """One solver substep of ``sim_dt``: the wheels' drive (torque commands, or the motor driver's loop),
        contact wrenches, one Featherstone step.

        The simulator's own step calls it on its two states; :class:`~atrv_warp.sim.diff.DiffRollout`
        calls it on a tape with one state per substep, its own ``commands`` (N,) ``wp.vec2`` (torques) or
        ``twist`` (N,) ``wp.vec2`` with ``mode`` (N,) and the driver's state before and after the substep
        (``driver_in``, ``driver_out``), ``physics`` (:class:`~atrv_warp.sim.kernels.params.WorldPhysics`, with a
        differentiable mu), ``flags`` (N,) and ``torque`` (N, W) outputs, ``solver_in``: a view of ``s_in`` with
        its own ``body_q`` for the solver to write, and the wheels' friction impulses of the previous substep
        (``warm_start``) and of this one (``impulses``), N x wheels ``wp.vec3`` each, and ``damping`` (N, W), the
        implicit driver's slope that the drive writes and the friction solve reads (a tape needs one per substep), and
        ``cap`` (N, W), its torque cap, likewise.
        """
        physics = self.params.physics if physics is None else physics
        d = self.driver
        s_in.clear_forces()
        wp.launch(drive_wheels, dim=self.num_worlds,
                  inputs=[self._layout, d.params, d.mode_array if mode is None else mode, commands,
                          d.twist_array if twist is None else twist, d.lag_array, physics, s_in.joint_q, s_in.joint_qd,
                          d.state if driver_in is None else driver_in],
                  outputs=[d.state if driver_out is None else driver_out, control.joint_f,
                           self._wheel_torque if torque is None else torque,
                           self._damping if damping is None else damping,
                           self._torque_cap if cap is None else cap], device=self.device)
        self.contact.apply(s_in, self.model.body_com, control.joint_f, self._damping if damping is None else damping,
                           self._torque_cap if cap is None else cap,
                           self._contact_flags if flags is None else flags, physics, warm_start, impulses)
        self.solver.step(s_in if solver_in is None else solver_in, s_out, control, None, self.sim_cfg.sim_dt)

    def _simulate(self) -> None:
        self._contact_flags.zero_()
        # Ping-pong between the two states, then one copy back if the substep count is odd, so
        # the result lives in state_0: the torch views and a recorded graph point at fixed buffers.
        states = (self.state_0, self.state_1)
        for i in range(self.substeps):
            self.substep(states[i % 2], states[(i + 1) % 2], self.control, self._commands)
        if self.substeps % 2:
            self.state_0.assign(self.state_1)
        self._update_views()

    def _update_views(self) -> None:
        s = self.state_0
        wp.launch(compute_rover_state, dim=self.num_worlds,
                  inputs=[self._layout, s.body_q, s.body_qd, self.model.body_com, s.joint_q, s.joint_qd],
                  outputs=[self._lin_vel, self._ang_vel, self._rpy, self._wheel_speed, self._nonfinite],
                  device=self.device)

    def step(self, commands: torch.Tensor | np.ndarray | None = None) -> None:
        """Advance every world by ``step_dt``.

        Args:
            commands: Optional (N, 2) [left, right] wheel torques [N·m]; if omitted, the
                values in :attr:`commands` are used (write into it to avoid a copy).
        """
        if commands is not None:
            self.set_commands(commands)
        if self.sim_cfg.use_graph:
            if self._graph is None:
                with wp.ScopedCapture(device=self.device) as capture:
                    self._simulate()
                self._graph = capture.graph
            wp.capture_launch(self._graph)
        else:
            self._simulate()
        self.sim_time += self.sim_cfg.step_dt

    def set_commands(self, commands, worlds=None) -> None:
        """Drive by torque: copy (N, 2), (M, 2) for the M selected ``worlds``, or (2,) [left, right] wheel torques
        [N·m] into :attr:`commands`, and switch those worlds to torque (all worlds when ``worlds`` is ``None``)."""
        mask = torch.as_tensor(_as_world_mask(worlds, self.num_worlds), device=self.commands.device)
        self.commands[mask] = self._checked_pairs(commands, mask, "commands")
        self.driver.mode[mask] = int(DRIVE_TORQUE)

    def set_twist(self, twist, worlds=None) -> None:
        """Drive by velocity, as ``/cmd_vel`` does: copy (N, 2), (M, 2) for the M selected ``worlds``, or (2,)
        (linear [m/s], angular [rad/s]) into the driver's command, restart its timeout, and switch those worlds to
        the driver (all worlds when ``worlds`` is ``None``)."""
        mask = torch.as_tensor(_as_world_mask(worlds, self.num_worlds), device=self.commands.device)
        d = self.driver
        d.twist[mask] = self._checked_pairs(twist, mask, "twist")
        d.age[mask] = 0.0
        d.mode[mask] = int(DRIVE_TWIST)

    def _checked_pairs(self, values, mask: torch.Tensor, what: str) -> torch.Tensor:
        """``values`` as (M, 2) rows for the M worlds of ``mask``, checked (a bad one is named by its world)."""
        count = int(mask.sum())
        c = torch.as_tensor(values, dtype=torch.float32).to(self.commands.device)
        if c.shape == (2,):
            c = c.expand(count, 2)
        if c.shape != (count, 2):
            raise ValueError(f"{what} must have shape ({count}, 2) or (2,), got {tuple(c.shape)}")
        if not torch.isfinite(c).all():
            worlds = mask.nonzero().flatten()
            bad = worlds[(~torch.isfinite(c)).any(-1)].tolist()
            raise ValueError(f"{what} contain NaN/inf in world(s) {bad}")
        return c

    def set_mode(self, mode: DriveMode | str, worlds=None) -> None:
        """Apply a fixed-torque driving mode to all worlds, or to the masked/indexed ``worlds`` (the ATRV-Jr's torques
        of :data:`DRIVE_MODE_TORQUES`, as the same share of this robot's torque limit)."""
        try:
            mode = DriveMode(mode)
        except ValueError:
            raise ValueError(f"unknown driving mode {mode!r}; known: {[m.value for m in DriveMode]}") from None
        share = self.rover_cfg.robot_spec.torque_limit / DRIVE_MODE_REFERENCE_TORQUE
        left, right = DRIVE_MODE_TORQUES[mode]
        self.set_commands((left * share, right * share) if share != 1.0 else (left, right), worlds)

    def reset(self, mask=None, poses=None, *, height: float | None = None) -> None:
        """Re-pose the selected worlds at rest, level, wheels still; others are untouched.

        Args:
            mask: (N,) bool mask or integer world indices; ``None`` = all worlds.
            poses: (N, 3) or (M, 3) for the M selected worlds: x [m], y [m], yaw [rad];
                ``None`` = origin, yaw 0 (in a world with a map, the centre of the map's cell farthest from
                every wall). A pose with |x| or |y| at or beyond the walls'
                inner faces (``ArenaConfig.half_size``) is a ``ValueError``.
            height: Chassis-origin height [m]; default :attr:`rest_height`.
        """
        m = _as_world_mask(mask, self.num_worlds)
        p = np.zeros((self.num_worlds, 3), dtype=np.float32)
        if poses is None and self.maps.maps:  # a map's world starts at its most open spot, not in a wall
            spots = [self.maps.open_spot(k) for k in range(len(self.maps.maps))]
            p[:, :2] = [spots[k] if k >= 0 else (0.0, 0.0) for k in self.maps.world_map]
        if poses is not None:
            given = np.asarray(poses.detach().cpu() if isinstance(poses, torch.Tensor) else poses, dtype=np.float32)
            if given.shape == (self.num_worlds, 3):
                p = given
            elif given.shape == (int(m.sum()), 3):
                p[m] = given
            else:
                raise ValueError(f"poses must have shape ({self.num_worlds}, 3) or ({int(m.sum())}, 3), "
                                 f"got {given.shape}")
            if not np.isfinite(p[m]).all():
                raise ValueError("poses contain NaN/inf")
            half = self.arena_cfg.half_size
            outside = np.flatnonzero(m & ((np.abs(p[:, 0]) >= half) | (np.abs(p[:, 1]) >= half)))
            if outside.size:
                w = int(outside[0])
                raise ValueError(f"reset pose outside the arena in world(s) {outside[:8].tolist()}: (x, y) = "
                                 f"({p[w, 0]:g}, {p[w, 1]:g}) m; |x| and |y| must be below {half:g} m, the walls' "
                                 "inner faces")
        self._reset_mask.assign(m)
        self._reset_poses.assign(p)
        self.reset_worlds(self._reset_mask, self._reset_poses, height)

    def reset_worlds(self, mask: wp.array, poses: wp.array, height: float | None = None) -> None:
        """Device-side masked reset: worlds where ``mask`` (N,) bool is set are re-posed at rest at
        ``poses`` (N,) ``wp.vec3`` (x [m], y [m], yaw [rad]); the others are untouched.

        For poses that a kernel produced on the device (a task's episode sampler): nothing is
        copied to the host and nothing is checked, so they must lie inside the arena. User input
        goes through :meth:`reset`, which checks it.
        """
        s = self.state_0
        h = self.rest_height if height is None else float(height)
        wp.launch(reset_worlds, dim=self.num_worlds, inputs=[self._layout, mask, poses, h],
                  outputs=[s.joint_q, s.joint_qd, self._contact_flags, self._nonfinite], device=self.device)
        if self.terrain.enabled:
            wp.launch(place_on_terrain, dim=self.num_worlds,
                      inputs=[self._layout.chassis_coord, self._layout.coords_per_world, self.terrain.kernel, mask,
                              poses, h, self._footprint], outputs=[s.joint_q], device=self.device)
        self.contact.reset(mask)
        self.driver.reset(mask)
        newton.eval_fk(self.model, s.joint_q, s.joint_qd, s, mask=mask)
        self._update_views()

    # ------------------------------------------------------------------ snapshots
    def _snapshot_views(self) -> dict[str, torch.Tensor]:
        """Torch views of everything the next step reads, by snapshot key."""
        s, m, inertia = self.state_0, self.model, self.contact.inertia
        views = {"joint_q": s.joint_q, "joint_qd": s.joint_qd, "body_q": s.body_q, "body_qd": s.body_qd,
                 "impulses": self.contact.impulses, "commands": self._commands, "nonfinite": self._nonfinite,
                 # the mass properties a payload changed, as the solver and the friction solver read them
                 "body_mass": m.body_mass, "body_inv_mass": m.body_inv_mass, "body_inertia": m.body_inertia,
                 "body_inv_inertia": m.body_inv_inertia, "body_com": m.body_com,
                 "rover_inv_mass": inertia.inv_mass, "rover_com": inertia.com, "rover_inv_inertia": inertia.inv_inertia}
        views.update(self.driver.snapshot_arrays())
        views = {k: wp.to_torch(v, requires_grad=False) for k, v in views.items()}
        views.update({f"params.{name}": self.params.view(name) for name in PARAMETERS})
        return views

    def get_state(self) -> dict[str, torch.Tensor]:
        """Copy of everything the next step reads (restore with :meth:`set_state`): the bodies' and joints' state,
        the friction solver's warm-start impulses, the commands, each world's parameters and the mass properties
        a payload changed, the non-finite flags and the sim time. Restoring it and stepping equals stepping on,
        bit for bit on the CPU."""
        state = {k: v.clone() for k, v in self._snapshot_views().items()}
        state["sim_time"] = torch.tensor(self.sim_time, dtype=torch.float64)
        return state

    def check_state(self, snapshot: Mapping[str, torch.Tensor]) -> None:
        """Raise ``ValueError`` naming the first entry of ``snapshot`` that :meth:`set_state` cannot restore here
        (missing, or another shape: a snapshot of another world count or rover); nothing is written."""
        views = self._snapshot_views()
        missing = sorted(set(views) - set(snapshot) - set(SNAPSHOT_ADDED))
        if missing or "sim_time" not in snapshot:
            raise ValueError(f"simulator snapshot lacks {missing or ['sim_time']} (taken by an older version of "
                             "atrv_warp, or not a snapshot)")
        for k, v in views.items():
            if k not in snapshot:  # an entry added since (SNAPSHOT_ADDED): restored as zero
                continue
            got = tuple(torch.as_tensor(snapshot[k]).shape)
            if got != tuple(v.shape):
                worlds = f" ({self.num_worlds} worlds here)" if k == "commands" else ""
                raise ValueError(f"simulator snapshot entry {k!r} has shape {got}, this simulator's is "
                                 f"{tuple(v.shape)}{worlds}")

    def set_state(self, snapshot: Mapping[str, torch.Tensor]) -> None:
        """Restore a snapshot taken by :meth:`get_state` (checked first by :meth:`check_state`: a mismatch is a
        ``ValueError`` naming it, and nothing is restored)."""
        self.check_state(snapshot)
        with torch.no_grad():  # a differentiable simulator's arrays are leaves that require grad
            for k, v in self._snapshot_views().items():
                if k in snapshot:
                    v.copy_(torch.as_tensor(snapshot[k]))
                else:  # an entry added since (SNAPSHOT_ADDED)
                    v.zero_()
        self.sim_time = float(snapshot["sim_time"])
        # Newton's route for runtime mass changes: the solver re-derives its spatial inertias from the model
        self.solver.notify_model_changed(newton.ModelFlags.BODY_INERTIAL_PROPERTIES)
        self._contact_flags.zero_()
        self._update_views()

    def set_joints(self, joint_q: torch.Tensor, joint_qd: torch.Tensor) -> None:
        """Put every world in the generalised state ``joint_q``, ``joint_qd`` (Newton's flat arrays, e.g.
        :meth:`~atrv_warp.sim.diff.DiffRollout.moving_state`'s): the bodies follow by forward kinematics and the
        wheels start unloaded (no friction warm start), as after a reset. To resume a run exactly, use
        :meth:`get_state` and :meth:`set_state` instead."""
        s = self.state_0
        with torch.no_grad():  # a differentiable simulator's arrays are leaves that require grad
            wp.to_torch(s.joint_q, requires_grad=False).copy_(joint_q)
            wp.to_torch(s.joint_qd, requires_grad=False).copy_(joint_qd)
        self.contact.impulses.zero_()
        newton.eval_fk(self.model, s.joint_q, s.joint_qd, s)
        self._contact_flags.zero_()
        self._nonfinite.zero_()
        self._update_views()

    # ------------------------------------------------------------------ convenience
    @property
    def collision(self) -> torch.Tensor:
        """(N,) bool: a wall, obstacle or chassis–ground contact happened during the last step."""
        return self.contact_flags != 0

    @property
    def wall_contact(self) -> torch.Tensor:
        """(N,) bool: a wall contact happened during the last step."""
        return (self.contact_flags & int(FLAG_WALL)) != 0

    @property
    def obstacle_contact(self) -> torch.Tensor:
        """(N,) bool: an obstacle contact happened during the last step."""
        return (self.contact_flags & int(FLAG_OBSTACLE)) != 0

    @property
    def footprint_radii(self) -> tuple[float, float]:
        """(inscribed, circumscribed) radius [m] of the rover's outline
        (:func:`~atrv_warp.sim.urdf.footprint_radii`)."""
        return footprint_radii(self.description, self.rover_cfg)

    @property
    def _footprint(self) -> float:
        """Half the wheelbase or track, whichever is smaller [m]: the span a reset levels the chassis over."""
        xy = np.array([w.origin[:2, 3] for w in self.description.wheels])
        return float(max(min(np.abs(xy[:, 0]).max(), np.abs(xy[:, 1]).max()), 0.1))

    @property
    def body_ground_contact(self) -> torch.Tensor:
        """(N,) bool: the chassis touched the ground during the last step."""
        return (self.contact_flags & int(FLAG_BODY_GROUND)) != 0

    def __repr__(self) -> str:
        return (f"RoverSim(num_worlds={self.num_worlds}, urdf={self.description.path!r}, "
                f"step_dt={self.sim_cfg.step_dt}, substeps={self.substeps}, device={self.device})")

