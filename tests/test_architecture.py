"""The architecture of docs/architecture.md holds: the import-linter contracts in
pyproject.toml (layers; no ML framework in the env layers), no import cycle between the
package's modules, no module much above 600 lines, no library module importing the CLI."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "rehabbot"
MAX_MODULE_LINES = 620  # "about 600"


def test_import_linter_contracts_are_kept() -> None:
    lint_imports = shutil.which("lint-imports", path=str(Path(sys.executable).parent))
    if lint_imports is None:
        pytest.skip('import-linter is not installed (pip install "rehabbot[dev]")')
    result = subprocess.run([lint_imports, "--no-cache"], cwd=ROOT, capture_output=True,
                            text=True, timeout=300)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-2000:]
    assert "0 broken" in result.stdout


def _import_graph():
    grimp = pytest.importorskip("grimp", reason='needs import-linter (rehabbot[dev])')
    return grimp.build_graph("rehabbot", cache_dir=None)


def test_no_import_cycles_between_modules() -> None:
    """Strongly connected components of the module graph (every import statement counts,
    those inside functions and under TYPE_CHECKING too); packages' own ``__init__`` that only
    re-export are modules like any other."""
    graph = _import_graph()
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles: list[list[str]] = []
    counter = [0]

    def visit(module: str) -> None:  # Tarjan's algorithm
        index[module] = low[module] = counter[0]
        counter[0] += 1
        stack.append(module)
        on_stack.add(module)
        for other in graph.find_modules_directly_imported_by(module):
            if other not in graph.modules:
                continue
            if other not in index:
                visit(other)
                low[module] = min(low[module], low[other])
            elif other in on_stack:
                low[module] = min(low[module], index[other])
        if low[module] == index[module]:
            component = []
            while True:
                other = stack.pop()
                on_stack.discard(other)
                component.append(other)
                if other == module:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10_000))
    for module in sorted(graph.modules):
        if module not in index:
            visit(module)
    assert cycles == []


def test_no_library_module_imports_the_cli() -> None:
    graph = _import_graph()
    offenders = sorted(
        module for module in graph.modules
        if not module.startswith("rehabbot.cli") and module != "rehabbot.__main__"
        and any(m.startswith("rehabbot.cli") for m in graph.find_modules_directly_imported_by(
            module)))
    assert offenders == []


def test_modules_stay_small() -> None:
    sizes = {path.relative_to(ROOT).as_posix(): len(path.read_text().splitlines())
             for path in PACKAGE.rglob("*.py")}
    too_big = {name: lines for name, lines in sizes.items() if lines > MAX_MODULE_LINES}
    assert too_big == {}
