"""The rooms of ``rl/`` import one way (:mod:`rl`'s docstring), with no circle, deferred imports
(inside functions) included."""

from __future__ import annotations

import ast
import importlib.util
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1] / "rl"
RANK = {"config_bounds": 0, "runs": 0, "envs": 1, "agents": 1, "tasks": 2, "a2cf": 3,
        "evaluation": 4, "training": 5, "studies": 6}  # fmt: skip
"""A room may import rooms of a lower rank and itself only; any module may import a config
module (``config.py``), which imports configs only (and modules that import nothing of ``rl``)."""


def _module(path: Path) -> str:
    parts = path.relative_to(ROOT.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports() -> dict[str, set[str]]:
    """rl module -> the rl modules it imports anywhere in its file."""
    modules = {_module(p): p for p in ROOT.rglob("*.py")}
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        found: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                base = node.module
                for alias in node.names:
                    full = f"{base}.{alias.name}"
                    found.add(full if full in modules else base)
            elif isinstance(node, ast.Import):
                found.update(a.name for a in node.names)
        graph[name] = {m for m in found if m in modules and m != name}
    return graph


def _room(module: str) -> str:
    return module.split(".")[1] if module.count(".") else ""


def _is_config(module: str) -> bool:
    return module.endswith(".config") or module == "rl.config_bounds"


def test_rooms_import_one_way() -> None:
    wrong = []
    graph = _imports()
    for module, imported in sorted(graph.items()):
        room = _room(module)
        if room not in RANK:
            continue  # rl/__init__.py
        for other in sorted(imported):
            there = _room(other)
            if _is_config(module) and not (_is_config(other) or not graph[other]):
                wrong.append(f"config {module} imports {other}, which is no config")
            elif _is_config(other):
                continue
            elif there and there != room and RANK[there] >= RANK[room]:
                wrong.append(f"{module} imports {other}")
    assert not wrong, "imports against the rooms' order:\n" + "\n".join(wrong)


def test_no_import_circle() -> None:
    graph = _imports()
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                return [*stack[stack.index(nxt) :], nxt]
            if nxt not in state and (cycle := visit(nxt)):
                return cycle
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (cycle := visit(node)):
            raise AssertionError("import circle: " + " -> ".join(cycle))


def test_few_modules_at_the_top() -> None:
    top = sorted(p.name for p in ROOT.glob("*.py"))
    assert len(top) <= 4, top


TREE_BUDGET_MIB = 52
"""The tracked tree travels with every GPU visit's call beside a part of the payload, 64 MiB in
all (docs/gpu.md): at 52 MiB the 108 MiB payload goes in 11 calls of 10 MiB parts."""


def test_the_tracked_tree_leaves_a_gpu_visit_room_for_its_payload() -> None:
    """What a device call sends besides its carried part (make_payload's own count)."""
    repo = ROOT.parent
    spec = importlib.util.spec_from_file_location(
        "make_payload", repo / "docs" / "results" / "gpu" / "make_payload.py"
    )
    make_payload = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(make_payload)
    try:
        total = make_payload.travelling_tree_bytes(repo) / 2**20
    except subprocess.CalledProcessError:
        pytest.skip("not a git checkout")
    assert total <= TREE_BUDGET_MIB, (
        f"the working tree a GPU visit sends is {total:.1f} MiB, over {TREE_BUDGET_MIB}: pack "
        "study records (docs/results/pack_record.py) or leave checkpoints and videos out "
        "(`git ls-files -z | xargs -0 du -b | sort -n | tail` names the largest)"
    )
