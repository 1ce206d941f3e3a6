"""mkdocs hook: figures drawn from the results files at build time, and checked against the code.

A measured figure lives in its results file alone (``benchmarks/results/*.json``, written by
``benchmarks/_common.write_results`` with its provenance). A page cites it so:

- ``{{ results_table NAME }}`` on a line of its own: the benchmark script that writes the file owns the table: its
  module-level ``TABLES = {"NAME": function}`` maps the name to a function that reads the file(s) with
  ``_common.load_results`` and returns Markdown; :data:`TABLES` gathers every script's (a name twice is an error);
- ``{{ result FILE:KEY.PATH | FORMAT }}`` inline: one value. ``FILE`` is relative to ``benchmarks/results/`` (or
  to the repository when it starts with ``docs/`` or ``benchmarks/``); ``KEY.PATH`` is dict keys and list indices
  joined by dots, and ``[field=value,other=value]`` picks the first list element with those fields; ``FORMAT`` is a
  Python format spec (``.1f``, ``,.0f``), optional; ``.1%`` gives a percentage as the pages write it (``91.3 %``);
- ``{{ verdict FILE:KEY.PATH OP BOUND | WHEN TRUE | WHEN FALSE }}`` inline: a page's verdict on one value (``OP``
  one of ``>=``, ``>``, ``<=``, ``<``): the first text where the value compares so with ``BOUND``, else the second;
- ``![...](NAME.png)``: a picture, whose provenance is a ``tEXt`` chunk of the PNG (``_common.save_figure``: a
  results file's record, plus the sha256 of the results files it is drawn from).

Every figure a page cites is checked against the code as it is now (:func:`status`): the benchmark script's
``VERSION``, the dynamics, driver and task fingerprints (each computed once per build, and kept for the next process
while the package's files are the same: :data:`FINGERPRINT_CACHE`), the fingerprint of each task on a robot it
recorded (:func:`current_task_robot`), the sha256 of each policy
and robot file it ran and, for a picture, of the results files it was drawn from (themselves current). A figure that
no longer matches, or records no provenance, fails the build unless the page marks it historical with a line
``{{ historical FILE }}`` (a picture: ``NAME.png`` as its link writes it), which renders as a note with its date and
the command that redraws it. A missing file or key, an unknown table, or a historical mark for a figure the page does
not cite or that is current fails the build too, naming the page, the file and the key.

Old script paths: where no script is at the path a file recorded (``benchmarks/x.py``, before the scripts moved into
topic folders), the script is the one under ``benchmarks/`` with its file name (:func:`script_path`; names are
unique, a test keeps them so), so a move needs no rerun.

Pages are ``docs/**/*.md``: those under ``docs/studies/`` are the lab record, the others the user pages. ``python
docs/hooks.py --stale`` lists every stale or unknown figure and the command that redraws it, and exits 1 if one is
not marked historical or a user page cites one at all; ``--audit`` lists the results files without provenance, the
superseded snapshots and the files no page cites. Helpers: ``benchmarks/_common.py`` (results files, PNG provenance,
Markdown tables), ``docs/result_values.py`` (``{{ result }}``, ``{{ verdict }}``), ``docs/command_table.py``
(``{{ command_table }}``, ``{{ command_table TOOL }}``: the command-line tools' table, from their parsers).
"""
from __future__ import annotations

import functools
import hashlib
import importlib
import importlib.util
import itertools
import json
import os
import re
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
BENCHMARKS = ROOT / "benchmarks"
sys.path[:0] = [str(ROOT), str(DOCS)]  # the benchmarks package (as `python -m benchmarks...` from the root has it)

from command_table import COMMANDS_LINE, command_table
from result_values import lookup, result, verdict  # noqa: F401 - the values, for the tests and the pages

from benchmarks import _common
from benchmarks._common import FigureError, load_results, results_path

RESULTS = _common.RESULTS
PLACEHOLDER = re.compile(r"^\{\{ results_table (\w+) \}\}$", re.MULTILINE)
RESULT = re.compile(r"\{\{ result (?P<file>[\w./-]+\.json):(?P<key>[^|}]+?)(?: \| (?P<fmt>[^}]*?))? \}\}")
VERDICT = re.compile(r"\{\{ verdict (?P<file>[\w./-]+\.json):(?P<key>[^|}]+?) (?P<op>>=|<=|>|<) (?P<bound>[-+\d.e]+) "
                     r"\| (?P<yes>[^|}]*?) \| (?P<no>[^|}]*?) \}\}")
HISTORICAL = re.compile(r"^\{\{ historical (?P<file>[\w./-]+\.(?:json|png)) \}\}$", re.MULTILINE)
PICTURE = re.compile(r"!\[[^\]]*\]\((?P<file>[\w./-]+\.png)\)")
VERSION_LINE = re.compile(r"^VERSION = (\d+)$", re.MULTILINE)
SUPERSEDED = re.compile(r"(?:^|_)(?:before|old|without|earlier)(?:_|$)")
"""The audit's rule for a superseded snapshot: a results file whose name has a ``before``, ``old``, ``without`` or
``earlier`` part (``X_before_Y.json``): kept beside the file that replaced it."""
_TRAIN = "python -m benchmarks.training.train_to_success --seeds 0 1 2"
PICTURE_COMMANDS = {
    "nav_learning_curve.png": f"{_TRAIN} --config nav --minutes 12 --figure docs/nav_learning_curve.png",
    "nav_wide_learning_curve.png": f"{_TRAIN} --config nav --minutes 12 --out benchmarks/results/"
                                   "train_to_success_nav_wide.json --figure docs/nav_wide_learning_curve.png "
                                   "randomization=wide",
    "nav_deploy_slip_learning_curve.png": f"{_TRAIN} --config nav_deploy --minutes 20 --out benchmarks/results/"
                                          "train_to_success_nav_deploy_slip.json --figure "
                                          "docs/nav_deploy_slip_learning_curve.png"}
"""The command that draws each picture drawn before pictures recorded their provenance (one with provenance records
its own); the studies show them as historical."""


# --- the tables, owned by the benchmark scripts ---------------------------------------------------------------

def benchmark_tables() -> dict[str, Callable[[], str]]:
    """Every benchmark script's ``TABLES``, imported from ``benchmarks/<topic>/*.py`` (the scripts that define one)."""
    tables: dict[str, Callable[[], str]] = {}
    owner: dict[str, Path] = {}
    for path in sorted(BENCHMARKS.glob("*/*.py")):
        if not re.search(r"^TABLES = ", path.read_text(), re.MULTILINE):
            continue
        module = importlib.import_module(".".join(path.relative_to(BENCHMARKS.parent).with_suffix("").parts))
        for name, function in module.TABLES.items():
            if name in tables:
                raise FigureError(f"results table {name!r} is defined by both {owner[name]} and {path}")
            tables[name], owner[name] = function, path
    return tables


TABLES = benchmark_tables()


# --- provenance ---------------------------------------------------------------------------------

FINGERPRINT_CACHE = "ATRV_WARP_FINGERPRINT_CACHE"
"""The variable naming the file where the fingerprints of the code as it is are kept between processes (default
``$XDG_CACHE_HOME/atrv_warp/fingerprints.json``, else ``~/.cache/...``): the docs build computes them, and the tests
that render the pages read them instead of running the same rollouts again."""


def code_digest() -> str:
    """What the fingerprints are a function of: the sha256 of every file of the package (its code, robot files,
    policies and configs), with the Python, Warp, Newton, torch and numpy versions and the machine."""
    import platform
    from importlib import metadata

    digest = hashlib.sha256()
    for path in sorted(p for p in (ROOT / "atrv_warp").rglob("*") if p.is_file() and "__pycache__" not in p.parts):
        digest.update(str(path.relative_to(ROOT)).encode() + b"\0" + path.read_bytes() + b"\0")
    versions = [platform.python_version(), platform.machine()]
    versions += [metadata.version(name) for name in ("warp-lang", "newton", "torch", "numpy")]
    digest.update(" ".join(versions).encode())
    return digest.hexdigest()


def fingerprint_cache() -> Path:
    """The file of :data:`FINGERPRINT_CACHE`."""
    named = os.environ.get(FINGERPRINT_CACHE)
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return Path(named) if named else base / "atrv_warp" / "fingerprints.json"


def _fingerprint_now(module: str, function: str) -> Callable[[], str]:
    key = f"{module}.{function}"

    @functools.cache
    def now() -> str:
        path, code = fingerprint_cache(), code_digest()
        try:
            kept = json.loads(path.read_text())
        except (OSError, ValueError):
            kept = {}
        if not isinstance(kept, dict) or kept.get("code") != code:
            kept = {"code": code, "values": {}}
        if key not in kept["values"]:
            kept["values"][key] = getattr(importlib.import_module(module), function)()
            try:  # written whole, then renamed: another process reads the old file or the new one
                path.parent.mkdir(parents=True, exist_ok=True)
                tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
                tmp.write_text(json.dumps(kept))
                tmp.replace(path)
            except OSError:
                pass  # a read-only home: computed, not kept
        return kept["values"][key]

    now.__doc__ = (f"``{key}()`` of the code as it is now: computed once per process, and kept in "
                   f"{FINGERPRINT_CACHE} for the next process while the package's files are the same "
                   "(:func:`code_digest`).")
    return now


current_dynamics = _fingerprint_now("atrv_warp.sim.fingerprints", "dynamics_fingerprint")  # a 2-s rollout
current_driver = _fingerprint_now("atrv_warp.sim.fingerprints", "driver_fingerprint")
current_task = _fingerprint_now("atrv_warp.task.fingerprints", "task_fingerprint")  # short rollouts of reach and nav


@functools.cache
def current_task_robot(key: str) -> str:
    """The current :func:`~atrv_warp.task.fingerprints.task_robot_fingerprint` of ``'task@robot'`` (a declaration,
    not a rollout: cheap, computed here); ``'gone: ...'`` where the task or the robot no longer loads."""
    from atrv_warp.task.fingerprints import task_robot_fingerprint

    task, _, robot = key.partition("@")
    try:
        return task_robot_fingerprint(task, robot)
    except ValueError as err:  # an unknown task; a robot file that does not load (RobotFileError)
        return f"gone: {err}"


def script_path(recorded: str) -> str:
    """Where the script a file recorded is now: the recorded path if a file is there, else the one script under
    ``benchmarks/`` with its file name (a script moved into a topic folder), else the recorded path."""
    if (ROOT / recorded).is_file() or not recorded.startswith("benchmarks/"):
        return recorded
    found = [p for p in BENCHMARKS.rglob(Path(recorded).name) if RESULTS not in p.parents]
    return str(found[0].relative_to(ROOT)) if len(found) == 1 else recorded


def script_version(script: str) -> int | None:
    """``VERSION`` of a benchmark script as it is now (:func:`script_path`), read from its text (no import)."""
    path = ROOT / script_path(script)
    m = VERSION_LINE.search(path.read_text()) if path.is_file() else None
    return int(m.group(1)) if m else None


def _provenance(name: str) -> dict | None:
    if name.endswith(".png"):
        path = ROOT / name
        if not path.is_file():
            raise FigureError(f"picture {name} not found ({path})")
        return _common.png_provenance(path)
    d = load_results(name)
    return d.get("provenance") if isinstance(d, dict) else None


def redraw_command(name: str) -> str:
    """The command that writes figure ``name``: the one it recorded, else its recorded script, else (a picture)
    :data:`PICTURE_COMMANDS`'s, else the benchmark whose name is the longest prefix of the file's; a recorded
    script that has moved is named where it is now (:func:`script_path`)."""
    try:
        p = _provenance(name) or {}
    except FigureError:
        p = {}
    if "command" in p:
        return re.sub(r"python (benchmarks/[\w/]+\.py)", lambda m: " ".join(_common.run_command(ROOT / script_path(m[1]))),
                      p["command"], count=1)
    script = p.get("script")
    if script is None and Path(name).name in PICTURE_COMMANDS:
        return PICTURE_COMMANDS[Path(name).name]
    if script is None and name.startswith("docs/"):
        return "python -m atrv_warp.evaluate --json " + name
    if script is None:
        stem = Path(name).parent.name if "/" in name else Path(name).stem
        scripts = sorted((p for p in BENCHMARKS.glob("*/*.py") if stem.startswith(p.stem)), key=lambda p: -len(p.stem))
        script = str(scripts[0].relative_to(ROOT)) if scripts else "?"
    return " ".join(_common.run_command(ROOT / script_path(script)))


class Status:
    """Whether a figure (a results file, a picture) matches the code as it is now: ``state`` is ``"current"``,
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


def _sha256(path: Path) -> str:
    """A file's SHA-256; a robot file's, of its identity (its bytes less its ``[deploy]`` table)."""
    if path.suffix == ".toml":
        from atrv_warp.core.robot import robot_file_sha256

        return robot_file_sha256(path)
    return hashlib.sha256(path.read_bytes()).hexdigest()


@functools.cache
def status(name: str) -> Status:
    """Check figure ``name`` (a results file, or a picture ``docs/NAME.png``) against the script's ``VERSION``, the
    fingerprints, the policies and robot files it ran and, for a picture, the results files it was drawn from."""
    p = _provenance(name)
    path = ROOT / name if name.endswith(".png") else results_path(name)
    if p is None:
        d = {} if name.endswith(".png") else load_results(name)
        when = d.get("time", "") if isinstance(d, dict) else ""
        return Status(name, "unknown", ["no provenance recorded"], when[:10] if when else f"{_git_date(path)} or earlier")
    reasons = []
    version = script_version(p["script"])
    if version != p["script_version"]:
        reasons.append(f"{p['script']} VERSION is {version}, the file was written by VERSION {p['script_version']}")
    for key, now, what in (("dynamics", current_dynamics, "dynamics"), ("driver", current_driver, "motor driver"),
                           ("task", current_task, "task")):
        if key in p and p[key] != now():
            reasons.append(f"{what} fingerprint {p[key]} != {now()} now")
    for key, digest in p.get("tasks", {}).items():
        now = current_task_robot(key)
        if digest != now:
            reasons.append(f"{key} fingerprint {digest} != {now} now (its task or robot file changed)")
    for kind, files in (("policy", p.get("policies", {})), ("robot file", p.get("robots", {}))):
        for file, digest in files.items():
            path = ROOT / file
            if not path.is_file():
                reasons.append(f"{kind} {file} is gone")
            elif _sha256(path) != digest:
                reasons.append(f"{kind} {file} has changed")
    for file, digest in p.get("results", {}).items():
        path = results_path(file)
        if not path.is_file() or hashlib.sha256(path.read_bytes()).hexdigest() != digest:
            reasons.append(f"results file {file} has changed since the picture was drawn")
        elif not status(file).current:
            reasons.append(f"drawn from {file}, whose figures are {status(file).state}")
    return Status(name, "stale" if reasons else "current", reasons, p["date"][:10])



# --- pages --------------------------------------------------------------------------------------

def historical_note(name: str, figure: str | None = None) -> str:
    """The visible note a ``{{ historical FILE }}`` line renders as (``figure``: a picture's repository path)."""
    st = status(figure or name)
    why = ("written before results files recorded their provenance" if st.state == "unknown"
           else "measured on code that has changed since: " + "; ".join(st.reasons))
    return (f'!!! note "Historical figures: `{name}`"\n    Measured {st.date}, {why}. '
            f"`{redraw_command(figure or name)}` redraws them.")


def pictures(markdown: str, page: str = "<page>") -> dict[str, str]:
    """The pictures (PNG) a page shows: the link as written -> its repository path (``docs/NAME.png``)."""
    folder = DOCS / Path(page).parent if page != "<page>" else DOCS
    return {m["file"]: os.path.relpath(os.path.normpath(folder / m["file"]), ROOT) for m in PICTURE.finditer(markdown)}


def render(markdown: str, page: str = "<page>") -> str:
    """``markdown`` with every table and value placeholder replaced, every historical mark turned into its
    note, and every cited file and picture checked (:func:`status`).

    Raises:
        FigureError: naming ``page``, the file and the key, for a missing file or key, an unknown table, a
            historical mark for a file the page does not cite, or a cited file or picture that is stale or of
            unknown provenance and not marked historical.
    """
    _common.CITED = []
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
        cited = list(_common.CITED)
    finally:
        _common.CITED = None
    shown = pictures(markdown, page)
    marked = set(HISTORICAL.findall(markdown))
    problems = [f"{page}: marks {name} historical but cites nothing from it"
                for name in sorted(marked - set(cited) - set(shown))]
    for name, figure in [(c, c) for c in cited] + list(shown.items()):
        try:
            st = status(figure)
        except FigureError as err:
            problems.append(f"{page}: {err}")
            continue
        if st.current and name in marked:
            problems.append(f"{page}: marks {name} historical, but its figures match the code: remove the mark")
        if not st.current and name not in marked:
            problems.append(f"{page}: cites {name}, whose figures are {st.state} ({'; '.join(st.reasons)}); "
                            f"redraw them (`{redraw_command(figure)}`) or mark them with a line "
                            f"{{{{ historical {name} }}}}")
    if problems:
        raise FigureError("\n".join(problems))
    return HISTORICAL.sub(lambda m: historical_note(m["file"], shown.get(m["file"])), out)


def citations(markdown: str, page: str = "<page>") -> list[str]:
    """The figures a page cites, in order: its results files (rendering it without the checks), then its
    pictures' repository paths."""
    _common.CITED = []
    try:
        for name in PLACEHOLDER.findall(markdown):
            if name in TABLES:
                TABLES[name]()
        for m in itertools.chain(RESULT.finditer(markdown), VERDICT.finditer(markdown)):
            load_results(m["file"])
        return list(_common.CITED) + list(pictures(markdown, page).values())
    finally:
        _common.CITED = None


def pages() -> list[Path]:
    """Every page: ``docs/**/*.md``."""
    return sorted(DOCS.rglob("*.md"))


def is_user_page(page: Path) -> bool:
    """A user page: a page not under ``docs/studies/`` (the lab record)."""
    return "studies" not in page.relative_to(DOCS).parts[:-1] if page.is_relative_to(DOCS) else True


def stale_report(pages: list[Path]) -> tuple[list[str], int]:
    """Lines naming every page's stale or unknown figures and the command that redraws them, and how many fail
    ``--stale``: those not marked historical, and every one a user page cites (a transitional picture aside)."""
    lines, failing = [], 0
    for page in pages:
        text = page.read_text()
        where = page.relative_to(ROOT) if page.is_relative_to(ROOT) else page
        src = str(page.relative_to(DOCS)) if page.is_relative_to(DOCS) else "<page>"
        marked, shown = set(HISTORICAL.findall(text)), {v: k for k, v in pictures(text, src).items()}
        for name in citations(text, src):
            st = status(name)
            if st.current:
                continue
            link = shown.get(name, name)
            label = "historical" if link in marked else "NOT MARKED"
            failing += label == "NOT MARKED" or (label == "historical" and is_user_page(page))
            lines.append(f"{where}: {name} is {st.state} ({'; '.join(st.reasons)}; {st.date}) "
                         f"[{label}] -> {redraw_command(name)}")
    return lines, failing


def audit() -> list[str]:
    """The results files without provenance, the superseded snapshots (:data:`SUPERSEDED`) and the files no page
    cites, one section each; and the pictures without provenance."""
    files = sorted(str(p.relative_to(RESULTS)) for p in RESULTS.rglob("*.json"))
    unknown = [f for f in files if _provenance(f) is None]
    superseded = [f for f in files if SUPERSEDED.search(Path(f).stem)]
    cited = {c for page in pages() for c in citations(page.read_text(), str(page.relative_to(DOCS)))}
    uncited = [f for f in files if f not in cited]
    pngs = sorted(str(p.relative_to(ROOT)) for p in DOCS.rglob("*.png"))
    bare = [p for p in pngs if _common.png_provenance(ROOT / p) is None]
    out = []
    for title, names in ((f"results files without provenance ({len(files)} files in all)", unknown),
                         ("superseded snapshots (rule: a name with a before, old, without or earlier part)", superseded),
                         ("results files no page cites (docs/**/*.md)", uncited),
                         ("pictures without provenance (docs/**/*.png)", bare)):
        out += [f"== {title}: {len(names)}", *(f"  {n}" for n in names), ""]
    return out


def on_pre_build(**kwargs) -> None:
    """A new build (``mkdocs serve`` rebuilds in one process) checks the files and the code afresh."""
    for cached in (status, current_dynamics, current_driver, current_task):
        cached.cache_clear()


def on_page_markdown(markdown: str, page=None, **kwargs) -> str:
    return render(markdown, page.file.src_uri if page is not None else "<page>")


if __name__ == "__main__":
    if sys.argv[1:] not in (["--stale"], ["--audit"]):
        sys.exit("usage: python docs/hooks.py --stale | --audit")
    report, failing = (audit(), 0) if sys.argv[1] == "--audit" else stale_report(pages())
    print("\n".join(report) or "every cited figure is current")
    sys.exit(1 if failing else 0)
