"""A ROS 2 node's parameters declared once, with their checks: the one style of both of the package's nodes (the
deploy node's :mod:`atrv_warp.deploy.parameters`, the simulator node's :mod:`atrv_warp.integrations.ros.parameters`).
No ROS import.

A :class:`Parameter` has its default, its kind (a topic, a frame, a file, a switch, a number or an integer with its
unit and range, a choice among words, ...) and what it does. :func:`check_parameters` turns the values a node was
given (``-p name:=value`` or a ``--params-file``, as ROS parsed them: ``1`` is an integer there, ``abc`` a string)
into the values it runs with, and refuses a value it cannot run with in one line naming the parameter, what it needs
and what it got. :func:`unknown_parameters` names what a node was given that it does not declare, from its command
line and from its parameter files. A node declares each parameter with ROS's dynamic typing, so that a value of the
wrong type reaches these checks instead of an rclpy traceback.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

__all__ = ["KINDS", "Parameter", "ParameterError", "check_parameters", "given_parameters", "parameter_help",
           "params_file_names", "params_files", "unknown_parameters"]

KINDS = ("topic", "frame", "file", "text", "name", "robot", "choice", "switch", "number", "integer")


class ParameterError(ValueError):
    """A parameter value a node cannot run with; the message is one line naming the parameter."""


@dataclass(frozen=True)
class Parameter:
    """One parameter of a node."""

    name: str
    default: str | bool | float | int
    text: str
    """What it does (the ``--help`` line)."""
    kind: str
    """:data:`KINDS`: ``topic`` (a ROS topic name, relative or absolute), ``frame`` (a tf frame id), ``file`` (a path
    to write, ``''`` = off), ``text`` (any text without control characters, ``''`` included: a file to read, a name
    the node checks itself), ``name`` (a word, ``''`` = none), ``robot`` (a robot's name or its robot file's path,
    ``''`` = none: the node runs with the name), ``choice`` (one of :attr:`choices`), ``switch`` (``true`` |
    ``false``), ``number`` or ``integer``."""
    unit: str = ""
    """The unit of a number (``m/s``)."""
    positive: bool = False
    """A number must be > :attr:`low` (else >= it)."""
    minus_one: str = ""
    """What -1 means for a number that may also be -1 (``the policy's``: the value it was trained with); ``''``: -1
    is out of range like any other value below :attr:`low`."""
    low: float = 0.0
    """The least value of a number (``-inf``: any finite number)."""
    high: float = math.inf
    """The greatest value of a number."""
    choices: tuple[str, ...] = ()
    """A ``choice``'s words."""

    def check(self, value):
        """``value`` as the node runs with it (a ``number`` as a float, an ``integer`` as an int).

        Raises:
            ParameterError: A value of another type, or out of range (one line naming the parameter).
        """
        if self.kind == "switch":
            if not isinstance(value, bool):
                raise self._error("true or false", value)
            return value
        if self.kind in ("number", "integer"):
            return self._number(value)
        if not isinstance(value, str):
            raise self._error("a string", value)
        if any(ord(c) < 32 or ord(c) == 127 for c in value):
            raise self._error("text without control characters", value)
        if self.kind == "choice":
            if value not in self.choices:
                raise self._error(f"one of {list(self.choices)}", value)
            return value
        if self.kind in ("topic", "frame") and not value:
            raise self._error(f"a {self.kind} name (it is empty)", value)
        if self.kind == "frame" and (value.strip() != value or " " in value or value.startswith("/")):
            raise self._error("a tf frame id without spaces or a leading '/' (e.g. odom)", value)
        if self.kind == "robot" and value and (value.endswith(".toml") or "/" in value):
            from atrv_warp.core.robot import RobotFileError, load_robot  # the light core: TOML and the standard library

            try:
                return load_robot(value).name  # a robot file, as the simulator node and every command take one
            except RobotFileError as err:
                raise self._error(f"a robot's name or a robot file that loads ({err})", value) from None
        if self.kind in ("name", "robot") and value and not value.replace("_", "").replace("-", "").isalnum():
            raise self._error("a name of letters, digits, '_' and '-'" + (", or a robot file's path (.toml)"
                                                                           if self.kind == "robot" else ""), value)
        return value

    def _number(self, value):
        integer = self.kind == "integer"
        what = "an integer" if integer else "a number"
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self._error(f"{what} [{self.unit}]" if self.unit else what, value)
        number = float(value)
        if self.minus_one and number == -1:
            return -1 if integer else number
        if integer and not (math.isfinite(number) and number.is_integer()):
            raise self._error(f"a whole number{self._range()}", value)
        if not math.isfinite(number) or number < self.low or number > self.high or (
                self.positive and number == self.low):
            raise self._error(f"{'an integer' if integer else 'a finite number'}{self._range()}", value)
        return int(number) if integer else number

    def _range(self) -> str:
        unit = f" [{self.unit}]" if self.unit else ""
        policy = f", or -1 ({self.minus_one})" if self.minus_one else ""
        if self.low == -math.inf and self.high == math.inf:
            return f"{unit}{policy}"
        if self.high == math.inf:
            return f" {'>' if self.positive else '>='} {self.low:g}{unit}{policy}"
        return f" in {'(' if self.positive else '['}{self.low:g}, {self.high:g}]{unit}{policy}"

    def _error(self, needs: str, value) -> ParameterError:
        kind = "an integer" if isinstance(value, int) and not isinstance(value, bool) else type(value).__name__
        return ParameterError(f"parameter {self.name} must be {needs}, got {value!r} ({kind}): {self.text}")


def check_parameters(parameters: Sequence[Parameter], values: dict) -> dict:
    """The ``values`` a node was given (by name; a missing one takes its default), checked against ``parameters``
    and as the node runs with them.

    Raises:
        ParameterError: An unknown name, or a value of the wrong type or out of range (one line naming it).
    """
    known = {p.name for p in parameters}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ParameterError(f"unknown parameter(s) {unknown}; known: {sorted(known)}")
    return {p.name: p.check(values.get(p.name, p.default)) for p in parameters}


def given_parameters(args: list[str] | None, params_files: dict[str, list[str]] | None = None) -> set[str]:
    """The names given as ``-p name:=value`` or set for the node by a ``--params-file`` (``params_files``: each
    file's parameter names for this node): what was set on purpose, not left at its default."""
    args = list(args or [])
    names = {args[i + 1].split(":=")[0] for i, a in enumerate(args[:-1]) if a in ("-p", "--param")}
    return names.union(*(params_files or {}).values())


def unknown_parameters(known: Iterable[str], args: list[str] | None,
                       params_files: dict[str, list[str]] | None = None) -> list[str]:
    """Names given as ``-p name:=value`` that are not ``known`` (nor ROS's own ``use_sim_time``), and those a
    ``--params-file`` sets for the node (``params_files``: each file's parameter names for this node), each with where
    it came from."""
    known = set(known) | {"use_sim_time"}
    found = sorted(given_parameters(args) - known)
    for file, file_names in (params_files or {}).items():
        found += [f"{name} (in {file})" for name in sorted(set(file_names) - known)]
    return found


def params_files(args: list[str] | None) -> list[str]:
    """The files named by ``--params-file FILE`` among a node's ROS arguments."""
    args = list(args or [])
    return [args[i + 1] for i, a in enumerate(args[:-1]) if a == "--params-file"]


def params_file_names(args: list[str] | None, node_name: str,
                      read: Callable[..., dict]) -> dict[str, list[str]]:
    """Each ``--params-file``'s parameter names for the node ``node_name`` (its fully qualified name; the file may
    name it, its namespace or ``/**``), read with ``read`` (rclpy's ``parameter_dict_from_yaml_file``, which a node
    passes in: this module imports no ROS).

    Raises:
        ParameterError: A file that cannot be read or is not a ROS parameter file (named).
    """
    found = {}
    for file in params_files(args):
        try:
            found[file] = list(read(file, use_wildcard=True, target_nodes=[node_name]))
        except RuntimeError as err:
            if "does not contain any valid parameters" not in str(err):
                raise ParameterError(f"--params-file {file}: {err}") from None
            found[file] = []  # a file for other nodes
        except (OSError, ValueError, AttributeError, TypeError) as err:  # unreadable, or YAML of another shape
            raise ParameterError(f"--params-file {file}: not a ROS parameter file ({err})") from None
    return found


def parameter_help(parameters: Sequence[Parameter]) -> str:
    """``parameters`` as ``name (default): description`` lines."""
    return "\n".join(f"    {p.name} ({p.default!r}): {p.text}" for p in parameters)
