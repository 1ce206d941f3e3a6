"""The first run on a machine compiles the simulator's Warp kernels; :func:`precompile` does it up front, in
parallel, and says so.

Warp compiles a module the first time one of its kernels is launched on a device, and caches the binary
(``warp.config.kernel_cache_dir``), so later runs load it in a fraction of a second. Left to itself, the first
step of a new simulator compiles the modules one after another, in silence. :func:`precompile` instead loads the
modules a step uses (:data:`STEP_MODULES`) on a pool of threads before the model is built, and where that takes
longer than :data:`QUIET_S` prints one line saying that it compiles, for which device and about how long it takes,
then a progress line every :data:`PROGRESS_S`; a warm cache prints nothing. A module not in the list still compiles
when it is first launched, as before: the list only decides what is done ahead and in parallel.

Kernels are compiled without their adjoints (``warp.config.enable_backward = False``, set by
:func:`atrv_warp.runtime.configure`): only :class:`~atrv_warp.sim.diff.DiffRollout` differentiates, and a
simulator built with ``requires_grad=True`` switches the adjoints on first (:func:`atrv_warp.runtime.enable_gradients`).
"""

from __future__ import annotations

import os
import sys
import time
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait

import warp as wp

__all__ = ["PROGRESS_S", "QUIET_S", "STEP_MODULES", "precompile", "step_modules"]

STEP_MODULES = (
    "atrv_warp.",
    "newton._src.geometry.bvh",
    "newton._src.sim.articulation",
    "newton._src.solvers.featherstone.kernels",
    # modules of one kernel each, named by the kernel and a hash
    "friction_kernels__locals__",  # the friction solve of each wheel count (the four-wheel default defined at import)
    "compute_body_inverses_kernel_",
    "create_inertia_matrix_kernel_",
    "validate_and_correct_inertia_kernel_",
)
"""Name prefixes of the Warp modules that building a simulator and stepping a task's environment launch kernels
of (``tests/test_kernel_cache.py`` checks the list against what a step loads). A task's own reward-term and end
kernels (``make_term_kernel``, ``make_ends_kernel``: small, one per term) compile at their first launch."""

QUIET_S = 2.0
"""Loading from a warm cache takes less than this [s]; longer, and :func:`precompile` says that it compiles."""
PROGRESS_S = 10.0
"""Seconds between progress lines while compiling."""

FIRST_COMPILE = {"cpu": "about 20 s on 2 cores", "cuda": "a minute or more"}
"""Roughly how long the first compile takes, by device kind (``benchmarks/perf/gpu_check.py`` measures the GPU's)."""

_done: set[tuple[str, str]] = set()


def _user_modules() -> dict:
    try:
        from warp._src.context import user_modules
    except ImportError:  # another Warp: its modules then compile on first launch, as Warp does by itself
        return {}
    return user_modules


def step_modules() -> list[str]:
    """The names of the Warp modules imported so far that :data:`STEP_MODULES` names, that hold a kernel, and whose
    code is known before a launch (one with ``wp.static`` expressions left to resolve compiles at its first launch:
    compiled ahead, it would be a variant no launch uses)."""
    return sorted(name for name, module in _user_modules().items()
                  if name.startswith(STEP_MODULES) and getattr(module, "kernels", True)
                  and not getattr(module, "has_unresolved_static_expressions", False))


def precompile(device: str | wp.context.Device | None = None, *, out=None) -> float:
    """Compile (or load from the cache) every module :func:`step_modules` names for ``device``, on a pool of
    threads, once per process; returns the seconds it took. Quiet unless it takes longer than :data:`QUIET_S`
    (``out``: where the lines go, ``sys.stdout`` by default)."""
    device = wp.get_device(device)
    modules = _user_modules()
    todo = [name for name in step_modules() if (name, device.alias) not in _done]
    if not todo:
        return 0.0
    out = out or sys.stdout
    workers = max(1, min(len(todo), len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity")
                         else os.cpu_count() or 1))
    t0 = time.perf_counter()
    announced, next_line, done = False, t0 + QUIET_S, 0
    with ThreadPoolExecutor(max_workers=workers, thread_name_prefix="warp-compile") as pool:
        pending = {pool.submit(wp.force_load, device, [modules[name]], max_workers=0) for name in todo}
        while pending:
            finished, pending = wait(pending, timeout=max(0.0, next_line - time.perf_counter()),
                                     return_when=FIRST_COMPLETED)
            for future in finished:
                future.result()  # a compile error raises here, as it would at the first launch
                done += 1
            now = time.perf_counter()
            if pending and now >= next_line:
                if not announced:
                    kind = "cuda" if device.is_cuda else "cpu"
                    print(f"compiling the simulator's Warp kernels for {device.alias} ({len(todo)} modules, {workers} "
                          f"at a time; the first run on a machine takes {FIRST_COMPILE[kind]}, later runs load them "
                          f"from {wp.config.kernel_cache_dir})", file=out, flush=True)
                    announced = True
                else:
                    print(f"  {done} of {len(todo)} modules compiled, {now - t0:.0f} s", file=out, flush=True)
                next_line = now + PROGRESS_S
    seconds = time.perf_counter() - t0
    if announced:
        print(f"  compiled in {seconds:.0f} s", file=out, flush=True)
    _done.update((name, device.alias) for name in todo)
    return seconds
