"""The inline placeholders' values: ``{{ result FILE:KEY | FORMAT }}`` and ``{{ verdict FILE:KEY OP BOUND | YES | NO }}``
(``docs/hooks.py`` documents them and renders the pages)."""

from __future__ import annotations

import operator
import re
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # the benchmarks package

from benchmarks._common import FigureError, load_results

COMPARISONS = {">=": operator.ge, ">": operator.gt, "<=": operator.le, "<": operator.lt}


def lookup(d: object, key: str, *, name: str = "") -> object:
    """``d``'s value at ``key`` (dots between keys and indices, ``[field=value]`` selectors; a key that itself holds
    dots, ``mujoco µ 0.8``, is matched whole)."""
    value = d
    tokens = re.findall(r"\[([^\]]*)\]|([^.\[\]]+)", key)
    i = -1
    while i + 1 < len(tokens):
        i += 1
        select, part = tokens[i]
        where = f"{name}:{key}"
        if part and isinstance(value, dict) and part not in value:  # a key with dots in it ("mujoco µ 0.8")
            for j in range(i + 1, len(tokens)):
                if tokens[j][0]:
                    break
                joined = ".".join(t[1] for t in tokens[i:j + 1])
                if joined in value:
                    part, i = joined, j
                    break
        if select:
            wants = [c.partition("=")[::2] for c in select.split(",")]
            found = [e for e in value if isinstance(e, dict) and all(str(e.get(f)) == w for f, w in wants)] \
                if isinstance(value, list) else []
            if not found:
                raise FigureError(f"results file {name} has no key {key!r}: no element with {select} ({where})")
            value = found[0]
        elif isinstance(value, dict) and part in value:
            value = value[part]
        elif isinstance(value, list) and part.lstrip("-").isdigit() and -len(value) <= int(part) < len(value):
            value = value[int(part)]
        else:
            raise FigureError(f"results file {name} has no key {key!r} (missing {part!r}, part {i + 1})")
    return value


def result(name: str, key: str, fmt: str = "") -> str:
    """The value at ``key`` in results file ``name``, formatted with ``fmt``."""
    value = lookup(load_results(name), key, name=name)
    try:
        if fmt.endswith("%"):  # the house style: "91.3 %", a space before the sign
            return format(100 * value, fmt[:-1] + "f") + " %"
        return format(value, fmt)
    except (TypeError, ValueError) as err:
        raise FigureError(f"results file {name}, key {key!r}: cannot format {value!r} as {fmt!r}") from err


def verdict(name: str, key: str, op: str, bound: float, yes: str, no: str) -> str:
    """``yes`` where the value at ``key`` in results file ``name`` compares with ``bound`` as ``op`` says, else
    ``no``."""
    value = lookup(load_results(name), key, name=name)
    if not isinstance(value, int | float) or isinstance(value, bool):
        raise FigureError(f"results file {name}, key {key!r}: a verdict needs a number, got {value!r}")
    return yes if COMPARISONS[op](value, bound) else no
