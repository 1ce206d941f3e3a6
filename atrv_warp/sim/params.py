"""Each world's physical parameters, as device arrays that the kernels read every substep.

A :class:`~atrv_warp.sim.RoverSim` starts every world at its configs' values (:class:`RoverConfig`,
:class:`ContactConfig`) and steps them bit for bit as it would with those scalars. Change a world's
values with :meth:`~atrv_warp.sim.RoverSim.set_params` (checked, from the host), or write the arrays
from a kernel and call :meth:`~atrv_warp.sim.RoverSim.apply_payload` (what a task's domain
randomization does on reset, without a host round trip).
"""

from __future__ import annotations

import numpy as np
import torch
import warp as wp

from atrv_warp.sim.config import ContactConfig, RoverConfig
from atrv_warp.sim.kernels.params import WorldPhysics

__all__ = ["PARAMETERS", "PARAMETER_KEYS", "WorldParams", "check_parameter", "parameter_values"]

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
