"""The house's structure holds: no import cycle, no module over 800 lines, no topic file
importing another topic's private helpers, no private name crossing a subpackage, a library
that never imports (or speaks of) the tactile application, tests and benchmarks that never
import each other, test files named for what they test, and no transform hook shadowing
``nn.Module.apply``.

Imports are read with ``ast`` from the source (module level and inside functions, and
``TYPE_CHECKING`` blocks too: a cycle a type checker follows is still a knot for a reader).
``from package import submodule`` is an edge to the submodule only, and the root package
(whose ``__init__`` imports lazily) is no node.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = next(p for p in Path(__file__).resolve().parents if (p / "pyproject.toml").is_file())
PACKAGE = ROOT / "event_transforms"
APPLICATION = "event_transforms.tactile"
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


def _subpackage(module: str) -> str:
    """The first level below the root package (``events``, ``functional``, ``transforms``,
    ``tactile``), or ``""`` for the root's own modules (``scenes``, ``_validation``, ...)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and (PACKAGE / parts[1]).is_dir() else ""


def _private_crossings(edges: dict[str, list[tuple[str, list[str]]]]) -> list[str]:
    out = []
    for module, targets in edges.items():
        for target, names in targets:
            private = [n for n in names if n.startswith("_") and not n.startswith("__")]
            if private and _subpackage(target) != _subpackage(module):
                out.append(f"{module} imports {private} from {target}")
    return out


def test_no_private_name_crosses_a_subpackage():
    """A helper two subpackages share lives in a private module of the lower one under a plain
    name (``functional._frame_ops.check_length``, ``events._kernel.bins_of``), never as an
    underscored name imported from another subpackage."""
    assert _private_crossings(_imports(_modules())) == []


def test_the_crossing_finder_finds_a_crossing():
    edges = {"event_transforms.transforms.x": [("event_transforms.functional.y", ["_helper", "public"])],
             "event_transforms.functional.z": [("event_transforms.functional.y", ["_helper"])]}
    assert _private_crossings(edges) == [
        "event_transforms.transforms.x imports ['_helper'] from event_transforms.functional.y"]


def _all_imports(path: Path) -> set[str]:
    """Every module an ``import``/``from ... import`` of the file names (absolute or resolved)."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            out |= {node.module, *(f"{node.module}.{alias.name}" for alias in node.names)}
    return out


def test_the_library_never_imports_the_application():
    """Nothing outside ``event_transforms/tactile/`` imports it: not lazily, not for typing."""
    modules = _modules()
    offences = [f"{module} imports {target}" for module, edges in _imports(modules).items()
                if not module.startswith(APPLICATION) for target, _ in edges if target.startswith(APPLICATION)]
    offences += [f"{module} imports {name}" for module, path in modules.items()
                 if not module.startswith(APPLICATION)
                 for name in _all_imports(path) if name.startswith(APPLICATION)]
    assert offences == []


def test_the_top_level_does_not_expose_the_application():
    import subprocess
    import sys

    code = ("import event_transforms as et; assert 'tactile' not in et.__all__, 'in __all__'; "
            "assert 'tactile' not in dir(et), 'in dir'; assert not hasattr(et, 'tactile'), 'an attribute'")
    result = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    assert result.returncode == 0, result.stderr


#: Words of the tactile study (its objects and physics) that the augmentation library does not use.
STUDY_WORDS = re.compile(r"\b(bolts?|hertz|grasps?|membranes?|tactile)\b", re.IGNORECASE)


def test_the_library_does_not_speak_of_the_study():
    hits = [f"{path.relative_to(ROOT)}:{n}: {line.strip()[:80]}" for path in PACKAGE.rglob("*.py")
            if "tactile" not in path.relative_to(PACKAGE).parts
            for n, line in enumerate(path.read_text().splitlines(), 1) if STUDY_WORDS.search(line)]
    assert hits == []


def _python_files(folder: str) -> list[Path]:
    return sorted(p for p in (ROOT / folder).rglob("*.py") if "__pycache__" not in p.parts)


@pytest.mark.parametrize("folder, other", [("tests", "benchmarks"), ("benchmarks", "tests")])
def test_tests_and_benchmarks_never_import_each_other(folder, other):
    """Shared helpers live in the library or in ``tests/support``; a benchmark is run, never imported
    by a test (its test runs it as a script), and never imports a test's helpers."""
    offences = [f"{path.relative_to(ROOT)} imports {name}" for path in _python_files(folder)
                for name in _all_imports(path) if name == other or name.startswith(f"{other}.")]
    assert offences == []


ISSUE = re.compile(r"issue[ _-]?\d+|\(#\d+\)", re.IGNORECASE)


@pytest.mark.parametrize("path", _python_files("tests"), ids=lambda p: str(p.relative_to(ROOT)))
def test_test_files_are_named_for_what_they_test(path):
    """No test file is named after an issue, and its docstring says what it tests, not which
    issue asked for it (the history is in the CHANGELOG and git)."""
    assert not ISSUE.search(path.name), f"{path.name} is named after an issue"
    docstring = ast.get_docstring(ast.parse(path.read_text())) or ""
    assert not ISSUE.search(docstring), f"{path.relative_to(ROOT)}'s docstring cites an issue: {ISSUE.search(docstring)[0]}"


@pytest.mark.parametrize("path", _python_files("tests") + _python_files("benchmarks"),
                         ids=lambda p: str(p.relative_to(ROOT)))
def test_no_test_or_benchmark_file_over_800_lines(path):
    lines = len(path.read_text().splitlines())
    assert lines <= MAX_LINES, f"{path.relative_to(ROOT)} has {lines} lines (at most {MAX_LINES})"


@pytest.mark.parametrize("folder", ["library", "tactile"])
def test_each_benchmark_folder_lists_every_script(folder):
    """A newcomer finds every benchmark in its folder's README, with its command: no script
    missing, none listed that is not there."""
    where = ROOT / "benchmarks" / folder
    scripts = {p.name for p in where.glob("*.py") if not p.name.startswith(("test_", "_"))}
    readme = (where / "README.md").read_text()
    listed = set(re.findall(r"^\| `(\w+\.py)` \|", readme, re.MULTILINE))
    assert listed == scripts, f"README lists {sorted(listed - scripts)} that are not there; misses {sorted(scripts - listed)}"
    for name in scripts:
        assert f"python -m benchmarks.{folder}.{name[:-3]}" in readme, f"{name}: no command in the README"
    pages = {p.name for p in where.glob("*.md") if p.name not in ("README.md", "RESULTS.md")}
    assert all(page in readme for page in pages), sorted(p for p in pages if p not in readme)


def test_benchmarks_are_in_their_folders():
    loose = sorted(p.name for p in (ROOT / "benchmarks").iterdir()
                   if p.is_file() and p.name not in ("README.md", "__init__.py", "_common.py", "_sections.py", "conftest.py",
                                                      "test_common.py"))
    assert loose == [], f"benchmarks/ holds {loose}: put a script in library/ or tactile/ and list it there"


def test_the_places_table_maps_every_functional_topic():
    """Names predict places: docs/transforms.md's table gives, for every functional topic file, the
    transforms file of its modules and its test file, and every file it names exists."""
    text = (ROOT / "docs" / "transforms.md").read_text()
    block = text.split("<!-- places:start -->", 1)[1].split("<!-- places:end -->", 1)[0]
    rows = [[c.strip().strip("`") for c in line.strip().strip("|").split("|")] for line in block.strip().splitlines()[2:]]
    topics = {p.name for p in (PACKAGE / "functional").glob("*.py") if not p.name.startswith("_")}
    assert {row[0] for row in rows} == topics
    for functional, transforms, tests in rows:
        assert transforms.startswith("—") or (PACKAGE / "transforms" / transforms).is_file(), transforms
        assert (ROOT / tests).is_file(), tests
