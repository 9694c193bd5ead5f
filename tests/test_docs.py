"""The documentation site builds warning-free, and every public name documents itself.

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
    "event_transforms.authoring",
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


def _has_example(doc: str) -> bool:
    example = re.search(r"^Examples?:\s*$", doc, re.MULTILINE)
    return bool(example) and ">>>" in doc[example.end():]


def _example_by_dispatcher(obj: object) -> bool:
    """A frame kernel (``<op>_frames``, registered for tensors) is what its dispatcher runs on
    frames, so the dispatcher's Example runs it; it needs no Example of its own (torchvision's
    ``rotate_image`` has none either). Event kernels keep their own: they are a different path."""
    import torch

    from event_transforms.functional._dispatch import _KERNELS

    for dispatcher, kernels in _KERNELS.items():
        if kernels.get(torch.Tensor) is obj:
            return _has_example(inspect.getdoc(dispatcher) or "")
    return False


def missing_sections(name: str, obj: object) -> list[str]:
    doc = inspect.getdoc(obj) or ""
    missing = []
    # A dataclass documents its constructor's arguments as its fields, under Attributes.
    args = r"^(Args|Arguments|Attributes):\s*$" if dataclasses.is_dataclass(obj) else r"^(Args|Arguments):\s*$"
    if _arguments(obj) and not re.search(args, doc, re.MULTILINE):
        missing.append("Args")
    if _tensors(obj) and not re.search(r"^Shape:\s*$", doc, re.MULTILINE):
        missing.append("Shape")
    if not _has_example(doc) and not _example_by_dispatcher(obj):
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


# The transform table of docs/transforms.md (every transform listed, its frames / events cell true)
# is checked by tests/library/test_public_names.py against the code and the batteries.



def test_the_functional_api_page_groups_each_kernel_under_its_dispatcher():
    """``docs/api/functional.md`` is what ``docs/hooks/api_functional.py`` writes from the kernel
    registry (each dispatcher, then its kernels), so a new operation cannot be left off it."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("api_functional", ROOT / "docs" / "hooks" / "api_functional.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    expected = module.page()
    assert "::: event_transforms.functional.rotate\n" in expected and "heading_level: 4" in expected
    assert (ROOT / "docs" / "api" / "functional.md").read_text() == expected, (
        "docs/api/functional.md is stale: run python docs/hooks/api_functional.py"
    )
