"""A simulator-config file: a TOML file whose ``[rover]`` and ``[contact]`` tables change the simulator's
:class:`~atrv_warp.sim.config.RoverConfig` and :class:`~atrv_warp.sim.config.ContactConfig` (``atrv-calibrate``
writes one), read and checked by name (:func:`load_sim_config`, :func:`read_sim_config`)."""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from atrv_warp.core.inputs import InputFileError, read_input
from atrv_warp.sim.config import ContactConfig, InertialOverride, RoverConfig, get_variant, replace_checked

__all__ = ["SIM_CONFIG_TABLES", "STANDARD_ERROR_TABLE", "SimConfigFile", "load_sim_config", "read_sim_config"]

SIM_CONFIG_TABLES = ("rover", "contact")
"""Tables of a simulator-config TOML file that change the simulation: ``[rover]`` holds
:class:`RoverConfig` fields, ``[contact]`` :class:`ContactConfig` fields. Any other table
(``[calibration]``, as ``atrv-calibrate`` writes) is a record that does not change the simulation; a randomization
centred on the file reads its standard errors (:data:`STANDARD_ERROR_TABLE`)."""


STANDARD_ERROR_TABLE = ("calibration", "standard_error")
"""Where a simulator-config file records the fit's standard error of each fitted value (``atrv-calibrate`` writes
``[calibration.standard_error]``, keyed by parameter name: ``friction = 0.0042``)."""


@dataclass(frozen=True)
class SimConfigFile:
    """A simulator-config TOML file as :func:`read_sim_config` reads it."""

    path: str
    """The file."""
    rover: RoverConfig
    """The rover, with the file's ``[rover]`` table applied."""
    contact: ContactConfig
    """The contact law, with the file's ``[contact]`` table applied."""
    keys: frozenset[tuple[str, str]]
    """The ``(table, key)`` pairs the file sets, e.g. ``("contact", "friction")``."""
    standard_error: dict[str, float] = field(default_factory=dict)
    """The fit's standard error of each value it fitted, by parameter name (``[calibration.standard_error]``,
    :data:`STANDARD_ERROR_TABLE`), in the parameter's unit; ``nan`` where the fit could not estimate one, empty
    for a file written by hand. A record only: it does not change the simulation."""

    def sets(self, table: str, key: str) -> bool:
        """Whether the file sets ``[table] key``."""
        return (table, key) in self.keys


def _overrides(path: Path, value) -> tuple[InertialOverride, ...]:
    """A sim config's ``[rover] inertial_overrides``: an array of tables ``{link = "...", mass = ..., inertia_diag =
    [...]}``, each checked, or a ``ValueError`` naming the file, the key and the entry."""
    where = f"sim config {path}: [rover] inertial_overrides"
    if not isinstance(value, list):
        raise ValueError(f"{where} must be an array of tables ([[rover.inertial_overrides]] with link, mass and "  # noqa: TRY004
                         f"inertia_diag), got {value!r}")
    out = []
    for k, entry in enumerate(value):
        if not isinstance(entry, dict):
            raise ValueError(f"{where}: entry {k} must be a table with link, mass and inertia_diag, got "  # noqa: TRY004
                             f"{entry!r}")
        unknown = sorted(set(entry) - {"link", "mass", "inertia_diag"})
        if unknown or "link" not in entry or "mass" not in entry:
            raise ValueError(f"{where}: entry {k} must set link and mass (and may set inertia_diag), got "
                             f"{sorted(entry)}")
        try:
            out.append(InertialOverride(**entry))
        except (TypeError, ValueError) as err:
            raise ValueError(f"{where}: entry {k}: {err}") from None
    return tuple(out)


def load_sim_config(path, rover: RoverConfig | None = None,
                    contact: ContactConfig | None = None) -> tuple[RoverConfig, ContactConfig]:
    """``rover`` and ``contact`` (default: the realistic variant's and the default contact) with the
    ``[rover]`` and ``[contact]`` tables of the TOML file at ``path`` applied.

    This is the ``--sim-config FILE`` of ``RoverSim(sim_config=...)``, ``RoverEnv(sim_config=...)``,
    ``python -m atrv_warp.train --env.sim-config`` and the ROS node's ``sim_config`` parameter; the file
    ``atrv-calibrate`` writes is one. A missing file, bad TOML, an unknown key or a bad value is a
    ``ValueError`` naming the file and the key. Example::

        [rover]
        torque_scale = 0.82
        payload_mass = 11.5    # kg, at the chassis' centre of mass unless payload_offset says otherwise
        [contact]
        friction = 0.55
    """
    read = read_sim_config(path, rover, contact)
    return read.rover, read.contact


def read_sim_config(path, rover: RoverConfig | None = None, contact: ContactConfig | None = None) -> SimConfigFile:
    """:func:`load_sim_config`, with what the file sets and its record of the fit's standard errors."""
    rover = rover or get_variant("realistic")
    contact = contact or ContactConfig()
    path = Path(path)
    try:
        text = read_input(path, "simulator config").decode("utf-8")
    except FileNotFoundError:
        raise ValueError(f"sim config {path}: cannot read it (no such file)") from None
    except InputFileError as err:
        raise ValueError(f"sim config {err}") from None
    except OSError as err:
        raise ValueError(f"sim config {path}: cannot read it ({err.strerror or err})") from None
    except UnicodeDecodeError:
        raise ValueError(f"sim config {path}: not a text file (a TOML file of [rover] and [contact] tables)") from None
    try:
        tables = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ValueError(f"sim config {path}: not valid TOML ({err})") from None
    unknown = sorted(set(tables) - {*SIM_CONFIG_TABLES, STANDARD_ERROR_TABLE[0]})
    if unknown:
        raise ValueError(f"sim config {path}: unknown table(s) {unknown}; known: [rover], [contact] (the simulation) "
                         f"and [{STANDARD_ERROR_TABLE[0]}] (a record)")
    configs = {"rover": rover, "contact": contact}
    keys = set()
    for table in SIM_CONFIG_TABLES:
        values = tables.get(table, {})
        if not isinstance(values, dict):
            raise ValueError(f"sim config {path}: [{table}] must be a table of keys, got {values!r}")  # noqa: TRY004
        values = dict(values)
        if table == "rover" and "inertial_overrides" in values:
            values["inertial_overrides"] = _overrides(path, values["inertial_overrides"])
        try:
            configs[table] = replace_checked(configs[table], **values)
        except (TypeError, ValueError) as err:
            raise ValueError(f"sim config {path}: [{table}] {err}") from None
        keys.update((table, key) for key in values)
    record = tables
    for name in STANDARD_ERROR_TABLE:
        record = record.get(name, {}) if isinstance(record, dict) else {}
    standard_error = {}
    for name, value in (record.items() if isinstance(record, dict) else ()):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or value < 0:
            raise ValueError(f"sim config {path}: [{'.'.join(STANDARD_ERROR_TABLE)}] {name} must be a number >= 0 "
                             f"(or nan), got {value!r}")
        standard_error[name] = float(value)
    return SimConfigFile(str(path), configs["rover"], configs["contact"], frozenset(keys), standard_error)
