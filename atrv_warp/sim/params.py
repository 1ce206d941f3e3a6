"""Each world's physical parameters, as device arrays that the kernels read every substep.

A :class:`~atrv_warp.sim.RoverSim` starts every world at its configs' values (:class:`RoverConfig`,
:class:`ContactConfig`) and steps them bit for bit as it would with those scalars. Change a world's
values with :meth:`~atrv_warp.sim.RoverSim.set_params` (checked, from the host), or write the arrays
from a kernel and call :meth:`~atrv_warp.sim.RoverSim.apply_payload` (what a task's domain
randomization does on reset, without a host round trip).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import warp as wp

from atrv_warp.sim.config import ContactConfig, RoverConfig
from atrv_warp.sim.kernels.params import WorldPhysics

__all__ = ["PARAMETERS", "PARAMETER_KEYS", "Bound", "WorldParams", "check_bounds", "check_parameter", "parameter_bounds",
           "parameter_values"]

PARAMETERS: dict[str, str] = {  # this order is also the randomization's draw streams' (PHYSICS_DRAWS): keep it
    "friction": "Coulomb coefficient mu of the wheels (and every other contact) [-]",
    "payload_mass": "point payload on the chassis [kg]",
    "payload_offset": "payload position from the chassis' centre of mass, chassis frame (x, y, z) [m]",
    "torque_scale": "motor torque per unit of commanded torque [-]",
    "speed_limit": "motor no-load speed [rad/s]",
    "wheel_radius": "rolling radius of the wheels [m] (odometry keeps assuming RoverConfig.wheel_radius)",
    "stiffness": "Hunt-Crossley contact stiffness kp [N/m^n]",
}
"""Each per-world parameter, with its meaning and unit."""

PARAMETER_KEYS: dict[str, tuple[str, str]] = {
    "friction": ("contact", "friction"),
    "payload_mass": ("rover", "payload_mass"),
    "payload_offset": ("rover", "payload_offset"),
    "torque_scale": ("rover", "torque_scale"),
    "speed_limit": ("rover", "wheel_speed_limit"),
    "wheel_radius": ("rover", "wheel_radius"),
    "stiffness": ("contact", "stiffness"),
}
"""Where each parameter's configured value lives: the config (``rover``: :class:`RoverConfig`, ``contact``:
:class:`ContactConfig`) and its field, which is also the table and key of a simulator-config TOML file."""


def parameter_values(rover: RoverConfig, contact: ContactConfig) -> dict[str, float | tuple[float, float, float]]:
    """Each parameter's value in ``rover`` and ``contact`` (:data:`PARAMETER_KEYS`), by name."""
    configs = {"rover": rover, "contact": contact}
    values = {name: getattr(configs[table], key) for name, (table, key) in PARAMETER_KEYS.items()}
    values["payload_offset"] = tuple(values["payload_offset"])
    return values


def check_parameter(name: str, value) -> None:
    """Raise a ``ValueError`` naming ``name`` if ``value`` (a number or an array of them) is not a valid
    value of the parameter."""
    if name not in PARAMETERS:
        raise ValueError(f"unknown physical parameter {name!r}; known: {sorted(PARAMETERS)}")
    v = np.asarray(value, dtype=np.float64)
    if not np.isfinite(v).all():
        raise ValueError(f"{name} must be finite, got {value!r}")
    if name == "payload_offset":
        return
    if name == "payload_mass" or name == "torque_scale":
        if (v < 0).any():
            raise ValueError(f"{name} must be >= 0, got {value!r}")
    elif (v <= 0).any():
        raise ValueError(f"{name} must be > 0, got {value!r}")


@dataclass(frozen=True)
class Bound:
    """The range of a parameter's values a robot's simulation stays meaningful in (a payload offset: its distance from
    the chassis' centre of mass)."""

    low: float
    high: float
    rule: str
    """What the range is relative to, in words (e.g. "0.5 to 2 times the robot's wheel radius, 0.125 m")."""


def parameter_bounds(description, configured_wheel_radius: float) -> dict[str, Bound]:
    """Each bounded parameter's range for the robot ``description`` (:class:`~atrv_warp.sim.urdf.RoverDescription`),
    stated relative to its own figures so that a smaller or larger robot's real values pass. Past them the explicit
    step blows up or the robot is another robot (measured on the ATRV-Jr, 58 kg, driven 10 s at full torque: a wheel
    radius of 100 m, a torque scale of 10⁴, a payload of 500 kg, a payload 10⁹ m away or a contact stiffness of 10⁷
    made its state non-finite; a stiffness of 3·10⁶ bounced it 1.9 m high):

    - ``wheel_radius``: 0.5 to 2 times the URDF's wheel radius (where it gives none: the configured one's);
    - ``torque_scale``: 0 to 5 (at most five times the motors' torque);
    - ``payload_mass``: 0 to 3 times the robot's mass;
    - ``payload_offset``: within twice the body's reach (:attr:`~atrv_warp.sim.urdf.RoverDescription.reach`) of the
      chassis' centre of mass;
    - ``stiffness``: 0.1 to 10 times the reference contact's 10⁵ N/m^n.
    """
    radius = description.wheel_radius or configured_wheel_radius
    mass, reach = description.total_mass, description.reach
    return {"wheel_radius": Bound(0.5 * radius, 2.0 * radius, f"0.5 to 2 times the robot's wheel radius, {radius:g} m"),
            "torque_scale": Bound(0.0, 5.0, "at most 5 times the motors' torque"),
            "payload_mass": Bound(0.0, 3.0 * mass, f"at most 3 times the robot's mass, {mass:.1f} kg"),
            "payload_offset": Bound(0.0, 2.0 * reach, f"within twice the body's reach, {2.0 * reach:.2f} m, of the "
                                                      "chassis' centre of mass"),
            "stiffness": Bound(1.0e4, 1.0e6, "0.1 to 10 times the reference contact's 1e5 N/m^n")}


def check_bounds(bounds: dict[str, Bound], name: str, value, label: str | None = None) -> None:
    """Raise a ``ValueError`` naming the parameter (as ``label`` where given: the file and key it came from) if
    ``value`` (a number, or an array of them; a payload offset: (..., 3)) leaves its :func:`parameter_bounds`."""
    bound = bounds.get(name)
    if bound is None:
        return
    v = np.asarray(value, dtype=np.float64)
    if name == "payload_offset":
        v = np.linalg.norm(v.reshape(-1, 3), axis=-1)
    bad = v[(v < bound.low) | (v > bound.high)]
    if bad.size:
        unit = "m" if name in ("wheel_radius", "payload_offset") else "kg" if name == "payload_mass" else ""
        shown = f"{float(bad.flat[0]):g}{' ' + unit if unit else ''}"
        raise ValueError(f"{label or name} {shown}{' away' if name == 'payload_offset' else ''} is outside "
                         f"{bound.low:.3g} … {bound.high:.3g} ({bound.rule})")


class WorldParams:
    """Each world's physical parameters: (N,) torch views of device arrays ((N, 3) for the payload offset).

    Attributes:
        friction, stiffness, wheel_radius, torque_scale, speed_limit, payload_mass, payload_offset: the
            views (:data:`PARAMETERS` says what each is). The motor, contact and friction kernels read the
            first five every substep; the payload reaches the solver through
            :meth:`~atrv_warp.sim.RoverSim.apply_payload`.
        nominal: each parameter's value from the configs.
        physics: the :class:`~atrv_warp.sim.kernels.params.WorldPhysics` struct the kernels take.
        payload_mass_array, payload_offset_array: the Warp arrays behind the payload views.
    """

    def __init__(self, num_worlds: int, *, rover: RoverConfig, contact: ContactConfig, device):
        self.num_worlds = num_worlds
        self.nominal = parameter_values(rover, contact)
        for name, value in self.nominal.items():
            check_parameter(name, value)
        p = WorldPhysics()
        for name in ("friction", "stiffness", "wheel_radius", "torque_scale", "speed_limit"):
            setattr(p, name, wp.full(num_worlds, self.nominal[name], dtype=float, device=device))
        # not a drawn parameter (PARAMETERS): every world takes the contact config's
        p.friction_rise = wp.full(num_worlds, contact.friction_rise, dtype=float, device=device)
        self.physics = p
        self.payload_mass_array = wp.full(num_worlds, rover.payload_mass, dtype=float, device=device)
        self.payload_offset_array = wp.array(np.tile(np.asarray(rover.payload_offset, dtype=np.float32),
                                                     (num_worlds, 1)), dtype=wp.vec3, device=device)
        self.friction = wp.to_torch(p.friction)
        self.stiffness = wp.to_torch(p.stiffness)
        self.wheel_radius = wp.to_torch(p.wheel_radius)
        self.torque_scale = wp.to_torch(p.torque_scale)
        self.speed_limit = wp.to_torch(p.speed_limit)
        self.payload_mass = wp.to_torch(self.payload_mass_array)
        self.payload_offset = wp.to_torch(self.payload_offset_array)

    def view(self, name: str) -> torch.Tensor:
        """The torch view of parameter ``name``."""
        if name not in PARAMETERS:
            raise ValueError(f"unknown physical parameter {name!r}; known: {sorted(PARAMETERS)}")
        return getattr(self, name)

    def as_dict(self, worlds=None) -> dict[str, np.ndarray]:
        """Copies of every parameter (of all worlds, or of ``worlds``), as numpy arrays."""
        idx = slice(None) if worlds is None else np.asarray(worlds)
        return {name: self.view(name).detach().cpu().numpy()[idx].copy() for name in PARAMETERS}
