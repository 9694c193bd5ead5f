"""The house's structure holds (issue 34): no import cycle, no module over 800 lines, no topic
file importing another topic's private helpers, and no transform hook shadowing
``nn.Module.apply``.

Imports are read with ``ast`` from the source (module level and inside functions, and
``TYPE_CHECKING`` blocks too: a cycle a type checker follows is still a knot for a reader).
``from package import submodule`` is an edge to the submodule only, and the root package
(whose ``__init__`` imports lazily) is no node.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "event_transforms"
MAX_LINES = 800
#: Layers whose files are topic files: one operation family each (the base class and the
#: containers of the transforms layer are its shared floor, not topics).
TOPIC_LAYERS = ("event_transforms.functional", "event_transforms.transforms")
NOT_TOPICS = {"event_transforms.transforms.base", "event_transforms.transforms.containers"}


def _modules() -> dict[str, Path]:
    out = {}
    for path in PACKAGE.rglob("*.py"):
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _resolve(module: str, is_package: bool, level: int, name: str | None) -> str:
    if not level:
        return name or ""
    base = module.split(".") if is_package else module.split(".")[:-1]
    if level > 1:
        base = base[: len(base) - (level - 1)]
    return ".".join(base + ([name] if name else []))


def _imports(modules: dict[str, Path]) -> dict[str, list[tuple[str, list[str]]]]:
    """module -> [(imported module, names imported from it)]."""
    out: dict[str, list[tuple[str, list[str]]]] = {}
    for module, path in modules.items():
        found = []
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                target = _resolve(module, path.name == "__init__.py", node.level, node.module)
                names = [alias.name for alias in node.names]
                submodules = [f"{target}.{n}" for n in names if f"{target}.{n}" in modules]
                if submodules:
                    found += [(sub, []) for sub in submodules]
                    names = [n for n in names if f"{target}.{n}" not in modules]
                if names and target in modules:
                    found.append((target, names))
            elif isinstance(node, ast.Import):
                found += [(alias.name, []) for alias in node.names if alias.name in modules]
        out[module] = [(t, n) for t, n in found if t != module and t != "event_transforms"]
    return out


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    groups: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                groups.append(sorted(group))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return groups


def test_no_import_cycle():
    modules = _modules()
    graph = {m: {t for t, _ in edges} for m, edges in _imports(modules).items()}
    assert _cycles(graph) == []


def test_the_cycle_finder_finds_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


@pytest.mark.parametrize("module", sorted(_modules()))
def test_no_module_over_800_lines(module):
    lines = len(_modules()[module].read_text().splitlines())
    assert lines <= MAX_LINES, f"{module} has {lines} lines (at most {MAX_LINES}): one job per file"


def _topic(module: str) -> tuple[str, str] | None:
    """(layer, topic) of a topic file; private modules (``_warp``) are shared helpers, not topics."""
    layer, _, name = module.rpartition(".")
    if layer in TOPIC_LAYERS and not name.startswith("_") and module not in NOT_TOPICS:
        return layer, name
    return None


def test_no_topic_file_imports_another_topics_private_names():
    modules = _modules()
    offences = []
    for module, edges in _imports(modules).items():
        if _topic(module) is None:
            continue
        for target, names in edges:
            target_topic = _topic(target)
            private = [n for n in names if n.startswith("_") and not n.startswith("__")]
            if private and target_topic is not None and target_topic[1] != _topic(module)[1]:
                offences.append(f"{module} imports {private} from {target}")
    assert offences == []


def test_no_class_defines_apply_and_no_override_ignore_for_it():
    """``apply`` stays ``torch.nn.Module.apply``: no class of the package defines it (the hook is
    ``apply_transform``), and no line needs ``type: ignore[override]`` for it."""
    hits = []
    for path in PACKAGE.rglob("*.py"):
        text = path.read_text()
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.ClassDef):
                hits += [f"{path.relative_to(ROOT)}:{item.lineno} {node.name}.apply" for item in node.body
                         if isinstance(item, ast.FunctionDef) and item.name == "apply"]
        hits += [f"{path.relative_to(ROOT)}:{n}" for n, line in enumerate(text.splitlines(), 1)
                 if "type: ignore[override]" in line and "apply" in line]
    assert hits == []
