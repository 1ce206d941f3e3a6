"""The docs' figures are traceable: a page's cited values come from the results files, and a results
file whose provenance no longer matches the code fails the build unless the page marks it historical
(``docs/hooks.py``; the provenance is written by ``benchmarks/_common.write_results``)."""

from __future__ import annotations

import hashlib
import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture
def hooks(tmp_path, monkeypatch):
    """docs/hooks.py with its results folder in ``tmp_path`` and the dynamics fingerprint pinned to ``"now"``."""
    spec = importlib.util.spec_from_file_location("docs_hooks_under_test", ROOT / "docs" / "hooks.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    monkeypatch.setattr(module, "RESULTS", tmp_path)
    monkeypatch.setattr(module._common, "RESULTS", tmp_path)  # noqa: SLF001 - where load_results reads
    monkeypatch.setattr(module, "current_dynamics", lambda: "now")
    monkeypatch.setattr(module, "current_task", lambda: "now")
    return module


def _write(folder: Path, name: str, figures: dict, **provenance) -> None:
    record = {"date": "2026-11-20T10:00:00Z", "commit": "0" * 40, "dirty": False,
              "script": "benchmarks/physics_report.py", "script_version": 1, "dynamics": "now", **provenance}
    (folder / name).write_text(json.dumps({**figures, "provenance": record}))


def test_a_current_figure_renders_from_its_file(hooks, tmp_path):
    _write(tmp_path, "r.json", {"rows": [{"n": 64, "rate": 1234.5}, {"n": 1024, "rate": 0.9132}]})
    page = ("A {{ result r.json:rows.0.rate | ,.0f }}, B {{ result r.json:rows[n=1024].rate | .1% }}, "
            "C {{ result r.json:rows.1.n }}, D {{ result r.json:rows[n=64,rate=1234.5].n }}.")
    assert hooks.render(page, "p.md") == "A 1,234, B 91.3 %, C 1024, D 64."


def test_a_verdict_follows_its_figure(hooks, tmp_path):
    """A page's verdict on a figure is drawn from the file with it: when the figure moves, so does the verdict."""
    page = ("{{ result r.json:rows[n=1].success | .1% }}, {{ verdict r.json:rows[n=1].success >= 0.8 | past the target "
            "| short of it }}; {{ verdict r.json:rows[n=1].success < 0.8 | under | not under }}.")
    _write(tmp_path, "r.json", {"rows": [{"n": 1, "success": 0.805}]})
    assert hooks.render(page, "p.md") == "80.5 %, past the target; not under."
    _write(tmp_path, "r.json", {"rows": [{"n": 1, "success": 0.795}]})
    assert hooks.render(page, "p.md") == "79.5 %, short of it; under."
    _write(tmp_path, "old.json", {"x": 0.9}, dynamics="before")  # a verdict cites its file, so it goes stale too
    with pytest.raises(hooks.FigureError, match=r"p\.md: cites old\.json, whose figures are stale"):
        hooks.render("{{ verdict old.json:x > 0.5 | yes | no }}", "p.md")
    assert hooks.citations("{{ verdict old.json:x > 0.5 | yes | no }}") == ["old.json"]
    _write(tmp_path, "r.json", {"rows": [{"n": 1, "success": "many"}]})
    with pytest.raises(hooks.FigureError, match=r"p\.md: results file r\.json, key 'rows\[n=1\]\.success': a verdict "
                                                r"needs a number, got 'many'"):
        hooks.render("{{ verdict r.json:rows[n=1].success >= 0.8 | yes | no }}", "p.md")


def test_a_missing_file_or_key_names_the_page_file_and_key(hooks, tmp_path):
    _write(tmp_path, "r.json", {"rows": [{"n": 64}]})
    with pytest.raises(hooks.FigureError, match=r"p\.md: .*results file gone\.json not found"):
        hooks.render("{{ result gone.json:x }}", "p.md")
    with pytest.raises(hooks.FigureError, match=r"p\.md: results file r\.json has no key 'rows\.0\.rate'"):
        hooks.render("{{ result r.json:rows.0.rate }}", "p.md")
    with pytest.raises(hooks.FigureError, match=r"p\.md: results file r\.json has no key 'rows\[n=5\]\.n': no element with n=5"):
        hooks.render("{{ result r.json:rows[n=5].n }}", "p.md")


def test_a_stale_fingerprint_fails_unless_the_page_marks_it_historical(hooks, tmp_path):
    _write(tmp_path, "old.json", {"x": 0.5}, dynamics="before")
    with pytest.raises(hooks.FigureError, match=r"p\.md: cites old\.json, whose figures are stale "
                                                r"\(dynamics fingerprint before != now now\)"):
        hooks.render("x = {{ result old.json:x }}", "p.md")
    out = hooks.render("x = {{ result old.json:x }}\n\n{{ historical old.json }}\n", "p.md")
    assert out.startswith("x = 0.5\n")
    assert '!!! note "Historical figures: `old.json`"' in out
    # the file recorded benchmarks/physics_report.py, which has moved into physics/: named where it is now
    assert "Measured 2026-11-20" in out and "`python -m benchmarks.physics.physics_report` redraws them" in out
    _write(tmp_path, "new.json", {"x": 0.5})
    with pytest.raises(hooks.FigureError, match="p.md: marks new.json historical, but its figures match the code"):
        hooks.render("{{ result new.json:x }}\n{{ historical new.json }}\n", "p.md")


def test_a_changed_task_is_stale(hooks, tmp_path):
    _write(tmp_path, "t.json", {"x": 1}, task="before")
    assert hooks.status("t.json").reasons == ["task fingerprint before != now now"]
    _write(tmp_path, "u.json", {"x": 1}, task="now")
    assert hooks.status("u.json").current


def test_a_changed_task_on_a_robot_is_stale(hooks, tmp_path):
    """A file of ``nav_deploy`` on the Jackal (a pair the reach/nav rollouts cannot see) goes stale when that pair's
    declaration changes, and names a task that is gone (issue 69, part 6)."""
    from atrv_warp.task.fingerprints import task_robot_fingerprint

    now = task_robot_fingerprint("nav_deploy", "jackal")
    _write(tmp_path, "j.json", {"x": 1}, tasks={"nav_deploy@jackal": now})
    assert hooks.status("j.json").current
    _write(tmp_path, "k.json", {"x": 1}, tasks={"nav_deploy@jackal": "before", "nav@husky": "x"})
    assert hooks.status("k.json").reasons[0] == (f"nav_deploy@jackal fingerprint before != {now} now (its task or "
                                                 "robot file changed)")
    _write(tmp_path, "g.json", {"x": 1}, tasks={"gone@jackal": "before"})
    assert "gone@jackal fingerprint before != gone: unknown task 'gone'" in hooks.status("g.json").reasons[0]


def test_a_changed_script_version_or_policy_is_stale(hooks, tmp_path, monkeypatch):
    _write(tmp_path, "v.json", {"x": 1}, script_version=0)
    assert hooks.status("v.json").state == "stale"
    assert "VERSION is 1, the file was written by VERSION 0" in hooks.status("v.json").reasons[0]
    policy = tmp_path / "p.pt"
    policy.write_bytes(b"weights")
    monkeypatch.setattr(hooks, "ROOT", tmp_path.parent)
    rel = f"{tmp_path.name}/p.pt"
    _write(tmp_path, "p.json", {"x": 1}, script="benchmarks/nope.py", script_version=None,
           policies={rel: hashlib.sha256(b"weights").hexdigest()})
    assert hooks.status("p.json").current
    hooks.status.cache_clear()
    policy.write_bytes(b"retrained")
    assert hooks.status("p.json").reasons == [f"policy {rel} has changed"]


def test_a_file_without_provenance_is_unknown_and_a_mark_must_cite(hooks, tmp_path):
    (tmp_path / "legacy.json").write_text(json.dumps({"x": 2, "time": "2026-11-01 09:00:00"}))
    with pytest.raises(hooks.FigureError, match="legacy.json, whose figures are unknown"):
        hooks.render("{{ result legacy.json:x }}", "p.md")
    assert "Measured 2026-11-01, written before" in hooks.render("{{ result legacy.json:x }}\n{{ historical legacy.json }}")
    with pytest.raises(hooks.FigureError, match="p.md: marks legacy.json historical but cites nothing from it"):
        hooks.render("{{ historical legacy.json }}", "p.md")


def test_the_stale_command_lists_each_figure_and_its_benchmark(hooks, tmp_path):
    _write(tmp_path, "sim_throughput_x.json", {"x": 1}, dynamics="before", script="benchmarks/sim_throughput.py")
    (tmp_path / "page.md").write_text("{{ result sim_throughput_x.json:x }}\n")
    lines, unmarked = hooks.stale_report([tmp_path / "page.md"])
    assert unmarked == 1
    assert "sim_throughput_x.json is stale" in lines[0]
    assert "[NOT MARKED] -> python -m benchmarks.perf.sim_throughput" in lines[0]


def test_every_shipped_page_renders_and_a_current_file_matches_the_code():
    """The real pages against the real results files, with the dynamics fingerprint recomputed."""
    spec = importlib.util.spec_from_file_location("docs_hooks_real", ROOT / "docs" / "hooks.py")
    hooks = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hooks)
    for page in sorted((ROOT / "docs").rglob("*.md")):
        hooks.render(page.read_text(), str(page.relative_to(ROOT / "docs")))
    assert hooks.status("physics_report.json").current, hooks.status("physics_report.json").reasons


def test_write_results_records_provenance(tmp_path):
    spec = importlib.util.spec_from_file_location("benchmarks_common", ROOT / "benchmarks" / "_common.py")
    _common = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(_common)
    out = _common.write_results(tmp_path / "r.json", {"x": 1}, version=3, dynamics=False,
                                policies=(ROOT / "atrv_warp" / "assets" / "pretrained_policy.pt",))
    p = json.loads(out.read_text())["provenance"]
    assert p["script_version"] == 3 and len(p["commit"]) == 40 and isinstance(p["dirty"], bool)
    assert "dynamics" not in p and "task" not in p and p["command"].startswith("python ")  # pytest is the script being run here
    digest = hashlib.sha256((ROOT / "atrv_warp/assets/pretrained_policy.pt").read_bytes()).hexdigest()
    assert p["policies"] == {"atrv_warp/assets/pretrained_policy.pt": digest}


def test_a_results_file_records_its_policies_task_on_its_robot(tmp_path):
    """With ``task=True``, each policy's recorded (task, robot) and the pairs named are recorded beside the reach/nav
    fingerprint, each under ``task@robot``."""
    from atrv_warp.policy import shipped_policy_path
    from atrv_warp.task.fingerprints import task_robot_fingerprint

    spec = importlib.util.spec_from_file_location("common_under_test", ROOT / "benchmarks" / "_common.py")
    _common = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(_common)
    p = _common.provenance(1, dynamics=False, policies=(shipped_policy_path("nav_deploy_jackal"),))
    assert "tasks" not in p  # the figures do not depend on the tasks
    p = _common.provenance(1, dynamics=False, task=True, policies=(shipped_policy_path("nav_deploy_jackal"),),
                           tasks=(("reach", "husky"), ("nav_deploy", "jackal")))
    assert p["tasks"] == {"reach@husky": task_robot_fingerprint("reach", "husky"),
                          "nav_deploy@jackal": task_robot_fingerprint("nav_deploy", "jackal")}, p["tasks"]


def test_the_dynamics_fingerprint_is_behaviour():
    from atrv_warp.sim import ContactConfig
    from atrv_warp.sim.fingerprints import dynamics_fingerprint

    now = dynamics_fingerprint()
    assert now == dynamics_fingerprint() and len(now) == 16
    assert dynamics_fingerprint(contact=ContactConfig(friction_law="viscous")) != now


def test_a_fingerprint_is_read_from_the_build_while_the_code_is_the_same(hooks, tmp_path, monkeypatch):
    """The docs build keeps its fingerprints (``ATRV_WARP_FINGERPRINT_CACHE``); a later process reads them while the
    package's files are the same (:func:`code_digest`), and computes them again otherwise."""
    cache = tmp_path / "fingerprints.json"
    monkeypatch.setenv(hooks.FINGERPRINT_CACHE, str(cache))
    code = hooks.code_digest()
    assert code == hooks.code_digest() and len(code) == 64
    cache.write_text(json.dumps({"code": code, "values": {"os.getcwd": "as the build computed it"}}))
    assert hooks._fingerprint_now("os", "getcwd")() == "as the build computed it"  # noqa: SLF001 - the factory
    cache.write_text(json.dumps({"code": "other code", "values": {"os.getcwd": "stale"}}))
    import os

    assert hooks._fingerprint_now("os", "getcwd")() == os.getcwd()  # noqa: SLF001
    assert json.loads(cache.read_text()) == {"code": code, "values": {"os.getcwd": os.getcwd()}}
    cache.write_text("{not json")  # a damaged file is computed again, not an error
    assert hooks._fingerprint_now("os", "getcwd")() == os.getcwd()  # noqa: SLF001


def test_the_command_table_comes_from_the_parsers():
    """Every installed command is in the table, and every argument of every argparse tool is listed."""
    import tomllib

    spec = importlib.util.spec_from_file_location("docs_command_table", ROOT / "docs" / "command_table.py")
    hooks = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hooks)
    overview = hooks.command_table()
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    for script in scripts:
        assert f"`{script}`" in overview, script
    for module, _ in hooks.COMMANDS:
        if module in ("train", "ros"):
            continue
        table = hooks.command_table(module)
        parser = hooks._command(module).build_parser()  # noqa: SLF001 - where the command's code is
        for action in parser._actions:  # noqa: SLF001
            for option in action.option_strings:
                assert option in table or option in ("-h", "--help"), (module, option)
    assert "`--resume`" in hooks.command_table("train") and "`-p num_rovers:=…`" in hooks.command_table("ros")
    assert "{{ command_table }}" in (ROOT / "docs" / "commands.md").read_text()


def test_the_nav_caption_is_written_from_the_outcomes():
    """docs/make_pictures.py writes the picture's caption from how its episodes ended; the shipped one matches
    its outcomes and the policy it ran."""
    spec = importlib.util.spec_from_file_location("docs_make_pictures", ROOT / "docs" / "make_pictures.py")
    pictures = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(pictures)
    caption = pictures.nav_caption({"scripted driver": ["obstacle", "wall", "obstacle"],
                                    "nav policy (SAC)": ["success", "success", "success"],
                                    pictures.DEPLOY: ["success", "obstacle", "timeout"]}, 7)
    assert "first 3 episodes" in caption and "(seed 7)" in caption
    assert "reaches the target in none of the 3 and runs into an obstacle in 2 of the 3" in caption
    assert "reaches it in all 3 and touches an obstacle in none of the 3" in caption
    assert "dotted) reaches it in 1 of the 3 and touches an obstacle in 1 of the 3" in caption
    shipped = json.loads((ROOT / "docs" / "nav.json").read_text())
    assert shipped["caption"] == pictures.nav_caption(shipped["outcomes"], shipped["seed"])
    policies = [ROOT / "atrv_warp" / "assets" / name for name in ("nav_policy.pt", "nav_deploy_atrvjr_policy.pt")]
    assert shipped["provenance"]["policies"] == {str(p.relative_to(ROOT)): hashlib.sha256(p.read_bytes()).hexdigest()
                                                 for p in policies}


def test_mkdocs_build_fails_naming_the_page_file_and_key(tmp_path):
    """End to end: a site built with docs/hooks.py fails on a page that cites a key its results file lacks."""
    import shutil
    import subprocess

    mkdocs = shutil.which("mkdocs")
    if mkdocs is None:
        pytest.skip("mkdocs is not installed (the docs extra)")
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "index.md").write_text("# Site\n\nx = {{ result physics_report.json:rows.0.no_such_key }}\n")
    (tmp_path / "mkdocs.yml").write_text(f"site_name: t\nstrict: true\nhooks:\n  - {ROOT / 'docs' / 'hooks.py'}\n")
    run = subprocess.run([mkdocs, "build", "--strict", "-q"], cwd=tmp_path, capture_output=True, text=True, check=False)
    assert run.returncode != 0
    assert "index.md: results file physics_report.json has no key 'rows.0.no_such_key'" in run.stderr, run.stderr[-2000:]


# --- the benchmarks own their tables; old script paths; the audit; pictures ------------------------------------

def test_each_table_comes_from_the_benchmark_that_writes_its_file(hooks):
    """``{{ results_table NAME }}`` is found in the module-level ``TABLES`` of a benchmark script; importing the
    scripts to find them imports neither torch nor warp (the hook's import stays light)."""
    import subprocess
    import sys

    assert hooks.TABLES["physics_report"].__module__ == "benchmarks.physics.physics_report"
    assert hooks.TABLES["sim_throughput_cuda"].__module__ == "benchmarks.perf.sim_throughput"
    code = ("import sys; sys.path.insert(0, 'docs'); import hooks; "
            "assert len(hooks.TABLES) > 50; print(sorted(m for m in ('torch', 'warp') if m in sys.modules))")
    run = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    assert run.stdout.strip() == "[]", run.stdout + run.stderr


def test_a_table_name_twice_is_an_error(hooks, tmp_path, monkeypatch):
    import sys

    package = tmp_path / "twice_benchmarks"  # imported as the package's modules are: by module name
    for topic in ("a", "b"):
        (package / topic).mkdir(parents=True)
        (package / topic / f"{topic}_script.py").write_text('TABLES = {"same": lambda: "x"}\n')
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(hooks, "BENCHMARKS", package)
    with pytest.raises(hooks.FigureError, match="results table 'same' is defined by both"):
        hooks.benchmark_tables()
    (package / "b" / "b_script.py").write_text('TABLES = {"other": lambda: "| y |"}\n')
    monkeypatch.delitem(sys.modules, "twice_benchmarks.b.b_script")
    assert {name: f() for name, f in hooks.benchmark_tables().items()} == {"same": "x", "other": "| y |"}


def test_an_old_script_path_is_found_by_its_name(hooks, tmp_path):
    """A results file written before the scripts moved into topic folders stays current: its script is found by
    file name, and its recorded command names the script where it is now."""
    assert hooks.script_path("benchmarks/sim_throughput.py") == "benchmarks/perf/sim_throughput.py"
    assert hooks.script_path("benchmarks/perf/sim_throughput.py") == "benchmarks/perf/sim_throughput.py"
    assert hooks.script_path("benchmarks/gone.py") == "benchmarks/gone.py"
    version = hooks.script_version("benchmarks/sim_throughput.py")
    assert version is not None and hooks.script_version("benchmarks/perf/sim_throughput.py") == version
    _write(tmp_path, "s.json", {"x": 1}, script="benchmarks/sim_throughput.py", script_version=version,
           command="python benchmarks/sim_throughput.py --seconds 2")
    assert hooks.status("s.json").current
    assert hooks.redraw_command("s.json") == "python -m benchmarks.perf.sim_throughput --seconds 2"


def test_script_names_are_unique_across_topics():
    """The old-path rule finds a script by its file name, so no two scripts under benchmarks/ share one."""
    names = [p.name for p in (ROOT / "benchmarks").rglob("*.py") if "results" not in p.parts and p.name != "__init__.py"]
    assert len(names) == len(set(names)), sorted(n for n in names if names.count(n) > 1)


def test_the_audit_lists_unknown_superseded_and_uncited_files(hooks, tmp_path, monkeypatch):
    docs = tmp_path / "site"
    docs.mkdir()
    _write(tmp_path, "cited.json", {"x": 1})
    _write(tmp_path, "cited_before_fix.json", {"x": 1})
    (tmp_path / "legacy.json").write_text(json.dumps({"x": 2}))
    (docs / "page.md").write_text("{{ result cited.json:x }} and {{ result cited_before_fix.json:x }}\n")
    monkeypatch.setattr(hooks, "DOCS", docs)
    out = "\n".join(hooks.audit())
    assert "== results files without provenance (3 files in all): 1\n  legacy.json\n" in out
    assert "superseded snapshots (rule: a name with a before, old, without or earlier part): 1\n" \
           "  cited_before_fix.json\n" in out
    assert "== results files no page cites (docs/**/*.md): 1\n  legacy.json\n" in out


def _figure_png(path: Path, common, **provenance) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(2, 1))
    ax.plot([0, 1], [0, 1])
    common.save_figure(fig, path, version=1, **provenance)
    plt.close(fig)


def test_a_picture_carries_its_provenance_and_goes_stale(hooks, tmp_path, monkeypatch):
    """``save_figure`` writes the provenance into the PNG (a tEXt chunk), the hook reads it back: the picture is
    current, then stale when the dynamics or a results file it was drawn from changes; a stale or bare picture
    fails the page unless marked historical."""
    common = hooks._common  # noqa: SLF001 - benchmarks/_common.py, as the hook imports it
    monkeypatch.setattr(hooks, "ROOT", tmp_path)
    monkeypatch.setattr(hooks, "DOCS", tmp_path / "docs")
    monkeypatch.setattr(hooks, "script_version", lambda script: 1)
    _write(tmp_path, "r.json", {"x": 1})
    png = tmp_path / "docs" / "fig.png"
    _figure_png(png, common, results=("r.json",))
    record = common.png_provenance(png)
    assert record["script_version"] == 1 and record["results"] == {
        "r.json": hashlib.sha256((tmp_path / "r.json").read_bytes()).hexdigest()}
    assert png.read_bytes().startswith(b"\x89PNG") and common.png_chunks(png.read_bytes())[0][0] == b"IHDR"
    assert hooks.render("![a figure](fig.png)", "p.md") == "![a figure](fig.png)"
    assert hooks.status("docs/fig.png").current
    hooks.status.cache_clear()
    _write(tmp_path, "r.json", {"x": 2})  # the figures it was drawn from changed
    assert hooks.status("docs/fig.png").reasons == ["results file r.json has changed since the picture was drawn"]
    with pytest.raises(hooks.FigureError, match=r"p\.md: cites fig\.png, whose figures are stale"):
        hooks.render("![a figure](fig.png)", "p.md")
    out = hooks.render("![a figure](../fig.png)\n{{ historical ../fig.png }}\n", "studies/p.md")
    assert '!!! note "Historical figures: `../fig.png`"' in out
    record["dynamics"] = "before"  # a picture of a simulation run goes stale with the dynamics
    common.write_png_provenance(png.read_bytes(), png, record)
    hooks.status.cache_clear()
    assert "dynamics fingerprint before != now now" in hooks.status("docs/fig.png").reasons
    bare = tmp_path / "docs" / "bare.png"
    bare.write_bytes(b"\x89PNG\r\n\x1a\n" + png.read_bytes()[8:33])  # the IHDR chunk alone: no provenance
    assert common.png_provenance(bare) is None and hooks.status("docs/bare.png").state == "unknown"
    with pytest.raises(hooks.FigureError, match="cites bare.png, whose figures are unknown"):
        hooks.render("![b](bare.png)", "p.md")
    assert "Historical figures" in hooks.render("![b](bare.png)\n{{ historical bare.png }}\n", "p.md")
