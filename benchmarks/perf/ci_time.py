"""Where CI's time goes: ``.ci/run`` end to end on a clean clone of each revision, one after the other, on this host.

    python -m benchmarks.perf.ci_time b2f1452 HEAD        # two revisions, in that order (the 2-core CI box: ~70 + ~40 min)
    python -m benchmarks.perf.ci_time HEAD --logs /tmp/ci  # keep each run's whole log there
    python -m benchmarks.perf.ci_time HEAD --append        # after the runs already in the results file

For each revision, in turn: ``git clone`` this repository into a temporary folder, check the revision out, and run
``bash .ci/run`` there as CI does (``CI=true``, its own fresh virtualenvs and empty Warp kernel cache; pip's download
cache is reused), with ``PYTEST_ADDOPTS`` adding ``--durations=30`` (older revisions do not print them) and JUnit
reports (one per tier in ``CI_JUNIT_DIR`` where ``.ci/run`` runs the tiers apart). The script timestamps every line of
the output as it arrives, so a phase's seconds (Chromium, each install, ruff, the docs, each pytest tier, the main
command) are the time from its ``== NAME`` header to the next, the same rule for every revision whatever its
``.ci/run`` prints itself. From the JUnit report it keeps each test file's total and the test
functions that ran (their parameters folded), so a later revision can show that nothing was dropped.

Measure on an idle machine: two busy processes on two cores slow each other several times over. The figures do not
depend on the dynamics (only on the code and the host), so the results file records no dynamics fingerprint.

Prints each phase as it ends and writes ``benchmarks/results/ci_time.json``.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import re
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

from benchmarks._common import load_results, markdown_table, write_results

VERSION = 1
"""This script's method, bumped by hand when what it measures or how changes (``_common.write_results``)."""

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "benchmarks" / "results"
HEADER = re.compile(r"^== (?P<name>.+?) \(\d\d:\d\d:\d\d\)\s*$")
"""A phase's first line in ``.ci/run``'s output: ``== NAME (HH:MM:SS)``."""
DURATION = re.compile(r"^\s*(?P<s>[\d.]+)s (?P<when>call|setup|teardown)\s+(?P<test>\S+)")
SUMMARY = re.compile(r"^=+ (?P<counts>.*\d+ (passed|failed).*) in (?P<s>[\d.]+)s")


def _git(*args: str, cwd: Path = ROOT) -> str:
    return subprocess.run(["git", *args], cwd=cwd, capture_output=True, text=True, check=True).stdout.strip()


def phases(lines: list[tuple[float, str]], end: float) -> list[dict]:
    """Each ``== NAME`` phase of a timestamped log (seconds since the start, line) and its seconds, to ``end``."""
    heads = [(t, m["name"]) for t, line in lines if (m := HEADER.match(line))]
    return [{"phase": name, "seconds": round((heads[i + 1][0] if i + 1 < len(heads) else end) - t, 1)}
            for i, (t, name) in enumerate(heads)]


def slowest(lines: list[str], count: int = 30) -> list[dict]:
    """pytest's ``--durations`` rows (seconds, call/setup/teardown, test id) of every pytest run, the ``count``
    slowest first."""
    rows = [m for line in lines if (m := DURATION.match(line))]
    rows = [{"seconds": float(m["s"]), "when": m["when"], "test": m["test"]} for m in rows]
    return sorted(rows, key=lambda r: -r["seconds"])[:count]


def pytest_summary(lines: list[str]) -> tuple[str, float] | None:
    """The closing counts of every pytest run in the log, added up (``616 passed, 10 skipped``), and their seconds."""
    found = [m for line in lines if (m := SUMMARY.match(line))]
    if not found:
        return None
    counts: dict[str, int] = {}
    for m in found:
        for n, kind in re.findall(r"(\d+) (\w+)", m["counts"]):
            counts[kind] = counts.get(kind, 0) + int(n)
    return ", ".join(f"{n} {kind}" for kind, n in counts.items()), sum(float(m["s"]) for m in found)


def junit(paths: list[Path]) -> dict:
    """From JUnit reports (one per pytest run): items run, the test functions (module::name, parameters folded),
    seconds per file."""
    cases = [case for path in paths if path.is_file() for case in ET.parse(path).getroot().iter("testcase")]
    items, functions, files = 0, set(), {}
    for case in cases:
        items += 1
        module = case.get("classname", "").replace(".", "/")
        file = module.split("/")[0] + "/" + module.split("/")[1] + ".py" if "/" in module else module
        functions.add(f"{case.get('classname')}::{case.get('name', '').split('[')[0]}")
        files[file] = files.get(file, 0.0) + float(case.get("time") or 0.0)
    by_time = sorted(files.items(), key=lambda kv: -kv[1])
    return {"items": items, "functions": sorted(functions),
            "files": [{"file": f, "seconds": round(s, 1)} for f, s in by_time]}


def run_ci(revision: str, tmp: Path, logs: Path | None) -> dict:
    """``.ci/run`` on a clean clone of ``revision``: its phases, pytest's summary and slowest tests, the JUnit data."""
    sha = _git("rev-parse", revision)
    repo = tmp / f"repo-{sha[:8]}"
    subprocess.run(["git", "clone", "-q", str(ROOT), str(repo)], check=True)
    _git("checkout", "-q", sha, cwd=repo)
    # A .ci/run that reads CI_JUNIT_DIR writes one report per tier there; an older one gets its report through
    # PYTEST_ADDOPTS (which the tests' own nested pytest runs would inherit, and write over, in a newer one)
    reports = tmp / f"junit-{sha[:8]}"
    reports.mkdir()
    tiered = "CI_JUNIT_DIR" in _git("show", f"{sha}:.ci/run")
    addopts = "--durations=30" + ("" if tiered else f" --junitxml={reports / 'pytest.xml'}")
    env = {**os.environ, "CI": "true", "PYTEST_ADDOPTS": addopts, "CI_JUNIT_DIR": str(reports)}
    print(f"\n{revision} ({sha[:8]}): bash .ci/run", flush=True)
    started = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
    t0 = time.monotonic()
    lines: list[tuple[float, str]] = []
    with subprocess.Popen(["bash", ".ci/run"], cwd=repo, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                          text=True, errors="replace", stdin=subprocess.DEVNULL) as proc:
        for line in proc.stdout:
            lines.append((time.monotonic() - t0, line.rstrip("\n")))
            if HEADER.match(line):
                print(f"  {lines[-1][0]:7.0f} s  {line.strip()}", flush=True)
    total = time.monotonic() - t0
    if logs is not None:
        logs.mkdir(parents=True, exist_ok=True)
        (logs / f"ci-{sha[:8]}.log").write_text("".join(f"{t:8.1f} {line}\n" for t, line in lines))
    text = [line for _, line in lines]
    summary = pytest_summary(text)
    print(f"  {total:7.0f} s  exit {proc.returncode}: {summary[0] if summary else 'no pytest summary'}")
    return {"revision": revision, "commit": sha, "started": started, "exit_code": proc.returncode, "total_s": round(total, 1),
            "phases": phases(lines, total), "pytest_summary": summary[0] if summary else None,
            "pytest_s": round(summary[1], 2) if summary else None, "slowest": slowest(text),
            **junit(sorted(reports.glob("*.xml")))}


def _cpu_model() -> str:
    """The processor's name and its widest vector extension (the host the figures hold for)."""
    try:
        info = Path("/proc/cpuinfo").read_text()
    except OSError:
        return "unknown"
    name = next((line.split(":", 1)[1].strip() for line in info.splitlines() if line.startswith("model name")), "?")
    flags = next((line.split(":", 1)[1].split() for line in info.splitlines() if line.startswith("flags")), [])
    return f"{name}, {'avx512f' if 'avx512f' in flags else 'avx2' if 'avx2' in flags else 'no avx2'}"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("revisions", nargs="+", help="revisions to run, in this order (e.g. the old main, then HEAD)")
    parser.add_argument("--logs", type=Path, default=None, help="a folder to keep each run's timestamped log in")
    parser.add_argument("--append", action="store_true", help="keep the runs already in --out and add these after them "
                                                                "(the same host, one after the other)")
    parser.add_argument("--out", default=str(RESULTS / "ci_time.json"))
    args = parser.parse_args()
    runs = json.loads(Path(args.out).read_text())["runs"] if args.append else []
    with tempfile.TemporaryDirectory(prefix="atrv-ci-time-") as tmp:
        runs += [run_ci(rev, Path(tmp), args.logs) for rev in args.revisions]
    first, last = runs[0], runs[-1]
    dropped = sorted(set(first["functions"]) - set(last["functions"]))
    result = {"machine": {"cpus": os.cpu_count(), "platform": sys.platform, "cpu": _cpu_model()}, "runs": runs,
              "dropped_functions": dropped, "added_functions": sorted(set(last["functions"]) - set(first["functions"]))}
    for run in runs:
        print(f"{run['revision']}: {run['total_s']:.0f} s, {run['items']} items, {len(run['functions'])} functions")
    if len(runs) > 1:
        print(f"{last['total_s'] / first['total_s']:.0%} of {first['revision']}'s time; "
              f"functions run before and not now: {dropped or 'none'}")
    write_results(args.out, result, version=VERSION, dynamics=False)
    print(f"wrote {args.out}")
    return 0 if all(run["exit_code"] == 0 for run in runs) else 1


# --- the tables the docs draw ---------------------------------------------------------------------------------------

def ci_phases() -> str:
    """Each phase's seconds for every revision measured, and the last against the first."""
    runs = load_results("ci_time.json")["runs"]
    names = list(dict.fromkeys(p["phase"] for run in runs for p in run["phases"]))
    seconds = [{p["phase"]: p["seconds"] for p in run["phases"]} for run in runs]
    rows = [[name, *(f"{s[name]:.0f}" if name in s else "—" for s in seconds)] for name in names]
    tests = [_pytest_s(run) for run in runs]
    rows.append(["*pytest, every tier*", *(f"{t:.0f}" if t is not None else "—" for t in tests)])
    upto = [_through_pytest(run) for run in runs]
    rows.append(["*through pytest*", *(f"{u:.0f}" if u is not None else "—" for u in upto)])
    rows.append(["**all of `.ci/run`**", *(f"**{run['total_s']:.0f}**" if run["exit_code"] == 0 else
                                           f"{run['total_s']:.0f} (stopped after {run['phases'][-1]['phase']})"
                                           for run in runs)])
    rows.append(["tests run (items / functions; failed)", *(f"{run['items']} / {len(run['functions'])}; "
                                                              f"{_failed(run)}" for run in runs)])
    header = ["phase (seconds)", *(f"`{run['commit'][:7]}`" for run in runs)]
    if len(runs) > 1:
        header.append("last / first")
        for row, name in zip(rows, names, strict=False):
            a, b = seconds[0].get(name), seconds[-1].get(name)
            row.append(f"{b / a:.2f}" if a and b is not None else "")
        rows[-4].append(f"{tests[-1] / tests[0]:.2f}" if tests[0] and tests[-1] else "")
        rows[-3].append(f"{upto[-1] / upto[0]:.2f}" if upto[0] and upto[-1] else "")
        whole = runs[0]["exit_code"] == 0 and runs[-1]["exit_code"] == 0  # else the totals cover other phases
        rows[-2].append(f"**{runs[-1]['total_s'] / runs[0]['total_s']:.2f}**" if whole else "")
        rows[-1].append("")
    return markdown_table(header, ["---", *["---:"] * (len(header) - 1)], rows)


def _pytest_phases(run: dict) -> list[int]:
    """The indices of a run's pytest phases (``pytest``, or one per tier)."""
    return [i for i, p in enumerate(run["phases"]) if p["phase"].startswith("pytest")]


def _pytest_s(run: dict) -> float | None:
    """The seconds of a run's pytest phases together."""
    found = _pytest_phases(run)
    return sum(run["phases"][i]["seconds"] for i in found) if found else None


def _through_pytest(run: dict) -> float | None:
    """The seconds up to pytest's end: the phases every run reaches (one whose tests fail stops there)."""
    found = _pytest_phases(run)
    return sum(p["seconds"] for p in run["phases"][:found[-1] + 1]) if found else None


def _failed(run: dict) -> str:
    found = re.search(r"(\d+) failed", run.get("pytest_summary") or "")
    return found.group(1) if found else "0"


def ci_slowest() -> str:
    """The 30 slowest test phases of the last revision measured (pytest's ``--durations=30``)."""
    run = load_results("ci_time.json")["runs"][-1]
    rows = [[f"{r['seconds']:.1f}", r["when"], f"`{r['test']}`"] for r in run["slowest"]]
    return markdown_table(["seconds", "phase", "test"], ["---:", "---", "---"], rows)


TABLES = {"ci_phases": ci_phases, "ci_slowest": ci_slowest}


if __name__ == "__main__":
    sys.exit(main())
