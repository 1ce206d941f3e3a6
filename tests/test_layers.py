"""Layers point down only: read every module's imports (lazy ones inside functions included) and
fail on one that reaches a higher layer, or on a circle of imports inside a layer.

From the bottom: ``core`` (the light core: torch and the standard library only); ``runtime`` and ``storage``; ``sim/`` (the simulator knows no task); ``task/`` (the
task knows no trainer); ``policy`` (a saved policy, loaded without the trainer); ``integrations/``
(Rerun, ROS 2, Gymnasium: no trainer internals); ``rl/`` (training); the command-line modules and
the package's lazy namespace on top.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "atrv_warp"

LAYERS = (
    ("atrv_warp.core",),
    ("atrv_warp.runtime", "atrv_warp.storage"),
    ("atrv_warp.world",),
    ("atrv_warp.sim",),
    ("atrv_warp.task",),
    ("atrv_warp.policy",),
    ("atrv_warp.integrations",),
    ("atrv_warp.rl",),
)
"""Module prefixes, lowest layer first. Anything else in the package (the command-line modules,
``atrv_warp`` itself) is the top layer."""
TOP = len(LAYERS)


def layer(module: str) -> int:
    for i, prefixes in enumerate(LAYERS):
        if any(module == p or module.startswith(p + ".") for p in prefixes):
            return i
    return TOP


def layer_name(i: int) -> str:
    return "/".join(p.removeprefix("atrv_warp.") for p in LAYERS[i]) if i < TOP else "the top (CLIs, atrv_warp)"


def imports(module: str, source: str, is_package: bool) -> set[str]:
    """Every ``atrv_warp`` module ``source`` imports, absolute or relative, at any depth."""
    out = set()
    package = module if is_package else module.rpartition(".")[0]
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                parts = parts[: len(parts) - node.level + 1]
                base = ".".join(parts + ([base] if base else []))
            # `from atrv_warp.sim import diff` imports the module atrv_warp.sim.diff: count the deeper one
            out.update(f"{base}.{a.name}" if f"{base}.{a.name}" in MODULES else base for a in node.names)
    return {m for m in out if m == "atrv_warp" or m.startswith("atrv_warp.")}


def _modules() -> dict[str, tuple[Path, bool]]:
    mods = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(ROOT).with_suffix("")
        is_package = rel.name == "__init__"
        name = ".".join(rel.parent.parts if is_package else rel.parts)
        mods[name] = (path, is_package)
    return mods


MODULES = _modules()


def upward_imports(sources: dict[str, tuple[str, bool]]) -> list[str]:
    """One line per import of a higher layer in ``sources`` (module -> (source, is_package))."""
    problems = []
    for module, (source, is_package) in sorted(sources.items()):
        here = layer(module)
        for target in sorted(imports(module, source, is_package)):
            if layer(target) > here:
                problems.append(f"{module} ({layer_name(here)}) imports {target} ({layer_name(layer(target))})")
    return problems


def test_no_module_imports_a_higher_layer():
    sources = {m: (p.read_text(), pkg) for m, (p, pkg) in MODULES.items()}
    problems = upward_imports(sources)
    assert not problems, "\n".join(problems)


def test_the_check_catches_an_upward_import():
    """The two imports issue 28 found, a relative one, and one through the package's lazy namespace."""
    found = upward_imports({
        "atrv_warp.sim.diff": ("def f():\n    from atrv_warp.task.config import TaskConfig\n", False),
        "atrv_warp.integrations.ros.node": ("from atrv_warp.rl import loop\n", False),
        "atrv_warp.task.env": ("from ..rl.config import TrainConfig\n", False),
        "atrv_warp.sim.scanner": ("import atrv_warp\n", False),
        "atrv_warp.task.kernels": ("from atrv_warp.sim.kernels.contact import FLAG_OBSTACLE\n", False),
    })
    assert found == [
        "atrv_warp.integrations.ros.node (integrations) imports atrv_warp.rl.loop (rl)",
        "atrv_warp.sim.diff (sim) imports atrv_warp.task.config (task)",
        "atrv_warp.sim.scanner (sim) imports atrv_warp (the top (CLIs, atrv_warp))",
        "atrv_warp.task.env (task) imports atrv_warp.rl.config (rl)",
    ], found
    assert layer("atrv_warp.simulation") == TOP  # a prefix is a whole module name, not a string prefix


def import_cycles(sources: dict[str, tuple[str, bool]]) -> list[list[str]]:
    """Each circle of imports among ``sources`` (module -> (source, is_package)), lazy ones inside functions
    included: the modules of each strongly connected component of two or more, sorted (Tarjan's algorithm)."""
    graph = {m: sorted(imports(m, src, pkg) & sources.keys() - {m}) for m, (src, pkg) in sources.items()}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    cycles = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = stack[stack.index(v):]
            del stack[stack.index(v):]
            if len(component) > 1:
                cycles.append(sorted(component))

    for module in sorted(graph):
        if module not in index:
            visit(module)
    return sorted(cycles)


def test_no_circle_of_imports():
    """Inside a layer too, imports point one way (issue 69: a circle of 13 modules in ``task/``, closed by imports
    inside functions): a module that needs a higher one's fact takes it from below, or moves."""
    cycles = import_cycles({m: (p.read_text(), pkg) for m, (p, pkg) in MODULES.items()})
    assert not cycles, "\n".join(" <-> ".join(c) for c in cycles)


def test_the_circle_check_catches_a_lazy_circle():
    """Two of the edges that closed ``task/``'s circle, one of them inside a function, and a module apart."""
    found = import_cycles({
        "atrv_warp.task.definition": ("def f():\n    from atrv_warp.task.kernels.steps import PHASES\n", False),
        "atrv_warp.task.kernels.steps": ("from atrv_warp.task import definition\n", False),
        "atrv_warp.task.spec": ("from atrv_warp.task.definition import READS\n", False),
    })
    assert found == [["atrv_warp.task.definition", "atrv_warp.task.kernels.steps"]], found


def third_party_imports(source: str) -> set[str]:
    """Top-level names of every module ``source`` imports that is neither the standard library nor this package."""
    from test_packaging import without_older_python_branches  # tomli on 3.10: the slim install declares it there

    names = set()
    for node in ast.walk(without_older_python_branches(ast.parse(source))):
        if isinstance(node, ast.Import):
            names.update(a.name.split(".")[0] for a in node.names)
        elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
            names.add(node.module.split(".")[0])
    return {n for n in names if n not in sys.stdlib_module_names and n != "atrv_warp"}


BUILD_TOOLS = {"atrv_warp.core.ros_interfaces": {"rosidl_adapter", "numpy"}}
"""A core module that builds ROS interfaces where no ROS install has them: the ``ros`` extra's rosidl generators (and
numpy's headers, which rclpy brings), imported only while it builds."""


def test_the_light_core_imports_only_torch():
    core = {m: p for m, (p, _) in MODULES.items() if layer(m) == 0}
    assert {"atrv_warp.core.geometry", "atrv_warp.core.scan", "atrv_warp.core.observation"} <= core.keys()
    found = {m: third_party_imports(p.read_text()) - {"torch"} - BUILD_TOOLS.get(m, set()) for m, p in core.items()}
    assert not any(found.values()), found
    assert third_party_imports("import warp as wp\nfrom torchrl.envs import EnvBase\nimport math\n") == {
        "warp", "torchrl"}


LIGHT = ("atrv_warp", "atrv_warp.core", "atrv_warp.task.spec", "atrv_warp.integrations.ros",
         "atrv_warp.integrations.ros.base")
"""Modules a robot's computer imports without the simulator: none of them loads Warp, Newton or TorchRL."""


def test_the_package_and_its_light_core_load_without_the_simulator():
    """In a fresh interpreter: importing the light modules loads none of warp, newton, torchrl; the simulator's
    package then configures Warp on its first import (the quiet console), and its configs and driving modes load
    without Newton (what the ROS node checks its parameters with), which its first name from the simulator brings."""
    code = (f"import sys\nimport {', '.join(LIGHT)}\n"
            "print(sorted(m for m in ('warp', 'newton', 'torchrl') if m in sys.modules))\n"
            "import atrv_warp.sim, atrv_warp.runtime as r\nprint(sorted(m for m in ('warp', 'newton') if m in "
            "sys.modules), r.is_configured())\n"
            "import atrv_warp.sim.config, atrv_warp.sim.modes\nprint('newton' in sys.modules)\n"
            "from atrv_warp.sim import RoverSim\nprint('newton' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.splitlines() == ["[]", "['warp'] True", "False", "True"], out.stdout + out.stderr
    assert out.stderr == "", out.stderr  # quiet: no Warp banner, no CUDA-driver notice


def test_the_ros_simulator_node_checks_its_parameters_before_it_imports_newton():
    """``python -m atrv_warp.ros`` with a bad parameter is refused in seconds: its node module, and what its
    parameter checks use, load without Newton; the simulator comes once the parameters are good."""
    pytest.importorskip("rclpy", reason="ROS 2 extra not installed: pip install -e '.[ros]'")
    code = ("import sys\nimport atrv_warp.integrations.ros.node, atrv_warp.integrations.ros.parameters\n"
            "import atrv_warp.core.robot, atrv_warp.task.config, atrv_warp.sim.terrain, atrv_warp.core.files\n"
            "print(sorted(m for m in ('newton', 'torchrl') if m in sys.modules))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.splitlines() == ["[]"], out.stdout + out.stderr


ROS_RUNTIME = {"rclpy", "geometry_msgs", "nav_msgs", "sensor_msgs", "std_msgs", "rcl_interfaces", "launch",
               "launch_ros"}
"""What the deploy node may import besides torch: rclpy and the message packages a robot's ROS 2 has, and ROS 2's
``launch`` (the launch files; only a ROS install has it). ``tf2_msgs`` and ``nav2_msgs`` load by name
(:mod:`atrv_warp.core.ros_interfaces`): a ROS install's, or built from their definitions."""


def test_the_deploy_node_imports_only_torch_ros_and_the_light_core():
    """``atrv_warp.deploy`` runs on a robot's computer: torch, rclpy and messages, and of this package only the light
    core, itself and the console setup (``runtime``, which ``atrv_warp/__init__`` imports)."""
    deploy = {m: p for m, (p, _) in MODULES.items() if m.startswith("atrv_warp.deploy")}
    assert {"atrv_warp.deploy.controller", "atrv_warp.deploy.node", "atrv_warp.deploy.cli"} <= deploy.keys()
    third = {m: third_party_imports(p.read_text()) - {"torch"} - ROS_RUNTIME for m, p in deploy.items()}
    assert not any(third.values()), third
    ours = {m: {t for t in imports(m, p.read_text(), p.name == "__init__.py")
                if not t.startswith(("atrv_warp.core", "atrv_warp.deploy"))} for m, p in deploy.items()}
    assert not any(ours.values()), ours
    assert imports("atrv_warp.runtime", (PACKAGE / "runtime.py").read_text(), False) == set()


MAX_FUNCTION_LINES = 100
"""A function a reader can hold: none in the package longer than this, but the Warp kernels and
functions (one launch is one body, and splitting one costs a launch or a copy of its arguments)."""


def long_functions(source: str) -> list[tuple[str, int]]:
    """Each function or method in ``source`` longer than ``MAX_FUNCTION_LINES``, but Warp's; a function that builds
    Warp kernels (a kernel factory) is measured without them."""
    def is_warp(node) -> bool:
        return any(ast.unparse(d).split("(")[0] in ("wp.kernel", "wp.func", "warp.kernel", "warp.func")
                   for d in node.decorator_list)

    found = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) or is_warp(node):
            continue
        nested = [n for n in ast.walk(node) if n is not node and isinstance(n, ast.FunctionDef) and is_warp(n)]
        lines = node.end_lineno - node.lineno + 1 - sum(n.end_lineno - n.lineno + 1 for n in nested)
        if lines > MAX_FUNCTION_LINES:
            found.append((node.name, lines))
    return found


def test_no_function_outside_the_warp_kernels_exceeds_100_lines():
    """In the package and in the benchmark scripts alike (issue 69, part 7)."""
    files = [*PACKAGE.rglob("*.py"), *(ROOT / "benchmarks").rglob("*.py")]
    long = {f"{path.relative_to(ROOT)}:{name}": lines
            for path in sorted(files) for name, lines in long_functions(path.read_text())}
    assert not long, f"functions over {MAX_FUNCTION_LINES} lines (split them): {long}"


def test_the_length_check_catches_a_long_function_and_spares_a_kernel():
    body = "".join(f"    x{i} = {i}\n" for i in range(MAX_FUNCTION_LINES))
    assert long_functions(f"def f():\n{body}") == [("f", MAX_FUNCTION_LINES + 1)]
    assert long_functions(f"@wp.kernel\ndef k():\n{body}") == []
    assert long_functions(f"@wp.kernel(enable_backward=False)\ndef k():\n{body}") == []
    factory = "def make(n):\n    @wp.kernel\n    def k():\n" + body.replace("    ", "        ") + "    return k\n"
    assert long_functions(factory) == []  # a kernel factory is measured without its kernels
    assert long_functions(f"def make(n):\n{body}    @wp.kernel\n    def k():\n        pass\n") == [("make", 102)]


BENCHMARKS = ROOT / "benchmarks"


def test_the_benchmarks_are_a_package_that_edits_no_import_path():
    """``python -m benchmarks.<topic>.<name>`` from the root: every topic is a package, no script touches
    ``sys.path``, and a script imports another by its module name (issue 69, part 7)."""
    edits, bare = [], []
    for path in sorted(BENCHMARKS.rglob("*.py")):
        tree = ast.parse(path.read_text())
        name = str(path.relative_to(ROOT))
        edits += [f"{name}:{n.lineno}" for n in ast.walk(tree) if isinstance(n, ast.Attribute) and n.attr == "path"
                  and isinstance(n.value, ast.Name) and n.value.id == "sys"]
        bare += [f"{name}:{n.lineno} from {n.module}" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)
                 and n.level == 0 and n.module and (BENCHMARKS / f"{n.module}.py").exists()]
    assert not edits, f"sys.path edited in {edits}"
    assert not bare, f"imported by a bare name (use benchmarks.<topic>.<name>): {bare}"
    topics = [p for p in BENCHMARKS.iterdir() if p.is_dir() and any(p.glob("*.py"))]
    assert (BENCHMARKS / "__init__.py").is_file() and all((p / "__init__.py").is_file() for p in topics), topics
