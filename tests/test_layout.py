"""The code layout's rules, checked with ``ast`` so a violation names the file, line and import.

- ``flexsheet/`` is the library: nothing in it imports ``nodes`` (the adapters);
- ``flexsheet/runtime/`` is generic: it imports nothing from ``model``, ``calibration``, ``experiments``,
  ``display``, ``twin`` or any algorithm package, and one file of it (``transport.py``) imports zmq;
- ``flexsheet/model/`` is pure: no transport (zmq, asyncio, msgpack, pymodbus), nothing above it;
- a node (``nodes/X/``) imports only ``flexsheet.*``, ``messages`` and ``nodes.X`` itself;
- no import cycle between folders (the packages of ``flexsheet/``, ``messages``, each node);
- no ``.py`` under ``docs/``; ``README.md`` ≤ 100 lines, none over 300 characters; each ``docs/`` page ≤ 300
  lines; no work-log words outside
  ``CHANGELOG.md``, in the docs or in the code's docstrings and comments;
- ``CHANGELOG.md`` (Keep a Changelog) ≤ 300 lines, none over 200 characters, with at least one released
  version heading ``## [x.y.z] - YYYY-MM-DD``.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TRANSPORT = {"zmq", "asyncio", "msgpack", "pymodbus"}
#: the library's packages that the generic runtime must not import
#: a work-log reference (history belongs in CHANGELOG.md; docs, docstrings and comments describe today)
WORK_LOG = re.compile(r"\bsessions? [0-9]+|\bsession-[0-9]+|this session|last session|\bissues? [0-9]+", re.I)
#: a released version's heading in CHANGELOG.md (https://keepachangelog.com/en/1.1.0/)
VERSION_HEADING = re.compile(r"^## \[[0-9]+\.[0-9]+\.[0-9]+\] - [0-9]{4}-[0-9]{2}-[0-9]{2}$")
ABOVE_RUNTIME = ("model", "calibration", "experiments", "display", "twin", "fem", "vision", "planning", "arm",
                 "rendering", "viz", "benches")


def _imports(path: Path) -> list[tuple[int, str]]:
    out = []
    for n in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(n, ast.Import):
            out += [(n.lineno, a.name) for a in n.names]
        elif isinstance(n, ast.ImportFrom):
            if n.level:
                raise AssertionError(f"{path.relative_to(ROOT)}:{n.lineno}: relative import; use absolute imports")
            out += [(n.lineno, n.module or "")]
            # ``from flexsheet import registry`` names the module flexsheet.registry
            out += [(n.lineno, f"{n.module}.{a.name}") for a in n.names if n.module in ("flexsheet", "nodes")]
    return out


def _folder(module: str) -> str | None:
    """The folder a module belongs to: ``flexsheet.<package>`` (a top-level module of ``flexsheet/`` such as
    ``flexsheet.cli`` is its own), ``messages`` or ``nodes.<name>``; None for a third-party module and for the
    bare package names."""
    parts = module.split(".")
    if parts[0] == "flexsheet":
        return "flexsheet." + parts[1] if len(parts) > 1 else None
    if parts[0] == "messages":
        return "messages"
    if parts[0] == "nodes" and len(parts) > 1:
        return "nodes." + parts[1]
    return None


def _module(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _library_imports(sub: str = "") -> list[tuple[Path, int, str]]:
    return [(p, line, mod) for p in sorted((ROOT / "flexsheet" / sub).rglob("*.py")) for line, mod in _imports(p)]


def test_the_library_imports_no_node():
    bad = [f"{p.relative_to(ROOT)}:{line}: imports {mod}" for p, line, mod in _library_imports()
           if mod == "nodes" or mod.startswith("nodes.")]
    assert bad == [], "flexsheet/ must not import the adapters in nodes/:\n" + "\n".join(bad)


def test_the_runtime_is_generic():
    bad = [f"{p.relative_to(ROOT)}:{line}: imports {mod}" for p, line, mod in _library_imports("runtime")
           if mod.split(".")[0] == "flexsheet" and len(mod.split(".")) > 1 and mod.split(".")[1] in ABOVE_RUNTIME]
    assert bad == [], "flexsheet/runtime/ must know nothing of the display:\n" + "\n".join(bad)


def test_one_runtime_file_talks_to_zmq():
    users = sorted({p.name for p, _, mod in _library_imports("runtime") if mod.split(".")[0] == "zmq"})
    assert users == ["transport.py"], f"runtime files importing zmq: {users}"


def test_nodes_import_only_flexsheet_messages_and_themselves():
    bad = []
    for path in sorted((ROOT / "nodes").rglob("*.py")):
        own = path.relative_to(ROOT).parts[1]
        for line, mod in _imports(path):
            parts = mod.split(".")
            if parts[0] == "nodes" and len(parts) > 1 and parts[1] != own:
                bad.append(f"{path.relative_to(ROOT)}:{line}: imports {mod} (another node)")
    assert bad == [], "cross-node imports:\n" + "\n".join(bad)


def test_model_is_pure():
    bad = [f"{p.relative_to(ROOT)}:{line}: imports {mod}" for p, line, mod in _library_imports("model")
           if mod.split(".")[0] in TRANSPORT or (mod.startswith("flexsheet.") and _folder(mod) not in
                                                  ("flexsheet.model", "flexsheet.yamlio", "flexsheet.manifest"))]
    assert bad == [], "flexsheet.model must stay pure:\n" + "\n".join(bad)


def _edges() -> tuple[dict[str, set[str]], dict[tuple[str, str], str]]:
    edges: dict[str, set[str]] = {}
    where: dict[tuple[str, str], str] = {}
    for base in ("flexsheet", "messages", "nodes"):
        for path in sorted((ROOT / base).rglob("*.py")):
            src = _folder(_module(path))
            for line, mod in _imports(path):
                dst = _folder(mod)
                if dst and src and dst != src:
                    edges.setdefault(src, set()).add(dst)
                    where.setdefault((src, dst), f"{path.relative_to(ROOT)}:{line} ({mod})")
    return edges, where


def _cycles(edges: dict[str, set[str]], where: dict[tuple[str, str], str]) -> list[str]:
    def reach(a: str, seen: set[str]) -> set[str]:
        for b in edges.get(a, ()):
            if b not in seen:
                seen.add(b)
                reach(b, seen)
        return seen

    return sorted(f"{a} -> {b} [{where[(a, b)]}] and back" for a in edges for b in edges[a] if a in reach(b, set()))


def test_no_import_cycle_between_folders():
    edges, where = _edges()
    assert "flexsheet.runtime" in edges and "flexsheet.fem" in edges, "the import graph was not read"
    assert _cycles(edges, where) == [], "import cycles between folders:\n" + "\n".join(_cycles(edges, where))


def test_the_cycle_finder_finds_a_planted_cycle():
    edges = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    where = {(x, y): "" for x in edges for y in edges[x]}
    assert [c.split(" ")[0] for c in _cycles(edges, where)] == ["a", "b", "c"]


def test_checker_reads_imports_with_lines(tmp_path):
    """The rules above are not vacuous: a planted import is reported with its line and module."""
    f = tmp_path / "x.py"
    f.write_text("import os\nfrom nodes.camera.node import CameraNode\nfrom flexsheet import registry\n")
    assert _imports(f) == [(1, "os"), (2, "nodes.camera.node"), (3, "flexsheet"), (3, "flexsheet.registry")]
    assert _folder("nodes.camera.node") == "nodes.camera" and _folder("flexsheet.fem.solver") == "flexsheet.fem"
    assert _folder("flexsheet.registry") == "flexsheet.registry" and _folder("numpy") is None
    assert _folder("flexsheet") is None


def test_no_python_under_docs():
    assert sorted(str(p.relative_to(ROOT)) for p in (ROOT / "docs").rglob("*.py")) == []


def test_readme_and_docs_are_short_pages_of_current_state():
    readme = (ROOT / "README.md").read_text().splitlines()
    assert len(readme) <= 100, f"README.md has {len(readme)} lines (at most 100)"
    long = [i + 1 for i, line in enumerate(readme) if len(line) > 300]
    assert long == [], f"README.md lines over 300 characters: {long}"
    pages = {p.name: len(p.read_text().splitlines()) for p in (ROOT / "docs").glob("*.md")}
    assert {k: v for k, v in pages.items() if v > 300} == {}, "docs pages over 300 lines"
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
    code = [p for base in ("flexsheet", "nodes", "messages", "tests") for p in sorted((ROOT / base).rglob("*.py"))
            if p != Path(__file__).resolve()]
    hist = [f"{p.relative_to(ROOT)}:{i + 1}" for p in pages + code
            for i, line in enumerate(p.read_text().splitlines()) if WORK_LOG.search(line)]
    assert hist == [], "development history outside CHANGELOG.md:\n" + "\n".join(hist[:20])


def test_changelog_is_short_and_versioned():
    lines = (ROOT / "CHANGELOG.md").read_text().splitlines()
    assert len(lines) <= 300, f"CHANGELOG.md has {len(lines)} lines (at most 300)"
    long = [i + 1 for i, line in enumerate(lines) if len(line) > 200]
    assert long == [], f"CHANGELOG.md lines over 200 characters: {long}"
    versions = [line for line in lines if VERSION_HEADING.match(line)]
    assert versions, "CHANGELOG.md has no released version heading '## [x.y.z] - YYYY-MM-DD'"
