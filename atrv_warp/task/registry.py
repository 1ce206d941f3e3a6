"""The registered tasks: the shipped ones (:mod:`atrv_warp.task.tasks`) and yours.

:func:`register_task` adds a :class:`~atrv_warp.task.definition.Task` under its name; :func:`load_task_module`
imports a Python file of yours that registers tasks (``--task-module my_task.py`` on the commands, ``task_module``
on the environment), so that training, evaluation and export find them by name. :func:`resolve_task` turns a name,
a :class:`~atrv_warp.task.config.TaskConfig` or a :class:`~atrv_warp.task.definition.Task` into a task.
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib.util
import sys
from pathlib import Path

from atrv_warp.task.config import TaskConfig
from atrv_warp.task.definition import Task
from atrv_warp.task.tasks import follow_path, nav, nav_deploy, reach

__all__ = ["TASKS", "TASK_VARIANTS", "get_task", "load_task_module", "register_task", "resolve_task", "task_names"]

TASKS: dict[str, Task] = {}
"""Every registered task, by name."""
TASK_VARIANTS: dict[str, TaskConfig] = {}
"""Every registered task's config, by name (an index of :data:`TASKS`)."""
_MODULES: dict[str, list[str]] = {}
"""The task modules loaded, by resolved path: the tasks each registered."""


def register_task(task: Task, *, replace: bool = False) -> Task:
    """Register ``task`` under its name; returns it.

    Raises:
        ValueError: A task of that name is registered already (unless ``replace``), or the name is not one.
    """
    if not isinstance(task, Task):
        raise TypeError(f"register_task takes an atrv_warp.task.definition.Task, got {type(task).__name__}")
    if not task.name.isidentifier():
        raise ValueError(f"task name {task.name!r} must be an identifier (letters, digits, _)")
    if task.name in TASKS and not replace and TASKS[task.name] is not task:
        raise ValueError(f"a task called {task.name!r} is registered already ({TASKS[task.name].source}); "
                         "name yours otherwise")
    TASKS[task.name] = task
    TASK_VARIANTS[task.name] = task.config
    return task


def _as_given(config, robot, footprint):
    """A task config given directly stays as given on every robot."""
    return config


def task_names() -> list[str]:
    """The registered tasks' names."""
    return sorted(TASKS)


def resolve_task(task: Task | TaskConfig | str | None) -> Task:
    """The task ``task`` names (``None``: ``reach``); a :class:`~atrv_warp.task.config.TaskConfig` is a task with the
    shipped reward table and success test (the reference's, weighted by its fields), used on any robot as it is.

    Raises:
        ValueError: An unknown name (the known ones listed; a task of your own needs its module loaded first).
    """
    if isinstance(task, Task):
        return task
    if isinstance(task, TaskConfig):  # the caller's config, as it is: not fitted to a robot
        return Task("custom", task, reach.TASK.terms, reach.TASK.success, scale=_as_given)
    name = "reach" if task is None else task
    try:
        return TASKS[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown task {name!r}; known: {task_names()} (a task of your own: load its module with "
                         "--task-module FILE.py, or import it before)") from None


def get_task(task) -> TaskConfig:
    """The config of the registered task called ``task`` (``None``: ``reach``), or ``task`` itself (a config)."""
    return task if isinstance(task, TaskConfig) else resolve_task(task).config


def load_task_module(path: str | Path) -> list[str]:
    """Import the Python file ``path``, which registers tasks with :func:`register_task` (once per file; again is a
    no-op); returns the names it registered.

    Raises:
        FileNotFoundError: No such file.
        ValueError: Not a ``.py`` file, or importing it failed (its error named, in one line): any exception,
            ``SystemExit`` and ``KeyboardInterrupt`` included (a module that exits ends no command but with this).
    """
    path = Path(path).resolve()
    if not path.is_file():
        raise FileNotFoundError(f"task module not found: {path}")
    if path.suffix != ".py":
        raise ValueError(f"task module {path}: not a Python file (.py)")
    if str(path) in _MODULES:
        return list(_MODULES[str(path)])
    name = f"atrv_warp_user_task_{hashlib.sha1(str(path).encode()).hexdigest()[:10]}"
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # Warp reads a kernel's source through its module
    before = dict(TASKS)
    try:
        spec.loader.exec_module(module)
    except BaseException as err:  # noqa: BLE001 - the user's module may fail or exit in any way; say how, in one line
        sys.modules.pop(name, None)
        raise ValueError(f"task module {path}: {type(err).__name__}: {' '.join(str(err).split())[:300]}") from None
    added = [n for n in TASKS if TASKS[n] is not before.get(n)]
    for n in added:
        if not TASKS[n].source:
            TASKS[n] = dataclasses.replace(TASKS[n], source=str(path))
    _MODULES[str(path)] = added
    return added


for _shipped in (reach, nav, nav_deploy, follow_path):
    register_task(_shipped.TASK)
