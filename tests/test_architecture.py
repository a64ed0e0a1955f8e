"""The package's shape: stage packages in one direction, no circles, science without plots or writes.

Layers, lowest first: ``common`` (shared names, provenance, run log) < ``fem``
(the engine) < the stages in DAG order < ``settings`` (the config checks the
rules call) < ``scripts`` (the rules' adapters).  A module may import its own
package and lower layers only; within a stage, only ``entry*`` and ``plots``
modules import plots, and only ``entry*`` modules (and ``common``) write
result files.
"""

from __future__ import annotations

import ast
import re
import subprocess
from pathlib import Path

import pytest

from workflow import settings

PKG = settings.REPO_ROOT / "workflow"
LAYERS = [
    "common",
    "fem",
    "doe",
    "musculoskeletal",
    "actuator",
    "cascade",
    "fea_check",
    "authors_study",
    "layout",
    "fidelity",
    "stability",
    "reporting",
    "settings",
    "scripts",
]
#: A module over this many lines says why in its docstring ("Over 400 lines: ...").
MAX_LINES = 400


def _modules() -> dict[str, Path]:
    out = {}
    for p in PKG.rglob("*.py"):
        parts = p.relative_to(PKG).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = p  # the root package is ""
    return out


def _imports(path: Path, dotted: str) -> list[tuple[str, bool]]:
    """(imported workflow module or name, at module level?) for every import in the file."""
    package = dotted if path.name == "__init__.py" else dotted.rpartition(".")[0]
    tree = ast.parse(path.read_text())
    top = {id(n) for n in tree.body}
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".") if package else []
                base = base[: len(base) - (node.level - 1)] if node.level > 1 else base
                mod = ".".join(base + ([node.module] if node.module else []))
            elif node.module and (node.module == "workflow" or node.module.startswith("workflow.")):
                mod = node.module.removeprefix("workflow").lstrip(".")
            else:
                continue
            for a in node.names:
                out.append((f"{mod}.{a.name}".lstrip("."), id(node) in top))
        elif isinstance(node, ast.Import):
            out += [
                (a.name.removeprefix("workflow."), id(node) in top)
                for a in node.names
                if a.name.startswith("workflow.")
            ]
    return out


def _graph() -> dict[str, set[str]]:
    mods = _modules()
    graph: dict[str, set[str]] = {}
    for dotted, path in mods.items():
        deps = set()
        for name, _ in _imports(path, dotted):
            # `from pkg import name`: the module `pkg.name` if it is one, else `pkg`
            while name and name not in mods:
                name = name.rpartition(".")[0]
            if name and name != dotted:
                deps.add(name)
        graph[dotted] = deps
    return graph


def _layer(module: str) -> int:
    return LAYERS.index(module.split(".")[0])


def back_edges(graph: dict[str, set[str]]) -> list[tuple[str, str]]:
    """Imports from a lower layer of a higher one."""
    return sorted((a, b) for a, deps in graph.items() for b in deps if a and b and _layer(b) > _layer(a))


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_the_checks_see_a_back_edge_and_a_circle():
    assert back_edges({"fem._unit": {"cascade.model"}, "cascade.model": set()}) == [("fem._unit", "cascade.model")]
    assert cycles({"a.x": {"a.y"}, "a.y": {"a.z"}, "a.z": {"a.x"}, "b": set()}) == [["a.x", "a.y", "a.z"]]


def test_every_module_sits_in_a_layer():
    assert {m.split(".")[0] for m in _modules() if m} <= set(LAYERS)


def test_no_back_edge_between_stage_packages():
    assert back_edges(_graph()) == []


def test_no_import_circle():
    assert cycles(_graph()) == []


def test_no_function_level_import_hides_a_dependency():
    hidden = [f"{d}: {name}" for d, p in _modules().items() for name, top in _imports(p, d) if not top]
    assert hidden == []


def _kind(module: str) -> str:
    last = module.rpartition(".")[2]
    if module.startswith(("common", "settings", "scripts")):
        return "shared"
    return "entry" if last.startswith("entry") else "plots" if last == "plots" else "science"


def test_science_imports_no_plots_and_no_entry_points():
    graph = _graph()
    bad = [
        (a, b) for a, deps in graph.items() for b in deps if _kind(a) == "science" and _kind(b) in ("plots", "entry")
    ]
    bad += [(a, b) for a, deps in graph.items() for b in deps if _kind(a) == "plots" and _kind(b) == "entry"]
    assert bad == []


def test_only_entry_points_write_results_and_only_plots_draw():
    writes, draws = [], []
    for dotted, path in _modules().items():
        text = path.read_text()
        if _kind(dotted) in ("science", "plots") and re.search(r"\bwrite_dataset\b", text):
            writes.append(dotted)
        if _kind(dotted) != "plots" and re.search(r"^\s*(import|from) matplotlib", text, re.M):
            draws.append(dotted)
    assert writes == [] and draws == []


def test_modules_stay_small_or_say_why():
    long = []
    for dotted, path in _modules().items():
        n = len(path.read_text().splitlines())
        doc = ast.get_docstring(ast.parse(path.read_text())) or ""
        if n > MAX_LINES and "Over 400 lines:" not in doc:
            long.append(f"{dotted} ({n} lines)")
    assert long == []


def test_user_facing_text_cites_the_paper_not_our_tracker():
    try:
        out = subprocess.run(
            [
                "git",
                "grep",
                "-n",
                "-I",
                "-i",
                "-E",
                r"issue [0-9]|CLARIFICATIONS",
                "--",
                ".",
                ":!CHANGELOG.md",
                ":!tests/test_architecture.py",
            ],
            cwd=settings.REPO_ROOT,
            capture_output=True,
            text=True,
            check=False,
        )
    except FileNotFoundError:
        pytest.skip("git is not installed")
    if out.returncode > 1:
        pytest.skip(f"not a git checkout: {out.stderr.strip()}")
    assert out.stdout == ""
