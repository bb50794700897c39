"""The house's structure, checked from the code's own imports: no import circles
in the package, no module beyond the size a reader can hold."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

PACKAGE = Path(__file__).resolve().parents[1] / "dftc_mujoco"


def _modules() -> dict[str, Path]:
    out = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _imports(name: str, path: Path, known: set[str]) -> set[str]:
    """The package modules ``name`` imports anywhere in its file (top level, in functions,
    under TYPE_CHECKING): each counts, as a reader follows it."""
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")
                up = up[: len(up) - node.level + 1]
                base = ".".join(up + ([base] if base else []))
            for a in node.names:  # `from . import x` names a module where one exists
                sub = f"{base}.{a.name}"
                found.add(sub if sub in known else base)
    return {m for m in found if m in known and m != name}


def test_the_package_has_no_import_circles():
    mods = _modules()
    names = sorted(mods)
    index = {m: i for i, m in enumerate(names)}
    edges = [(index[a], index[b]) for a in names for b in _imports(a, mods[a], set(mods))]
    # a module importing its own package's __init__ (which hands names on) is no circle
    edges = [(a, b) for a, b in edges if not names[a].startswith(names[b] + ".")]
    rows, cols = np.array(edges, dtype=int).T
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(len(names), len(names)))
    _, label = connected_components(graph, directed=True, connection="strong")
    circles = [
        [names[i] for i in np.flatnonzero(label == c)]
        for c in np.unique(label)
        if (label == c).sum() > 1
    ]
    assert not circles, f"import circles: {circles}"


#: the package's folders (and root modules) from the bottom layer up, as the layout page
#: draws them; names on one line are peers (none imports another)
LAYERS = [
    ("errors",),
    ("runtime",),
    ("core",),
    ("onboard",),
    ("onboard.execution",),
    ("blocks",),
    ("scenario",),
    ("sim",),
    ("render",),
    ("reporting",),
    ("closed_loop",),
    ("watch",),
    ("campaign",),
    ("envs",),
    ("run",),
    ("calibrate", "plot", "precompile"),
]


def _layer_of(module: str) -> str:
    parts = module.split(".")[1:]
    if parts[:2] == ["onboard", "execution"]:
        return "onboard.execution"
    return parts[0] if parts else ""


def test_the_folders_are_layers_each_importing_only_from_below():
    """The package reads as its layers (docs/concepts/layout.md): a module imports only
    from its own folder and the folders below it, never from one above (the package's
    ``__init__``, which hands names on, aside)."""
    mods = _modules()
    rank = {name: k for k, names in enumerate(LAYERS) for name in names}
    unplaced = {_layer_of(m) for m in mods} - set(rank) - {""}
    assert not unplaced, f"folders with no layer in LAYERS: {sorted(unplaced)}"
    upward = []
    for name, path in mods.items():
        mine = _layer_of(name)
        for other in _imports(name, path, set(mods)):
            theirs = _layer_of(other)
            if mine and theirs and theirs != mine and rank[theirs] >= rank[mine]:
                upward.append(f"{name} -> {other}")
    assert not upward, upward
    page = (PACKAGE.parent / "docs" / "concepts" / "layout.md").read_text(encoding="utf-8")
    drawn = page[page.index("```text") : page.index("```", page.index("```text") + 7)]
    for names in LAYERS:  # the page draws every layer
        for name in names:
            shown = name.split(".")[-1] + (
                "/" if name not in ("errors", "run", "plot", "precompile") else ".py"
            )
            assert shown in drawn, shown


def test_the_onboard_algorithms_stand_on_the_graph_and_the_mission_alone():
    """The layer order: the onboard blocks import, from this package, only the graph, the
    mission, the errors and the events, and never MuJoCo (or the scenario parser, the
    physics, ...)."""
    mods = _modules()
    allowed = {
        "dftc_mujoco.core.graph",
        "dftc_mujoco.core.mission",
        "dftc_mujoco.errors",
        "dftc_mujoco.core.events",
    }
    for name, path in mods.items():
        if not name.startswith("dftc_mujoco.onboard"):
            continue
        outside = {
            m for m in _imports(name, path, set(mods)) if not m.startswith("dftc_mujoco.onboard")
        }
        assert outside <= allowed, (name, sorted(outside - allowed))
        tree = ast.parse(path.read_text(encoding="utf-8"))
        names = {
            a.name.split(".")[0]
            for n in ast.walk(tree)
            if isinstance(n, ast.Import)
            for a in n.names
        }
        names |= {
            (n.module or "").split(".")[0]
            for n in ast.walk(tree)
            if isinstance(n, ast.ImportFrom) and not n.level
        }
        assert "mujoco" not in names, name


def test_the_package_type_checks():
    """mypy (configured in pyproject.toml, installed by the dev extra) finds nothing."""
    import shutil
    import subprocess
    import sys

    if (
        shutil.which("mypy") is None
        and subprocess.run([sys.executable, "-c", "import mypy"], capture_output=True).returncode
    ):
        import pytest

        pytest.skip("mypy is not installed (pip install -e '.[dev]')")
    root = PACKAGE.parent
    done = subprocess.run(
        [sys.executable, "-m", "mypy", "--no-error-summary"],
        cwd=root,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert done.returncode == 0, done.stdout + done.stderr


def test_every_cited_note_is_in_the_repository():
    """Comments cite what a reader can open: each ``docs/notes.md, n`` names a note there."""
    import re

    root = PACKAGE.parent
    notes = (root / "docs" / "notes.md").read_text(encoding="utf-8")
    have = {int(m) for m in re.findall(r"^(\d+)\. ", notes, flags=re.M)}
    cited = set()
    for path in [*PACKAGE.rglob("*.py"), *(root / "docs").rglob("*.md"), root / "README.md"]:
        text = path.read_text(encoding="utf-8")
        assert "NOTES " not in text.replace("NOTES.md", ""), path  # the old, absent file
        for group in re.findall(r"docs/notes\.md, ([0-9,\- ]+)", text):
            cited |= {int(x) for x in re.findall(r"\d+", group)}
    assert cited and cited <= have, sorted(cited - have)


def test_no_module_is_beyond_what_a_reader_holds():
    """No module of the package is over 700 lines (the scenario hub was 1,570)."""
    sizes = {p: len(p.read_text(encoding="utf-8").splitlines()) for p in PACKAGE.rglob("*.py")}
    assert max(sizes.values()) <= 700, sorted(sizes.items(), key=lambda kv: -kv[1])[:3]


def test_every_module_has_a_row_in_the_layout_table():
    """The docs' layout page (docs/concepts/layout.md, "How the code is organised") says
    where each concept lives: every module of the package is named in its table, by its
    path, by its folder's row (``render/``) or by its name in a row that groups several."""
    import re

    page = (PACKAGE.parent / "docs" / "concepts" / "layout.md").read_text(encoding="utf-8")
    start = page.index("| module | holds | paper |")
    end = page.find("\n\n", start)
    table = page[start : end if end >= 0 else len(page)]
    named = set(re.findall(r"`([^`]+)`", " ".join(r.split("|")[1] for r in table.splitlines())))
    missing = []
    for path in PACKAGE.rglob("*.py"):
        rel = path.relative_to(PACKAGE).as_posix()
        folder = rel.rsplit("/", 1)[0] + "/" if "/" in rel else ""
        if path.name in ("__init__.py", "__main__.py") or {rel, folder, path.name} & named:
            continue
        missing.append(rel)
    assert not missing, sorted(missing)


def test_no_function_in_the_package_is_over_100_lines():
    """A function a reader can hold: none of the package's is longer than 100 lines
    (Simulation.reset was 181, checks.preflight 167, events.describe 139)."""
    import ast

    long = []
    for name, path in _modules().items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                lines = (node.end_lineno or node.lineno) - node.lineno + 1
                if lines > 100:
                    long.append(f"{name}.{node.name}: {lines} lines")
    assert not long, long


def _kind_literals(node: ast.AST, kinds: set[str]) -> list[str]:
    """The event kinds ``node`` names as string constants (itself or inside a tuple, list or
    set)."""
    items = node.elts if isinstance(node, ast.Tuple | ast.List | ast.Set) else [node]
    return [n.value for n in items if isinstance(n, ast.Constant) and n.value in kinds]


def _names_kind(node: ast.AST) -> bool:
    """Whether ``node`` reads an event's kind: ``kind``, ``e["kind"]``, ``e.get("kind")``."""
    text = ast.unparse(node)
    return text == "kind" or text.endswith(("['kind']", "get('kind')"))


def test_no_event_kind_is_a_string_literal_outside_the_events_module():
    """Events are typed: a kind is compared, made and filtered as ``events.Kind``, so a
    misspelt kind is an AttributeError where it is written, not a branch that never runs.
    (Before, 57 literals named kinds across 16 modules.)"""
    from dftc_mujoco.core.events import KINDS

    kinds = set(KINDS)
    found = []
    for name, path in _modules().items():
        if name == "dftc_mujoco.core.events":
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Compare):
                sides = [node.left, *node.comparators]
                if any(_names_kind(s) for s in sides):
                    lits = [k for s in sides for k in _kind_literals(s, kinds)]
                    found += [f"{name}:{node.lineno} compares with {k!r}" for k in lits]
            elif isinstance(node, ast.Call):
                callee = ast.unparse(node.func)
                if callee.endswith(("make", ".add", "of_kind")):
                    for a in node.args[:2]:
                        found += [
                            f"{name}:{node.lineno} {callee}({k!r})"
                            for k in _kind_literals(a, kinds)
                        ]
            elif isinstance(node, ast.Dict):
                for key, value in zip(node.keys, node.values, strict=True):
                    if isinstance(key, ast.Constant) and key.value == "kind":
                        found += [
                            f"{name}:{node.lineno} {{'kind': {k!r}}}"
                            for k in _kind_literals(value, kinds)
                        ]
    assert not found, found
