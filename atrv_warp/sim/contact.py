"""The contact model a simulator launches: the rover's shapes, the arena's planes and the law.

:class:`ContactModel` turns the configs and the built Newton model into the structs the
Hunt–Crossley kernel (:mod:`atrv_warp.sim.kernels.contact`) reads, once per simulator, and launches
it. :class:`~atrv_warp.sim.RoverSim` and :class:`~atrv_warp.sim.diff.DiffRollout` both step through
it, so there is one contact model to change.
"""

from __future__ import annotations

import newton
import warp as wp

from atrv_warp.sim.config import ArenaConfig, ContactConfig, RoverConfig
from atrv_warp.sim.kernels.contact import ArenaPlanes, ContactParams, RoverShapes, compute_contact_forces
from atrv_warp.sim.model import BuiltModel

__all__ = ["ContactModel"]


def _law(cfg: ContactConfig) -> ContactParams:
    p = ContactParams()
    p.stiffness = cfg.stiffness
    p.damping = cfg.damping
    p.exponent = cfg.exponent
    p.linear_region = cfg.linear_region
    p.linear_coeff = cfg.linear_region ** (cfg.exponent - 1.0)
    return p


def _planes(arena: ArenaConfig, device) -> ArenaPlanes:
    """Ground and the four walls as half-spaces ``n·x >= offset`` (inner faces)."""
    planes = ArenaPlanes()
    planes.normal = wp.array([n for n, _ in arena.planes()], dtype=wp.vec3, device=device)
    planes.offset = wp.array([o for _, o in arena.planes()], dtype=float, device=device)
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


class ContactModel:
    """Hunt–Crossley contact of every world's rover against the arena, ready to launch.

    Attributes (read-only; the kernel's inputs):
        params: the law (:class:`~atrv_warp.sim.kernels.contact.ContactParams`).
        shapes: the template rover's shapes (:class:`~atrv_warp.sim.kernels.contact.RoverShapes`).
        planes: ground and walls (:class:`~atrv_warp.sim.kernels.contact.ArenaPlanes`).
        friction: (1,) Coulomb coefficient, the default for :meth:`apply`.
    """

    def __init__(self, built: BuiltModel, *, rover: RoverConfig, contact: ContactConfig, arena: ArenaConfig,
                 sim_dt: float, device):
        self.num_worlds = built.num_worlds
        self.bodies_per_world = built.rover_builder.body_count
        self.device = device
        self.params = _law(contact)
        self.shapes = _shapes(built, rover, contact, sim_dt, device)
        self.planes = _planes(arena, device)
        self.friction = wp.array([contact.friction], dtype=float, device=device)

    def apply(self, state: newton.State, body_com: wp.array, flags: wp.array, friction: wp.array | None = None) -> None:
        """Add every contact wrench to ``state.body_f`` and OR the contact bits into ``flags``.

        ``friction`` (1,) overrides the configured coefficient, e.g. a differentiable one.
        """
        wp.launch(compute_contact_forces, dim=self.num_worlds,
                  inputs=[self.bodies_per_world, self.shapes, self.planes, self.params,
                          self.friction if friction is None else friction, state.body_q, state.body_qd, body_com],
                  outputs=[state.body_f, flags], device=self.device)
