"""What a new user waits for: install time in a fresh virtualenv, and Warp's cold kernel compile.

    python -m benchmarks.perf.fresh_install                 # pip's download cache as it is
    python -m benchmarks.perf.fresh_install --no-pip-cache  # downloads included (needs the network)

1. Creates a virtualenv in a temporary folder and times the README's install,
   ``pip install -e .`` (core dependencies only; ``--extras test,ros`` for the test command's).
2. Runs ``python -m atrv_warp.train --config smoke`` in it twice, with an empty Warp kernel
   cache (``WARP_CACHE_PATH`` in a temporary folder) and then with that cache warm. The
   difference is the one-off kernel compile a first run pays; the smoke preset builds every
   kernel the main command uses (simulation, task, evaluation).

Prints the figures and writes ``benchmarks/results/fresh_install.json``.
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks._common import write_results

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "benchmarks" / "results"


def _timed(cmd: list[str], **kwargs) -> float:
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False, **kwargs)
    elapsed = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({proc.returncode}):\n{proc.stdout[-2000:]}\n{proc.stderr[-2000:]}")
    return elapsed


def _tree_size(path: Path) -> int:
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file())


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--extras", default="", help="extras to install, e.g. test,ros (default: none, as the "
                                                     "README's main command)")
    parser.add_argument("--no-pip-cache", action="store_true", help="pip install --no-cache-dir (downloads included)")
    parser.add_argument("--out", default=str(RESULTS / "fresh_install.json"))
    args = parser.parse_args()

    with tempfile.TemporaryDirectory(prefix="atrv-fresh-") as tmp:
        tmp = Path(tmp)
        venv = tmp / "venv"
        t_venv = _timed([sys.executable, "-m", "venv", str(venv)])
        py = str(venv / "bin" / "python")
        target = f"{ROOT}[{args.extras}]" if args.extras else str(ROOT)
        pip = [py, "-m", "pip", "install", "-q", "--disable-pip-version-check", "-e", target]
        if args.no_pip_cache:
            pip.insert(4, "--no-cache-dir")
        print(f"pip install -e {target!r} into a fresh venv ...", flush=True)
        t_install = _timed(pip)
        site_size = _tree_size(venv)
        print(f"  {t_install:.0f} s, venv {site_size / 2**30:.2f} GiB", flush=True)

        env = {**os.environ, "WARP_CACHE_PATH": str(tmp / "warp-cache")}
        env.pop("ATRV_WARP_VERBOSE", None)
        runs = []
        for label in ("cold", "warm"):
            out_dir = tmp / f"runs-{label}"
            cmd = [py, "-m", "atrv_warp.train", "--config", "smoke", f"out_dir={out_dir}"]
            print(f"python -m atrv_warp.train --config smoke, {label} kernel cache ...", flush=True)
            runs.append(_timed(cmd, env=env, cwd=tmp))
            print(f"  {runs[-1]:.1f} s", flush=True)
        cache_size = _tree_size(tmp / "warp-cache")
        versions = subprocess.run([py, "-c", "import torch, warp; print(torch.__version__, warp.config.version)"],
                                  capture_output=True, text=True, check=True, env=env).stdout.split()
    result = {
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version(), "platform": platform.platform()},
        "pip_download_cache": "disabled" if args.no_pip_cache else "as found (reused)",
        "extras": args.extras,
        "venv_create_s": round(t_venv, 1),
        "pip_install_s": round(t_install, 1),
        "venv_gib": round(site_size / 2**30, 2),
        "smoke_train_cold_cache_s": round(runs[0], 1),
        "smoke_train_warm_cache_s": round(runs[1], 1),
        "cold_compile_s": round(runs[0] - runs[1], 1),
        "kernel_cache_mib": round(cache_size / 2**20, 1),
        "torch": versions[0],
        "warp": versions[1],
    }
    print(f"\ninstall: {t_install:.0f} s ({result['pip_download_cache']} pip cache), venv {site_size / 2**30:.2f} GiB")
    print(f"kernel compile on first run: {result['cold_compile_s']:.0f} s "
          f"(smoke run {runs[0]:.0f} s cold vs {runs[1]:.0f} s warm; cache {result['kernel_cache_mib']:.0f} MiB)")
    write_results(args.out, result, version=VERSION, dynamics=False)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
