"""Console behaviour shared by every entry point: quiet by default, detail on request.

By default the package keeps the console to what a user needs:

- Warp's per-module ``Module … load on device 'cpu'`` lines and its init banner are hidden
  (``warp.config.log_level = LOG_WARNING``);
- the CUDA-driver warning that Warp's native library prints on a machine without a GPU is
  held back (the entry points say once which device simulates instead, :func:`device_summary`);
- TorchRL's INFO messages are hidden (``RL_LOGGING_LEVEL=WARNING`` unless you set it).

``ATRV_WARP_VERBOSE=1`` in the environment, or ``--verbose`` on a command (which calls
:func:`set_verbose`), brings all of it back, in worker processes too. Importing ``atrv_warp`` runs
:func:`configure_logging` (an environment variable, nothing imported); importing the simulator
(:mod:`atrv_warp.sim`) runs :func:`configure` once, before any module imports Newton (whose import
initialises Warp). So the package and its light core (:mod:`atrv_warp.core`) load without Warp.
"""

from __future__ import annotations

import os
import sys
import tempfile

__all__ = ["CORES_ENV", "TRAINER_CORE", "VERBOSE_ENV", "WORKER_CORE", "add_verbose_argument", "available_memory",
           "configure", "configure_logging", "device_summary", "enable_gradients",
           "error_line", "is_configured", "is_verbose", "pin_to_core", "run_cores", "set_verbose"]

VERBOSE_ENV = "ATRV_WARP_VERBOSE"
"""Environment variable: ``1`` (or ``true``/``yes``/``on``) shows library detail."""

CORES_ENV = "ATRV_WARP_CORES"
"""Environment variable: the cores a run may use, comma-separated (``0,1``). The run's first :func:`pin_to_core`
records them before it pins its own process to one, so that the worker processes started after it (which
inherit that one-core affinity) still pin themselves to the others."""

TRAINER_CORE = 0
"""The run's core (an index into :func:`run_cores`) the trainer pins itself to, where its collector has a worker."""
WORKER_CORE = 1
"""The run's core the ``async`` collector's worker and the background validation run on: the worker waits for
the learner most of the time, so the validation fits beside it."""

_held_back = ""  # what Warp's native init wrote to stderr while we were quiet


def is_verbose() -> bool:
    """Whether library detail is shown (``ATRV_WARP_VERBOSE``)."""
    return os.environ.get(VERBOSE_ENV, "").strip().lower() in ("1", "true", "yes", "on")


def _init_warp_quietly() -> str:
    """``wp.init()`` with file descriptor 2 redirected; returns what the native code printed."""
    import warp as wp

    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile(mode="w+b") as sink:
        os.dup2(sink.fileno(), 2)
        try:
            wp.init()
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        sink.seek(0)
        return sink.read().decode(errors="replace")


def configure_logging() -> None:
    """TorchRL's console level (``RL_LOGGING_LEVEL``, read when TorchRL is imported), unless you set it;
    imports nothing."""
    os.environ.setdefault("RL_LOGGING_LEVEL", "INFO" if is_verbose() else "WARNING")


_configured = False


def is_configured() -> bool:
    """Whether :func:`configure` has run in this process (Warp is initialised and quiet)."""
    return _configured


def configure() -> None:
    """Apply the console policy to Warp and TorchRL and initialise Warp; once per process (the simulator's
    package runs it on import), a no-op after."""
    global _held_back, _configured
    if _configured:
        return
    _configured = True
    import warp as wp

    verbose = is_verbose()
    configure_logging()
    wp.config.log_level = wp.LOG_INFO if verbose else wp.LOG_WARNING
    # kernels without their adjoints: a third of the compile, and only gradients need them (enable_gradients)
    wp.config.enable_backward = False
    if verbose:
        wp.init()
        return
    text = _init_warp_quietly()
    # keep anything but the driver notice: a real error from the native library must still show
    kept = [line for line in text.splitlines() if line and "Could not find or load the NVIDIA CUDA driver" not in line]
    _held_back += text
    if kept:
        print("\n".join(kept), file=sys.stderr)


def enable_gradients() -> None:
    """Compile Warp kernels with their adjoints from here on, those of the modules loaded already included (they
    compile again, once): what a simulator that is differentiated needs (``RoverSim(requires_grad=True)`` calls it).
    :func:`configure` leaves them out, which cuts a first compile to about a third."""
    import warp as wp

    if wp.config.enable_backward:
        return
    wp.config.enable_backward = True
    try:
        from warp._src.context import user_modules
    except ImportError:
        return
    for module in list(user_modules.values()):
        wp.set_module_options({"enable_backward": True}, module)


def set_verbose(verbose: bool = True) -> None:
    """Switch library detail on or off for this process and the workers it starts."""
    import logging

    import warp as wp

    global _held_back
    os.environ[VERBOSE_ENV] = "1" if verbose else "0"
    os.environ["RL_LOGGING_LEVEL"] = "INFO" if verbose else "WARNING"
    wp.config.log_level = wp.LOG_INFO if verbose else wp.LOG_WARNING
    level = logging.INFO if verbose else logging.WARNING
    for name in ("torchrl", "tensordict"):
        logger = logging.getLogger(name)
        logger.setLevel(level)
        for handler in logger.handlers:
            handler.setLevel(level)
    if verbose and _held_back:
        print(_held_back.rstrip(), file=sys.stderr)
        _held_back = ""


def device_summary(device: str | None = None) -> str:
    """One line naming the device that simulates, e.g. ``simulation on cpu (no CUDA device found)``."""
    configure()  # Warp initialised quietly, if the simulator has not been imported yet
    import warp as wp

    dev = wp.get_device(device)
    cuda = wp.get_cuda_device_count()
    if dev.is_cuda:
        return f"simulation on {dev.alias} ({dev.name}), Warp {wp.config.version}"
    extra = "no CUDA device found" if cuda == 0 else f"{cuda} CUDA device(s) available: pass device=cuda:0"
    return f"simulation on cpu ({extra}), Warp {wp.config.version}"


def available_memory(device: str = "cpu") -> int | None:
    """Bytes free for new allocations on ``device`` (``cpu``: the system's ``MemAvailable``; ``cuda:N``: the GPU's
    free memory), or None where the system does not say."""
    if str(device).startswith("cuda"):
        try:
            import torch

            return int(torch.cuda.mem_get_info(torch.device(str(device)))[0])
        except (RuntimeError, AssertionError, ValueError):
            return None
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def add_verbose_argument(parser) -> None:
    """``--verbose`` on an ``argparse`` command line (call :func:`set_verbose` when it is given)."""
    parser.add_argument("--verbose", action="store_true",
                        help=f"show library detail: Warp module loads, TorchRL INFO (same as {VERBOSE_ENV}=1)")


def error_line(prog: str, message: str) -> int:
    """Print ``prog: error: message`` as one line on stderr; returns the exit status 2."""
    print(f"{prog}: error: {' '.join(str(message).split())}", file=sys.stderr)
    return 2


def run_cores() -> list[int]:
    """The cores this run may use: :data:`CORES_ENV` where set (by the run's first pin, inherited by its workers),
    else those this process may run on now."""
    recorded = os.environ.get(CORES_ENV, "").strip()
    if not recorded:
        return sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else list(range(os.cpu_count() or 1))
    try:
        cores = sorted({int(c) for c in recorded.split(",")})
    except ValueError:
        raise ValueError(f"{CORES_ENV}={recorded!r}: expected core numbers separated by commas, e.g. 0,1") from None
    return cores


def pin_to_core(index: int, pid: int = 0) -> None:
    """Pin this process (or process ``pid``, one this process started) to the ``index``-th of :func:`run_cores`
    (modulo their number); the first pin records the run's cores in :data:`CORES_ENV` for the processes started
    after it. Does nothing where the OS has no affinity call."""
    if not hasattr(os, "sched_setaffinity"):
        return
    cores = run_cores()
    os.environ.setdefault(CORES_ENV, ",".join(map(str, cores)))
    os.sched_setaffinity(pid, {cores[index % len(cores)]})
