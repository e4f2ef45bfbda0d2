"""The package's walls as tests: the import-linter contracts of pyproject.toml, and deferred imports say why.

Each contract in ``[tool.importlinter]`` runs as its own test (``lint-imports --contract ID``) so that a failure
names the wall that broke and shows import-linter's report of the offending import chains. The second test walks
the syntax tree of every module under ``simspad/``: an import inside a function body is allowed only to defer a
heavy optional dependency, and then carries a ``# deferred: <why>`` comment on its line.
"""

from __future__ import annotations

import ast
import io
import subprocess
import sys
import tokenize
import tomllib
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGE = REPO / "simspad"
CONFIG = REPO / "pyproject.toml"
DEFERRED_TAG = "# deferred:"
LINT_IMPORTS = ("import sys; from importlinter.cli import lint_imports_command; "
                "sys.exit(lint_imports_command())")


def _contract_ids() -> list[str]:
    config = tomllib.loads(CONFIG.read_text(encoding="utf-8"))
    return [contract["id"] for contract in config["tool"]["importlinter"]["contracts"]]


@pytest.mark.parametrize("contract", _contract_ids())
def test_import_contract_is_kept(contract, tmp_path, child_env):
    pytest.importorskip("importlinter")
    # child_env: this checkout's package is analysed, not an editable install's; the cache goes to tmp_path.
    proc = subprocess.run([sys.executable, "-c", LINT_IMPORTS, "--config", str(CONFIG), "--contract", contract,
                           "--no-logo", "--cache-dir", str(tmp_path / "cache")],
                          cwd=REPO, env={**child_env, "NO_COLOR": "1", "COLUMNS": "120"}, capture_output=True,
                          text=True, timeout=300)
    report = (proc.stdout + proc.stderr).strip()
    if proc.returncode != 0 or "Contracts: 1 kept, 0 broken." not in report:
        pytest.fail(f"import-linter contract {contract!r} is broken (exit {proc.returncode}):\n\n{report}",
                    pytrace=False)


def _comments_by_line(source: str) -> dict[int, str]:
    """The comment (if any) on each physical line of ``source``."""
    tokens = tokenize.generate_tokens(io.StringIO(source).readline)
    return {tok.start[0]: tok.string for tok in tokens if tok.type == tokenize.COMMENT}


def _function_level_imports(tree: ast.AST) -> list[ast.Import | ast.ImportFrom]:
    """Import statements anywhere inside a function or method body (nested classes and functions included)."""
    found = []

    def visit(node: ast.AST, in_function: bool) -> None:
        for child in ast.iter_child_nodes(node):
            if in_function and isinstance(child, (ast.Import, ast.ImportFrom)):
                found.append(child)
            visit(child, in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)))

    visit(tree, False)
    return found


def _unmarked_imports(source: str, filename: str = "<source>") -> list[ast.Import | ast.ImportFrom]:
    """Function-level imports of ``source`` with no ``# deferred:`` comment on any of their lines."""
    comments = _comments_by_line(source)
    return [node for node in _function_level_imports(ast.parse(source, filename=filename))
            if not any(comments.get(line, "").startswith(DEFERRED_TAG)
                       for line in range(node.lineno, (node.end_lineno or node.lineno) + 1))]


def undeclared_deferred_imports(package: Path = PACKAGE) -> list[str]:
    """``path:line: statement`` of each function-level import without a ``# deferred:`` comment."""
    problems = []
    for path in sorted(package.rglob("*.py")):
        source = path.read_text(encoding="utf-8")
        for node in _unmarked_imports(source, str(path)):
            statement = " ".join(ast.get_source_segment(source, node).split())
            problems.append(f"{path.relative_to(REPO)}:{node.lineno}: {statement}")
    return problems


def test_function_level_imports_say_why_they_are_deferred():
    problems = undeclared_deferred_imports()
    if problems:
        pytest.fail(f"{len(problems)} import(s) inside function bodies without a '{DEFERRED_TAG} <why>' comment on "
                    "their line. Move each to the top of its module or, if it defers a heavy optional dependency "
                    "(mitsuba, matplotlib, dask…), say so in that comment:\n  " + "\n  ".join(problems),
                    pytrace=False)


def test_the_deferred_import_check_sees_what_it_should():
    """The AST walk finds imports in methods and nested functions and accepts the tag on any line of a statement."""
    source = ("import os\n"
              "def f():\n"
              "    import json\n"
              "    import numpy  # deferred: heavy\n"
              "    from math import (  # deferred: heavy\n"
              "        pi,\n"
              "    )\n"
              "class A:\n"
              "    import re\n"
              "    def g(self):\n"
              "        def h():\n"
              "            import csv  # not the tag\n")
    assert [node.lineno for node in _unmarked_imports(source)] == [3, 12]
