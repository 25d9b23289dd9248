"""The code layout's rules, checked with ``ast`` so a violation names the file, line and import.

- the map: the Layout table of docs/architecture.md (one row per part: ``may import``, ``never imports``) is
  read from the page and holds for every import of every file of ``flexsheet/``, ``nodes/`` and ``messages/``,
  in functions too (the generic runtime, the pure model, the algorithms' layers), but for :data:`PENDING`;
- ``flexsheet/`` is the library: nothing in it imports ``nodes`` (the adapters); only
  ``flexsheet/runtime/zmq/`` imports zmq;
- node types are entry points (``flexsheet.nodes``): no file of ``flexsheet/`` names a ``nodes.…:Class``;
- a node (``nodes/X/``) imports only ``flexsheet.*``, ``messages`` and ``nodes.X`` itself; only the twin's own
  nodes (``nodes/world/``, ``nodes/arm_controller_sim/``) import ``flexsheet.twin``;
- no bench lives in ``nodes/``: no file there is named ``*bench*`` and no ``flexsheet.benches`` entry point
  names a module there (benches are ``flexsheet/benches/``, under the library's rules);
- no import cycle between folders (the packages of ``flexsheet/``, ``messages``, each node), nor between the
  modules inside a folder (imports under ``if TYPE_CHECKING:`` are not run and do not count);
- no re-export: a module's ``__all__`` names only what it defines; no ``_private`` name is imported from
another module;
- no file of ``flexsheet/`` or ``nodes/`` over 500 lines, no function over 80;
- the unit tests mirror the library: ``tests/unit/<package>/test_<module>.py`` tests
  ``flexsheet/<package>/<module>.py`` (or the package ``<module>/``), a subpackage's likewise
  (``tests/unit/fem/reference/test_paths.py`` ``flexsheet/fem/reference/paths.py``),
  ``tests/unit/test_<x>.py`` ``flexsheet/<x>.py``;
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
#: a work-log reference (history belongs in CHANGELOG.md; docs, docstrings and comments describe today)
WORK_LOG = re.compile(r"\bsessions? [0-9]+|\bsession-[0-9]+|this session|last session|\bissues? [0-9]+", re.I)
#: a released version's heading in CHANGELOG.md (https://keepachangelog.com/en/1.1.0/)
VERSION_HEADING = re.compile(r"^## \[[0-9]+\.[0-9]+\.[0-9]+\] - [0-9]{4}-[0-9]{2}-[0-9]{2}$")


def _imports(path: Path) -> list[tuple[int, str]]:
    out = []
    for n in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(n, ast.Import):
            out += [(n.lineno, a.name) for a in n.names]
        elif isinstance(n, ast.ImportFrom):
            if n.level:
                raise AssertionError(f"{path.relative_to(ROOT)}:{n.lineno}: relative import; use absolute "
                                     "imports")
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
    return [(p, line, mod) for p in sorted((ROOT / "flexsheet" / sub).rglob("*.py")) for line,
            mod in _imports(p)]


def test_the_library_imports_no_node():
    bad = [f"{p.relative_to(ROOT)}:{line}: imports {mod}" for p, line, mod in _library_imports()
           if mod == "nodes" or mod.startswith("nodes.")]
    assert bad == [], "flexsheet/ must not import the adapters in nodes/:\n" + "\n".join(bad)


# ------------------------------------------------------------------------- the map of docs/architecture.md
#: the page whose Layout table is the import map: one row per part, its ``may import`` and ``never imports``
ARCHITECTURE = ROOT / "docs" / "architecture.md"
MAP_HEADER = ("part", "what lives there", "may import", "never imports")
TICKED = re.compile(r"`([^`]+)`")
#: the top-level folders whose modules are the project's (any other import is a third-party package)
PROJECT_ROOTS = ("flexsheet", "messages", "nodes")


def _map_rows(text: str) -> list[tuple[int, list[str], list[str], list[str]]]:
    """(line, part paths, may import, never imports) of each row of the map: the table under the header
    ``| part | what lives there | may import | never imports |``; each name is what a cell writes in
    backticks. Raises ``AssertionError`` when the page has no such table or a row has another number of
    cells."""
    lines = text.splitlines()
    head = [i for i, line in enumerate(lines)
            if tuple(c.strip() for c in line.strip().strip("|").split("|")) == MAP_HEADER]
    assert len(head) == 1, f"{ARCHITECTURE.relative_to(ROOT)}: no one table headed {' | '.join(MAP_HEADER)}"
    rows = []
    for i in range(head[0] + 2, len(lines)):
        if not lines[i].startswith("|"):
            break
        cells = lines[i].strip().strip("|").split("|")
        assert len(cells) == 4, f"docs/architecture.md:{i + 1}: a map row needs 4 cells (no | inside one)"
        rows.append((i + 1, *(TICKED.findall(cells[k]) for k in (0, 2, 3))))
    return rows


def _map_target(name: str, root: Path = ROOT) -> str:
    """The module prefix a map cell's name stands for: ``flexsheet`` (the whole library), ``messages``,
    ``nodes.<name>`` (the file's own node) as written, ``runtime.plugins`` → ``flexsheet.runtime.plugins``
    when ``flexsheet/runtime/plugins(.py)`` exists, any other name (``zmq``) as a third-party package's."""
    if name.split(".")[0] in PROJECT_ROOTS:
        return name
    path = root / "flexsheet" / name.replace(".", "/")
    return f"flexsheet.{name}" if path.is_dir() or path.with_suffix(".py").is_file() else name


def _is_module(module: str, root: Path) -> bool:
    path = root.joinpath(*module.split("."))
    return path.is_dir() or path.with_suffix(".py").is_file()


def _map_imports(path: Path, root: Path = ROOT) -> list[tuple[int, str]]:
    """(line, module) of every import of ``path``, in a function or under ``if TYPE_CHECKING:`` too; ``from a
    import b`` names the module ``a.b`` when it is one of the project's, else ``a``."""
    out = []
    for n in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(n, ast.Import):
            out += [(n.lineno, a.name) for a in n.names]
        elif isinstance(n, ast.ImportFrom) and n.module:
            subs = [f"{n.module}.{a.name}" for a in n.names]
            own = [s for s in subs if s.split(".")[0] in PROJECT_ROOTS and _is_module(s, root)]
            out += [(n.lineno, s) for s in own] + ([(n.lineno, n.module)] if len(own) < len(subs) else [])
    return out


def _own_part(rel: str) -> str:
    """The module prefix a file belongs to (its imports inside it are free): ``flexsheet.<package>`` or the
    top-level module ``flexsheet.<x>``, ``nodes.<name>``, ``messages``."""
    parts = rel.removesuffix(".py").split("/")
    return ".".join(parts[:2]) if parts[0] != "messages" else "messages"


def _matches(module: str, prefix: str) -> bool:
    return module == prefix or module.startswith(prefix + ".")


def _row_of(rel: str, rows: list) -> tuple | None:
    """The row whose part covers the file ``rel``: a ``.py`` path names that file, a folder path every file
    under it, ``<name>`` any one folder; a named folder is preferred to ``<name>``, then the longest path."""
    found = []
    for row in rows:
        for part in row[1]:
            pat = re.escape(part).replace(re.escape("<name>"), "[^/]+")
            if re.fullmatch(pat + ("" if part.endswith(".py") else ".*"), rel):
                found.append(("<name>" not in part, len(part), row))
    return max(found, key=lambda f: f[:2])[2] if found else None


def _map_faults(root: Path = ROOT) -> list[tuple[str, str, str]]:
    """(file, module, the line that says why) for each import of a file of ``flexsheet/``, ``nodes/`` and
    ``messages/`` that the map of ``root/docs/architecture.md`` forbids: a project module outside the file's
    own part that its row's ``may import`` does not name or its ``never imports`` does, or a third-party
    package its ``never imports`` names; a file no row covers is one fault (module '')."""
    doc = root / "docs" / "architecture.md"
    rows = _map_rows(doc.read_text())
    bad = []
    for path in [p for base in PROJECT_ROOTS for p in sorted((root / base).rglob("*.py"))]:
        rel = path.relative_to(root).as_posix()
        row = _row_of(rel, rows)
        if row is None:
            bad.append((rel, "", f"{rel}: no row of the map in docs/architecture.md covers this file"))
            continue
        line, parts, may, never = row
        own = _own_part(rel)
        allowed = [_map_target(m, root).replace("nodes.<name>", own) for m in may]
        banned = [_map_target(m, root) for m in never]
        rule = f"docs/architecture.md:{line}: {', '.join(parts)} may import {', '.join(may) or 'nothing'}" + (
            f"; never imports {', '.join(never)}" if never else "")
        for n, mod in _map_imports(path, root):
            project = mod.split(".")[0] in PROJECT_ROOTS and mod != "flexsheet"
            if any(_matches(mod, b) for b in banned) or (
                    project and not _matches(mod, own) and not any(_matches(mod, a) for a in allowed)):
                bad.append((rel, mod, f"{rel}:{n}: imports {mod} ({rule})"))
    return bad


#: imports that break the map in files that are being reworked elsewhere: (file, module) → the fix they await.
#: Each entry must still be a fault (the test says so when one is fixed): delete it with the fix.
PENDING: dict[tuple[str, str], str] = {}


def test_the_map_holds_for_every_file():
    """Every import of every file of ``flexsheet/`` (benches included), ``nodes/`` and ``messages/``, in a
    function or not, keeps to the Layout table of docs/architecture.md, except the :data:`PENDING` ones."""
    faults = _map_faults()
    assert len(_map_rows(ARCHITECTURE.read_text())) >= 15, "the check read no map"
    found = {(f, m) for f, m, _ in faults}
    stale = sorted(k for k in PENDING if k not in found)
    assert stale == [], "PENDING entries that are no longer faults (delete them):\n" + "\n".join(
        map(str, stale))
    bad = [why for f, m, why in faults if (f, m) not in PENDING]
    assert bad == [], "imports the map of docs/architecture.md forbids:\n" + "\n".join(bad)


def test_the_map_check_sees_planted_faults(tmp_path):
    """Read from a planted page: an import its row does not name (in a function too), a banned third-party
    package, another node's module, the twin from a device node and a file no row covers are faults; the own
    part, a module a row names, a leaf, the twin from the twin's own node and other third-party imports are
    not."""
    rows = ["| part | what lives there | may import | never imports |", "|---|---|---|---|",
            "| `flexsheet/model/` | m | `dirs` | `zmq` |",
            "| `flexsheet/fem/` | f | `model`, `runtime.console` | — |",
            "| `flexsheet/runtime/`, `flexsheet/dirs.py` | r | nothing | — |",
            "| `nodes/<name>/` | n | `flexsheet`, `nodes.<name>` | `twin` |",
            "| `nodes/world/` | w | `flexsheet`, `nodes.<name>` | — |"]
    files = {"docs/architecture.md": "# A\n\n" + "\n".join(rows) + "\n\ntext\n",
             "flexsheet/model/a.py": "import numpy\nimport zmq.asyncio\nfrom flexsheet import dirs\n"
                                     "from flexsheet.model import b\n",
             "flexsheet/model/b.py": "def f():\n    from flexsheet.fem.x import y\n",
             "flexsheet/fem/x.py": "from flexsheet.runtime.console import show\n"
                                   "from flexsheet.runtime import other\n",
             "flexsheet/runtime/console.py": "", "flexsheet/runtime/other.py": "", "flexsheet/dirs.py": "",
             "flexsheet/twin/t.py": "",
             "nodes/camera/node.py": "from nodes.camera.sources import S\nfrom nodes.world import node\n"
                                     "from flexsheet.twin.t import T\n",
             "nodes/camera/sources.py": "", "nodes/world/node.py": "from flexsheet.twin.t import T\n",
             "messages/__init__.py": ""}
    for f, text in files.items():
        (tmp_path / f).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / f).write_text(text)
    faults = _map_faults(tmp_path)
    assert [(f, m) for f, m, _ in faults] == [
        ("flexsheet/fem/x.py", "flexsheet.runtime.other"), ("flexsheet/model/a.py", "zmq.asyncio"),
        ("flexsheet/model/b.py", "flexsheet.fem.x"), ("flexsheet/twin/t.py", ""),
        ("messages/__init__.py", ""), ("nodes/camera/node.py", "nodes.world.node"),
        ("nodes/camera/node.py", "flexsheet.twin.t")]
    assert faults[1][2] == ("flexsheet/model/a.py:2: imports zmq.asyncio (docs/architecture.md:5: "
                            "flexsheet/model/ may import dirs; never imports zmq)")


# ---------------------------------------------------------------------------- where to look, in few files
#: a path in backticks: a file (folders optional) with a file's extension, or a folder ending in ``/``; a
#: topic (``/fingertip``) or a name (``Clock.now``) is none
DOC_PATH = re.compile(r"^([\w.-]+/)*[\w-]+\.(py|md|yaml|vert|frag|urdf|json|obj)$|^([\w.-]+/)+$")


def _where_to_look(text: str) -> tuple[list[tuple[str, list[str]]], list[list[str]]]:
    """(each lookup of the "Where to look" section with the paths its row names, the paths of each item of its
    numbered list) of the architecture page's text."""
    section = text.split("\n## Where to look\n", 1)[1].split("\n## ", 1)[0]
    rows = [line.strip("|").split("|") for line in section.splitlines()
            if line.startswith("|") and not line.startswith("|---")][1:]
    items = [line for line in section.splitlines() if re.match(r"^[0-9]+\. ", line)]
    return ([(r[0].strip(), [p for p in TICKED.findall(r[1]) if DOC_PATH.match(p)]) for r in rows],
            [[p for p in TICKED.findall(item) if DOC_PATH.match(p)] for item in items])


def test_where_to_look_names_at_most_three_files_that_exist():
    """The architecture page's "Where to look": each lookup opens at most three files, the camera frame → arm
    command path at most twelve, and every path it names exists."""
    rows, path = _where_to_look(ARCHITECTURE.read_text())
    assert len(rows) >= 6 and all(files for _, files in rows), "the check read no lookup"
    many = [what for what, files in rows if len(files) > 3]
    assert many == [], f"lookups that open more than three files: {many}"
    assert 1 <= len(path) <= 12 and all(p for p in path), "the camera → arm path: one file per step, ≤ 12"
    named = [p for _, files in rows for p in files] + [p for item in path for p in item]
    # a file named bare in a step lies beside that step's first file
    missing = [p for p in named if not (ROOT / p).exists()
               and not any((ROOT / item[0]).parent.joinpath(p).exists() for item in path if p in item)]
    assert missing == [], f"paths in docs/architecture.md's Where to look that do not exist: {missing}"


def test_the_where_to_look_reader_reads_a_planted_section():
    text = ("# A\n\n## Where to look\n\n| to look up | open |\n|---|---|\n"
            "| x | `a/b.py` (in `B`), `docs/c.md`, `/topic` |\n\n1. `n/node.py`: to `/t` via `F.g`.\n"
            "2. `m/x.py`: beside `y.py`.\n\n## Next\n\n| `z/z.py` | |\n")
    assert _where_to_look(text) == ([("x", ["a/b.py", "docs/c.md"])], [["n/node.py"], ["m/x.py", "y.py"]])


#: raw pyzmq outside the runtime, on purpose: the transport bench's baseline (the runtime against
#: raw pyzmq) and the link attacks (a squatter and a slow reader are raw sockets, not nodes)
RAW_ZMQ = {"flexsheet/benches/transport.py", "flexsheet/experiments/faults/links.py"}


def test_only_the_runtime_zmq_package_talks_to_zmq():
    users = sorted({str(p.relative_to(ROOT)) for p, _,
                    mod in _library_imports() if mod.split(".")[0] == "zmq"})
    assert any(u.startswith("flexsheet/runtime/zmq/") for u in users), "the check read no zmq import"
    bad = [u for u in users if not u.startswith("flexsheet/runtime/zmq/") and u not in RAW_ZMQ]
    assert bad == [], f"files outside flexsheet/runtime/zmq/ importing zmq: {bad}"


#: an entry-point-like reference to an adapter, ``nodes.<name>.<module>:<attribute>``
NODE_SPEC = re.compile(r"\bnodes\.[a-z_]+\.[a-z_]+:[A-Za-z_]+")


def test_node_types_come_from_entry_points():
    bad = [f"{p.relative_to(ROOT)}:{i + 1}" for p in sorted((ROOT / "flexsheet").rglob("*.py"))
           for i, line in enumerate(p.read_text().splitlines()) if NODE_SPEC.search(line)]
    assert bad == [], "flexsheet/ names adapters (use the flexsheet.nodes entry points):\n" + "\n".join(bad)
    toml = (ROOT / "pyproject.toml").read_text()
    assert '[project.entry-points."flexsheet.nodes"]' in toml and NODE_SPEC.search(toml)


def test_nodes_import_only_flexsheet_messages_and_themselves():
    bad = []
    for path in sorted((ROOT / "nodes").rglob("*.py")):
        own = path.relative_to(ROOT).parts[1]
        for line, mod in _imports(path):
            parts = mod.split(".")
            if parts[0] == "nodes" and len(parts) > 1 and parts[1] != own:
                bad.append(f"{path.relative_to(ROOT)}:{line}: imports {mod} (another node)")
    assert bad == [], "cross-node imports:\n" + "\n".join(bad)


#: the nodes that are devices' adapters (the world and the arm controller are the twin's own nodes)
DEVICE_NODES = ("camera", "head_camera", "triangulator", "planner", "arm_bridge", "fem", "renderer", "viz")
#: the twin's own nodes: they play the simulated world and the arm controllers, so they may import the twin
TWIN_NODES = ("world", "arm_controller_sim")
#: the benches' section of pyproject.toml and its ``name = "module:attribute"`` lines
BENCHES_SECTION = re.compile(r'^\[project\.entry-points\."flexsheet\.benches"\]\n(.*?)(?=^\[|\Z)',
                             re.M | re.S)
ENTRY_LINE = re.compile(r'^([A-Za-z0-9_-]+)\s*=\s*"([^"]+)"', re.M)


def _adapter_files(name: str) -> list[Path]:
    """A node's modules (every file of ``nodes/<name>/``: no bench lives there)."""
    return sorted((ROOT / "nodes" / name).rglob("*.py"))


def _benches(toml: str) -> dict[str, str]:
    """Name → ``"module:attribute"`` of the ``flexsheet.benches`` entry points in the text of
    ``pyproject.toml``."""
    section = BENCHES_SECTION.search(toml)
    return dict(ENTRY_LINE.findall(section.group(1))) if section else {}


def _nodes_faults(root: Path) -> list[str]:
    """What stops ``root/nodes/`` from being adapters only: a file of a node other than the twin's own
    (:data:`TWIN_NODES`) that imports ``flexsheet.twin``, a file named ``*bench*``, and a
    ``flexsheet.benches`` entry point of ``root/pyproject.toml`` whose module is under ``nodes``."""
    bad = []
    for path in sorted((root / "nodes").rglob("*.py")):
        rel = path.relative_to(root).as_posix()
        if "bench" in path.name:
            bad.append(f"{rel}: a bench in nodes/ (benches live in flexsheet/benches/)")
        if rel.split("/")[1] not in TWIN_NODES:
            bad += [f"{rel}:{line}: imports {mod}" for line, mod in _imports(path)
                    if mod == "flexsheet.twin" or mod.startswith("flexsheet.twin.")]
    bad += [f"pyproject.toml: bench {name} is {spec}, in nodes/ (benches live in flexsheet/benches/)"
            for name, spec in _benches((root / "pyproject.toml").read_text()).items()
            if spec.split(":")[0] == "nodes" or spec.startswith("nodes.")]
    return bad


def test_nodes_hold_no_bench_and_only_the_twins_nodes_import_the_twin():
    """A device node takes its device through a port (``flexsheet/vision/camera_port.py``,
    ``head_camera_port.py``, ``flexsheet/arm/controller_port.py``, ``flexsheet/rendering/output_port.py``: an
    entry point per source); the twin provides the simulated side, and only the twin's own nodes (the world,
    the arm controller twin) import ``flexsheet.twin``. The benches are graphs and measurements built on the
    library (``flexsheet/benches/``), never files of ``nodes/``."""
    assert len(_benches((ROOT / "pyproject.toml").read_text())) >= 10, "the check read no bench entry point"
    assert any(mod.startswith("flexsheet.twin") for p in _adapter_files("world") for _, mod in _imports(p)), \
        "the check read no import of the twin"
    bad = _nodes_faults(ROOT)
    assert bad == [], "nodes/ holds benches or imports the twin (put it behind a port):\n" + "\n".join(bad)


def test_the_nodes_check_sees_planted_benches_and_twin_imports(tmp_path):
    """A device node's import of the twin (either form), a file named ``*bench*`` and a bench entry point into
    ``nodes`` are refused; the twin's own nodes' imports of it and a bench of the library are not."""
    files = {"nodes/camera/node.py": "from flexsheet.twin.camera import twin_renderer\n",
             "nodes/planner/node.py": "import os\nfrom flexsheet import twin\n",
             "nodes/world/node.py": "from flexsheet.twin.world import World\n",
             "nodes/arm_controller_sim/node.py": "import flexsheet.twin.controller\n",
             "nodes/viz/bench.py": "import os\n",
             "nodes/fem/timing.py": "import os\n",
             "pyproject.toml": '[project.entry-points."flexsheet.benches"]\n'
                               'arm = "flexsheet.benches.arm:main"\nfem_timing = "nodes.fem.timing:main"\n\n'
                               '[tool.x]\ny = "nodes.a:b"\n'}
    for f, text in files.items():
        (tmp_path / f).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / f).write_text(text)
    assert _nodes_faults(tmp_path) == [
        "nodes/camera/node.py:1: imports flexsheet.twin.camera",
        "nodes/planner/node.py:2: imports flexsheet.twin",
        "nodes/viz/bench.py: a bench in nodes/ (benches live in flexsheet/benches/)",
        "pyproject.toml: bench fem_timing is nodes.fem.timing:main, in nodes/ (benches live in "
        "flexsheet/benches/)"]


def _sim_branches(source: str) -> list[int]:
    """Lines of ``source`` that branch on simulation: ``.simulated`` or ``.sim`` read, a name ``sim``, or a
    comparison with ``"sim"``."""
    lines = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Attribute) and node.attr in ("simulated", "sim"):
            lines.append(node.lineno)
        elif isinstance(node, ast.Name) and node.id == "sim":
            lines.append(node.lineno)
        elif isinstance(node, ast.Compare) and any(isinstance(c, ast.Constant) and c.value == "sim"
                                                   for c in (node.left, *node.comparators)):
            lines.append(node.lineno)
    return sorted(set(lines))


def test_device_nodes_do_not_branch_on_simulation_and_stay_short():
    """A device node is the same code on both clocks (the runtime's :class:`PacedCall`,
    :meth:`Node.background`, :meth:`Node.pause` and the ports hold the difference), its ``node.py`` is at most
    250 lines, and the planner imports nothing from ``flexsheet.arm`` (the two arms' command is
    :mod:`flexsheet.planning.arm_command`)."""
    branches = [f"{p.relative_to(ROOT)}:{line}" for name in DEVICE_NODES for p in _adapter_files(name)
                for line in _sim_branches(p.read_text())]
    assert branches == [], "device nodes branching on simulation:\n" + "\n".join(branches)
    long = {name: n for name in DEVICE_NODES
            if (n := len((ROOT / "nodes" / name / "node.py").read_text().splitlines())) > 250}
    assert long == {}, f"device node.py files over 250 lines: {long}"
    arm = [f"{p.relative_to(ROOT)}:{line}: {mod}" for p in _adapter_files("planner") for line,
           mod in _imports(p)
           if mod == "flexsheet.arm" or mod.startswith("flexsheet.arm.")]
    assert arm == [], "the planner node imports the arms' package:\n" + "\n".join(arm)


def test_the_simulation_branch_finder_sees_planted_branches():
    planted = ("if self.clock.simulated:\n    pass\n"
               "x = 1\n"
               "if p.source == 'sim':\n    pass\n"
               "y = self.sim\n"
               "check(self.clock)\n"
               "z = Literal['sim', 'tcp']\n")
    assert _sim_branches(planted) == [1, 4, 6]


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

    return sorted(f"{a} -> {b} [{where[(a, b)]}] and back" for a in edges for b in edges[a]
                  if a in reach(b, set()))


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
    assert (_folder("nodes.camera.node") == "nodes.camera"
            and _folder("flexsheet.fem.solver") == "flexsheet.fem")
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
    code = [p for base in ("flexsheet", "nodes", "messages", "tests")
            for p in sorted((ROOT / base).rglob("*.py"))
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


# ------------------------------------------------------------------------------------ inside the folders
def _code_files() -> list[Path]:
    return [p for base in ("flexsheet", "messages", "nodes") for p in sorted((ROOT / base).rglob("*.py"))]


def _run_imports(path: Path, modules: set[str]) -> list[tuple[int, str, list[str]]]:
    """(line, module imported, names) of every import that runs (not under ``if TYPE_CHECKING:``); ``from a
    import b`` names the module ``a.b`` when that is one of ``modules``."""
    out: list[tuple[int, str, list[str]]] = []

    def visit(node: ast.AST) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test):
                for c in child.orelse:
                    visit(c)
                continue
            if isinstance(child, ast.Import):
                out.extend((child.lineno, a.name, []) for a in child.names)
            elif isinstance(child, ast.ImportFrom) and child.module:
                for a in child.names:
                    sub = f"{child.module}.{a.name}"
                    out.append((child.lineno, sub, []) if sub in modules
                               else (child.lineno, child.module, [a.name]))
            visit(child)

    visit(ast.parse(path.read_text(), str(path)))
    return out


def _module_edges() -> tuple[dict[str, set[str]], dict[tuple[str, str], str]]:
    files = _code_files()
    modules = {_module(p) for p in files}
    edges: dict[str, set[str]] = {}
    where: dict[tuple[str, str], str] = {}
    for path in files:
        src = _module(path)
        for line, mod, _ in _run_imports(path, modules):
            if mod in modules and mod != src and _folder(mod) == _folder(src):
                edges.setdefault(src, set()).add(mod)
                where.setdefault((src, mod), f"{path.relative_to(ROOT)}:{line}")
    return edges, where


def test_no_import_cycle_inside_a_folder():
    edges, where = _module_edges()
    assert "flexsheet.runtime.node" in edges, "the module graph was not read"
    assert _cycles(edges, where) == [], "import cycles inside folders:\n" + "\n".join(_cycles(edges, where))


def test_no_private_name_is_imported_from_another_module():
    files = _code_files() + sorted((ROOT / "tests").rglob("*.py"))
    modules = {_module(p) for p in _code_files()}
    bad = [f"{p.relative_to(ROOT)}:{line}: {mod}.{n}" for p in files for line, mod,
           names in _run_imports(p, modules)
           if mod in modules and mod != _module(p) for n in names if n.startswith("_")
           and not n.startswith("__")]
    assert (bad
            == []), "private names imported from another module (make them public or move the caller):\n" + \
        "\n".join(bad[:40])


def _defined(tree: ast.Module) -> set[str]:
    out: set[str] = set()
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            out.add(node.name)
        elif isinstance(node, ast.Assign):
            for t in node.targets:
                out |= {n.id for n in ast.walk(t) if isinstance(n, ast.Name)}
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            out.add(node.target.id)
    return out


#: the message package's one import path of every message type (``from messages import Fingertip``), as a ROS
#: message package's: the only module that names what others define
FACADES = {"messages/__init__.py"}


def test_no_module_re_exports_what_another_defines():
    bad = []
    for path in [p for p in _code_files() if str(p.relative_to(ROOT)) not in FACADES]:
        tree = ast.parse(path.read_text(), str(path))
        names = next((ast.literal_eval(n.value) for n in tree.body if isinstance(n, ast.Assign)
                      and any(isinstance(t, ast.Name) and t.id == "__all__" for t in n.targets)), [])
        foreign = sorted(set(names) - _defined(tree))
        if foreign:
            bad.append(f"{path.relative_to(ROOT)}: __all__ names {foreign}, defined elsewhere")
    assert bad == [], "re-exports (import a name from the module that defines it):\n" + "\n".join(bad)


def test_files_and_functions_are_short():
    long_files, long_funcs = [], []
    for path in [p for base in ("flexsheet", "nodes") for p in sorted((ROOT / base).rglob("*.py"))]:
        text = path.read_text()
        if len(text.splitlines()) > 500:
            long_files.append(f"{path.relative_to(ROOT)}: {len(text.splitlines())} lines")
        for node in ast.walk(ast.parse(text, str(path))):
            if (isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
                and node.end_lineno - node.lineno + 1 > 80):
                long_funcs.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.name}: "
                                  f"{node.end_lineno - node.lineno + 1} lines")
    assert long_files == [], "files over 500 lines:\n" + "\n".join(long_files)
    assert long_funcs == [], "functions over 80 lines:\n" + "\n".join(long_funcs)


def test_the_inside_checks_see_planted_faults(tmp_path):
    """A planted private import, a TYPE_CHECKING-only import and a re-export are read as such."""
    f = tmp_path / "x.py"
    f.write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from flexsheet.model import "
                 "sheet\nfrom flexsheet.model.sheet import _p, clamp_poses\n__all__ = ['clamp_poses', "
                 "'y']\ny = 1\n")
    got = _run_imports(f, {"flexsheet.model.sheet"})
    assert got == [(1, "typing", ["TYPE_CHECKING"]), (4, "flexsheet.model.sheet", ["_p"]),
                   (4, "flexsheet.model.sheet", ["clamp_poses"])]
    assert _defined(ast.parse(f.read_text())) == {"__all__", "y"}


# -------------------------------------------------------------------------- the unit tests mirror the library
#: folders of tests/unit/ that mirror a package other than flexsheet/<folder>/: the message package
MIRRORS = {"messages": ROOT / "messages"}


def _unmirrored(unit: Path, lib: Path, mirrors: dict[str, Path]) -> list[str]:
    """The test files under ``unit`` (relative paths) whose name is no module of ``lib``:
    ``<package>/test_<m>.py`` needs the module ``lib/<package>/<m>.py`` or the package ``lib/<package>/<m>/``
    (under ``mirrors[<package>]`` instead where given), ``<package>/<sub>/test_<m>.py`` the same in the
    subpackage ``lib/<package>/<sub>/``, ``test_<x>.py`` directly in ``unit`` the module ``lib/<x>.py``."""
    bad = []
    for path in sorted(unit.rglob("test_*.py")):
        rel = path.relative_to(unit)
        name = rel.stem.removeprefix("test_")
        if len(rel.parts) == 1:
            found = (lib / f"{name}.py").is_file()
        else:
            base = mirrors.get(rel.parts[0], lib / rel.parts[0]).joinpath(*rel.parts[1:-1])
            found = (base / f"{name}.py").is_file() or (base / name / "__init__.py").is_file()
        if not found:
            bad.append(rel.as_posix())
    return bad


def test_unit_tests_mirror_the_library():
    """Every tests/unit/<package>/test_<module>.py tests flexsheet/<package>/<module>.py (or the package
    flexsheet/<package>/<module>/), a subpackage's tests/unit/<package>/<sub>/test_<module>.py likewise, every
    tests/unit/test_<x>.py tests flexsheet/<x>.py: a test lives where the module it judges does, and a
    module's tests are found by its name."""
    bad = _unmirrored(ROOT / "tests" / "unit", ROOT / "flexsheet", MIRRORS)
    assert "arm/test_kinematics.py" not in bad and "test_cli.py" not in bad, "the rule read no test file"
    assert bad == [], "unit tests named after no module (tests/unit/<package>/test_<module>.py for " \
        "flexsheet/<package>/<module>.py):\n" + "\n".join(bad)


def test_the_mirror_rule_refuses_a_planted_bad_name(tmp_path):
    """A test named after no module (in a package or a subpackage), one in a folder the library lacks and one
    for a missing top-level module are refused; a module's, a subpackage's, a subpackage's module's, a
    top-level module's and a mirrored folder's tests pass."""
    lib, unit, other = tmp_path / "lib", tmp_path / "unit", tmp_path / "messages"
    for f in ("pkg/mod.py", "pkg/sub/__init__.py", "pkg/sub/leaf.py", "pkg/data/table.json", "cli.py"):
        (lib / f).parent.mkdir(parents=True, exist_ok=True)
        (lib / f).write_text("")
    other.mkdir()
    (other / "registers.py").write_text("")
    for f in ("pkg/test_mod.py", "pkg/test_sub.py", "test_cli.py", "messages/test_registers.py",
              "pkg/conftest.py",
              "pkg/test_pkg_mod.py", "pkg/test_data.py", "pkg/sub/test_mod.py", "pkg/sub/test_leaf.py",
              "pkg/nosub/test_mod.py", "test_main.py", "nope/test_mod.py"):
        (unit / f).parent.mkdir(parents=True, exist_ok=True)
        (unit / f).write_text("")
    assert _unmirrored(unit, lib, {"messages": other}) == ["nope/test_mod.py", "pkg/nosub/test_mod.py",
                                                           "pkg/sub/test_mod.py", "pkg/test_data.py",
                                                           "pkg/test_pkg_mod.py", "test_main.py"]


# ------------------------------------------------------------------ experiments sit on top of the product
#: the CLI front ends, which wire the experiments' commands (``flexsheet experiment …``)
CLI_FRONT_ENDS = {"flexsheet/cli.py", "flexsheet/cli_commands.py"}
#: a launch file's ``report:`` line and the module it names
REPORT_LINE = re.compile(r"^report:\s*([A-Za-z0-9_.:]+)", re.M)


def _experiments_importers(root: Path) -> list[str]:
    """The imports of ``flexsheet.experiments`` (``file:line``) in the code under ``root`` (``flexsheet/``,
    ``nodes/``, ``messages/``) outside ``flexsheet/experiments/`` and the CLI front ends."""
    bad = []
    for base in ("flexsheet", "nodes", "messages"):
        for path in sorted((root / base).rglob("*.py")):
            rel = path.relative_to(root).as_posix()
            if rel.startswith("flexsheet/experiments/") or rel in CLI_FRONT_ENDS:
                continue
            bad += [f"{rel}:{line}: {mod}" for line, mod in _imports(path)
                    if mod == "flexsheet.experiments" or mod.startswith("flexsheet.experiments.")]
    return bad


def _reports_into_experiments(launch: Path) -> list[str]:
    """The launch files under ``launch`` whose ``report:`` names a module of ``flexsheet.experiments``."""
    return [f"{p.name}: {m}" for p in sorted(launch.rglob("*.yaml"))
            for m in REPORT_LINE.findall(p.read_text())
            if m.split(":")[0] == "flexsheet.experiments" or m.startswith("flexsheet.experiments.")]


def test_only_the_experiments_and_the_cli_import_the_experiments():
    """The product (the report, the tables, the studies the commands share) is built below the experiments:
    only ``flexsheet/experiments/`` and the CLI front ends import ``flexsheet.experiments``, and no launch's
    report runs from it."""
    assert (_experiments_importers(ROOT)
            == []), "imports of flexsheet.experiments outside it and the CLI:\n" + \
        "\n".join(_experiments_importers(ROOT))
    assert REPORT_LINE.search((ROOT / "launch" / "sim.yaml").read_text()), "the check read no report: line"
    assert _reports_into_experiments(ROOT / "launch") == [], "launch reports run from flexsheet.experiments"


def test_the_experiments_rule_sees_planted_faults(tmp_path):
    """A planted import of the experiments in the library and a launch report into them are refused; the
    experiments' own imports and the CLI's are not."""
    for f, text in {"flexsheet/fem/x.py": "def f():\n    from flexsheet.experiments.stroke import run\n",
                    "flexsheet/experiments/y.py": "from flexsheet.experiments import stroke\n",
                    "flexsheet/cli.py": "import flexsheet.experiments.scenes\n",
                    "nodes/a/node.py": "from flexsheet import experiments\n",
                    "launch/bad.yaml": "report: flexsheet.experiments.report:main\n",
                    "launch/good.yaml": "report: flexsheet.analysis.report:main\n"}.items():
        (tmp_path / f).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / f).write_text(text)
    (tmp_path / "messages").mkdir()
    assert _experiments_importers(tmp_path) == ["flexsheet/fem/x.py:2: flexsheet.experiments.stroke",
                                                "nodes/a/node.py:1: flexsheet.experiments"]
    assert _reports_into_experiments(tmp_path / "launch") == ["bad.yaml: flexsheet.experiments.report:main"]


# ---------------------------------------------------------------------------------- dependencies in sight
#: the most project imports (``flexsheet``, ``nodes``, ``messages``) inside functions: a
#: module's dependencies are read at its top; an import stays inside a function only for
#: a heavy or optional dependency (a GL context, a camera SDK, dask, scipy.optimize,
#: pinocchio) or the start-up time of the CLI, with its reason on its line
MAX_LOCAL_IMPORTS = 60
#: files whose imports inside functions share one reason: the CLI front ends load a command's
#: modules only when it runs, so that ``flexsheet --help`` and completion start at once
LAZY_FILES = {"flexsheet/cli.py": "start-up time", "flexsheet/cli_commands.py": "start-up time"}
PROJECT = ("flexsheet", "nodes", "messages")


def _local_imports(path: Path) -> list[tuple[int, str, bool]]:
    """(line, module, whether a comment on its lines gives a reason) of each project import inside a
    function."""
    lines = path.read_text().splitlines()
    out: list[tuple[int, str, bool]] = []

    def visit(node: ast.AST, inside: bool) -> None:
        for child in ast.iter_child_nodes(node):
            if inside and isinstance(child, (ast.Import, ast.ImportFrom)):
                mods = ([a.name for a in child.names] if isinstance(child, ast.Import)
                        else [child.module or ""])
                if any(m.split(".")[0] in PROJECT for m in mods):
                    said = any("#" in line for line in lines[child.lineno - 1:child.end_lineno])
                    out.append((child.lineno, mods[0], said))
            visit(child, inside or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)))

    visit(ast.parse("\n".join(lines), str(path)), False)
    return out


def _all_local_imports() -> list[tuple[str, int, str, bool]]:
    return [(p.relative_to(ROOT).as_posix(), line, mod, said) for p in _code_files()
            for line, mod, said in _local_imports(p)]


def test_few_imports_inside_functions():
    found = _all_local_imports()
    assert found, "the check read no import inside a function"
    assert len(found) <= MAX_LOCAL_IMPORTS, f"{len(found)} project imports inside functions (at most " \
        f"{MAX_LOCAL_IMPORTS}): import at the module's top"


def test_each_import_inside_a_function_says_why():
    bad = [f"{rel}:{line}: {mod}" for rel, line, mod,
           said in _all_local_imports() if not said and rel not in LAZY_FILES]
    assert (bad
            == []), "imports inside functions without a reason on their line (# lazy: …):\n" + "\n".join(bad)


def test_the_local_import_check_sees_planted_faults(tmp_path):
    """A project import inside a function is found with or without its reason; one at the top, one of the
    standard library inside a function and a nested function's are told apart."""
    f = tmp_path / "x.py"
    f.write_text("import os\nfrom flexsheet.model import sheet\n\n\ndef f():\n    import json\n"
                 "    from flexsheet.fem.cache import ArrayCache\n    from messages import topics  # lazy: "
                 "why\n\n    def g():\n        import nodes.camera.node\n")
    assert _local_imports(f) == [(7, "flexsheet.fem.cache", False), (8, "messages", True),
                                 (11, "nodes.camera.node", False)]
