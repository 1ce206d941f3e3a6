"""Kernels made from a task's declaration: its ends (with its success test), one per reward term, one per field of
an observation kind of its own. Each is made once per function and place (cached), so that environments of one task
share their compiled kernels.
"""

from __future__ import annotations

from typing import Any

import warp as wp

from atrv_warp.task.definition import PHASES
from atrv_warp.task.kernels.state import TermInputs
from atrv_warp.task.kernels.steps import make_ends_kernel, make_term_kernel

__all__ = ["ends_kernel", "field_kernel", "term_kernels"]

_ENDS: dict[object, wp.Kernel] = {}
_TERMS: dict[tuple[object, int, int], wp.Kernel] = {}
_FIELDS: dict[tuple[object, int, float, float], wp.Kernel] = {}


def ends_kernel(success) -> wp.Kernel:
    """The ends kernel of a success test (:func:`~atrv_warp.task.kernels.steps.make_ends_kernel`)."""
    if success not in _ENDS:
        _ENDS[success] = make_ends_kernel(success)
    return _ENDS[success]


def term_kernels(task) -> list[tuple[wp.Kernel, float]]:
    """Each reward term of ``task`` (a :class:`~atrv_warp.task.definition.Task`) with a weight, as (its kernel, its
    weight); a term weighted 0 is skipped (its column stays 0: 0 x inf would be NaN)."""
    out = []
    for column, term in enumerate(task.terms):
        weight = term.weight_of(task.config)
        if weight == 0.0:
            continue
        key = (term.warp, column, PHASES[term.when])
        if key not in _TERMS:
            _TERMS[key] = make_term_kernel(term.warp, column, PHASES[term.when])
        out.append((_TERMS[key], weight))
    return out


def field_kernel(value, column: int, low: float, high: float) -> wp.Kernel:
    """The kernel of one observation field of a task's own kind: ``value(params, inputs, world)`` clipped to
    [``low``, ``high``] into ``column`` (0 in a blown-up world)."""
    key = (value, column, low, high)
    if key in _FIELDS:
        return _FIELDS[key]

    @wp.kernel(module="unique")
    def write_field(params: Any, inputs: TermInputs, obs: wp.array2d(dtype=float)):
        world = wp.tid()
        v = float(0.0)
        if inputs.rover.nonfinite[world] == 0:
            v = wp.clamp(value(params, inputs, world), low, high)
        obs[world, column] = v

    _FIELDS[key] = write_field
    return write_field
