"""The repository's documentation stands alone and stays in step with the code.

- Every relative link in README.md and docs/*.md names a file of the repository.
- Nothing (code, docs, specs, tests, examples, benchmarks) refers to a design document outside the repository.
- docs/format.md documents every sensor parameter a spec can set and every group and root attribute that a
  recording's layout requires.
- docs/internals.md's tree names every module of the package, in its own folder, and no module that is gone.
"""

from __future__ import annotations

import dataclasses
import re
import subprocess
from pathlib import Path

import pytest

from simspad.io.recording import layout
from simspad.sensors.presets import PRESETS

REPO = Path(__file__).resolve().parents[1]
DOCS = sorted((REPO / "docs").glob("*.md")) + [REPO / "README.md"]
FORMAT = (REPO / "docs" / "format.md").read_text(encoding="utf-8")
#: A pointer to the design notes or reference list the project started from, which live outside the repository
#: (spelled in two pieces so that this file does not match itself, nor a plain grep of the repository).
OUTSIDE_DOC = re.compile("DES" + r"IGN(\.md| ?§)|" + "REFER" + r"ENCES\.md")


def _tracked_text_files() -> list[Path]:
    try:
        out = subprocess.run(["git", "ls-files"], cwd=REPO, capture_output=True, text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout")
    paths = [REPO / line for line in out.splitlines()]
    return [p for p in paths if p.suffix in {".py", ".md", ".toml", ".txt", ".cfg", ".json"} and p.is_file()]


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.name)
def test_relative_links_resolve(doc):
    text = doc.read_text(encoding="utf-8")
    for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text):
        if "://" in target or target.startswith("mailto:"):
            continue
        assert (doc.parent / target).exists(), f"{doc.name} links to {target}, which does not exist"


def test_no_reference_to_a_design_document_outside_the_repository():
    offenders = []
    for path in _tracked_text_files():
        if path == Path(__file__).resolve():
            continue
        for n, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
            if OUTSIDE_DOC.search(line):
                offenders.append(f"{path.relative_to(REPO)}:{n}: {line.strip()[:80]}")
    assert not offenders, "\n".join(offenders)


def test_format_documents_every_sensor_parameter():
    missing = [f"{kind}.{f.name}" for kind, presets in PRESETS.items()
               for f in dataclasses.fields(next(iter(presets.values()))) if f"`{f.name}`" not in FORMAT]
    assert not missing, f"docs/format.md does not document {missing}"


def test_format_documents_the_recording_layout():
    names = set(re.findall(r"`/?([a-z_0-9/]+)`", FORMAT))
    required = set(layout.REQUIRED_ROOT_ATTRS)
    for table in (layout.REQUIRED_DATASETS, layout.REQUIRED_GROUP_ATTRS):
        for items in table.values():
            required.update(items)
    missing = sorted(r for r in required if r not in names)
    assert not missing, f"docs/format.md does not document {missing}"


def _internals_tree_modules() -> set[str]:
    """The modules docs/internals.md's tree names, as paths: a line ``  name/`` (two spaces a level) opens a
    folder, and every ``*.py`` on it or on the lines under it belongs to that folder."""
    text = (REPO / "docs" / "internals.md").read_text(encoding="utf-8")
    tree = text.split("## The tree", 1)[1].split("```", 2)[1]
    named, folders = set(), []
    for line in tree.splitlines():
        indent = len(line) - len(line.lstrip())
        if not line.strip() or indent % 2 or indent >= 20:  # continuation lines are indented further
            rest = line
        else:
            folders = folders[: indent // 2]
            m = re.match(r"(\S+)/(\s|$)", line.lstrip())
            rest = line.lstrip()[len(m.group(1)) + 1:] if m else line
            if m:
                folders.append(m.group(1))
        # a name with a folder in front (``io/manifest.py``) points elsewhere in the tree
        named.update("/".join(folders + [f]) for f in re.findall(r"(?<![/\w])(\w+\.py)\b", rest))
    return named


def test_internals_tree_names_every_module():
    package = REPO / "simspad"
    modules = {str(p.relative_to(REPO)) for p in package.rglob("*.py")
               if p.name != "__init__.py"}
    named = _internals_tree_modules()
    missing = sorted(modules - named)
    assert not missing, f"docs/internals.md's tree does not name {missing}"
    # the tree also shows the repository's root (setup.py, scenes/<name>/scene.py): only simspad/ is checked
    gone = sorted(n for n in named - modules if n.startswith("simspad/") and not n.endswith("/__init__.py"))
    assert not gone, f"docs/internals.md's tree names modules that do not exist: {gone}"
