"""Package metadata: one version, the licence, the citation, the extras by job."""

from __future__ import annotations

import importlib.metadata
import re
import subprocess
import sys
from pathlib import Path

import pytest

import event_transforms

ROOT = Path(__file__).resolve().parents[1]


def _pyproject() -> dict:
    tomllib = pytest.importorskip("tomllib") if sys.version_info >= (3, 11) else pytest.importorskip("tomli")
    return tomllib.loads((ROOT / "pyproject.toml").read_text())


class TestVersion:
    def test_pyproject_reads_the_version_from_the_package(self):
        project = _pyproject()
        assert "version" not in project["project"] and "version" in project["project"]["dynamic"]
        assert project["tool"]["setuptools"]["dynamic"]["version"] == {"attr": "event_transforms.__version__"}

    def test_installed_metadata_agrees(self):
        try:
            installed = importlib.metadata.version("event-transforms")
        except importlib.metadata.PackageNotFoundError:
            pytest.skip("event-transforms is not installed (run from a checkout)")
        assert installed == event_transforms.__version__

    def test_citation_agrees(self):
        text = (ROOT / "CITATION.cff").read_text()
        assert re.search(r"^version: (\S+)$", text, re.M).group(1) == event_transforms.__version__
        assert "10.1109/ACCESS.2022.3224584" in text


class TestMetadata:
    def test_licence(self):
        project = _pyproject()["project"]
        assert project["license"] == "MIT" and project["license-files"] == ["LICENSE"]
        assert (ROOT / "LICENSE").read_text().startswith("MIT License")

    def test_base_install_is_torch_and_numpy(self):
        names = [re.split(r"[<>=!~ ]", d)[0] for d in _pyproject()["project"]["dependencies"]]
        assert names == ["torch", "numpy"]

    def test_python_classifiers_match_requires_python(self):
        project = _pyproject()["project"]
        minors = sorted(int(c.rsplit(".", 1)[1]) for c in project["classifiers"]
                        if re.fullmatch(r"Programming Language :: Python :: 3\.\d+", c))
        assert project["requires-python"] == f">=3.{minors[0]}"
        assert minors == list(range(minors[0], minors[-1] + 1))

    def test_import_loads_neither_torchvision_nor_tqdm(self):
        # torch itself imports tqdm when it is installed (torch.hub): count only what we add
        code = ("import sys, torch; before = set(sys.modules); "
                "import event_transforms as et; et.Compose; et.EventsToFrames; et.Scene; et.infer_scene; "
                "import event_transforms.functional; "
                "print(sorted(m for m in ('torchvision', 'tqdm', 'matplotlib') if m in set(sys.modules) - before))")
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
        assert out.stdout.strip() == "[]"
