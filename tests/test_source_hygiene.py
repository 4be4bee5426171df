"""No module of the package, the validation report or the benchmarks defines a top-level name twice.

A second ``def`` of the same name silently replaces the first (the validation runner once lost
four checks that way, hidden by its cache); this is the cheap guard against it.
"""

import ast
from collections import Counter
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SOURCES = sorted(p for d in ("hbgear", "validation", "benchmarks") for p in (ROOT / d).rglob("*.py")
                 if not any(part.startswith(".") for part in p.relative_to(ROOT).parts))


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: str(p.relative_to(ROOT)))
def test_no_top_level_definition_twice(path):
    tree = ast.parse(path.read_text(), filename=str(path))
    names = Counter(node.name for node in tree.body
                    if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)))
    twice = sorted(name for name, count in names.items() if count > 1)
    assert not twice, f"{path.relative_to(ROOT)} defines {twice} more than once"
