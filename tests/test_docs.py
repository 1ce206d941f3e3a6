"""The documentation's code runs: every ```python block of the README and of the docs pages,
in order, one namespace per page (later blocks of a page may use earlier ones' names)."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
BLOCK = re.compile(r"^```python\n(.*?)^```", re.MULTILINE | re.DOTALL)


def python_blocks(text: str) -> list[str]:
    return BLOCK.findall(text)


def test_the_block_reader_finds_python_and_only_python():
    text = "a\n```python\nx = 1\n```\n```bash\nls\n```\n```python\ny = x\n```\n"
    assert python_blocks(text) == ["x = 1\n", "y = x\n"]


def test_the_readme_is_a_door():
    """A short README (issue 28: at most about 200 lines) with the two set-up commands."""
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 200
    assert 'pip install -e . && python -m atrv_warp.train' in text
    assert TEST_COMMAND in text


TEST_COMMAND = ('pip install -e ".[test,ros,ray,docs]" && mkdocs build --strict && python -m pytest -m "not slow" -n 2 '
                '&& python -m pytest -m slow')
"""The README's test command: the quick tier on two workers, then the slow tier one test at a time."""


def test_ci_runs_the_readmes_test_command():
    """``.ci/run`` runs each part of the README's test command, in its order (``pip install`` through its quiet
    wrapper; the docs build and the pytest runs may add an output folder or a report)."""
    ci = (ROOT / ".ci" / "run").read_text().splitlines()
    parts = [part.strip().replace("pip install ", "quiet_pip ", 1) for part in TEST_COMMAND.split("&&")]
    found = [next((i for i, line in enumerate(ci) if line.strip() == part or line.strip().startswith(part + " ")),
                  None) for part in parts]
    assert None not in found, dict(zip(parts, found, strict=True))
    assert found == sorted(found), dict(zip(parts, found, strict=True))


@pytest.mark.parametrize("page", [p for p in PAGES if python_blocks(p.read_text())], ids=lambda p: str(p.relative_to(ROOT)))
def test_code_blocks_run(page, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # a block that writes a file writes it here
    namespace: dict = {"__name__": f"docs_{page.stem}"}
    for i, block in enumerate(python_blocks(page.read_text())):
        try:
            exec(compile(block, f"{page.name}, python block {i + 1}", "exec"), namespace)  # noqa: S102
        except Exception as err:
            raise AssertionError(f"{page.relative_to(ROOT)}, python block {i + 1} fails:\n{block}") from err


def _hooks():
    import importlib.util

    spec = importlib.util.spec_from_file_location("docs_hooks", ROOT / "docs" / "hooks.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_results_tables_come_from_the_results_files():
    """The docs' ``{{ results_table NAME }}`` lines render from benchmarks/results/, and only known names."""
    import json

    hooks = _hooks()
    used = set()
    for page in PAGES:
        text = page.read_text()
        used |= set(hooks.PLACEHOLDER.findall(text))
        where = os.path.relpath(page, ROOT / "docs")  # pictures are found from the page's folder: README's is ../
        assert not hooks.PLACEHOLDER.search(hooks.render(text, where)), page.name
    assert used == set(hooks.TABLES)  # every table is shown somewhere
    last = json.loads((ROOT / "benchmarks" / "results" / "sim_throughput.json").read_text())["rows"][-1]
    assert f"| {last['num_worlds']:,} | {last['env_steps_per_s']:,.0f} | {last['ms_per_step']:.3f} |" in \
        hooks.TABLES["sim_throughput"]()
    with pytest.raises(hooks.FigureError, match="unknown results table 'nope'"):
        hooks.render("{{ results_table nope }}")
