"""Differentiable rollouts: gradients of a chassis trajectory (and of the wheel speeds and motor torques) with
respect to wheel-torque actions or ``/cmd_vel`` twists through the base's motor driver, the initial state, and each world's friction coefficient,
chassis mass, motor torque scale and speed limit and wheel radius, through Newton's Featherstone solver and our
contact kernel, recorded on a ``wp.Tape`` and exposed as a ``torch.autograd.Function``.

What makes the gradients agree with finite differences (the docs' differentiable-simulation page):

- a backward-pass fix for Newton 1.8's Featherstone adjoint, whose in-place conversion of
  external wrenches corrupts every derivative that multiplies them: the steering gradient
  (:func:`restore_external_wrench`);
- mass-matrix scratch of its own for every substep (Featherstone shares it across steps);
- the wheel–ground contact as the analytic deepest point of a cylinder on a plane
  (``kernels/contact.py``), a smooth function of the pose, so the contact point moves with the
  wheel in the derivative as it does in the simulation.

``benchmarks/physics/diff_gradients.py`` measures the agreement against the horizon over 0.05-5 s
(the docs' page has the tables and the stated horizon).

Example::

    from atrv_warp.sim.diff import DiffRollout
    roll = DiffRollout(num_worlds=1, steps=20)                  # 20 env steps = 1 s
    actions = torch.zeros(20, 1, 2, requires_grad=True)        # [left, right] in [-1, 1] x 20 N·m
    poses = roll(actions)                                       # (21, 1, 7) chassis x, y, z, qx, qy, qz, qw
    poses[-1, 0, 0].backward()                                  # d x_final / d actions
"""

from __future__ import annotations

import copy
import dataclasses

import newton
import torch
import warp as wp

from atrv_warp.sim.config import ArenaConfig, ContactConfig, RoverConfig, SimConfig, get_variant
from atrv_warp.sim.driver import DRIVE_TORQUE, DRIVE_TWIST, DriverConfig, make_state
from atrv_warp.sim.kernels.params import WorldPhysics, apply_payload
from atrv_warp.sim.kernels.rover import RoverLayout, motor_torque
from atrv_warp.sim.simulator import RoverSim

__all__ = ["DEFAULT_ACTION_SCALE", "DIFF_PARAMETERS", "DiffRollout", "NonFiniteGradientError",
           "restore_external_wrench"]


_SCRATCH = ("M", "J", "P", "H", "L")

DEFAULT_ACTION_SCALE = 20.0
"""Wheel torque per unit action [N·m] when none is given: the reference task's
(``TaskConfig.action_scale``; the simulator knows no task, so a test keeps the two equal)."""


DIFF_PARAMETERS = ("friction", "chassis_mass", "torque_scale", "speed_limit", "wheel_radius", "friction_rise")
"""The physical parameters a rollout differentiates, one value per world each: Coulomb mu [-], chassis
mass [kg] (the URDF's plus a payload at its centre of mass), motor torque scale [-], motor no-load speed
[rad/s] and wheel rolling radius [m] (:data:`atrv_warp.sim.params.PARAMETERS`), and the wheels' sliding friction's
rise with slip speed [s/m] (:attr:`~atrv_warp.sim.config.ContactConfig.friction_rise`, one value for every world
in a simulator)."""


class NonFiniteGradientError(FloatingPointError):
    """The backward pass produced NaN or inf (the rollout was too long or too violent)."""


@wp.kernel
def scale_actions(actions: wp.array2d(dtype=float), scale: float, commands: wp.array(dtype=wp.vec2)):
    """Wheel torques [N·m] of actions clipped to [-1, 1], as the environment's ``action_to_torque``: the clamp's
    derivative is zero outside the range, so an action past it gets no gradient."""
    world = wp.tid()
    left = wp.clamp(actions[world, 0], -1.0, 1.0)
    right = wp.clamp(actions[world, 1], -1.0, 1.0)
    commands[world] = wp.vec2(scale * left, scale * right)


@wp.kernel
def as_twist(actions: wp.array2d(dtype=float), twist: wp.array(dtype=wp.vec2)):
    """Each world's (linear [m/s], angular [rad/s]) command, as given (the driver applies its own limits)."""
    world = wp.tid()
    twist[world] = wp.vec2(actions[world, 0], actions[world, 1])


@wp.kernel
def payload_from_chassis_mass(chassis_mass: wp.array(dtype=float), nominal_mass: float,
                              payload: wp.array(dtype=float)):
    """Each world's chassis mass [kg] as a payload at the chassis' centre of mass."""
    world = wp.tid()
    payload[world] = chassis_mass[world] - nominal_mass


@wp.kernel
def gather_side_speeds(layout: RoverLayout, joint_qd: wp.array(dtype=float), wheel_weight: wp.array(dtype=float),
                       out: wp.array2d(dtype=float)):
    """(N, 2) mean forward speed of each side's wheels [rad/s] (``out`` zeroed before; one thread per wheel)."""
    world, k = wp.tid()
    v = joint_qd[world * layout.dofs_per_world + layout.wheel_dof[k]]
    wp.atomic_add(out, world, layout.wheel_side[k], wheel_weight[k] * v)


@wp.kernel
def gather_side_torques(layout: RoverLayout, commands: wp.array(dtype=wp.vec2), physics: WorldPhysics,
                        joint_qd: wp.array(dtype=float), side_weight: wp.array(dtype=float),
                        out: wp.array2d(dtype=float)):
    """(N, 2) mean torque each side's motors apply [N·m], forward-positive: the world's motor (torque scale,
    no-load taper) for side ``commands`` (the torque commands, or the driver's output) at the wheel speeds of
    ``joint_qd``, as ``drive_wheels`` computes it (``out`` zeroed before; one thread per wheel)."""
    world, k = wp.tid()
    side = layout.wheel_side[k]
    sign = layout.wheel_sign[k]
    v = joint_qd[world * layout.dofs_per_world + layout.wheel_dof[k]]
    tau = motor_torque(commands[world][side] * physics.torque_scale[world], sign * v, physics.speed_limit[world])
    wp.atomic_add(out, world, side, side_weight[k] * tau)


@wp.kernel
def gather_chassis_pose(body_q: wp.array(dtype=wp.transform), bodies_per_world: int, chassis: int,
                        out: wp.array2d(dtype=float)):
    world = wp.tid()
    X = body_q[world * bodies_per_world + chassis]
    p = wp.transform_get_translation(X)
    q = wp.transform_get_rotation(X)
    for i in range(3):
        out[world, i] = p[i]
    for i in range(4):
        out[world, 3 + i] = q[i]


def restore_external_wrench(state_out: newton.State, state_in: newton.State):
    """Backward-pass fix for Newton 1.8's Featherstone adjoint with external wrenches.

    ``eval_rigid_tau`` converts the external wrenches in place (``body_f_ext[child] = f(body_f_ext[child])``,
    from world/COM to the solver's frame). Warp's adjoint kernel replays the forward body to
    recover intermediates, so the replay reads the *converted* wrench: its sign and moment arm
    are wrong in every term that multiplies it, i.e. the derivative of the joint torques with
    respect to the pose (how turning the rover changes the torque its wheel forces exert). For
    a rover driven by contact forces that is the steering gradient (28-79 % off after 1 s:
    ``benchmarks/physics/diff_gradients.py --without-wrench-fix``). Recorded right after ``solver.step``, this
    function runs just before that step's adjoints and puts the unconverted wrench back, so the
    replay sees what the forward pass saw. (``body_f_ext`` = ``body_f`` plus FREE-joint entries of
    ``joint_f``, which this rollout never sets.)
    """

    def restore():
        wp.copy(state_out.body_f_ext, state_in.body_f)

    return restore


class DiffRollout:
    """A fixed-horizon, differentiable rollout of ``num_worlds`` rovers.

    Args:
        num_worlds: Rovers simulated together (gradients are per world).
        steps: Horizon in env steps (``SimConfig.step_dt`` = 0.05 s each).
        variant, rover, contact, arena, sim: As for :class:`~atrv_warp.sim.RoverSim`
            (graph replay and tile GEMM are switched off: the tape records eager launches).
        device: Warp device.
        wrench_fix: Apply :func:`restore_external_wrench` (keep ``True``; ``False`` reproduces
            Newton 1.8's wrong steering gradient, for comparison).
        action_scale: Wheel torque per unit action [N·m]; a task passes its own
            (``TaskConfig.action_scale``).
        twist: The actions are ``/cmd_vel`` commands (linear [m/s], angular [rad/s]) through the base's motor driver
            (:mod:`atrv_warp.sim.driver`, the simulator's own kernel, every substep), whose PI integral is part of
            the initial state (a calibration from a ``/cmd_vel`` log does this); else wheel torques.
        driver: The motor driver's configuration (default: :class:`~atrv_warp.sim.driver.DriverConfig`'s, with the
            nominal rover's radius and track). The rollout's commands are always fresh: its timeout is off (a
            replayed log passes zero where the base's timeout stopped it).
        mass_matrix_interval: Substeps between refreshes of Featherstone's mass matrix (it must divide the
            substeps of a step). 1 refreshes every substep; the substeps of a step (``None``, as ``SimConfig`` has it)
            refresh once per step, as :class:`~atrv_warp.sim.RoverSim` does by default. Its dense products are
            most of a CPU rollout's time, so a refresh per step runs it about 3x faster; the tape differentiates
            the matrix where it was formed and holds it over the step, as the forward pass does.

    Calling the object runs the rollout; see :meth:`__call__`.
    """

    def __init__(self, num_worlds: int = 1, steps: int = 20, *, variant: str = "realistic",
                 rover: RoverConfig | None = None, contact: ContactConfig | None = None,
                 arena: ArenaConfig | None = None, sim: SimConfig | None = None, device: str = "cpu",
                 wrench_fix: bool = True, action_scale: float = DEFAULT_ACTION_SCALE,
                 twist: bool = False, driver: DriverConfig | None = None, mass_matrix_interval: int | None = 1):
        if steps < 1:
            raise ValueError(f"steps must be >= 1, got {steps}")
        sim_cfg = sim or SimConfig()
        sim_cfg = SimConfig(step_dt=sim_cfg.step_dt, sim_dt=sim_cfg.sim_dt, gravity=sim_cfg.gravity,
                            mass_matrix_interval=mass_matrix_interval, use_tile_gemm=False, use_graph=False)
        driver = dataclasses.replace(driver or DriverConfig(), cmd_vel_timeout=1e30)
        self.sim = RoverSim(num_worlds, rover=rover or get_variant(variant), contact=contact, arena=arena,
                            sim=sim_cfg, device=device, requires_grad=True, driver=driver)
        self.num_worlds, self.steps = num_worlds, steps
        self.wrench_fix = wrench_fix
        """Record :func:`restore_external_wrench` after each solver step (``False`` only to measure
        what the workaround fixes, as ``benchmarks/physics/diff_gradients.py --without-wrench-fix`` does)."""
        self.action_scale = float(action_scale)
        """Wheel torque per unit action [N·m]."""
        self.twist = twist
        """The actions are twists through the motor driver (else wheel torques)."""
        model = self.sim.model
        n_sub = steps * self.sim.substeps
        self.states = [model.state(requires_grad=True) for _ in range(n_sub + 1)]
        self.controls = [model.control(clone_variables=True) for _ in range(n_sub)]
        for c in self.controls:
            c.joint_f.requires_grad = True
        dev = self.sim.device

        def zeros(shape, dtype=float, grad=True):
            return wp.zeros(shape, dtype=dtype, device=dev, requires_grad=grad)

        self._actions = [zeros((num_worlds, 2)) for _ in range(steps)]
        self._commands = [zeros(num_worlds, wp.vec2) for _ in range(steps)]
        self._poses = [zeros((num_worlds, 7)) for _ in range(steps + 1)]
        self._speeds = [zeros((num_worlds, 2)) for _ in range(steps + 1)]
        self._side_torques = [zeros((num_worlds, 2)) for _ in range(steps)]
        # the driver's state at every substep boundary (its odometry and integral chain through the tape)
        self._driver = [make_state(num_worlds, dev, requires_grad=True) for _ in range(n_sub + 1)]
        self._mode = wp.full(num_worlds, DRIVE_TWIST if twist else DRIVE_TORQUE, dtype=wp.int32, device=dev)
        self._params = {name: zeros(num_worlds) for name in DIFF_PARAMETERS}
        self._payload = zeros(num_worlds)
        self._payload_offset = zeros(num_worlds, wp.vec3, grad=False)
        self._all = wp.full(num_worlds, True, dtype=bool, device=dev)
        wheels = self.sim.description.wheels
        per_side = [sum(w.side == side for w in wheels) for side in (0, 1)]
        self._wheel_weight = wp.array([w.drive_sign / per_side[w.side] for w in wheels], dtype=float, device=dev)
        self._side_weight = wp.array([1.0 / per_side[w.side] for w in wheels], dtype=float, device=dev)
        # the simulator's per-world physics, every parameter but the stiffness an input of the tape
        physics = WorldPhysics()
        physics.stiffness = self.sim.params.physics.stiffness
        for name in ("friction", "wheel_radius", "torque_scale", "speed_limit", "friction_rise"):
            setattr(physics, name, self._params[name])
        self._physics = physics
        # the URDF's chassis: a rover config's payload is a point mass on it, as every other payload here
        self.nominal_chassis_mass = float(self.sim.nominal_chassis.mass)
        self._nominal = {"friction": self.sim.contact_cfg.friction,
                         "chassis_mass": self.nominal_chassis_mass + self.sim.rover_cfg.payload_mass,
                         "torque_scale": self.sim.rover_cfg.torque_scale,
                         "speed_limit": self.sim.rover_cfg.wheel_speed_limit,
                         "wheel_radius": self.sim.rover_cfg.wheel_radius,
                         "friction_rise": self.sim.contact_cfg.friction_rise}
        self._flags = wp.zeros(num_worlds, dtype=wp.int32, device=dev)
        # The friction solver starts each substep from the previous one's impulses: one array per
        # substep boundary, so the tape differentiates through that chain too.
        self._impulses = [wp.zeros_like(self.sim.contact.impulses, requires_grad=True) for _ in range(n_sub + 1)]
        self._torque = wp.zeros((num_worlds, len(wheels)), dtype=float, device=dev)  # the drive's effort, not read back
        # an implicit driver's slope and torque cap, written by each substep's drive and read by its friction solve
        # (which a tape's backward pass runs again on them): one of each per substep
        self._damping = [wp.zeros((num_worlds, len(wheels)), dtype=float, device=dev) for _ in range(n_sub)]
        self._cap = [wp.zeros((num_worlds, len(wheels)), dtype=float, device=dev) for _ in range(n_sub)]
        # Featherstone keeps its mass-matrix scratch (M, J, P, H, L) on the solver, shared by every
        # step. Under a tape each step must own them, or the adjoints of all steps mix in one buffer
        # (gradients explode with the horizon); so each substep gets its own set, swapped in below.
        solver = self.sim.solver
        # With a refresh every ``interval`` substeps, the substeps in between read the set their refresh wrote.
        self._refresh = solver.update_mass_matrix_interval
        self._scratch = [{name: wp.zeros_like(getattr(solver, name), requires_grad=True) for name in _SCRATCH}
                         for _ in range(n_sub // self._refresh)]
        # The solver re-evaluates forward kinematics into its input state's body_q, which the
        # previous substep wrote and the contact kernel read: an overwrite on the tape, which
        # Warp's wp.config.verify_autograd_array_access flags. With Newton 1.8 the gradients agree
        # to five digits either way; we still keep every tape array written once. Each substep
        # hands the solver a view of its state (same joint_q, joint_qd, body_f) with its own body_q.
        self._solver_in = []
        for s in self.states[:-1]:
            view = copy.copy(s)
            view.body_q = wp.zeros_like(s.body_q, requires_grad=True)
            self._solver_in.append(view)
        self._tape: wp.Tape | None = None
        self._rollout_id = 0

    # ------------------------------------------------------------------ recording
    def _gather(self, k: int, t: int) -> None:
        """Chassis pose and side wheel speeds of substep state ``k`` into step ``t``'s outputs."""
        sim, lay = self.sim, self.sim.layout
        state = self.states[k]
        wp.launch(gather_chassis_pose, dim=self.num_worlds, inputs=[state.body_q, lay.bodies_per_world,
                                                                   lay.chassis_body],
                  outputs=[self._poses[t]], device=sim.device)
        wp.launch(gather_side_speeds, dim=(self.num_worlds, len(sim.description.wheels)),
                  inputs=[sim.layout, state.joint_qd, self._wheel_weight], outputs=[self._speeds[t]],
                  device=sim.device)

    def _record(self) -> None:
        sim, lay = self.sim, self.sim.layout
        n = self.num_worlds
        # The chassis mass (a payload at its centre of mass) is an input of the tape: the simulator's payload
        # kernel sets the chassis and the friction solver's model of the rover, then the solver re-derives
        # its spatial inertias (Newton's public route for runtime mass changes), all recorded.
        wp.launch(payload_from_chassis_mass, dim=n, inputs=[self._params["chassis_mass"], self.nominal_chassis_mass],
                  outputs=[self._payload], device=sim.device)
        model, inertia = sim.model, sim.contact.inertia
        wp.launch(apply_payload, dim=n,
                  inputs=[self._all, self._payload, self._payload_offset, lay.bodies_per_world, lay.chassis_body,
                          sim.nominal_chassis, sim.contact.nominal_rover, 0],
                  outputs=[model.body_mass, model.body_inv_mass, model.body_inertia, model.body_inv_inertia,
                           model.body_com, inertia.inv_mass, inertia.com, inertia.inv_inertia], device=sim.device)
        sim.solver.notify_model_changed(newton.ModelFlags.BODY_INERTIAL_PROPERTIES)
        s0 = self.states[0]
        newton.eval_fk(sim.model, s0.joint_q, s0.joint_qd, s0)
        self._gather(0, 0)
        k = 0
        for t in range(self.steps):
            kernel, inputs = (as_twist, [self._actions[t]]) if self.twist else \
                (scale_actions, [self._actions[t], self.action_scale])
            wp.launch(kernel, dim=n, inputs=inputs, outputs=[self._commands[t]], device=sim.device)
            for _ in range(sim.substeps):
                s_in, s_out = self.states[k], self.states[k + 1]
                for name, arr in self._scratch[k // self._refresh].items():
                    setattr(sim.solver, name, arr)
                sim.substep(s_in, s_out, self.controls[k], self._commands[t], physics=self._physics,
                            flags=self._flags, torque=self._torque, solver_in=self._solver_in[k],
                            warm_start=self._impulses[k], impulses=self._impulses[k + 1], twist=self._commands[t],
                            driver_in=self._driver[k], driver_out=self._driver[k + 1], mode=self._mode,
                            damping=self._damping[k], cap=self._cap[k])
                if self._tape is not None and self.wrench_fix:
                    self._tape.record_func(backward=restore_external_wrench(s_out, s_in), arrays=[])
                k += 1
            # the torque of the step's last substep, as the simulator's wheel_torque (and a ROS node's effort);
            # recomputed from that substep's inputs, which the tape differentiates (the drive's output it does not)
            side = self._driver[k].applied if self.twist else self._commands[t]
            wp.launch(gather_side_torques, dim=(n, len(sim.description.wheels)),
                      inputs=[lay, side, self._physics, self.states[k - 1].joint_qd, self._side_weight],
                      outputs=[self._side_torques[t]], device=sim.device)
            self._gather(k, t + 1)

    @torch.no_grad()
    def forward(self, actions: torch.Tensor, joint_q: torch.Tensor, joint_qd: torch.Tensor, integral: torch.Tensor,
                params: dict[str, torch.Tensor], record: bool = True
                ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, int]:
        """Run the rollout, on a fresh tape if ``record``; returns poses (steps + 1, N, 7), side wheel speeds
        (steps + 1, N, 2), side motor torques (steps, N, 2) and the rollout's number (which :meth:`backward`
        checks against the tape it holds)."""
        for t in range(self.steps):
            wp.to_torch(self._actions[t]).copy_(actions[t])
        s0 = self.states[0]
        wp.to_torch(s0.joint_q).copy_(joint_q.reshape(-1))
        wp.to_torch(s0.joint_qd).copy_(joint_qd.reshape(-1))
        for d in self._driver:
            for a in (d.reference, d.integral, d.applied, d.age, d.odometry, d.odom_twist, d.fused, d.fused_velocity,
                      d.velocity):
                a.zero_()
        wp.to_torch(self._driver[0].integral).copy_(integral)
        if self.twist:  # the driver tracked the first command already (its limits, if any, start from there)
            wp.to_torch(self._driver[0].reference).copy_(actions[0])
        for name in DIFF_PARAMETERS:
            wp.to_torch(self._params[name]).copy_(params[name].reshape(-1))
        for s in self.states:
            s.body_f.zero_()
        for a in self._speeds + self._side_torques:
            a.zero_()  # accumulated into
        self._impulses[0].zero_()  # a rollout starts from rest, unloaded
        self._rollout_id += 1
        self._tape = wp.Tape() if record else None
        if record:
            with self._tape:
                self._record()
        else:
            self._record()
        return (torch.stack([wp.to_torch(p).clone() for p in self._poses]),
                torch.stack([wp.to_torch(p).clone() for p in self._speeds]),
                torch.stack([wp.to_torch(p).clone() for p in self._side_torques]), self._rollout_id)

    def backward(self, grad_poses: torch.Tensor, grad_speeds: torch.Tensor | None, rollout_id: int,
                 grad_torques: torch.Tensor | None = None):
        """Back-propagate ``grad_poses`` (and ``grad_speeds``, ``grad_torques``) through rollout number
        ``rollout_id`` (the latest recorded); returns the gradients of the actions, initial joint_q, joint_qd, controller integral and of
        each of :data:`DIFF_PARAMETERS`."""
        tape = self._tape
        if tape is None or rollout_id != self._rollout_id:
            raise RuntimeError(
                "this rollout's tape is gone: a DiffRollout keeps the tape of its latest call only, and a "
                "tape serves one backward pass. Call backward before running the same DiffRollout again "
                "(or use one DiffRollout per rollout awaiting its backward pass).")
        grads = {p: wp.from_torch(grad_poses[i].contiguous()) for i, p in enumerate(self._poses)}
        if grad_speeds is not None:
            grads.update({p: wp.from_torch(grad_speeds[i].contiguous()) for i, p in enumerate(self._speeds)})
        if grad_torques is not None:
            grads.update({p: wp.from_torch(grad_torques[i].contiguous()) for i, p in enumerate(self._side_torques)})
        tape.backward(grads=grads)
        s0 = self.states[0]
        out = {"actions": torch.stack([wp.to_torch(a.grad).clone() for a in self._actions]),
               "initial joint_q": wp.to_torch(s0.joint_q.grad).clone(),
               "initial joint_qd": wp.to_torch(s0.joint_qd.grad).clone(),
               "controller integral": wp.to_torch(self._driver[0].integral.grad).view(-1, 2).clone()}
        out.update({name: wp.to_torch(self._params[name].grad).clone() for name in DIFF_PARAMETERS})
        tape.zero()
        self._tape = None
        for name, g in out.items():
            if not torch.isfinite(g).all():
                raise NonFiniteGradientError(
                    f"gradient w.r.t. {name.replace('_', ' ')} is not finite after a {self.steps}-step rollout; "
                    "shorten the horizon or soften the actions")
        return tuple(out.values())

    # ------------------------------------------------------------------ torch entry point
    def initial_state(self, poses: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """Generalised coordinates (joint_q, joint_qd) of rovers at rest at (x, y, yaw) ``poses`` (N, 3)."""
        sim = self.sim
        sim.reset(poses=poses)
        return (wp.to_torch(sim.state_0.joint_q).detach().clone(), wp.to_torch(sim.state_0.joint_qd).detach().clone())

    def moving_state(self, poses: torch.Tensor, velocity: torch.Tensor, yaw_rate: torch.Tensor,
                     wheel_speed: torch.Tensor, *, wheel_radius: torch.Tensor | float | None = None,
                     payload_mass: torch.Tensor | float | None = None, tilt: torch.Tensor | None = None,
                     tilt_rate: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """Generalised coordinates (joint_q, joint_qd) of rovers on flat ground, in motion: at (x, y, yaw)
        ``poses`` (N, 3), with chassis-origin velocity ``velocity`` (N, 2) (forward, left) in the chassis
        frame [m/s], ``yaw_rate`` (N,) [rad/s] about the chassis' z, and the wheels' forward speeds
        ``wheel_speed`` [rad/s]: (N, 2) each side's (left, right), or (N, W) each wheel's in the description's order
        (a state recorded on a real rover: its pose, twist and wheel encoders).

        ``tilt`` (N, 2): the chassis' roll and pitch [rad] (default level), as a reference pose's orientation gives
        them; ``tilt_rate`` (N, 2): its angular velocity about its own x and y [rad/s] (default none), as an
        ``Odometry``'s twist gives it. A rover that pitches as it accelerates, restarted level, rocks back, and that
        shortens the path a replay rolls out.

        Each rover stands at its own rest height (:meth:`~atrv_warp.sim.RoverSim.rest_heights`) for the rolling
        radius ``wheel_radius`` [m] and payload ``payload_mass`` [kg] it will be rolled out with (default: the
        configured rover's): a rollout with another radius than the configured one would otherwise start with its
        wheels in the air or in the ground."""
        from atrv_warp.core.geometry import quat_to_matrix, rpy_to_quat

        q, qd = self.initial_state(poses)
        sim, lay = self.sim, self.sim.layout
        n = self.num_worlds
        q, qd = q.view(n, -1), qd.view(n, -1)
        if wheel_radius is not None or payload_mass is not None:
            radius = sim.rover_cfg.wheel_radius if wheel_radius is None else wheel_radius
            height = sim.rest_heights(radius, sim.rover_cfg.payload_mass if payload_mass is None else payload_mass)
            q[:, lay.chassis_coord + 2] = height.to(device=q.device, dtype=q.dtype).expand(n)
        yaw = torch.as_tensor(poses, dtype=torch.float32)[:, 2]
        rpy = torch.zeros(n, 3)
        rpy[:, 2] = yaw
        if tilt is not None:
            rpy[:, :2] = torch.as_tensor(tilt, dtype=torch.float32)
            q[:, lay.chassis_coord + 3:lay.chassis_coord + 7] = rpy_to_quat(rpy).to(device=q.device, dtype=q.dtype)
        rot = quat_to_matrix(rpy_to_quat(rpy))  # (N, 3, 3) world from chassis
        cos, sin = torch.cos(yaw), torch.sin(yaw)
        v = torch.as_tensor(velocity, dtype=torch.float32)
        omega = torch.zeros(n, 3)  # the chassis' angular velocity, its own frame, then the world's
        omega[:, 2] = torch.as_tensor(yaw_rate, dtype=torch.float32)
        if tilt_rate is not None:
            omega[:, :2] = torch.as_tensor(tilt_rate, dtype=torch.float32)
        omega = (rot @ omega[..., None])[..., 0]
        # Featherstone's free joint: the centre of mass' velocity, world frame, then the angular velocity
        com = (rot @ torch.tensor([float(c) for c in sim.nominal_chassis.com])[:, None])[..., 0]
        linear = torch.stack([cos * v[:, 0] - sin * v[:, 1], sin * v[:, 0] + cos * v[:, 1], torch.zeros(n)], -1)
        linear = linear + torch.linalg.cross(omega, com)
        d = lay.chassis_dof
        qd[:, d:d + 3] = linear.to(device=qd.device, dtype=qd.dtype)
        qd[:, d + 3:d + 6] = omega.to(device=qd.device, dtype=qd.dtype)
        ws = torch.as_tensor(wheel_speed, dtype=torch.float32)
        dofs = lay.wheel_dof.numpy()
        for j, wheel in enumerate(sim.description.wheels):
            qd[:, int(dofs[j])] = wheel.drive_sign * (ws[:, wheel.side] if ws.shape[1] == 2 else ws[:, j])
        return q.reshape(-1), qd.reshape(-1)

    def __call__(self, actions: torch.Tensor, initial_state: tuple[torch.Tensor, torch.Tensor] | None = None,
                 friction: torch.Tensor | float | None = None,
                 chassis_mass: torch.Tensor | float | None = None, *,
                 torque_scale: torch.Tensor | float | None = None, speed_limit: torch.Tensor | float | None = None,
                 wheel_radius: torch.Tensor | float | None = None, friction_rise: torch.Tensor | float | None = None,
                 integral: torch.Tensor | None = None,
                 wheel_speeds: bool = False, wheel_torques: bool = False
                 ) -> torch.Tensor | tuple[torch.Tensor, ...]:
        """Roll out and return chassis poses (steps + 1, N, 7): x, y, z [m], quaternion (x, y, z, w).

        Args:
            actions: (steps, N, 2) (x :attr:`action_scale` N·m), differentiable; clipped to [-1, 1] as the
                environment clips them, so an action outside the range gets a zero gradient. With :attr:`twist`,
                each step's (linear [m/s], angular [rad/s]) command instead (not clipped; the driver's limits apply).
            initial_state: (joint_q, joint_qd) from :meth:`initial_state` or :meth:`moving_state` (default:
                every rover at the origin, at rest); differentiable.
            friction: Coulomb coefficient, one for all worlds or (N,) one per world (default: the
                contact config's), differentiable.
            chassis_mass: Chassis mass [kg], one or (N,) one per world, e.g. with a payload (default: the
                URDF's, :attr:`nominal_chassis_mass`, plus the rover config's payload). The difference from the URDF's
                is a point mass at the chassis' centre of mass (the simulator's payload, :meth:`~atrv_warp.sim.RoverSim.set_params`), which
                the wheels' friction solver's model of the rover carries too. Differentiable.
            torque_scale, speed_limit, wheel_radius: The motor's torque scale [-] and no-load speed [rad/s],
                and the wheels' rolling radius [m]; one or (N,) each (default: the rover config's),
                differentiable.
            friction_rise: The wheels' sliding friction's rise with slip speed [s/m]
                (:attr:`~atrv_warp.sim.config.ContactConfig.friction_rise`), one or (N,) (default: the contact
                config's), differentiable.
            integral: (N, 2) the motor driver's PI integral per side at the start [rad] (default zero),
                differentiable.
            wheel_speeds: Also return each side's mean forward wheel speed (steps + 1, N, 2) [rad/s].
            wheel_torques: Also return each side's mean motor torque in each step's last substep (steps, N, 2)
                [N·m], forward-positive (what the simulator's ``wheel_torque`` and the ROS node's joint
                efforts report), after the poses and the wheel speeds if asked for.
        """
        expected = (self.steps, self.num_worlds, 2)
        if tuple(actions.shape) != expected:
            raise ValueError(f"actions must have shape {expected} (steps, worlds, [left, right]), "
                             f"got {tuple(actions.shape)}")
        if not torch.isfinite(actions).all():
            raise ValueError("actions contain NaN/inf")
        if initial_state is None:
            initial_state = self.initial_state()
        given = {"friction": friction, "chassis_mass": chassis_mass, "torque_scale": torque_scale,
                 "speed_limit": speed_limit, "wheel_radius": wheel_radius, "friction_rise": friction_rise}
        params = []
        for name in DIFF_PARAMETERS:
            value = self._per_world(name, self._nominal[name] if given[name] is None else given[name])
            zero_ok = name in ("torque_scale", "friction_rise")
            low_ok = (value >= 0.0) if zero_ok else (value > 0.0)
            if not (torch.isfinite(value).all() and bool(low_ok.all())):
                raise ValueError(f"{name} must be {'>= 0' if zero_ok else '> 0'} and finite, got "
                                 f"{value.detach().tolist()}")
            params.append(value)
        integral = torch.zeros(self.num_worlds, 2) if integral is None else torch.as_tensor(integral).float()
        if tuple(integral.shape) != (self.num_worlds, 2):
            raise ValueError(f"integral must have shape ({self.num_worlds}, 2), got {tuple(integral.shape)}")
        inputs = (actions.float(), initial_state[0].float(), initial_state[1].float(), integral, *params)
        if not (torch.is_grad_enabled() and any(t.requires_grad for t in inputs)):
            poses, speeds, torques, _ = self.forward(*inputs[:4], dict(zip(DIFF_PARAMETERS, params)), record=False)
        else:
            poses, speeds, torques = _RolloutFn.apply(self, *inputs)
        out = (poses,) + ((speeds,) if wheel_speeds else ()) + ((torques,) if wheel_torques else ())
        return out if len(out) > 1 else poses

    def _per_world(self, name: str, value) -> torch.Tensor:
        """``value`` as (N,) float32: one number for every world, or one per world (differentiable)."""
        v = torch.as_tensor(value, dtype=torch.float32)
        if v.numel() == 1:
            return v.reshape(1).expand(self.num_worlds)
        if tuple(v.shape) != (self.num_worlds,):
            raise ValueError(f"{name} must be one number or one per world ({self.num_worlds},), got shape "
                             f"{tuple(v.shape)}")
        return v


class _RolloutFn(torch.autograd.Function):
    @staticmethod
    def forward(ctx, roll: DiffRollout, actions, joint_q, joint_qd, integral, *params):
        # autograd wants each gradient on its input's device; the rollout's live on the simulator's
        ctx.devices = [t.device for t in (actions, joint_q, joint_qd, integral, *params)]
        poses, speeds, torques, ctx.rollout_id = roll.forward(
            actions.detach(), joint_q.detach(), joint_qd.detach(), integral.detach(),
            {name: p.detach() for name, p in zip(DIFF_PARAMETERS, params)})
        ctx.roll = roll
        return poses, speeds, torques

    @staticmethod
    def backward(ctx, grad_poses, grad_speeds, grad_torques):
        grads = ctx.roll.backward(grad_poses, grad_speeds, ctx.rollout_id, grad_torques)
        return None, *(g.to(d) for g, d in zip(grads, ctx.devices))
