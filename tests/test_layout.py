"""The architecture as docs/design.md states it: imports go one way (the world <- the
trackers <- the harness <- the RL layer), with no cycle between modules, and the commands
are installed."""

import ast
import importlib.metadata
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("dgpt_gym", "agents", "baselines")


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def project_imports() -> dict[str, set[str]]:
    """``{module: project modules it imports}``, function-level imports included."""
    modules = {
        module_name(path): path for package in PACKAGES for path in (ROOT / package).rglob("*.py")
    }
    graph = {}
    for name, path in modules.items():
        imported = set()
        for node in ast.walk(ast.parse(path.read_text())):
            targets = []
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                targets = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
            imported |= {target for target in targets if target in modules and target != name}
        graph[name] = imported
    return graph


def layer(module: str) -> int:
    if module.startswith("agents.rl"):
        return 3
    if module.startswith("dgpt_gym.benchmark"):
        return 2
    if module.startswith(("agents", "baselines")):
        return 1
    return 0


def test_imports_never_go_down_the_layers():
    # a package __init__ that only re-exports is part of its layer's surface
    wrong = [
        (module, target)
        for module, targets in project_imports().items()
        for target in targets
        if layer(target) > layer(module)
    ]
    assert wrong == []


def test_no_import_cycle_between_modules():
    graph = project_imports()
    state: dict[str, int] = {}
    cycles = []

    def visit(module, stack):
        state[module] = 1
        for target in graph[module]:
            if state.get(target) == 1:
                cycles.append(stack[stack.index(target) :] + [target])
            elif target not in state:
                visit(target, [*stack, target])
        state[module] = 2

    for module in graph:
        if module not in state:
            visit(module, [module])
    assert cycles == []


def test_function_level_imports_are_for_optional_dependencies_only():
    hidden = []
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            for function in ast.walk(ast.parse(path.read_text())):
                if not isinstance(function, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    continue
                for node in ast.walk(function):
                    if isinstance(node, ast.ImportFrom) and node.module:
                        top = node.module.split(".")[0]
                    elif isinstance(node, ast.Import):
                        top = node.names[0].name.split(".")[0]
                    else:
                        continue
                    if top in PACKAGES:
                        hidden.append(f"{module_name(path)}.{function.name}: {top}")
    assert hidden == []


@pytest.mark.parametrize(
    "command, target",
    [
        ("dgpt-evaluate", "dgpt_gym.benchmark.cli:main"),
        ("dgpt-bench", "dgpt_gym.benchmark.speed:main"),
        ("dgpt-train-rl", "agents.rl.cli:main"),
    ],
)
def test_the_commands_are_installed(command, target):
    points = {p.name: p.value for p in importlib.metadata.entry_points(group="console_scripts")}
    assert points.get(command) == target
    executable = shutil.which(command, path=str(Path(sys.executable).parent))
    assert executable is not None
    result = subprocess.run([executable, "--help"], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0 and "usage:" in result.stdout


def test_every_package_folder_is_a_regular_package():
    # a folder without __init__.py imports from a source tree but is left out of the wheel
    folders = {path.parent for package in PACKAGES for path in (ROOT / package).rglob("*.py")}
    assert (
        sorted(str(f.relative_to(ROOT)) for f in folders if not (f / "__init__.py").exists()) == []
    )


def test_the_citation_names_the_version_being_cited():
    """CITATION.cff's ``version`` is the package's (pyproject.toml), so that a citation
    points at the code that made the numbers."""
    import re

    def versions(path: str, key: str) -> list[str]:
        pattern = re.compile(rf'^{key}\s*[:=]\s*"([^"]+)"')
        return [
            m[1] for line in (ROOT / path).read_text().splitlines() if (m := pattern.match(line))
        ]

    assert versions("CITATION.cff", "version") == versions("pyproject.toml", "version")
    assert versions("pyproject.toml", "version") == [importlib.metadata.version("dgpt-gym")]
