"""mkdocs hook: figures drawn from the results files at build time, and checked against the code.

A measured figure lives in its results file alone (``benchmarks/results/*.json``, written by
``benchmarks/_common.write_results`` with its provenance). A page cites it in one of two ways:

- ``{{ results_table NAME }}`` on a line of its own: :data:`TABLES` maps ``NAME`` to the function
  that reads the file(s) and returns the Markdown table;
- ``{{ result FILE:KEY.PATH | FORMAT }}`` inline: one value. ``FILE`` is relative to
  ``benchmarks/results/`` (or to the repository when it starts with ``docs/`` or ``benchmarks/``);
  ``KEY.PATH`` is dict keys and list indices joined by dots, and ``[field=value,other=value]`` picks the first
  list element with those fields; ``FORMAT`` is a Python format spec (``.1f``, ``,.0f``),
  optional; ``.1%`` gives a percentage as the pages write it (``91.3 %``);
- ``{{ verdict FILE:KEY.PATH OP BOUND | WHEN TRUE | WHEN FALSE }}`` inline: a page's verdict on one value (``OP``
  one of ``>=``, ``>``, ``<=``, ``<``), so that "past the target" cannot outlive the figure it judges: it renders
  the first text where the value at ``KEY.PATH`` compares so with ``BOUND``, the second where it does not.

Every file a page cites is checked against the code as it is now (:func:`status`): the benchmark
script's ``VERSION``, the dynamics fingerprint (``atrv_warp.sim.checks.dynamics_fingerprint``) and, for
figures that ran an environment, the task fingerprint (``atrv_warp.task.evaluation.task_fingerprint``),
each recomputed once per build, and the sha256 of each policy file it ran. A file that no longer matches,
or that records no provenance (written before it was recorded), fails the build unless the page marks
it historical with a line ``{{ historical FILE }}``, which renders as a note with the file's date and
the command that redraws it. A missing file or key, an unknown table, or a historical mark for a file
the page does not cite or whose figures are current fails the build too, naming the page, the file and
the key.

A line ``{{ command_table }}`` (or ``{{ command_table TOOL }}``) renders the command-line tools' table
(or one tool's arguments) from their own parsers (:func:`command_table`).

``python docs/hooks.py --stale`` lists every stale or unknown figure of every page, and the
benchmark that redraws it; it exits 1 if one is not marked historical.
"""

from __future__ import annotations

import functools
import hashlib
import itertools
import json
import math
import operator
import re
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
RESULTS = ROOT / "benchmarks" / "results"
BENCHMARKS = ROOT / "benchmarks"
PLACEHOLDER = re.compile(r"^\{\{ results_table (\w+) \}\}$", re.MULTILINE)
RESULT = re.compile(r"\{\{ result (?P<file>[\w./-]+\.json):(?P<key>[^|}]+?)(?: \| (?P<fmt>[^}]*?))? \}\}")
VERDICT = re.compile(r"\{\{ verdict (?P<file>[\w./-]+\.json):(?P<key>[^|}]+?) (?P<op>>=|<=|>|<) (?P<bound>[-+\d.e]+) "
                     r"\| (?P<yes>[^|}]*?) \| (?P<no>[^|}]*?) \}\}")
COMPARISONS = {">=": operator.ge, ">": operator.gt, "<=": operator.le, "<": operator.lt}
HISTORICAL = re.compile(r"^\{\{ historical (?P<file>[\w./-]+\.json) \}\}$", re.MULTILINE)
VERSION_LINE = re.compile(r"^VERSION = (\d+)$", re.MULTILINE)


class FigureError(Exception):
    """A page cites a figure that cannot be drawn (a missing file or key) or is stale."""


def results_path(name: str) -> Path:
    """A cited file's path: under ``benchmarks/results/``, or the repository's for ``docs/...``, ``benchmarks/...``."""
    return ROOT / name if name.startswith(("docs/", "benchmarks/")) else RESULTS / name


_cited: list[str] | None = None
"""While a page renders, the files its tables and values read (:func:`render`)."""


def _load(name: str) -> dict:
    if _cited is not None and name not in _cited:
        _cited.append(name)
    path = results_path(name)
    if not path.is_file():
        raise FigureError(f"results file {name} not found ({path})")
    return json.loads(path.read_text())


# --- provenance ---------------------------------------------------------------------------------

@functools.cache
def current_driver() -> str:
    """The motor driver's fingerprint of the code as it is now (computed once per process)."""
    from atrv_warp.sim.checks import driver_fingerprint

    return driver_fingerprint()


@functools.cache
def current_dynamics() -> str:
    """The dynamics fingerprint of the code as it is now (computed once per process: a 2-s rollout)."""
    from atrv_warp.sim.checks import dynamics_fingerprint

    return dynamics_fingerprint()


@functools.cache
def current_task() -> str:
    """The task fingerprint of the code as it is now (computed once per process: short rollouts of both tasks)."""
    from atrv_warp.task.evaluation import task_fingerprint

    return task_fingerprint()


def script_version(script: str) -> int | None:
    """``VERSION`` of a benchmark script as it is now, read from its text (no import)."""
    path = ROOT / script
    m = VERSION_LINE.search(path.read_text()) if path.is_file() else None
    return int(m.group(1)) if m else None


def redraw_command(name: str) -> str:
    """The command that writes results file ``name``: the one it recorded, else its recorded script, else
    the benchmark whose name is the longest prefix of the file's."""
    d = json.loads(results_path(name).read_text()) if results_path(name).is_file() else {}
    if "command" in d.get("provenance", {}):
        return d["provenance"]["command"]
    script = d.get("provenance", {}).get("script")
    if script is None and name.startswith("docs/"):
        return "python -m atrv_warp.evaluate --json " + name
    if script is None:
        stem = Path(name).parent.name if "/" in name else Path(name).stem
        scripts = sorted((p for p in BENCHMARKS.glob("*.py") if stem.startswith(p.stem)), key=lambda p: -len(p.stem))
        script = str(scripts[0].relative_to(ROOT)) if scripts else "?"
    return f"python {script}"


class Status:
    """Whether a results file's figures match the code as it is now: ``state`` is ``"current"``,
    ``"stale"`` (with ``reasons``) or ``"unknown"`` (no provenance recorded); ``date`` is when it was measured."""

    def __init__(self, file: str, state: str, reasons: list[str], date: str):
        self.file, self.state, self.reasons, self.date = file, state, reasons, date

    @property
    def current(self) -> bool:
        return self.state == "current"


def _git_date(path: Path) -> str:
    out = subprocess.run(["git", "log", "-1", "--format=%cs", "--", str(path)], cwd=ROOT, capture_output=True,
                         text=True, check=False).stdout.strip()
    return out or "unknown date"


@functools.cache
def status(name: str) -> Status:
    """Check results file ``name``'s provenance against the script's ``VERSION``, the dynamics and the policies now."""
    d = _load(name)
    p = d.get("provenance") if isinstance(d, dict) else None
    if p is None:
        when = d.get("time", "") if isinstance(d, dict) else ""
        return Status(name, "unknown", ["no provenance recorded"],
                      (when[:10] if when else f"{_git_date(results_path(name))} or earlier"))
    reasons = []
    version = script_version(p["script"])
    if version != p["script_version"]:
        reasons.append(f"{p['script']} VERSION is {version}, the file was written by VERSION {p['script_version']}")
    if "dynamics" in p and p["dynamics"] != current_dynamics():
        reasons.append(f"dynamics fingerprint {p['dynamics']} != {current_dynamics()} now")
    if "driver" in p and p["driver"] != current_driver():
        reasons.append(f"motor driver fingerprint {p['driver']} != {current_driver()} now")
    if "task" in p and p["task"] != current_task():
        reasons.append(f"task fingerprint {p['task']} != {current_task()} now")
    for kind, files in (("policy", p.get("policies", {})), ("robot file", p.get("robots", {}))):
        for file, digest in files.items():
            path = ROOT / file
            if not path.is_file():
                reasons.append(f"{kind} {file} is gone")
            elif hashlib.sha256(path.read_bytes()).hexdigest() != digest:
                reasons.append(f"{kind} {file} has changed")
    return Status(name, "stale" if reasons else "current", reasons, p["date"][:10])


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
    value = lookup(_load(name), key, name=name)
    try:
        if fmt.endswith("%"):  # the house style: "91.3 %", a space before the sign
            return format(100 * value, fmt[:-1] + "f") + " %"
        return format(value, fmt)
    except (TypeError, ValueError) as err:
        raise FigureError(f"results file {name}, key {key!r}: cannot format {value!r} as {fmt!r}") from err


def verdict(name: str, key: str, op: str, bound: float, yes: str, no: str) -> str:
    """``yes`` where the value at ``key`` in results file ``name`` compares with ``bound`` as ``op`` says, else
    ``no``."""
    value = lookup(_load(name), key, name=name)
    if not isinstance(value, int | float) or isinstance(value, bool):
        raise FigureError(f"results file {name}, key {key!r}: a verdict needs a number, got {value!r}")
    return yes if COMPARISONS[op](value, bound) else no


def _table(header: list[str], align: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join(align) + "|"]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def sim_throughput(name: str = "sim_throughput.json") -> str:
    """``sim_throughput.json``: env-steps/s and ms per step against the number of worlds."""
    rows = _load(name)["rows"]
    return _table(["worlds", "env-steps/s", "ms/step"], ["---:"] * 3,
                  [[f"{r['num_worlds']:,}", f"{r['env_steps_per_s']:,.0f}", f"{r['ms_per_step']:.3f}"] for r in rows])


def sim_throughput_cuda() -> str:
    """``sim_throughput_cuda.json``: the same on one GPU."""
    return sim_throughput("sim_throughput_cuda.json")


def sim_choices() -> str:
    """``sim_throughput.json``: graph replay and tile GEMM on and off."""
    rows = _load("sim_throughput.json")["choices"]
    on = {True: "on", False: "off"}
    return _table(["worlds", "graph replay", "tile GEMM", "env-steps/s"], ["---:", "---", "---", "---:"],
                  [[str(r["num_worlds"]), on[r["use_graph"]], on[r["use_tile_gemm"]], f"{r['env_steps_per_s']:,.0f}"]
                   for r in rows])


def sim_vs_mujoco() -> str:
    """``sim_vs_mujoco.json``: our env-steps/s against MuJoCo's rollout of the twin."""
    rows = _load("sim_vs_mujoco.json")["rows"]
    return _table(["N", "ours env-steps/s", "MuJoCo env-steps/s", "ours / MuJoCo"], ["---:"] * 4,
                  [[str(r["num_worlds"]), f"{r['ours_env_steps_per_s']:,.0f}", f"{r['mujoco_env_steps_per_s']:,.0f}",
                    f"{r['ratio_ours_over_mujoco']:.2f}"] for r in rows])


def physics_report() -> str:
    """``physics_report.json``: the physics figures against the reference's and analytic ones."""
    rows = _load("physics_report.json")["rows"]
    return _table(["quantity", "atrv_warp", "reference / analytic"], ["---", "---:", "---"],
                  [[r["quantity"], r["atrv_warp"], r["reference"]] for r in rows])


def skid_turning() -> str:
    """``skid_calibration.json``: the effective track ratio chi per command and mu, against Coulomb."""
    d = _load("skid_calibration.json")
    rows = d["turning"]
    commands = sorted({(r["linear"], r["angular"]) for r in rows}, key=lambda c: (c[0], -abs(c[1])))
    columns = [(r["law"], r["mu"]) for r in rows]
    columns = sorted(set(columns), key=lambda c: (c[0] != "coulomb", c[1]))
    chi = {(r["law"], r["mu"], r["linear"], r["angular"]): r["chi"] for r in rows}
    coulomb = {(r["linear"], r["angular"]): r["chi_coulomb"] for r in rows if r["law"] == "coulomb"}
    header = ["v [m/s], ω [rad/s]"] + [f"µ {mu:g}" + ("" if law == "coulomb" else f" ({law})") for law, mu in columns]
    body = [[f"{v:g}, {w:g}"] + [f"{chi[(law, mu, v, w)]:.2f}" for law, mu in columns] for v, w in commands]
    table = _table(header + ["pure Coulomb"], ["---"] + ["---:"] * (len(columns) + 1),
                   [row + [f"{coulomb[c]:.2f}"] for row, c in zip(body, commands)])
    return table + f"\n\nMedian chi at µ 0.3, the ROS node's `effective_track_factor`: **{d['effective_track_factor']:.2f}**."


def skid_checks() -> str:
    """``skid_calibration.json``: rolling slip, wheel odometry, traction limit and slopes."""
    d = _load("skid_calibration.json")
    rows = [["slip ratio at +2 N·m per wheel", f"{100 * d['slip_ratio_2Nm']:.2f} %", "< 3 %"]]
    for o in d["odometry"]:
        what = f"{o['linear']:g} m/s" if o["linear"] else f"{o['angular']:g} rad/s in place"
        rows.append([f"wheel odometry from rest, {what}, {o['seconds']:g} s", f"{100 * o['relative_error']:.2f} % off",
                     "< 2 %"])
    for t in d["traction"]:
        rows.append([f"full torque, µ {t['mu']:g}: acceleration [m/s²]", f"{t['acceleration']:.2f}",
                     f"µ g = {t['mu_g']:.2f}"])
    for s in d["slopes"]:
        rows.append([f"parked, µ {s['mu']:g}, {s['fraction_of_atan_mu']:g} × atan µ = {s['degrees']:.1f}°: moved in 5 s",
                     f"{1000 * s['moved']:.1f} mm" if s["moved"] < 1.0 else f"{s['moved']:.2f} m",
                     "holds" if s["fraction_of_atan_mu"] < 1 else "slides"])
    return _table(["check", "atrv_warp", "target"], ["---", "---:", "---"], rows)


def _train_to_success(name: str) -> str:
    d = _load(name)
    rows = []
    for s in d["seeds"]:
        reached = s["reached"]
        rows.append([str(s["seed"]), f"{s['wall_s_to_threshold']:.0f} s" if reached else "not reached",
                     f"{s['frames_to_threshold']:,}" if reached else "", f"{100 * s['final_eval_best_policy']['success_rate']:.1f} %",
                     f"{s['updates_per_s']:.1f}", f"{s['frames_per_s']:,.0f}"])
    m = d["median"]
    median_wall = "not reached" if m["wall_s_to_threshold"] is None else f"{m['wall_s_to_threshold']:.0f} s"
    rows.append(["median", f"**{median_wall}**", "", f"**{100 * m['final_success_rate']:.1f} %**",
                 f"{m['updates_per_s']:.1f}", f"{m['frames_per_s']:,.0f}"])
    return _table(["seed", "90 % after", "frames then", "best policy, final (1,000 episodes)", "updates/s", "frames/s"],
                  ["---:"] * 6, rows)


def train_to_success() -> str:
    """``train_to_success.json``: the reach task's time to 90 % per seed."""
    return _train_to_success("train_to_success.json")


def train_to_success_nav() -> str:
    """``train_to_success_nav.json``: the nav task's time to 90 % per seed."""
    return _train_to_success("train_to_success_nav.json")


PPO_VS_SAC = (("reach", "SAC", "train_to_success.json", "--seeds 0 1 2 --minutes 10"),
              ("reach", "PPO", "train_to_success_ppo.json", "--config ppo --seeds 0 1 2 --minutes 10 --eval-every 327680"),
              ("nav", "SAC", "train_to_success_nav.json", "--config nav --seeds 0 1 2 --minutes 12"),
              ("nav", "PPO", "train_to_success_nav_ppo.json",
               "--config nav_ppo --seeds 0 1 2 --minutes 20 --eval-every 327680"))
"""(task, algorithm, results file of ``benchmarks/train_to_success.py``, its arguments) of the PPO-SAC table."""


def ppo_vs_sac() -> str:
    """``train_to_success*.json``: SAC and PPO on both tasks, medians over seeds; a file not written yet
    is a row saying which command writes it."""
    rows = []
    for task, algo, name, args in PPO_VS_SAC:
        if not (RESULTS / name).is_file():
            rows.append([task, algo, "not measured yet", "", "", "", f"`python benchmarks/train_to_success.py {args}`"])
            continue
        d = _load(name)
        m, seeds = d["median"], d["seeds"]
        reached = sum(s["reached"] for s in seeds)
        wall = "not reached by every seed" if m["wall_s_to_threshold"] is None else f"{m['wall_s_to_threshold']:.0f} s"
        rows.append([task, algo, f"**{wall}** ({reached} of {len(seeds)} seeds)", f"**{100 * m['final_success_rate']:.1f} %**",
                     f"{m['updates_per_s']:.1f}", f"{m['frames_per_s']:,.0f}",
                     f"`{name}` ({d['preset']}, {d.get('num_envs', 'n/a')} worlds, {d['minutes_per_seed']:g} min per seed)"])
    return _table(["task", "algorithm", "90 % after (median)", "final success (median)", "updates/s", "frames/s",
                   "results file"], ["---", "---", "---:", "---:", "---:", "---:", "---"], rows)


def video_cost() -> str:
    """``video_cost.json``: what an evaluation video costs, per task."""
    rows = []
    for r in _load("video_cost.json")["rows"]:
        m = r["median"]
        rows.append([r["task"], f"{m['evaluation_s']:.2f} s", f"{r['recording_s']:.2f} s", f"{m['mp4_s']:.2f} s",
                     f"{m['mp4_and_gif_s'] - m['mp4_s']:.2f} s", f"{100 * r['video_share_of_evaluation']:.0f} %",
                     f"{r['frames']} ({r['width']}×{r['height']}, {r['fps']:g} fps)", f"{r['mp4_bytes'] / 1e6:.2f} MB"])
    return _table(["task", "evaluation (256 episodes)", "recording", "drawing + MP4", "+ GIF (TensorBoard)",
                   "video / evaluation", "frames", "MP4"], ["---"] + ["---:"] * 7, rows)


def train_to_success_nav_wide() -> str:
    """``train_to_success_nav_wide.json``: the nav task's time to 90 % per seed under the ``wide`` randomization."""
    return _train_to_success("train_to_success_nav_wide.json")


def randomization_eval() -> str:
    """``randomization_eval.json``: the randomized and the plain nav policy, nominal and under ``wide``."""
    d = _load("randomization_eval.json")
    rows = []
    for name, p in d["policies"].items():
        rows.append([f"{name} (`{Path(p['path']).name}`)", f"**{100 * p['wide']['success_rate']:.1f} %**",
                     f"{100 * p['none']['success_rate']:.1f} %", f"{100 * p['wide']['obstacle_rate']:.1f} %",
                     f"{100 * p['wide']['wall_rate']:.1f} %", f"{100 * p['wide']['timeout_rate']:.1f} %"])
    return _table([f"nav policy ({d['episodes']:,} episodes each)", "success, `wide`", "success, nominal rover",
                   "obstacle, `wide`", "wall, `wide`", "timeout, `wide`"], ["---"] + ["---:"] * 5, rows)


def randomization_bins() -> str:
    """``randomization_eval.json``: success by parameter bin under ``wide``, both policies."""
    d = _load("randomization_eval.json")
    policies = list(d["policies"])
    rows = []
    for param, label in (("friction", "µ"), ("payload_mass", "payload [kg]"), ("latency", "latency [steps]")):
        bins = [d["policies"][p]["wide"]["success_by_bin"][param] for p in policies]
        for i, r in enumerate(bins[0]):
            span = f"{r['low'] + 0.5:g}" if param == "latency" else f"{r['low']:g}–{r['high']:g}"
            rows.append([f"{label} {span}", f"{r['episodes']}",
                         *(f"{100 * b[i]['success']:.1f} %" for b in bins)])
    return _table(["bin", "episodes", *(f"{p} policy" for p in policies)], ["---"] + ["---:"] * (1 + len(policies)),
                  rows)


def randomization_cost() -> str:
    """``randomization_cost.json``: env-steps/s with ``wide`` against ``none``, interleaved."""
    d = _load("randomization_cost.json")
    return _table(["task", "N", "`none` env-steps/s", "`wide` env-steps/s", "wide / none", "step time"],
                  ["---", "---:", "---:", "---:", "---:", "---:"],
                  [[r["task"], str(r["num_envs"]), f"{r['none_env_steps_per_s']:,.0f}",
                    f"{r['wide_env_steps_per_s']:,.0f}", f"{r['wide_over_none']:.3f}", f"{r['slowdown_pct']:+.1f} %"]
                   for r in d["rows"]])


def evaluations() -> str:
    """``evaluations.json``: the shipped policies and the scripted drivers on the 1,000 test episodes."""
    rows = []
    for e in _load("evaluations.json")["rows"]:
        rows.append([e["label"], f"**{100 * e['success_rate']:.1f} %**", f"{100 * e['wall_rate']:.1f} %",
                     f"{100 * e.get('obstacle_rate', 0.0):.1f} %", f"{100 * e['flip_rate']:.1f} %",
                     f"{100 * e['timeout_rate']:.1f} %", f"{e['mean_return']:.2f}", f"{e['mean_steps']:.1f}"])
    return _table(["policy", "success", "wall", "obstacle", "flip", "timeout", "mean return", "mean steps"],
                  ["---"] + ["---:"] * 7, rows)


def coulomb_cost() -> str:
    """``compare_revisions_coulomb.json``: this tree's step against 0.1.x's (viscous friction), interleaved."""
    d = _load("compare_revisions_coulomb.json")
    return _table(["N", "0.1.x (viscous) env-steps/s", "Coulomb env-steps/s", "Coulomb / 0.1.x"],
                  ["---:"] * 4,
                  [[str(r["num_worlds"]), f"{r['old_median']:,.0f}", f"{r['new_median']:,.0f}", f"{r['ratio']:.3f}"]
                   for r in d["rows"] if r["kind"] == "sim"])


def calibration() -> str:
    """``calibration.json``: a hidden rover's parameters against the fitted ones, per command source (and the old
    fit's, where the file has one)."""
    d = _load("calibration.json")
    runs = dict(d["runs"])
    header = ["", "truth"] + [f"fitted ({name} replay)" for name in runs]
    if d.get("old"):
        runs["old"] = d["old"]
        header.append(f"fitted (cmd_vel, the fit of {d['old']['revision'][:7]})")
    rows = []
    for p in runs["cmd_vel"]["fitted"]:
        truth = d["truth"]["wheel_speed_limit" if p == "speed_limit" else p]
        cells = []
        for run in runs.values():
            if p in run["fitted"] and "standard_error" in run:
                se, spread = (("—" if math.isnan(v) else f"{v:.2g}") for v in (run["standard_error"][p], run["spread"][p]))
                cells.append(f"{run['fitted'][p]:.4g} ± {se}, spread {spread} ({100 * run['relative_error'][p]:.1f} % off)")
            elif p in run["fitted"]:
                cells.append(f"{run['fitted'][p]:.4g} ({100 * run['relative_error'][p]:.1f} % off)")
            else:
                cells.append("not fitted (applied as recorded)")
        rows.append([p, f"{truth:g}", *cells])
    for split in ("train", "held_out"):
        cells = []
        for run in runs.values():
            e = run["error_summary"][split]
            cells.append(f"{100 * e['before_m']:.1f} → {100 * e['after_m']:.1f} cm ({e['reduction']:.1f}×)")
        rows.append([f"position error, {split.replace('_', '-')} (median)", "", *cells])
    rows.append(["converged", "", *[("yes" if r["converged"] else "no: " + r.get("reason", "").split(": ", 1)[-1])
                                     for r in runs.values()]])
    rows.append(["fit wall time (2 cores)", "", *[f"{r['fit_s']:.0f} s (+ {r['compile_s']:.0f} s compiling)"
                                                for r in runs.values()]])
    return _table(header, ["---", "---:"] + ["---"] * len(runs), rows)


def calibration_data() -> str:
    """``calibration_data.json``: each recorded rover's fit against the seconds of driving it was given."""
    d = _load("calibration_data.json")
    rows = []
    for name, r in d["rovers"].items():
        t = r["truth"]
        for f in r["fits"]:
            e = f["relative_error"]
            rows.append([name.replace("_", " ") if f is r["fits"][0] else "", f"{f['seconds']:.0f} s",
                         f"{100 * e['friction']:+.1f} %", f"{100 * e['torque_scale']:+.1f} %",
                         f"{e['payload_mass'] * t['payload_mass']:+.1f} kg",
                         f"{1000 * e['wheel_radius'] * t['wheel_radius']:+.1f} mm",
                         f"{100 * r['held_out_before_m']:.1f} → {100 * f['held_out_after_m']:.1f} cm",
                         "yes" if f["converged"] else "no", f"{f['fit_s']:.0f} s"])
    return _table(["rover", "driving fitted", "µ", "torque scale", "payload", "wheel radius",
                   "held-out error (median)", "converged", "fit"], ["---"] + ["---:"] * 6 + ["---", "---:"], rows)


def calibration_sweep(name: str = "calibration_sweep.json") -> str:
    """``calibration_sweep.json``: each drawn rover's truth, the fit's errors (within tolerance or not, and whether
    the 95 % interval covers the truth), the held-out error and whether the fit converged."""
    d = _load(name)
    def cell(v: dict, scale: float, unit: str) -> str:  # ✗ outside the tolerance, ° the interval misses the truth
        return f"{scale * v['error']:+.1f} {unit}{'' if v['covered'] else '°'}{'' if v['within'] else ' ✗'}"

    rows = []
    for r in d["rovers"]:
        p, t = r["params"], r["truth"]
        rows.append([str(r["rover"]), f"{t['friction']:.2f}", f"{t['torque_scale']:.2f}", f"{t['payload_mass']:.1f}",
                     f"{1000 * t['wheel_radius']:.1f}", cell(p["friction"], 100 / t["friction"], "%"),
                     cell(p["torque_scale"], 100 / t["torque_scale"], "%"), cell(p["payload_mass"], 1.0, "kg"),
                     cell(p["wheel_radius"], 1000.0, "mm"),
                     f"{100 * r['held_out']['before_m']:.1f} → {100 * r['held_out']['after_m']:.1f} cm",
                     "yes" if r["converged"] else "no", f"{r['fit_s']:.0f} s"])
    return _table(["rover", "µ", "torque", "payload [kg]", "wheel [mm]", "µ error", "torque error", "payload error",
                   "wheel error", "held-out error", "converged", "fit"],
                  ["---:"] * 5 + ["---:"] * 4 + ["---", "---", "---:"], rows)


def calibration_misfit() -> str:
    """``calibration_misfit.json``: what the fit does with each effect its model lacks."""
    d = _load("calibration_misfit.json")
    effects = {"none": "nothing", "latency_1": "/cmd_vel 0.05 s late", "latency_2": "/cmd_vel 0.1 s late",
               "motor_lag": "0.1 s motor torque lag", "payload_off_centre": "payload 0.25 m ahead, 0.15 m left",
               "slope": "a 10° slope", "stiffness_1.4x": "ground 1.4× stiffer"}
    rows = []
    for r in d["cases"]:
        p, t, m = r["params"], r["truth"], r["misfit"]
        errors = [f"{100 * p['friction']['error'] / t['friction']:+.1f} %", f"{100 * p['torque_scale']['error'] / t['torque_scale']:+.1f} %",
                  f"{p['payload_mass']['error']:+.1f} kg", f"{1000 * p['wheel_radius']['error']:+.1f} mm"]
        errors = [e + ("" if p[k]["within"] else " ✗")
                  for e, k in zip(errors, ("friction", "torque_scale", "payload_mass", "wheel_radius"))]
        ratios = " / ".join(f"{m['ratio'][c]:.1f}" for c in ("position", "wheel_speed", "effort") if c in m["ratio"])
        rows.append([effects.get(r["case"], r["case"]), *errors,
                     f"{100 * r['held_out']['before_m']:.1f} → {100 * r['held_out']['after_m']:.1f} cm",
                     f"{r['latency']['seconds']:g} s", "yes" if r["converged"] else "no",
                     f"{ratios}: {'**misfit**' if m['flagged'] else 'passes'}"])
    return _table(["recorded with", "µ error", "torque error", "payload error", "wheel error", "held-out error",
                   "latency found", "converged", "model check (position / wheel speed / effort ÷ noise)"],
                  ["---"] + ["---:"] * 5 + ["---:", "---", "---"], rows)


def _twin_truth(t: dict) -> str:
    """A twin rover's true values, as the twin tables show them."""
    return f"{t['friction']:.2f}, {t['torque_scale']:.2f}, {t['payload_mass']:.1f}, {1000 * t['wheel_radius']:.1f}"


def calibration_twin(name: str = "calibration_twin.json") -> str:
    """``calibration_twin.json``: each rover recorded in the MuJoCo twin and fitted in ours, beside the same rover
    recorded in ours (the sweep's row, where it ran it)."""
    d = _load(name)
    rise = "friction_rise" in d.get("fit_params", [])
    rows = []
    for r in d["rovers"]:
        p, t, h, m = r["params"], r["truth"], r["held_out"], r.get("misfit") or {}
        errors = [f"{100 * p['friction']['error'] / t['friction']:+.1f} %",
                  f"{100 * p['torque_scale']['error'] / t['torque_scale']:+.1f} %",
                  f"{p['payload_mass']['error']:+.1f} kg", f"{1000 * p['wheel_radius']['error']:+.1f} mm"]
        cut = f"{h['cut']:.1f}×" + ("" if h["passes"] is None else " ✓" if h["passes"] else " ✗")
        ratios = " / ".join(f"{m['ratio'][c]:.1f}" for c in ("position", "wheel_speed", "effort") if c in m.get("ratio", {}))
        o, turn = r.get("ours"), r["in_place_turn"]
        rows.append([r["rover"].replace("_", " "), _twin_truth(t), *errors,
                     *([f"{r['fitted']['friction_rise']:.2f}"] if rise else []),
                     f"{100 * h['before_m']:.1f} → {100 * h['after_m']:.1f} cm", cut, "yes" if r["converged"] else "no",
                     f"{turn['twin']:.2f} / {turn['ours']:.2f} / {turn['ours_fitted']:.2f}",
                     f"{ratios}{': **misfit**' if m.get('flagged') else ''}",
                     "-" if o is None else f"{100 * o['held_out']['before_m']:.1f} → {100 * o['held_out']['after_m']:.1f} cm"])
    return _table(["rover", "truth: µ, torque, payload [kg], wheel [mm]", "µ error", "torque error", "payload error",
                   "wheel error", *(["friction rise [s/m]"] if rise else []), "held-out error", "cut", "converged",
                   "turn in place at 1 rad/s: twin / ours / ours fitted",
                   "model check (position / wheel speed / effort ÷ noise)", "the same rover in ours"],
                  ["---", "---"] + ["---:"] * (7 if rise else 6) + ["---", "---:", "---", "---:"], rows)


def calibration_twin_validation() -> str:
    """``calibration_twin_seed1.json`` and ``calibration_twin_friction_rise_seed1.json``: rovers drawn from another
    seed, fitted with the CLI's defaults and with the friction's rise, side by side, and a line counting the rovers
    the rise's fit leaves worse."""
    plain, rise = _load("calibration_twin_seed1.json"), _load("calibration_twin_friction_rise_seed1.json")
    rows, worse = [], 0
    for a, b in zip(plain["rovers"], rise["rovers"], strict=True):
        ha, hb = a["held_out"], b["held_out"]
        worse += hb["after_m"] > ha["after_m"]
        rows.append([a["rover"].replace("_", " "), _twin_truth(a["truth"]), f"{100 * ha['before_m']:.1f} cm",
                     f"{100 * ha['after_m']:.1f} cm ({ha['cut']:.1f}×)", f"{100 * hb['after_m']:.1f} cm ({hb['cut']:.1f}×)",
                     f"{b['fitted']['friction_rise']:.2f}"])
    table = _table(["rover", "truth: µ, torque, payload [kg], wheel [mm]", "nominal model's held-out error",
                    "after the default fit (cut)", "after the fit with the rise (cut)", "friction rise [s/m]"],
                   ["---", "---", "---:", "---:", "---:", "---:"], rows)
    return (f"{table}\n\nThe fit with the rise leaves a larger held-out error than the default fit on {worse} of these "
            f"{len(rows)} rovers.")


def calibration_twin_friction_rise() -> str:
    """``calibration_twin_friction_rise.json``: :func:`calibration_twin` with the friction's rise fitted too."""
    return calibration_twin("calibration_twin_friction_rise.json")


def _diff_gradients(kind: str, name: str = "diff_gradients.json") -> str:
    d = _load(name)
    rows = d["agreement"]
    horizons = sorted({r["horizon_s"] for r in rows})
    scenarios = list(dict.fromkeys(r["scenario"] for r in rows))
    cell = {(r["scenario"], r["horizon_s"]): r for r in rows}

    def fmt(r: dict) -> str:
        if r[f"{kind}_negligible"]:
            return "~0"
        return f"{100 * r[f'{kind}_rel_err']:.1f} %" + ("†" if r[f"{kind}_fd_rough"] else "")

    return _table(["scenario", *(f"{h:.2f} s" for h in horizons)], ["---"] + ["---:"] * len(horizons),
                  [[sc, *(fmt(cell[(sc, h)]) for h in horizons)] for sc in scenarios])


def diff_gradients_common() -> str:
    """``diff_gradients.json``: both wheels together, tape against central differences."""
    return _diff_gradients("common")


def diff_gradients_differential() -> str:
    """``diff_gradients.json``: left against right (steering)."""
    return _diff_gradients("differential")


def diff_gradients_friction() -> str:
    """``diff_gradients.json``: the friction coefficient."""
    return _diff_gradients("friction")


def diff_gradients_mass() -> str:
    """``diff_gradients.json``: the chassis mass."""
    return _diff_gradients("mass")


def diff_gradients_twist_linear() -> str:
    """``diff_gradients_twist.json``: the forward-speed command through the motor driver."""
    return _diff_gradients("linear", "diff_gradients_twist.json")


def diff_gradients_twist_angular() -> str:
    """``diff_gradients_twist.json``: the yaw-rate command through the motor driver."""
    return _diff_gradients("angular", "diff_gradients_twist.json")


def diff_cost() -> str:
    """``diff_gradients.json``: forward and backward cost of the taped rollout per world-step."""
    return _table(["worlds", "forward [µs / world-step]", "backward [µs / world-step]", "backward / forward"],
                  ["---:"] * 4,
                  [[str(r["num_worlds"]), f"{r['forward_us_per_world_step']:.0f}", f"{r['backward_us_per_world_step']:.0f}",
                    f"{r['backward_over_forward']:.2f}"] for r in _load("diff_gradients.json")["cost"]])


def env_throughput() -> str:
    """``env_throughput.json``: raw simulator, ``env.rollout`` and ``Collector`` frames/s."""
    return _table(["N", "raw sim frames/s", "env.rollout", "overhead", "Collector", "overhead"], ["---:"] * 6,
                  [[str(r["num_envs"]), f"{r['raw_sim_fps']:,.0f}", f"{r['rollout_fps']:,.0f}",
                    f"{100 * r['rollout_overhead']:.1f} %", f"{r['collector_fps']:,.0f}",
                    f"{100 * r['collector_overhead']:.1f} %"] for r in _load("env_throughput.json")["rows"]])


def env_scaling() -> str:
    """``env_throughput.json``: one and two collector workers."""
    d = _load("env_throughput.json")
    return _table([f"collector ({d['worker_envs']} worlds per worker, {d['steps_per_worker_batch']} steps per worker batch)",
                   "1 worker frames/s", "2 workers frames/s", "speed-up"], ["---", "---:", "---:", "---:"],
                  [[f"`{name}`", f"{r['1_worker_fps']:,.0f}", f"{r['2_workers_fps']:,.0f}", f"{r['speedup']:.2f}×"]
                   for name, r in d["scaling"].items()])


def nav_throughput(name: str = "nav_throughput.json") -> str:
    """``nav_throughput.json``: the nav task's env-steps/s against the reach task's."""
    rows = []
    for r in _load(name)["rows"]:
        us = r["us_per_world_step"]
        rows.append([str(r["num_envs"]), f"{r['reach_env_steps_per_s']:,.0f}", f"{r['nav_env_steps_per_s']:,.0f}",
                     f"{r['nav_over_reach']:.2f}", f"{us['sim_flat']:.1f} / {us['sim_nav']:.1f} / {us['scan']:.1f} µs"])
    return _table(["N", "reach env-steps/s", "nav env-steps/s", "nav / reach",
                   "per world-step: sim flat / sim terrain + obstacles / scan"], ["---:"] * 4 + ["---"], rows)


def nav_throughput_cuda() -> str:
    """``nav_throughput_cuda.json``: the same on one GPU."""
    return nav_throughput("nav_throughput_cuda.json")


def ray_collection() -> str:
    """``ray_collection.json``: TorchRL's ``RayCollector`` against ``MultiSyncCollector``."""
    d = _load("ray_collection.json")
    fps, ratio = d["best_fps"], d["ray_over_local"]
    return _table([f"workers x {d['worlds_per_worker']} worlds", "MultiSyncCollector frames/s", "RayCollector frames/s",
                   "Ray / local"], ["---:"] * 4,
                  [[k, f"{fps[f'MultiSyncCollector x{k}']:,.0f}", f"{fps[f'RayCollector x{k}']:,.0f}", f"{ratio[k]:.2f}"]
                   for k in sorted(ratio)])


def step_profile() -> str:
    """``step_profile.json``: where one step's kernel time goes, by kernel, at its number of worlds."""
    d = _load("step_profile.json")
    owner = {"newton": "Newton", "atrv_warp": "ours"}
    rows = [[owner.get(r["owner"], r["owner"]), f"`{r['name']}`", f"{r['ms_per_step']:.2f}", f"{100 * r['share']:.1f} %",
             f"{r['calls_per_step']:g}"] for r in d["rows"][:10]]
    ms = d["ms_by_owner"]
    rows.append(["", "all of Newton / all of ours", f"{ms['newton']:.2f} / {ms['atrv_warp']:.2f}",
                 f"{100 * d['by_owner']['newton']:.1f} % / {100 * d['by_owner']['atrv_warp']:.1f} %", ""])
    return _table(["owner", "kernel", "ms per step", "share", "launches per step"], ["---", "---", "---:", "---:", "---:"],
                  rows)


def substep_speed() -> str:
    """``substep_study_coulomb_1e7.json``: today's step (Coulomb friction) at five and three substeps."""
    d = _load("substep_study_coulomb_1e7.json")
    rows = [[f"{r['substeps']} ({r['sim_dt']:.3g} s)" + (", the default" if r["substeps"] == 5 else ""),
             f"**{r['env_steps_per_s']:,.0f}**", f"{r['speedup_vs_5']:.2f}", f"{r['world_steps']:,}", str(r["nonfinite_worlds"]),
             f"{r['impact_max_speed']:.2f}"] for r in d["rows"]]
    return _table([f"substeps (sim_dt), {d['worlds']:,} worlds", "env-steps/s, one core", "vs 5",
                   "random-torque world-steps", "non-finite worlds", "wall impacts: fastest [m/s]"],
                  ["---", "---:", "---:", "---:", "---:", "---:"], rows)


def substep_study() -> str:
    """``substep_study.json``: speed, accuracy and stability per substep count (viscous friction law)."""
    rows = []
    for r in _load("substep_study.json")["rows"]:
        name = f"{r['substeps']} ({r['sim_dt']:.3g} s)" + (", plain law" if r["damping_limit"] is None else "")
        rows.append([name, f"{r['env_steps_per_s']:,.0f}", f"{r['speedup_vs_5']:.2f}",
                     f"{r['x_after_1.0_s']:.3f} / {r['x_after_3.0_s']:.3f} / {r['x_after_4.9_s']:.3f}",
                     f"{r['accel_2Nm']:.4f}", str(r["nonfinite_worlds"]),
                     f"{r['held_nonfinite_worlds']} / {r['held_overspeed_worlds']}",
                     f"{r['impact_max_speed']:.2f} / {r['impact_overspeed_worlds']}"])
    return _table(["substeps (sim_dt)", "env-steps/s", "vs 5", "reference drive x after 1 / 3 / 4.9 s [m]",
                   "accel at +2 N·m [m/s²]", "fresh torques: non-finite",
                   "held torques: non-finite / over 1.2× top speed", "wall impacts: fastest [m/s] / over 1.2×"],
                  ["---"] + ["---:"] * 7, rows)


def sac_update_cost() -> str:
    """``sac_update_cost.json``: one gradient step of the trainer's ``Learner`` per loss and batch, one thread."""
    names = {"loss=sac": "SAC", "sac, critics in a loop": "SAC, critics in a Python loop instead of TorchRL's vmap",
             "sac, torch.compile": "SAC, loss and backward under `torch.compile`", "loss=crossq": "CrossQ",
             "loss=redq": "REDQ (10 critics)"}
    cells: dict[str, dict[int, str]] = {}
    for v in _load("sac_update_cost.json")["variants"]:
        text = f"{v['ms_per_update']:.1f} ms"
        if v["warmup_s"] > 5:
            text += f", after {v['warmup_s']:.0f} s of compilation"
        cells.setdefault(names.get(v["variant"], v["variant"]), {})[v["batch"]] = text
    order = [n for n in names.values() if n in cells]
    return _table(["variant", "batch 256", "batch 512"], ["---", "---:", "---:"],
                  [[n, cells[n].get(256, ""), cells[n].get(512, "")] for n in order])


def mujoco_agreement() -> str:
    """``mujoco_agreement.json``: each figure in our simulator and in the MuJoCo twin, the gap, its tolerance and
    its reason."""
    rows = []
    for r in _load("mujoco_agreement.json")["rows"]:
        tolerance = "reported" if r["tolerance"] is None else f"±{r['tolerance']:.3g}"
        within = {None: "-", True: "yes", False: "**no**"}[r["within"]]
        rows.append([r["figure"], f"{r['ours']:.4g}", f"{r['mujoco']:.4g}", f"{r['gap']:+.3g} {r['unit']}", tolerance,
                     within, r["reason"]])
    return _table(["figure", "ours", "MuJoCo", "gap", "tolerance", "within", "why a gap"],
                  ["---", "---:", "---:", "---:", "---:", "---", "---"], rows)


def mujoco_turning_study() -> str:
    """``mujoco_turning_study.json``: per MuJoCo contact setting, the twin's sink at rest, chi in the agreement's
    turns and how often a wheel was airborne in them, the sliding wheels' friction over their load at µ 0.8, the
    fastest in-place turn at µ 0.8, and turns on the hills terrain; our simulator first."""
    data = _load("mujoco_turning_study.json")
    rows = data["rows"]

    def cell(setting, turn, mu, field="chi_substeps"):
        return next(r for r in rows if r["setting"] == setting and r["turn"] == turn and r["mu"] == mu)[field]

    ours = {(c["turn"], c["mu"]): c["chi"] for c in data["ours"]["chi"]}
    out = [["**ours** (Coulomb, one contact per wheel)", f"{data['ours']['sink_mm']:.1f}",
            f"{ours['in_place', 0.3]:.2f} / {ours['arc', 0.3]:.2f}", f"{ours['in_place', 0.8]:.2f} / {ours['arc', 0.8]:.2f}",
            "-", "-", f"{ours['fast_in_place', 0.8]:.2f}", "-",
            f"{data['ours']['terrain']['in_place']:.2f} / {data['ours']['terrain']['arc']:.2f}"]]
    for s in data["settings"]:
        name = s["setting"]
        nominal = [(t, mu) for mu in (0.3, 0.8) for t in ("in_place", "arc")]
        airborne = max(cell(name, t, mu, "airborne") for t, mu in nominal)
        ratio = cell(name, "in_place", 0.8, "friction_ratio")
        label = f"**{s['label']}**" if name == "tyre" else s["label"]
        out.append([label, f"{s['sink_mm']:.2f}",
                    f"{cell(name, 'in_place', 0.3):.2f} / {cell(name, 'arc', 0.3):.2f}",
                    f"{cell(name, 'in_place', 0.8):.2f} / {cell(name, 'arc', 0.8):.2f}", f"{airborne:.0%}",
                    "-" if ratio is None else f"{ratio:.2f}", f"{cell(name, 'fast_in_place', 0.8):.2f}",
                    f"{cell(name, 'fast_in_place', 0.8, 'airborne'):.0%}",
                    f"{s['terrain']['in_place']:.2f} / {s['terrain']['arc']:.2f}"])
    return _table(["MuJoCo setting", "sink [mm]", "chi µ 0.3: in place / arc", "chi µ 0.8: in place / arc",
                   "wheel airborne (worst of these turns)", "friction / load, µ 0.8 in place",
                   "chi at 2 rad/s in place, µ 0.8", "airborne then", "hills, µ 0.3: yaw rate / command, in place / arc"],
                  ["---", "---:", "---:", "---:", "---:", "---:", "---:", "---:", "---:"], out)


def mujoco_transfer(name: str = "mujoco_transfer.json") -> str:
    """``mujoco_transfer.json``: each deployable policy in the MuJoCo twin at each µ (and in our simulator on the
    same episodes), success and how the others ended."""
    rows = []
    for policy, runs in _load(name)["policies"].items():
        for where, r in runs.items():
            rows.append([policy, where, str(r["episodes"]), f"{r['success']:.1%}", f"{r['obstacle']:.1%}",
                         f"{r['timeout']:.1%}", f"{r['flip']:.1%}", f"{r['mean_steps']:.0f}"])
    return _table(["policy", "where", "episodes", "success", "obstacle", "timeout", "flip", "mean steps"],
                  ["---", "---", "---:", "---:", "---:", "---:", "---:", "---:"], rows)


def deploy_policy() -> str:
    """``deploy_policy.json``: the deployable and the torque nav policy on the same test episodes, how each ended
    and how each drives."""
    rows = []
    for r in _load("deploy_policy.json")["rows"]:
        rows.append([f"{r['policy']} (`{r['file']}`)", "`wide`" if r["randomization"] == "wide" else "nominal",
                     f"**{r['success_rate']:.1%}**", f"{r['timeout_rate']:.1%}", f"{r['obstacle_rate']:.1%}",
                     f"{r['mean_abs_dv']:.3f}", f"{r['mean_abs_dw']:.3f}", f"{r['mean_peak_speed']:.2f}",
                     f"{r['mean_closest_obstacle']:.2f} / {r['p5_closest_obstacle']:.2f}"])
    return _table(["policy", "rover", "success", "timeout", "obstacle", "mean abs. Δv per step [m/s]",
                   "mean abs. Δω per step [rad/s]", "peak speed [m/s]", "closest obstacle, mean / 5th pct. [m]"],
                  ["---", "---", "---:", "---:", "---:", "---:", "---:", "---:", "---:"], rows)


def deploy_base_limit(name: str = "deploy_base_limit.json") -> str:
    """``deploy_base_limit.json``: the deployable policy through a base without and with the task's acceleration
    limit, success and how far the goal it sees from odometry is from the true one."""
    d = _load(name)
    rows = []
    for r in d["runs"]:
        base = "none" if r["base"] == "unlimited" else f"{d['limit']['linear_max_acceleration']:g} m/s²"
        rows.append(["`wide`" if r["randomization"] == "wide" else "nominal", base, f"**{r['success_rate']:.1%}**",
                     f"{r['timeout_rate']:.1%}", f"{r['obstacle_rate']:.1%}", f"{r['mean_steps']:.0f}",
                     f"{r['odometry_error_median']:.2f} / {r['odometry_error_p90']:.2f}"])
    return _table(["rover", "base's acceleration limit", "success", "timeout", "obstacle", "mean steps",
                   "goal seen from odometry, off by up to [m] (median / 90th pct. episode)"],
                  ["---", "---", "---:", "---:", "---:", "---:", "---:"], rows)


def deploy_odometry_scale(name: str = "deploy_odometry_scale.json") -> str:
    """``deploy_odometry_scale.json``: deployable policies' success (and timeouts) against how many times the distance
    driven their odometry reads, on the nominal rover and under ``wide``."""
    d = _load(name)
    presets = {"none": "nominal", "wide": "`wide`"}
    columns = [(label, preset) for label in d["policies"] for preset in presets]
    rows = []
    for scale in d["scales"]:
        cells = []
        for label, preset in columns:
            r = next(r for r in d["policies"][label]["runs"]
                     if r["randomization"] == preset and r["odometry_scale"] == scale)
            cells.append(f"**{100 * r['success_rate']:.1f} %** ({100 * r['timeout_rate']:.1f} %)")
        rows.append([f"{scale:.1f}", *cells])
    return _table(["odometry / distance driven", *[f"{label}, {presets[p]}: success (timeout)" for label, p in columns]],
                  ["---:"] * (1 + len(columns)), rows)


def train_to_success_nav_deploy() -> str:
    """``train_to_success_nav_deploy.json``: the deployable nav task's time to 90 % per seed (under ``wide``)."""
    return _train_to_success("train_to_success_nav_deploy.json")


def mujoco_odometry_drives() -> str:
    """``mujoco_odometry.json``'s scripted drives: encoders' distance over the path, launch and steady, per engine."""
    d = _load("mujoco_odometry.json")
    rows = [[f"{r['mu']:g}", f"{r['linear']:g} m/s, {r['angular']:g} rad/s",
             *(f"{r[engine][phase]:.3f}" for engine in ("ours", "twin") for phase in ("launch", "steady"))]
            for r in d["drives"]]
    return _table(["µ", "command", "ours, launch", "ours, steady", "twin, launch", "twin, steady"],
                  ["---", "---", "---:", "---:", "---:", "---:"], rows)


def train_to_success_nav_deploy_shipped() -> str:
    """``train_to_success_nav_deploy_shipped.json``: the run the shipped deployable policy comes from (seed 0)."""
    return _train_to_success("train_to_success_nav_deploy_shipped.json")


def robot_check() -> str:
    """``robot_check.json``: every shipped robot's check, one column per robot."""
    d = _load("robot_check.json")
    robots = d["robots"]

    def settle(r: dict, v: float, w: float) -> str:
        cells = [s for s in r["steps"] if (s["linear"], s["angular"]) == (v, w)]
        return " / ".join("never" if not math.isfinite(s["settle"]) else f"{s['settle']:.2f} s" for s in cells)

    rows = [
        ["mass", *(f"{r['mass']:.1f} kg" for r in robots.values())],
        ["wheel radius", *(f"{r['wheel_radius']:.4g} m" for r in robots.values())],
        ["track / wheelbase", *(f"{r['track']:.3f} / {r['wheelbase']:.3f} m" for r in robots.values())],
        ["reach (centre of mass to farthest corner)", *(f"{r['reach']:.2f} m" for r in robots.values())],
        ["limits (file)", *(f"{r['file']['limits']['linear_velocity']:g} m/s, "
                            f"{r['file']['limits']['angular_velocity']:g} rad/s" for r in robots.values())],
        ["driver gains kp / ki (rule)", *(f"{r['gains']['kp']:g} / {r['gains']['ki']:g}" for r in robots.values())],
        ["effective track factor (measured; file)", *(f"{r['effective_track_factor']:.2f}; "
                                                      f"{r['file']['effective_track_factor']:g}"
                                                      for r in robots.values())],
        ["Clearpath's wheel_separation_multiplier", *(f"{r['clearpath_multiplier']:g}" if r["clearpath_multiplier"]
                                                      else "-" for r in robots.values())],
        ["top speed under full torque (µ 0.8)", *(f"{r['top_speed']:.2f} m/s" for r in robots.values())],
        ["in place 0.5 rad/s settles (µ 0.3 / 0.8)", *(settle(r, 0.0, 0.5) for r in robots.values())],
        ["arc 0.3 m/s, 0.3 rad/s settles", *(settle(r, 0.3, 0.3) for r in robots.values())],
        ["arc 1 m/s, 0.2 rad/s settles", *(settle(r, 1.0, 0.2) for r in robots.values())],
    ]
    return _table(["", *(f"`{name}`" for name in robots)], ["---"] + ["---:"] * len(robots), rows)


def robot_limits() -> str:
    """The shipped robots' limits, read from their files (``atrv_warp/robots/*.toml``), with each one's source."""
    from atrv_warp.core.robot import ROBOTS, load_robot

    rows = []
    for name in ROBOTS:
        robot = load_robot(name)
        lim = robot.limits
        cells = [lim.linear_velocity, lim.angular_velocity, lim.linear_acceleration, lim.angular_acceleration]
        sources = dict.fromkeys(robot.sources.get(f"limits.{k}", "").split(" (")[0] for k in
                                ("linear_velocity", "angular_velocity", "linear_acceleration", "angular_acceleration"))
        rows.append([f"`{name}`", *("-" if c is None else f"{c:g}" for c in cells),
                     "; ".join(f"`{_cell(x)}`" for x in sources if x)])
    return _table(["robot", "v [m/s]", "ω [rad/s]", "a [m/s²]", "α [rad/s²]", "source (repository@commit:path)"],
                  ["---"] + ["---:"] * 4 + ["---"], rows)


def task_fit() -> str:
    """The ``nav_deploy`` task fitted to each shipped robot (:mod:`atrv_warp.task.scaling`), computed from the code."""
    from atrv_warp.core.robot import ROBOTS
    from atrv_warp.sim.config import RoverConfig
    from atrv_warp.task.registry import resolve_task
    from atrv_warp.task.scaling import fit_task

    declared = resolve_task("nav_deploy")
    rows = []
    for name in ROBOTS:
        c = fit_task(declared, RoverConfig(robot=name)).config
        period = c.control_period or 0.05
        acc = "-" if c.linear_max_acceleration is None else f"{c.linear_max_acceleration:g}"
        rows.append([f"`{name}`", f"{c.max_linear:g} / {c.max_angular:g}", acc, f"{period:g} s ({1 / period:g} Hz)",
                     f"{c.max_steps * period:g} s", f"{c.max_steps * period * c.max_linear:g} m",
                     f"{c.reach_radius:g} / {c.clearance_radius:g} m", f"{c.action_scale:g} N·m"])
    c = declared.config
    rows.append(["as declared (before robots had files)", f"{c.max_linear:g} / {c.max_angular:g}",
                 f"{c.linear_max_acceleration:g}", "0.05 s (20 Hz)", f"{c.max_steps * 0.05:g} s",
                 f"{c.max_steps * 0.05 * c.max_linear:g} m", f"{c.reach_radius:g} / {c.clearance_radius:g} m",
                 f"{c.action_scale:g} N·m"])
    return _table(["robot", "action 1: m/s / rad/s", "a [m/s²]", "control period", "episode", "at full speed",
                   "reach / clearance radius", "torque action 1"], ["---"] + ["---:"] * 7, rows)


def robot_policies() -> str:
    """``robot_policies.json``: each shipped robot's deployable nav policy on its own robot (the test set under
    ``wide`` and nominal, and the MuJoCo twin), with the time it took to train from its own
    ``train_to_success_nav_deploy_<robot>.json``."""
    d = _load("robot_policies.json")
    rows = []
    for name, r in d["robots"].items():
        train = _load(f"train_to_success_nav_deploy_{name}.json")
        seeds = train["seeds"]
        reached = [s for s in seeds if s["reached"]]
        wall = train["median"]["wall_s_to_threshold"]
        if len(seeds) > 1:
            when = "not reached by every seed" if wall is None else f"{wall / 60:.1f} min (median of {len(seeds)})"
        else:
            when = f"{wall / 60:.1f} min" if wall is not None else "not reached"
        frames = f"{sorted(s['frames_to_threshold'] for s in reached)[len(reached) // 2]:,}" if reached else "-"
        twin = r.get("mujoco")
        rows.append([f"`{name}`", f"{r['max_linear']:g} m/s, {r['max_angular']:g} rad/s",
                     f"{r['control_period']:g} s", f"{100 * r['wide']['success']:.1f} %",
                     f"{100 * r['nominal']['success']:.1f} %",
                     f"{100 * twin['success']:.1f} % ({twin['episodes']})" if twin else "-", when, frames])
    return _table(["robot", "limits", "period", "`wide` (1,000)", "nominal (1,000)", "MuJoCo twin, nominal µ",
                   "90 % after", "frames then"], ["---"] + ["---:"] * 7, rows)


TABLES: dict[str, Callable[[], str]] = {
    "task_fit": task_fit,
    "robot_policies": robot_policies,
    "robot_check": robot_check,
    "robot_limits": robot_limits,
    "deploy_policy": deploy_policy,
    "deploy_base_limit": deploy_base_limit,
    "deploy_base_limit_old_policy": lambda: deploy_base_limit("deploy_base_limit_old_policy.json"),
    "train_to_success_nav_deploy": train_to_success_nav_deploy,
    "train_to_success_nav_deploy_shipped": train_to_success_nav_deploy_shipped,
    "train_to_success_parking": lambda: _train_to_success("train_to_success_parking.json"),
    "train_to_success_nav_deploy_earlier": lambda: _train_to_success("train_to_success_nav_deploy_earlier.json"),
    "train_to_success_nav_deploy_batch512": lambda: _train_to_success("train_to_success_nav_deploy_batch512.json"),
    "mujoco_odometry_drives": mujoco_odometry_drives,
    "deploy_odometry_scale": deploy_odometry_scale,
    "train_to_success_nav_deploy_slip": lambda: _train_to_success("train_to_success_nav_deploy_slip.json"),
    "mujoco_transfer_wide_slip": lambda: mujoco_transfer("mujoco_transfer_wide_slip.json"),
    "train_to_success_nav_deploy_slip_gain": lambda: _train_to_success("train_to_success_nav_deploy_slip_gain.json"),
    "mujoco_transfer_wide_slip_gain": lambda: mujoco_transfer("mujoco_transfer_wide_slip_gain.json"),
    "diff_gradients_common": diff_gradients_common,
    "diff_gradients_differential": diff_gradients_differential,
    "diff_gradients_friction": diff_gradients_friction,
    "diff_gradients_mass": diff_gradients_mass,
    "diff_gradients_twist_linear": diff_gradients_twist_linear,
    "diff_gradients_twist_angular": diff_gradients_twist_angular,
    "diff_cost": diff_cost,
    "env_throughput": env_throughput,
    "env_scaling": env_scaling,
    "nav_throughput": nav_throughput,
    "calibration_misfit": calibration_misfit,
    "calibration_twin": calibration_twin,
    "calibration_twin_friction_rise": calibration_twin_friction_rise,
    "calibration_twin_validation": calibration_twin_validation,
    "mujoco_transfer_plain": lambda: mujoco_transfer("mujoco_transfer_plain.json"),
    "mujoco_transfer_truth_odometry": lambda: mujoco_transfer("mujoco_transfer_truth_odometry.json"),
    "mujoco_transfer_accel_odometry": lambda: mujoco_transfer("mujoco_transfer_accel_odometry.json"),
    "calibration_sweep_seed1": lambda: calibration_sweep("calibration_sweep_seed1.json"),
    "nav_throughput_cuda": nav_throughput_cuda,
    "ray_collection": ray_collection,
    "step_profile": step_profile,
    "substep_speed": substep_speed,
    "substep_study": substep_study,
    "sac_update_cost": sac_update_cost,
    "calibration": calibration,
    "calibration_data": calibration_data,
    "calibration_sweep": calibration_sweep,
    "calibration_sweep_before_rest_height": lambda: calibration_sweep("calibration_sweep_before_rest_height.json"),
    "coulomb_cost": coulomb_cost,
    "physics_report": physics_report,
    "skid_turning": skid_turning,
    "skid_checks": skid_checks,
    "mujoco_agreement": mujoco_agreement,
    "mujoco_transfer": mujoco_transfer,
    "mujoco_turning_study": mujoco_turning_study,
    "train_to_success": train_to_success,
    "train_to_success_nav": train_to_success_nav,
    "ppo_vs_sac": ppo_vs_sac,
    "video_cost": video_cost,
    "train_to_success_nav_wide": train_to_success_nav_wide,
    "randomization_eval": randomization_eval,
    "randomization_bins": randomization_bins,
    "randomization_cost": randomization_cost,
    "evaluations": evaluations,
    "sim_throughput": sim_throughput,
    "sim_throughput_cuda": sim_throughput_cuda,
    "sim_choices": sim_choices,
    "sim_vs_mujoco": sim_vs_mujoco,
}


# --- the command table, from the command-line tools' own parsers ------------------------------

COMMANDS = (("train", "atrv-train"), ("evaluate", "atrv-evaluate"), ("demo", "atrv-demo"), ("model", "atrv-model"),
            ("export", "atrv-export"), ("calibrate", "atrv-calibrate"), ("ros", "atrv-ros"), ("deploy", "atrv-deploy"),
            ("robot", "atrv-robot"))
"""(``atrv_warp.<module>``, the command ``pyproject.toml`` installs) of every command-line tool."""
COMMANDS_LINE = re.compile(r"^\{\{ command_table( \w+)? \}\}$", re.MULTILINE)


def _cell(text: str) -> str:
    return " ".join(str(text).split()).replace("``", "`").replace("|", "\\|")


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

    from atrv_warp.rl.config import TrainCommand, TrainConfig

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

    return [[f"`-p {name}:=…`", f"`{default!r}`", _cell(text)] for name, default, text in PARAMETERS]


def _deploy_rows() -> list[list[str]]:
    from atrv_warp.deploy.parameters import PARAMETERS

    return (_argparse_rows(_command("deploy").build_parser())
            + [[f"`-p {p.name}:=…`", f"`{p.default!r}`", _cell(p.text)] for p in PARAMETERS])


def _command(module: str):
    import importlib

    return importlib.import_module(f"atrv_warp.{module}")


def command_summary(module: str) -> str:
    """A command's one-line description, from its parser (or, for train and ros, its module docstring)."""
    if module in ("train", "ros"):  # their docstrings, read without importing torchrl or ROS
        import ast

        text = ast.get_docstring(ast.parse((ROOT / "atrv_warp" / f"{module}.py").read_text()))
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
        return _table(["command", "installed as", "what it does"], ["---", "---", "---"],
                      [[f"[`python -m atrv_warp.{m}`](#{m})", f"`{script}`", command_summary(m)] for m, script in COMMANDS]
                      + [["`python -m atrv_warp.evaluate --baseline`", "`atrv-baseline`", "the scripted driver's evaluation"]])
    return _table(["argument", "default", "meaning"], ["---", "---", "---"], command_options(which))


def historical_note(name: str) -> str:
    """The visible note a ``{{ historical FILE }}`` line renders as."""
    st = status(name)
    why = ("written before results files recorded their provenance" if st.state == "unknown"
           else "measured on code that has changed since: " + "; ".join(st.reasons))
    return (f'!!! note "Historical figures: `{name}`"\n    Measured {st.date}, {why}. '
            f"`{redraw_command(name)}` redraws them.")


def render(markdown: str, page: str = "<page>") -> str:
    """``markdown`` with every table and value placeholder replaced, every historical mark turned into its
    note, and every cited file checked (:func:`status`).

    Raises:
        FigureError: naming ``page``, the file and the key, for a missing file or key, an unknown table, a
            historical mark for a file the page does not cite, or a cited file that is stale or of unknown
            provenance and not marked historical.
    """
    global _cited
    _cited = []
    try:
        def table(match: re.Match) -> str:
            name = match.group(1)
            if name not in TABLES:
                raise FigureError(f"unknown results table {name!r}; known: {sorted(TABLES)}")
            return TABLES[name]()

        def value(match: re.Match) -> str:
            return result(match["file"], match["key"].strip(), (match["fmt"] or "").strip())

        def judged(match: re.Match) -> str:
            return verdict(match["file"], match["key"].strip(), match["op"], float(match["bound"]), match["yes"],
                           match["no"])

        try:
            out = VERDICT.sub(judged, RESULT.sub(value, PLACEHOLDER.sub(table, markdown)))
            out = COMMANDS_LINE.sub(lambda m: command_table(m.group(1).strip() if m.group(1) else None), out)
        except FigureError as err:
            raise FigureError(f"{page}: {err}") from err
        cited = list(_cited)
    finally:
        _cited = None
    marked = set(HISTORICAL.findall(markdown))
    problems = [f"{page}: marks {name} historical but cites nothing from it" for name in sorted(marked - set(cited))]
    for name in cited:
        st = status(name)
        if st.current and name in marked:
            problems.append(f"{page}: marks {name} historical, but its figures match the code: remove the mark")
        if not st.current and name not in marked:
            problems.append(f"{page}: cites {name}, whose figures are {st.state} ({'; '.join(st.reasons)}); "
                            f"redraw them (`{redraw_command(name)}`) or mark them with a line "
                            f"{{{{ historical {name} }}}}")
    if problems:
        raise FigureError("\n".join(problems))
    return HISTORICAL.sub(lambda m: historical_note(m["file"]), out)


def citations(markdown: str) -> list[str]:
    """The results files a page cites, in order (rendering it without the checks)."""
    global _cited
    _cited = []
    try:
        for name in PLACEHOLDER.findall(markdown):
            if name in TABLES:
                TABLES[name]()
        for m in itertools.chain(RESULT.finditer(markdown), VERDICT.finditer(markdown)):
            _load(m["file"])
        return list(_cited)
    finally:
        _cited = None


def stale_report(pages: list[Path]) -> tuple[list[str], int]:
    """Lines naming every page's stale or unknown figures and the command that redraws them, and how many are
    not marked historical."""
    lines, unmarked = [], 0
    for page in pages:
        text = page.read_text()
        marked = set(HISTORICAL.findall(text))
        for name in citations(text):
            st = status(name)
            if st.current:
                continue
            unmarked += name not in marked
            label = "historical" if name in marked else "NOT MARKED"
            where = page.relative_to(ROOT) if page.is_relative_to(ROOT) else page
            lines.append(f"{where}: {name} is {st.state} ({'; '.join(st.reasons)}; {st.date}) "
                         f"[{label}] -> {redraw_command(name)}")
    return lines, unmarked


def on_pre_build(**kwargs) -> None:
    """A new build (``mkdocs serve`` rebuilds in one process) checks the files and the code afresh."""
    status.cache_clear()
    current_dynamics.cache_clear()
    current_driver.cache_clear()
    current_task.cache_clear()


def on_page_markdown(markdown: str, page=None, **kwargs) -> str:
    return render(markdown, page.file.src_uri if page is not None else "<page>")


if __name__ == "__main__":
    if sys.argv[1:] != ["--stale"]:
        sys.exit("usage: python docs/hooks.py --stale")
    report, unmarked = stale_report(sorted(DOCS.glob("*.md")))
    print("\n".join(report) or "every cited figure is current")
    sys.exit(1 if unmarked else 0)
