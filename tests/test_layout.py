"""The code layout's rules (issue 12), checked with ``ast`` so a violation names the file, line and import.

- a node (``nodes/X/``) imports only ``flexsheet.*``, ``messages`` and ``nodes.X`` itself;
- ``flexsheet.model`` is pure: no transport (zmq, asyncio, msgpack, pymodbus) and nothing from the runtime,
  the experiments or the nodes;
- no import cycle between the top-level parts (runtime, model, experiments, messages, nodes).
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TRANSPORT = {"zmq", "asyncio", "msgpack", "pymodbus"}


def _imports(path: Path) -> list[tuple[int, str]]:
    out = []
    for n in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(n, ast.Import):
            out += [(n.lineno, a.name) for a in n.names]
        elif isinstance(n, ast.ImportFrom):
            if n.level:
                raise AssertionError(f"{path.relative_to(ROOT)}:{n.lineno}: relative import; use absolute imports")
            out.append((n.lineno, n.module or ""))
    return out


def _part(module: str) -> str | None:
    parts = module.split(".")
    if parts[0] == "flexsheet" and len(parts) > 1 and parts[1] in ("runtime", "model", "experiments"):
        return "flexsheet." + parts[1]
    if parts[0] in ("messages", "nodes"):
        return parts[0]
    return None


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
    bad = []
    for path in sorted((ROOT / "flexsheet" / "model").rglob("*.py")):
        for line, mod in _imports(path):
            top = mod.split(".")[0]
            if top in TRANSPORT or _part(mod) in ("flexsheet.runtime", "flexsheet.experiments", "nodes"):
                bad.append(f"{path.relative_to(ROOT)}:{line}: imports {mod}")
    assert bad == [], "flexsheet.model must stay pure:\n" + "\n".join(bad)


def test_no_cycle_between_parts():
    edges: dict[str, set[str]] = {}
    where: dict[tuple[str, str], str] = {}
    for base in ("flexsheet", "messages", "nodes"):
        for path in sorted((ROOT / base).rglob("*.py")):
            src = _part(".".join(path.relative_to(ROOT).with_suffix("").parts))
            if src is None:
                continue
            for line, mod in _imports(path):
                dst = _part(mod)
                if dst and dst != src:
                    edges.setdefault(src, set()).add(dst)
                    where.setdefault((src, dst), f"{path.relative_to(ROOT)}:{line} ({mod})")

    def reach(a: str, seen: set[str]) -> set[str]:
        for b in edges.get(a, ()):
            if b not in seen:
                seen.add(b)
                reach(b, seen)
        return seen

    cycles = [f"{a} -> {b} [{where[(a, b)]}] and back" for a in edges for b in edges[a] if a in reach(b, set())]
    assert cycles == [], "import cycles between parts:\n" + "\n".join(cycles)


def test_checker_catches_a_cross_node_import(tmp_path):
    """The rule above is not vacuous: a planted cross-node import is reported with its line."""
    f = tmp_path / "x.py"
    f.write_text("import os\nfrom nodes.planner.stroke import SurfacePlanner\n")
    assert [m for _, m in _imports(f)] == ["os", "nodes.planner.stroke"]
    assert _imports(f)[1][0] == 2
