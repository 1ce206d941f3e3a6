"""Differentiable rollouts: gradients of a chassis trajectory with respect to wheel-torque
actions, the initial state, the friction coefficient and the chassis mass, through Newton's Featherstone solver
and our contact kernel, recorded on a ``wp.Tape`` and exposed as a ``torch.autograd.Function``.

What makes the gradients agree with finite differences (the docs' differentiable-simulation page):

- a backward-pass fix for Newton 1.8's Featherstone adjoint, whose in-place conversion of
  external wrenches corrupts every derivative that multiplies them: the steering gradient
  (:func:`restore_external_wrench`);
- mass-matrix scratch of its own for every substep (Featherstone shares it across steps);
- the wheel–ground contact as the analytic deepest point of a cylinder on a plane
  (``kernels/contact.py``), a smooth function of the pose, so the contact point moves with the
  wheel in the derivative as it does in the simulation.

``benchmarks/diff_gradients.py`` measures the agreement against the horizon over 0.05-5 s
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

import newton
import torch
import warp as wp

from atrv_warp.sim.config import ArenaConfig, ContactConfig, RoverConfig, SimConfig, get_variant
from atrv_warp.sim.kernels.params import WorldPhysics, apply_payload
from atrv_warp.sim.simulator import RoverSim

__all__ = ["DEFAULT_ACTION_SCALE", "DiffRollout", "NonFiniteGradientError", "restore_external_wrench"]


_SCRATCH = ("M", "J", "P", "H", "L")

DEFAULT_ACTION_SCALE = 20.0
"""Wheel torque per unit action [N·m] when none is given: the reference task's
(``TaskConfig.action_scale``; the simulator knows no task, so a test keeps the two equal)."""


class NonFiniteGradientError(FloatingPointError):
    """The backward pass produced NaN or inf (the rollout was too long or too violent)."""


@wp.kernel
def scale_actions(actions: wp.array2d(dtype=float), scale: float, commands: wp.array(dtype=wp.vec2)):
    world = wp.tid()
    commands[world] = wp.vec2(scale * actions[world, 0], scale * actions[world, 1])


@wp.kernel
def payload_from_chassis_mass(chassis_mass: wp.array(dtype=float), nominal_mass: float,
                              payload: wp.array(dtype=float)):
    """Each world's chassis mass [kg] as a payload at the chassis' centre of mass."""
    world = wp.tid()
    payload[world] = chassis_mass[world] - nominal_mass


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
    ``benchmarks/diff_gradients.py --without-wrench-fix``). Recorded right after ``solver.step``, this
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

    Calling the object runs the rollout; see :meth:`__call__`.
    """

    def __init__(self, num_worlds: int = 1, steps: int = 20, *, variant: str = "realistic",
                 rover: RoverConfig | None = None, contact: ContactConfig | None = None,
                 arena: ArenaConfig | None = None, sim: SimConfig | None = None, device: str = "cpu",
                 wrench_fix: bool = True, action_scale: float = DEFAULT_ACTION_SCALE):
        if steps < 1:
            raise ValueError(f"steps must be >= 1, got {steps}")
        sim_cfg = sim or SimConfig()
        sim_cfg = SimConfig(step_dt=sim_cfg.step_dt, sim_dt=sim_cfg.sim_dt, gravity=sim_cfg.gravity,
                            mass_matrix_interval=1, use_tile_gemm=False, use_graph=False)
        self.sim = RoverSim(num_worlds, rover=rover or get_variant(variant), contact=contact, arena=arena,
                            sim=sim_cfg, device=device, requires_grad=True)
        self.num_worlds, self.steps = num_worlds, steps
        self.wrench_fix = wrench_fix
        """Record :func:`restore_external_wrench` after each solver step (``False`` only to measure
        what the workaround fixes, as ``benchmarks/diff_gradients.py --without-wrench-fix`` does)."""
        self.action_scale = float(action_scale)
        """Wheel torque per unit action [N·m]."""
        model = self.sim.model
        n_sub = steps * self.sim.substeps
        self.states = [model.state(requires_grad=True) for _ in range(n_sub + 1)]
        self.controls = [model.control(clone_variables=True) for _ in range(n_sub)]
        for c in self.controls:
            c.joint_f.requires_grad = True
        dev = self.sim.device
        self._actions = [wp.zeros((num_worlds, 2), dtype=float, device=dev, requires_grad=True) for _ in range(steps)]
        self._commands = [wp.zeros(num_worlds, dtype=wp.vec2, device=dev, requires_grad=True) for _ in range(steps)]
        self._poses = [wp.zeros((num_worlds, 7), dtype=float, device=dev, requires_grad=True)
                       for _ in range(steps + 1)]
        self._friction = wp.zeros(num_worlds, dtype=float, device=dev, requires_grad=True)
        self._chassis_mass = wp.zeros(num_worlds, dtype=float, device=dev, requires_grad=True)
        self._payload = wp.zeros(num_worlds, dtype=float, device=dev, requires_grad=True)
        self._payload_offset = wp.zeros(num_worlds, dtype=wp.vec3, device=dev)
        self._all = wp.full(num_worlds, True, dtype=bool, device=dev)
        # the simulator's per-world physics, with a differentiable mu of the tape's own
        physics = WorldPhysics()
        params = self.sim.params.physics
        physics.friction, physics.stiffness, physics.wheel_radius = self._friction, params.stiffness, params.wheel_radius
        physics.torque_scale, physics.speed_limit = params.torque_scale, params.speed_limit
        self._physics = physics
        self.nominal_chassis_mass = float(model.body_mass.numpy()[self.sim.layout.chassis_body])
        self._flags = wp.zeros(num_worlds, dtype=wp.int32, device=dev)
        # The friction solver starts each substep from the previous one's impulses: one array per
        # substep boundary, so the tape differentiates through that chain too.
        self._impulses = [wp.zeros_like(self.sim.contact.impulses, requires_grad=True) for _ in range(n_sub + 1)]
        self._torque = wp.zeros((num_worlds, len(self.sim.description.wheels)), dtype=float, device=dev)
        # Featherstone keeps its mass-matrix scratch (M, J, P, H, L) on the solver, shared by every
        # step. Under a tape each step must own them, or the adjoints of all steps mix in one buffer
        # (gradients explode with the horizon); so each substep gets its own set, swapped in below.
        solver = self.sim.solver
        self._scratch = [{name: wp.zeros_like(getattr(solver, name), requires_grad=True) for name in _SCRATCH}
                         for _ in range(n_sub)]
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
    def _record(self) -> None:
        sim, lay = self.sim, self.sim.layout
        n = self.num_worlds
        # The chassis mass (a payload at its centre of mass) is an input of the tape: the simulator's payload
        # kernel sets the chassis and the friction solver's model of the rover, then the solver re-derives
        # its spatial inertias (Newton's public route for runtime mass changes), all recorded.
        wp.launch(payload_from_chassis_mass, dim=n, inputs=[self._chassis_mass, self.nominal_chassis_mass],
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
        wp.launch(gather_chassis_pose, dim=n, inputs=[s0.body_q, lay.bodies_per_world, lay.chassis_body],
                  outputs=[self._poses[0]], device=sim.device)
        k = 0
        for t in range(self.steps):
            wp.launch(scale_actions, dim=n, inputs=[self._actions[t], self.action_scale], outputs=[self._commands[t]],
                      device=sim.device)
            for _ in range(sim.substeps):
                s_in, s_out = self.states[k], self.states[k + 1]
                for name, arr in self._scratch[k].items():
                    setattr(sim.solver, name, arr)
                sim.substep(s_in, s_out, self.controls[k], self._commands[t], physics=self._physics,
                            flags=self._flags, torque=self._torque, solver_in=self._solver_in[k],
                            warm_start=self._impulses[k], impulses=self._impulses[k + 1])
                if self._tape is not None and self.wrench_fix:
                    self._tape.record_func(backward=restore_external_wrench(s_out, s_in), arrays=[])
                k += 1
            wp.launch(gather_chassis_pose, dim=n, inputs=[self.states[k].body_q, lay.bodies_per_world,
                                                         lay.chassis_body], outputs=[self._poses[t + 1]],
                      device=sim.device)

    @torch.no_grad()
    def forward(self, actions: torch.Tensor, joint_q: torch.Tensor, joint_qd: torch.Tensor,
                friction: torch.Tensor, chassis_mass: torch.Tensor, record: bool = True) -> tuple[torch.Tensor, int]:
        """Run the rollout, on a fresh tape if ``record``; returns poses (steps + 1, N, 7) and the
        rollout's number (which :meth:`backward` checks against the tape it holds)."""
        for t in range(self.steps):
            wp.to_torch(self._actions[t]).copy_(actions[t])
        s0 = self.states[0]
        wp.to_torch(s0.joint_q).copy_(joint_q.reshape(-1))
        wp.to_torch(s0.joint_qd).copy_(joint_qd.reshape(-1))
        wp.to_torch(self._friction).copy_(friction.reshape(-1))
        wp.to_torch(self._chassis_mass).copy_(chassis_mass.reshape(-1))
        for s in self.states:
            s.body_f.zero_()
        self._impulses[0].zero_()  # a rollout starts from rest, unloaded
        self._rollout_id += 1
        self._tape = wp.Tape() if record else None
        if record:
            with self._tape:
                self._record()
        else:
            self._record()
        return torch.stack([wp.to_torch(p).clone() for p in self._poses]), self._rollout_id

    def backward(self, grad_poses: torch.Tensor, rollout_id: int):
        """Back-propagate ``grad_poses`` through rollout number ``rollout_id`` (the latest recorded)."""
        tape = self._tape
        if tape is None or rollout_id != self._rollout_id:
            raise RuntimeError(
                "this rollout's tape is gone: a DiffRollout keeps the tape of its latest call only, and a "
                "tape serves one backward pass. Call backward before running the same DiffRollout again "
                "(or use one DiffRollout per rollout awaiting its backward pass).")
        grads = {p: wp.from_torch(grad_poses[i].contiguous()) for i, p in enumerate(self._poses)}
        tape.backward(grads=grads)
        g_actions = torch.stack([wp.to_torch(a.grad).clone() for a in self._actions])
        s0 = self.states[0]
        g_q = wp.to_torch(s0.joint_q.grad).clone()
        g_qd = wp.to_torch(s0.joint_qd.grad).clone()
        g_mu = wp.to_torch(self._friction.grad).clone()
        g_mass = wp.to_torch(self._chassis_mass.grad).clone()
        tape.zero()
        self._tape = None
        for name, g in (("actions", g_actions), ("initial joint_q", g_q), ("initial joint_qd", g_qd),
                        ("friction", g_mu), ("chassis mass", g_mass)):
            if not torch.isfinite(g).all():
                raise NonFiniteGradientError(
                    f"gradient w.r.t. {name} is not finite after a {self.steps}-step rollout; shorten the "
                    "horizon or soften the actions")
        return g_actions, g_q, g_qd, g_mu, g_mass

    # ------------------------------------------------------------------ torch entry point
    def initial_state(self, poses: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """Generalised coordinates (joint_q, joint_qd) of rovers at rest at (x, y, yaw) ``poses`` (N, 3)."""
        sim = self.sim
        sim.reset(poses=poses)
        return (wp.to_torch(sim.state_0.joint_q).detach().clone(), wp.to_torch(sim.state_0.joint_qd).detach().clone())

    def __call__(self, actions: torch.Tensor, initial_state: tuple[torch.Tensor, torch.Tensor] | None = None,
                 friction: torch.Tensor | float | None = None,
                 chassis_mass: torch.Tensor | float | None = None) -> torch.Tensor:
        """Roll out and return chassis poses (steps + 1, N, 7): x, y, z [m], quaternion (x, y, z, w).

        Args:
            actions: (steps, N, 2) in [-1, 1] (x :attr:`action_scale` N·m), differentiable.
            initial_state: (joint_q, joint_qd) from :meth:`initial_state` (default: every rover at
                the origin, at rest); differentiable.
            friction: Coulomb coefficient, one for all worlds or (N,) one per world (default: the
                contact config's), differentiable.
            chassis_mass: Chassis mass [kg], one or (N,) one per world, e.g. with a payload (default:
                the URDF's, :attr:`nominal_chassis_mass`). The difference is a point mass at the chassis'
                centre of mass (the simulator's payload, :meth:`~atrv_warp.sim.RoverSim.set_params`), which
                the wheels' friction solver's model of the rover carries too. Differentiable.
        """
        expected = (self.steps, self.num_worlds, 2)
        if tuple(actions.shape) != expected:
            raise ValueError(f"actions must have shape {expected} (steps, worlds, [left, right]), "
                             f"got {tuple(actions.shape)}")
        if not torch.isfinite(actions).all():
            raise ValueError("actions contain NaN/inf")
        if initial_state is None:
            initial_state = self.initial_state()
        if friction is None:
            friction = self.sim.contact_cfg.friction
        friction = self._per_world("friction", friction)
        if not (torch.isfinite(friction).all() and bool((friction > 0.0).all())):
            raise ValueError(f"friction must be > 0 and finite, got {friction.detach().tolist()}")
        if chassis_mass is None:
            chassis_mass = self.nominal_chassis_mass
        chassis_mass = self._per_world("chassis_mass", chassis_mass)
        if not (torch.isfinite(chassis_mass).all() and bool((chassis_mass > 0.0).all())):
            raise ValueError(f"chassis_mass must be a positive number of kg, got {chassis_mass.detach().tolist()}")
        inputs = (actions.float(), initial_state[0].float(), initial_state[1].float(), friction, chassis_mass)
        if not (torch.is_grad_enabled() and any(t.requires_grad for t in inputs)):
            return self.forward(*inputs, record=False)[0]  # nothing to differentiate: no tape
        return _RolloutFn.apply(self, *inputs)


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
    def forward(ctx, roll: DiffRollout, actions, joint_q, joint_qd, friction, chassis_mass):
        poses, ctx.rollout_id = roll.forward(actions.detach(), joint_q.detach(), joint_qd.detach(), friction.detach(),
                                             chassis_mass.detach())
        ctx.roll = roll
        return poses

    @staticmethod
    def backward(ctx, grad_poses):
        g_a, g_q, g_qd, g_mu, g_mass = ctx.roll.backward(grad_poses, ctx.rollout_id)
        return None, g_a, g_q, g_qd, g_mu, g_mass
