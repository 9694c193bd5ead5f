"""The documentation site builds warning-free, and every public name documents itself (issue 25).

Two checks:

- ``mkdocs build --strict`` of ``mkdocs.yml`` into a temporary folder: a broken link, a
  docstring griffe cannot read or a missing page fails the suite, not a later release.
- Every public name (``__all__`` of ``event_transforms``, ``event_transforms.functional``,
  ``event_transforms.events`` and ``event_transforms.transforms``, and the public methods of
  ``EventBatch``) has an ``Args`` section where it takes arguments, a ``Shape`` section where it
  takes or returns tensors, and a runnable ``Example`` (a doctest, which the suite runs with
  ``--doctest-modules``). A new public name without them fails here. The exemptions below are the names where a section means
  nothing, each with its reason.

The pages' own code blocks run as doctests through pytest's ``--doctest-glob=docs/*.md``
(``pyproject.toml``).
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

MODULES = (
    "event_transforms", "event_transforms.functional", "event_transforms.events", "event_transforms.transforms",
)

#: (name, section) pairs where the section is meaningless; the reason is beside each.
EXEMPT: dict[tuple[str, str], str] = {
    # Warning categories: classes raised by the library with a message, never called by a user.
    ("EventsOutsideSensorWarning", "Args"): "a warning category, not constructed by users",
    ("EventsOutsideSensorWarning", "Shape"): "a warning category, holds no tensor",
    ("EventsOutsideWindowWarning", "Args"): "a warning category, not constructed by users",
    ("EventsOutsideWindowWarning", "Shape"): "a warning category, holds no tensor",
    # Params is a type alias (a nested dict of tensors), not a callable.
    ("Params", "Args"): "a type alias",
    ("Params", "Shape"): "a type alias; the shapes are each module's params_spec",
    ("Params", "Example"): "a type alias; every module's make_params example shows a tree",
    # EventBatch methods without arguments; pin_memory needs a CUDA build to run.
    ("EventBatch.split", "Args"): "takes no argument",
    ("EventBatch.sample_index", "Args"): "takes no argument",
    ("EventBatch.columns", "Args"): "takes no argument",
    ("EventBatch.to_padded", "Args"): "takes no argument",
    ("EventBatch.pin_memory", "Args"): "takes no argument",
    ("EventBatch.pin_memory", "Example"): "needs a CUDA build to pin memory; EventBatch.to's example moves a batch",
}

TENSOR_WORDS = re.compile(r"\b(Tensor|EventBatch|Video|ndarray|ArrayLike)\b")


def public_names() -> dict[str, object]:
    """Every public name, as ``qualified name -> object`` (one entry per object)."""
    names: dict[str, object] = {}
    seen: set[int] = set()
    for module_name in MODULES:
        module = importlib.import_module(module_name)
        for name in module.__all__:
            obj = getattr(module, name)
            if inspect.ismodule(obj) or not callable(obj) or id(obj) in seen:  # constants: documented beside them
                continue
            seen.add(id(obj))
            names[name] = obj
    from event_transforms import EventBatch

    for name, member in vars(EventBatch).items():
        if name.startswith("_") or isinstance(member, property) or not callable(getattr(EventBatch, name)):
            continue  # properties and columns are documented in the class docstring
        names[f"EventBatch.{name}"] = getattr(EventBatch, name)
    return names


def _signature(obj: object) -> inspect.Signature | None:
    try:
        return inspect.signature(obj.__init__ if inspect.isclass(obj) else obj)  # type: ignore[misc]
    except (TypeError, ValueError):
        return None


def _arguments(obj: object) -> list[str]:
    signature = _signature(obj)
    if signature is None:
        return []
    return [p for p in signature.parameters if p not in ("self", "cls", "args", "kwargs")]


def _tensors(obj: object) -> bool:
    """Whether the name takes or returns tensors (or event batches, arrays of events)."""
    from event_transforms.transforms import EventTransform

    if inspect.isclass(obj) and issubclass(obj, (EventTransform, torch_module())):
        return True
    signature = _signature(obj)
    if signature is None:
        return False
    annotations = [str(p.annotation) for p in signature.parameters.values()]
    annotations.append(str(signature.return_annotation))
    return any(TENSOR_WORDS.search(a) for a in annotations)


def torch_module() -> type:
    import torch

    return torch.nn.Module


def missing_sections(name: str, obj: object) -> list[str]:
    doc = inspect.getdoc(obj) or ""
    missing = []
    # A dataclass documents its constructor's arguments as its fields, under Attributes.
    args = r"^(Args|Arguments|Attributes):\s*$" if dataclasses.is_dataclass(obj) else r"^(Args|Arguments):\s*$"
    if _arguments(obj) and not re.search(args, doc, re.MULTILINE):
        missing.append("Args")
    if _tensors(obj) and not re.search(r"^Shape:\s*$", doc, re.MULTILINE):
        missing.append("Shape")
    example = re.search(r"^Examples?:\s*$", doc, re.MULTILINE)
    if not example or ">>>" not in doc[example.end():]:
        missing.append("Example")
    return [section for section in missing if (name, section) not in EXEMPT]


def test_every_public_name_has_args_shape_and_example():
    names = public_names()
    assert len(names) > 100, sorted(names)  # the three modules and EventBatch, not an empty walk
    missing = {name: sections for name, obj in names.items() if (sections := missing_sections(name, obj))}
    assert not missing, "public names without these docstring sections:\n" + "\n".join(
        f"  {name}: {', '.join(sections)}" for name, sections in sorted(missing.items())
    )


def test_exemptions_name_public_names_that_lack_the_section():
    names = public_names()
    for (name, section), reason in EXEMPT.items():
        assert name in names, f"exemption for {name!r} ({reason}): not a public name any more"
        doc = inspect.getdoc(names[name]) or ""
        assert not re.search(rf"^{section}s?:\s*$", doc, re.MULTILINE), f"{name} has {section} now: drop its exemption"


def test_checker_sees_a_missing_section():
    def kernel(frames):  # a public kernel as a newcomer might write it
        """Do something.

        Example:
            >>> 1
            1
        """

    kernel.__annotations__ = {"frames": "Tensor", "return": "Tensor"}
    assert missing_sections("kernel", kernel) == ["Args", "Shape"]


@pytest.mark.slow
def test_site_builds_strict(tmp_path):
    pytest.importorskip("mkdocs", reason="mkdocs is not installed (it is in the test extra: pip install '.[test]')")
    pytest.importorskip("mkdocstrings_handlers.python", reason="mkdocstrings[python] is not installed (test extra)")
    result = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file", str(ROOT / "mkdocs.yml"),
         "--site-dir", str(tmp_path / "site")],
        check=False, cwd=ROOT, capture_output=True, text=True, timeout=300,
    )
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-6000:]
    assert "WARNING" not in result.stderr, result.stderr[-6000:]
    for page in ("index", "transforms/index", "events/index", "api/functional/index", "api/events/index"):
        assert (tmp_path / "site" / f"{page}.html").is_file(), page
    functional = (tmp_path / "site" / "api" / "functional" / "index.html").read_text()
    assert 'id="event_transforms.functional.rotate"' in functional  # the API pages are generated


# --------------------------------------------------------------------------- the transforms table


def transform_rows() -> list[tuple[list[str], str]]:
    """The rows of docs/transforms.md's table: (module names in the first cell, events cell)."""
    from tests.test_readme_table import markdown_tables

    text = (ROOT / "docs" / "transforms.md").read_text().replace("\\|", "/")
    table = next(t for t in markdown_tables(text) if t[0][:3] == ["module", "frames", "events"])
    return [(re.findall(r"`(\w+)", row[0]), row[2]) for row in table[1:]]


def takes_events(cls: type) -> bool:
    """Whether a transform class has a kernel for an EventBatch (registered, or its own)."""
    from event_transforms.transforms import base

    registry = base._EVENT_KERNELS
    return cls.apply_events is not base.EventTransform.apply_events or any(k in registry for k in cls.__mro__)


def test_transforms_table_lists_every_transform():
    import event_transforms as et
    from event_transforms.transforms import EventTransform

    listed = {name for names, _ in transform_rows() for name in names}
    public = {
        name for name in et.__all__
        if inspect.isclass(obj := getattr(et, name)) and issubclass(obj, EventTransform) and obj is not EventTransform
    }
    assert public - listed == set(), f"transforms missing from docs/transforms.md's table: {sorted(public - listed)}"
    assert listed - public == set(), f"names in docs/transforms.md's table that are not transforms: {sorted(listed - public)}"


def test_transforms_table_events_column_is_true():
    import event_transforms as et

    for names, cell in transform_rows():
        if cell.startswith("if every member"):  # containers: as their members
            continue
        only = re.findall(r"`(\w+)`", cell) if cell.startswith("`") else None  # "`A`": A of the row only
        for name in names:
            claimed = name in only if only is not None else cell.startswith("yes")
            assert claimed == takes_events(getattr(et, name)), (
                f"docs/transforms.md says {name} {'takes' if claimed else 'does not take'} an EventBatch; the code disagrees"
            )
