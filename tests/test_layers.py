"""The package's layers, from the imports in its source (every ``import`` statement, including those
inside functions):

- ``hbgear/engine``: generic; imports nothing from ``hbgear.gear``, the config, the outputs, the
  CLI or the API (``hbgear.errors`` is shared by all layers);
- ``hbgear/gear``: the gear pair; imports the engine, never the config, the outputs, the CLI or the API;
- ``hbgear/outputs``: the files and figures; never the CLI;
- no import cycles between the modules of ``hbgear`` (module-level imports);
- ``import hbgear`` and the CLI front door import no JAX and no matplotlib.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "hbgear"


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _imports(path: Path, top_level_only: bool = False) -> set[str]:
    """Absolute names of the hbgear modules `path` imports."""
    module = _module_name(path)
    package = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
    tree = ast.parse(path.read_text(), filename=str(path))
    nodes = tree.body if top_level_only else ast.walk(tree)
    found = set()
    for node in nodes:
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name.split(".")[0] == "hbgear"}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.split(".")[0] != "hbgear":
                continue
            found.add(target)
            for alias in node.names:  # `from . import x` may name a submodule
                candidate = f"{target}.{alias.name}"
                if (PACKAGE.parent / (candidate.replace(".", "/") + ".py")).exists() or \
                        (PACKAGE.parent / candidate.replace(".", "/")).is_dir():
                    found.add(candidate)
    return found


SOURCES = sorted(PACKAGE.rglob("*.py"))
FORBIDDEN = {
    "hbgear.engine": ("hbgear.gear", "hbgear.config", "hbgear.build", "hbgear.outputs", "hbgear.cli", "hbgear.api",
                      "hbgear.runtime"),
    "hbgear.gear": ("hbgear.config", "hbgear.build", "hbgear.outputs", "hbgear.cli", "hbgear.api", "hbgear.runtime"),
    "hbgear.outputs": ("hbgear.cli",),
}


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: str(p.relative_to(ROOT)))
def test_imports_go_downwards_only(path):
    module = _module_name(path)
    for layer, forbidden in FORBIDDEN.items():
        if module == layer or module.startswith(layer + "."):
            bad = sorted(name for name in _imports(path) if any(name == f or name.startswith(f + ".") for f in forbidden))
            assert not bad, f"{module} (layer {layer}) imports {bad}"


def test_no_import_cycles():
    graph = {}
    for path in SOURCES:
        name = _module_name(path)
        graph[name] = {m for m in _imports(path, top_level_only=True) if m != name and not name.startswith(m + ".")}
    state: dict[str, int] = {}

    def visit(node, stack):
        state[node] = 1
        for nxt in sorted(graph.get(node, ())):
            if nxt not in graph:
                continue
            if state.get(nxt) == 1:
                cycle = stack[stack.index(nxt):] + [nxt]
                raise AssertionError("import cycle: " + " -> ".join(cycle))
            if nxt not in state:
                visit(nxt, stack + [nxt])
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node, [node])


def test_the_front_door_imports_neither_jax_nor_matplotlib():
    """Nor numpy: ``hbgear --help`` and a bad argument answer in ~0.08 s (numpy's import alone
    took half of the 0.16 s ``--help`` before the stability map's module imported it lazily)."""
    code = ("import sys, hbgear, hbgear.cli; hbgear.cli._load_builtin_commands(); hbgear.cli.build_parser(); "
            "print(sorted(m for m in ('jax', 'matplotlib', 'scipy', 'numpy') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.strip() == "[]"
