"""The command-line tools' table, drawn from their own parsers at docs build time (``{{ command_table }}``,
``{{ command_table TOOL }}`` in a page; ``docs/hooks.py`` renders it)."""

from __future__ import annotations

import itertools
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # the benchmarks package

from benchmarks._common import markdown_cell as _cell
from benchmarks._common import markdown_table

COMMANDS = (("train", "atrv-train"), ("evaluate", "atrv-evaluate"), ("demo", "atrv-demo"), ("model", "atrv-model"),
            ("export", "atrv-export"), ("calibrate", "atrv-calibrate"), ("ros", "atrv-ros"), ("deploy", "atrv-deploy"),
            ("robot", "atrv-robot"))
"""(``atrv_warp.<module>``, the command ``pyproject.toml`` installs) of every command-line tool."""
COMMANDS_LINE = re.compile(r"^\{\{ command_table( \w+)? \}\}$", re.MULTILINE)


def _argparse_rows(parser) -> list[list[str]]:
    import argparse

    rows = []
    for action in parser._actions:  # noqa: SLF001 - argparse keeps its arguments here and nowhere public
        if isinstance(action, argparse._HelpAction):  # noqa: SLF001
            continue
        if isinstance(action, argparse._SubParsersAction):  # noqa: SLF001 - a tool of subcommands: each one's rows
            helps = {a.dest: a.help for a in action._choices_actions}  # noqa: SLF001
            for name, sub in action.choices.items():
                rows.append([f"`{name}`", "", _cell(helps.get(name) or "")])
                rows += [[f"`{name}` {row[0]}", *row[1:]] for row in _argparse_rows(sub)]
            continue
        value = "" if action.nargs == 0 else " " + (action.metavar or action.dest.upper())
        name = ", ".join(f"`{o}{value}`" for o in action.option_strings) or f"`{action.metavar or action.dest}`"
        default = "" if action.default in (None, False, argparse.SUPPRESS) else f"`{action.default}`"
        text = (action.help or "").replace("%(default)s", str(action.default))
        rows.append([name, default, _cell(text)])
    return rows


def _train_rows() -> list[list[str]]:
    import dataclasses
    import typing

    from atrv_warp.rl.command_line import TrainCommand
    from atrv_warp.rl.config import TrainConfig

    rows = []
    docs = _attribute_docs(TrainCommand)
    for f in dataclasses.fields(TrainCommand):
        if f.name == "train":
            continue
        default = f.default if f.default is not dataclasses.MISSING else ""
        rows.append([f"`--{f.name}`", f"`{default}`" if default not in (None, False, "") else "", _cell(docs.get(f.name, ""))])
    groups = [f.name for f in dataclasses.fields(TrainConfig)]
    hints = typing.get_type_hints(TrainConfig)
    rows.append(["`FIELD=VALUE`, `--GROUP.FIELD VALUE`", "",
                 (f"any field of the configuration's groups ({', '.join(f'`{g}`' for g in groups if g in hints)}); "
                  "`--help` lists every field with its documentation")])
    return rows


def _attribute_docs(cls) -> dict[str, str]:
    """The docstrings written under a dataclass's fields."""
    import ast
    import inspect
    import textwrap

    tree = ast.parse(textwrap.dedent(inspect.getsource(cls)))
    body, docs = tree.body[0].body, {}
    for a, b in itertools.pairwise(body):
        if isinstance(a, ast.AnnAssign) and isinstance(b, ast.Expr) and isinstance(b.value, ast.Constant):
            docs[a.target.id] = str(b.value.value)
    return docs


def _ros_rows() -> list[list[str]]:
    from atrv_warp.integrations.ros.parameters import PARAMETERS

    return [[f"`-p {p.name}:=…`", f"`{p.default!r}`", _cell(p.text)] for p in PARAMETERS]


def _deploy_rows() -> list[list[str]]:
    from atrv_warp.deploy.parameters import PARAMETERS

    return (_argparse_rows(_command("deploy").build_parser())
            + [[f"`-p {p.name}:=…`", f"`{p.default!r}`", _cell(p.text)] for p in PARAMETERS])


def _module_name(module: str) -> str:
    """Where a command's code is: ``atrv_warp.cli.<module>`` (``atrv_warp.<module>`` re-exports it), else
    ``atrv_warp.<module>``."""
    return f"atrv_warp.cli.{module}" if (ROOT / "atrv_warp" / "cli" / f"{module}.py").is_file() else f"atrv_warp.{module}"


def _command(module: str):
    import importlib

    return importlib.import_module(_module_name(module))


def command_summary(module: str) -> str:
    """A command's one-line description, from its parser (or, for train and ros, its module docstring)."""
    if module in ("train", "ros"):  # their docstrings, read without importing torchrl or ROS
        import ast

        text = ast.get_docstring(ast.parse((ROOT / (_module_name(module).replace(".", "/") + ".py")).read_text()))
    else:
        text = _command(module).build_parser().description
    return _cell(text.split("\n")[0].split(": ``")[0].rstrip(".") + ".")


def command_options(module: str) -> list[list[str]]:
    """A command's arguments: name, default, help."""
    if module == "train":
        return _train_rows()
    if module == "ros":
        return _ros_rows()
    if module == "deploy":
        return _deploy_rows()
    return _argparse_rows(_command(module).build_parser())


def command_table(which: str | None = None) -> str:
    """The overview of every command, or one command's options (``which``), from the parsers themselves."""
    if which is None:
        return markdown_table(["command", "installed as", "what it does"], ["---", "---", "---"],
                              [[f"[`python -m atrv_warp.{m}`](#{m})", f"`{script}`", command_summary(m)] for m, script in COMMANDS]
                              + [["`python -m atrv_warp.evaluate --baseline`", "`atrv-baseline`", "the scripted driver's evaluation"]])
    return markdown_table(["argument", "default", "meaning"], ["---", "---", "---"], command_options(which))
