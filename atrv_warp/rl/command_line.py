"""The training command line and the configuration files it reads.

A configuration comes from, in order: the :class:`~atrv_warp.rl.config.TrainConfig` defaults, a TOML preset or file
(one table per group, read with ``tomllib``), then the command line. One parser reads the file's values and the
command line alike: `tyro <https://brentyi.github.io/tyro/>`_, on :class:`TrainCommand` (``--optim.lr 1e-3``); the
short form ``lr=1e-3`` (a field's name alone) and the true/false words are spelt out in one table, :data:`SPELLINGS`.
An unknown key or a bad value stops before any work, in one line.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import math
import tomllib
import typing
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Annotated

import tyro

from atrv_warp.rl.config import GROUP_TYPES, TrainConfig, toml_text
from atrv_warp.rl.run import check_resumed_task_module, toml_value

__all__ = [
    "BOOLEAN_SPELLINGS",
    "DEFAULT_PRESET",
    "FLAG_ALIASES",
    "PROG",
    "SPELLINGS",
    "TrainCommand",
    "cli_args",
    "load_train_config",
    "parse_command",
    "preset_names",
]


SPELLINGS: dict[str, str] = {
    **{f.name: f"{group}.{f.name}" for group, cls in GROUP_TYPES.items() for f in dataclasses.fields(cls)},
    "collector": "collector.kind",
}
"""Short command-line keys and the ``group.field`` each names: every field by its name alone (field
names are unique across groups, so ``lr=3e-4`` is enough), and ``collector=sync`` for ``collector.kind``."""
BOOLEAN_SPELLINGS = {"1": "True", "true": "True", "yes": "True", "on": "True",
                     "0": "False", "false": "False", "no": "False", "off": "False"}
"""The words a true/false field accepts (any case), as tyro spells them."""
FLAG_ALIASES = {"--sim-config": "--env.sim-config", "--map": "--env.map"}
"""Flags shared with the other commands (``atrv-calibrate`` writes what ``--sim-config`` reads), and the field each sets."""
DEFAULT_PRESET = "default"
PROG = "python -m atrv_warp.train"


@dataclass(frozen=True)
class TrainCommand:
    """The training command line: which configuration to start from, and the configuration."""

    train: Annotated[TrainConfig, tyro.conf.arg(name=""), tyro.conf.FlagConversionOff] = field(
        default_factory=TrainConfig)
    config: str = DEFAULT_PRESET
    """A preset shipped with the package (``default``, ``smoke``, ``nav``, ``nav_deploy``, ``nav_deploy_gpu``, ``ppo``, ``nav_ppo``) or a TOML file."""
    resume: str | None = None
    """Continue the run in this folder (its ``config.toml``, then the command line)."""
    verbose: Annotated[bool, tyro.conf.arg(aliases=("-v",))] = False
    """Show library detail: Warp module loads, TorchRL INFO (same as ATRV_WARP_VERBOSE=1)."""


def _field_type(dotted: str):
    group, _, name = dotted.partition(".")
    return typing.get_type_hints(GROUP_TYPES[group])[name]


def _token(dotted: str, value) -> list[str]:
    """``--group.field VALUE`` for tyro, true/false spelt as tyro spells them, and a whole number written as a float
    (``total_frames=1e6``, a TOML's ``5e5``) as an integer for an integer field.

    Raises:
        ValueError: A number for an integer field that is not whole, or past 2^63 (named).
    """
    text = str(value)
    kind = _field_type(dotted)
    if typing.get_origin(kind) is tuple:  # a list: a TOML array, or `[a, b]` / `a,b` / `a` on the command line
        items = value if isinstance(value, (list, tuple)) else [
            t.strip() for t in text.strip().removeprefix("[").removesuffix("]").split(",") if t.strip()]
        return [f"--{dotted.replace('_', '-')}", *(str(t) for t in items)]
    if kind is bool:
        text = BOOLEAN_SPELLINGS.get(text.strip().lower(), text)
    elif kind is int and not isinstance(value, bool):
        text = _whole(dotted, value, text)
    return [f"--{dotted.replace('_', '-')}", text]


def _whole(dotted: str, value, text: str) -> str:
    """``text`` of an integer field as an integer: ``1e6`` and ``5e5.0`` are whole numbers; ``2.5``, ``1e30`` and
    ``nan`` are refused by name (tyro said "invalid literal for int()")."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        return text  # not a number: tyro names it
    if text.strip().lstrip("+-").isdigit():
        return text
    if not (math.isfinite(number) and number.is_integer() and abs(number) < 2**63):
        raise ValueError(f"train config: {dotted} must be a whole number, got {text}")
    return str(int(number))


def _unknown(keys: list[str], where: str = "") -> ValueError:
    return ValueError(f"unknown train config key(s) {sorted(keys)}{where}; known: {sorted(SPELLINGS)}")


def cli_args(tokens: list[str]) -> list[str]:
    """Command-line tokens for tyro: ``lr=1e-3`` or ``optim.lr=1e-3`` become ``--optim.lr 1e-3``
    (:data:`SPELLINGS`); everything else passes through. An unknown key is a ``ValueError`` naming it."""
    out = []
    for token in tokens:
        flag, eq, value = token.partition("=")
        if flag in FLAG_ALIASES:
            out += [FLAG_ALIASES[flag], value] if eq else [FLAG_ALIASES[flag]]
            continue
        key, eq, value = token.partition("=")
        if not eq or token.startswith("-"):
            out.append(token)
            continue
        dotted = SPELLINGS.get(key, key)
        if dotted not in SPELLINGS.values():
            raise _unknown([key])
        out += _token(dotted, value)
    return out


def _task_tokens(tokens: list[str]) -> tuple[list[str], tuple[tuple[str, str], ...]]:
    """The command line's task fields (``env.task.<field>=VALUE`` or ``task.<field>=VALUE``) apart from the rest;
    ``env.task.name=NAME`` names the task (as ``task=NAME``)."""
    rest, fields = [], []
    for token in tokens:
        key, eq, value = token.partition("=")
        prefix = next((p for p in ("env.task.", "task.") if eq and key.startswith(p)), None)
        if prefix is None:
            rest.append(token)
        elif key[len(prefix):] == "name":
            rest.append(f"env.task={value}")
        else:
            fields.append((key[len(prefix):], toml_text(toml_value(value))))
    return rest, tuple(fields)


def _with_task_fields(cfg: TrainConfig, fields: tuple[tuple[str, str], ...]) -> TrainConfig:
    """``cfg`` with ``fields`` set among its task fields (a field given again takes the later value)."""
    if not fields:
        return cfg
    merged = dict(cfg.env.task_fields)
    merged.update(fields)
    return dataclasses.replace(cfg, env=dataclasses.replace(cfg.env, task_fields=tuple(merged.items())))


def _toml_args(values: dict, label: str) -> list[str]:
    """Tokens for tyro from a TOML document of one table per group (an ``[env.task]`` table's ``name`` among them;
    its other keys are the task's fields, which :func:`_file_config` sets after the parse); a flat key (as run folders
    written before 0.2.0 hold) is a ``ValueError`` saying where it goes now."""
    flat = [k for k, v in values.items() if not (k in GROUP_TYPES and isinstance(v, dict))]
    if flat:
        where = ", ".join(f"{k} under [{SPELLINGS[k].partition('.')[0]}]" for k in sorted(flat) if k in SPELLINGS)
        if where:
            raise ValueError(f"{label}: flat keys {sorted(flat)} are from before atrv_warp 0.2.0, which reads one "
                             f"table per group: write {where}")
        raise _unknown(flat, f" in {label}")
    out, unknown = [], []
    for group, table in values.items():
        for name, value in table.items():
            if group == "env" and name == "task" and isinstance(value, dict):
                if "name" in value:
                    out += _token("env.task", value["name"])
                continue
            if f"{group}.{name}" in SPELLINGS.values():
                out += _token(f"{group}.{name}", value)
            else:
                unknown.append(f"{group}.{name}")
    if unknown:
        raise _unknown(unknown, f" in {label}")
    return out


def _tyro(tokens: list[str], default: TrainCommand | None, where: str = "") -> TrainCommand:
    """Parse with tyro; a bad argument is a one-line ``ValueError`` (``--help`` prints and exits)."""
    errors = io.StringIO()
    try:
        with contextlib.redirect_stderr(errors):
            return tyro.cli(TrainCommand, args=tokens, default=default, prog=PROG,
                            description="Train a driver with TorchRL SAC or PPO. Configuration fields: --group.field "
                                        "VALUE, or field=VALUE.")
    except SystemExit as err:
        if not err.code:
            raise
        # tyro's message is a title, a rule or a box border, the error, a rule, then help: keep the error
        lines = [line.strip(" │╭╮╰╯") for line in errors.getvalue().splitlines()]
        lines = [line for line in lines if line]
        rules = [i for i, line in enumerate(lines) if set(line) <= set("─-")]
        if len(rules) >= 2 and rules[0] == 1:  # title, rule, error, rule
            body = lines[2:rules[1]]
        else:  # a box whose top border holds the title
            body = lines[1:rules[0]] if rules else lines
        raise ValueError(f"train config{where}: {' '.join(' '.join(body).split())}") from None


def preset_names() -> list[str]:
    """Names of the training presets shipped inside the package (``atrv_warp/rl/configs/*.toml``)."""
    folder = resources.files("atrv_warp.rl").joinpath("configs")
    return sorted(f.name.removesuffix(".toml") for f in folder.iterdir() if f.name.endswith(".toml"))


def _read_config_source(source: str) -> tuple[str, bytes]:
    """``(label, TOML bytes)`` for a preset name (``smoke``) or a file path (``my.toml``)."""
    path = Path(source)
    if path.is_file():
        return source, path.read_bytes()
    name = source
    if source.endswith(".toml") and path.parent.name == "configs":
        name = path.name.removesuffix(".toml")  # `configs/smoke.toml`: the packaged preset
    if name in preset_names():  # packaged, so a non-editable install has the same defaults
        return f"preset {name!r}", resources.files("atrv_warp.rl").joinpath(f"configs/{name}.toml").read_bytes()
    raise FileNotFoundError(f"config {source!r} is neither a file nor a preset; presets: {preset_names()}")


def _file_config(source: str | None) -> TrainConfig:
    """The :class:`TrainConfig` defaults, then the preset or TOML file ``source``."""
    if source is None:
        return TrainConfig()
    label, text = _read_config_source(str(source))
    try:
        values = tomllib.loads(text.decode())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
        raise ValueError(f"{label}: not valid TOML: {err}") from None
    task = values.get("env", {}).get("task") if isinstance(values.get("env"), dict) else None
    fields = tuple((k, toml_text(v)) for k, v in task.items() if k != "name") if isinstance(task, dict) else ()
    return _with_task_fields(_tyro(_toml_args(values, label), None, f" in {label}").train, fields)


def load_train_config(source: str | None = None, overrides: dict | None = None) -> TrainConfig:
    """Read a TOML config, apply ``overrides`` (``{"lr": "1e-3"}`` or ``{"optim.lr": ...}``), check
    every key and value.

    ``source`` is a preset name (:func:`preset_names`: ``default``, ``nav``, ``smoke``), a file path
    (``configs/<preset>.toml`` that is not a file names the packaged preset), or ``None`` for the
    :class:`TrainConfig` defaults alone.
    """
    base = _file_config(source)
    rest, fields = _task_tokens([f"{k}={v}" for k, v in (overrides or {}).items()])
    return _with_task_fields(_tyro(cli_args(rest), TrainCommand(train=base)).train, fields).validate()


def parse_command(tokens: list[str]) -> TrainCommand:
    r"""The training command line: ``--config`` (or the ``--resume``\ d run's ``config.toml``), then
    every field given. ``ValueError`` or ``FileNotFoundError`` in one line on a bad one.

    A resumed run's ``config.toml`` is read as data: the task module it names is not imported, and the command line
    must name it (``env.task_module=``), the same file the run recorded (:func:`~atrv_warp.rl.run.check_resumed_task_module`)."""
    tokens, fields = _task_tokens(tokens)
    args = cli_args(tokens)
    first = _tyro([a for a in args if a not in ("-h", "--help")], None)  # which file to start from
    if first.resume:
        run_dir = Path(first.resume)
        if not (run_dir / "config.toml").is_file():
            raise FileNotFoundError(f"--resume: {run_dir / 'config.toml'} not found")
        saved = _file_config(str(run_dir / "config.toml"))
        # the run folder's task module is never imported: the command line names it (checked below)
        base = dataclasses.replace(saved, run=dataclasses.replace(saved.run, out_dir=str(run_dir.parent),
                                                                  name=run_dir.name),
                                   env=dataclasses.replace(saved.env, task_module=""))
    else:
        base = _file_config(first.config)
    cmd = _tyro(args, dataclasses.replace(first, train=base))
    cmd = dataclasses.replace(cmd, train=_with_task_fields(cmd.train, fields))
    if first.resume and saved.env.task_module:
        check_resumed_task_module(run_dir, saved.env.task_module, cmd.train.env.task_module)
    cmd.train.validate()
    return cmd
