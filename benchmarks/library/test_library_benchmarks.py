"""Smoke tests of the library's benchmark scripts: each main() runs on a tiny configuration.

Nothing here asserts on timing: the scripts measure, the tests only check that they run,
print a table, and write their own section of a results file without touching others.
"""

from __future__ import annotations


import numpy as np
import pytest
import torch

from benchmarks._common import synthetic_frames
from benchmarks._sections import results_file as _results, section as _section
from benchmarks.library import kornia_warp, peers, scaling, transforms


class TestTransforms:
    def test_quick_run_writes_its_section(self, tmp_path, capsys):
        path = _results(tmp_path)
        result = transforms.main(["--quick", "--results", str(path), "--rounds", "1", "--min-run-time", "0.001"])
        section = _section(path, "transforms")
        for name in (*transforms.GOALS, "torchvision v2 rotate, per-sample loop", "kornia VideoSequential"):
            assert name in section
        assert "× clone" in section and "Environment:" in section
        assert result["ratios"]["frames.clone() (baseline)"] == 1.0
        assert "× clone" in capsys.readouterr().out

    def test_every_case_keeps_the_shape(self):
        frames = synthetic_frames(transforms.QUICK_SHAPE)
        cases = {**transforms.build_cases(frames), **transforms.peer_rotations(frames)}
        for name, fn in cases.items():
            assert fn().shape == frames.shape, name

    def test_profile_names_a_row(self):
        assert "grid_sampler" in transforms.profile("Rotate(15°)", transforms.QUICK_SHAPE, rows=100)
        with pytest.raises(ValueError, match="name"):
            transforms.profile("nope", transforms.QUICK_SHAPE)


class TestKorniaWarp:
    def test_quick_run_writes_its_section(self, tmp_path):
        path = _results(tmp_path)
        result = kornia_warp.main(["--quick", "--results", str(path), "--rounds", "1", "--min-run-time", "0.001"])
        section = _section(path, "kornia_warp")
        assert "× own warp" in section and "Agreement" in section and "kornia 0." in section
        for kornia_row, own_row in kornia_warp.PAIRS.items():
            assert kornia_row in section and own_row in section
            assert result["counts"][own_row].ops < result["counts"][kornia_row].ops
        assert max(result["differences"].values()) < 1e-4


class TestScaling:
    def test_quick_run(self, tmp_path):
        path = _results(tmp_path)
        result = scaling.main(["--quick", "--results", str(path), "--min-run-time", "0.001"])
        section = _section(path, "scaling")
        assert "slope in B" in section and "ev/frame" in section and "10⁷" in section
        assert set(result["sizes"]["TES exact"]) == {"B", "T", "H·W"}


class TestPeers:
    def test_tonic_style_paths_match_the_library_binning(self):
        data = peers.load_samples(2)
        to_frame, _ = peers._tonic_to_frame(data["config"])
        for events, crop, frames in zip(data["events"], data["crops"], data["frames"]):
            assert torch.equal(peers._crop_pool(to_frame(events), crop), frames)

    def test_per_frame_loop_conserves_counts_without_drops(self):
        sample = synthetic_frames((6, 2, 9, 7))
        torch.manual_seed(0)
        out = peers.per_frame_loop_tes(sample)
        # events moved out of frames 0 and 1 (shift -2) are dropped; the rest are kept
        assert float(out.sum()) <= float(sample.sum()) and bool((out >= 0).all())

    def test_quick_run(self, tmp_path):
        path = _results(tmp_path)
        result = peers.main(["--quick", "--results", str(path), "--workers", "0"])
        section = _section(path, "peers")
        assert "(c) tonic style" in section and "(e) per-frame" in section and "(d) kornia" in section
        assert result["TES-2(0.5)"]["ratios"]["(a) per batch, exact"] == 1.0


class TestImports:
    def test_quick_run(self, tmp_path):
        from benchmarks.library import imports

        path = _results(tmp_path)
        result = imports.main(["--quick", "--results", str(path)])
        assert not result["help_imports_torch"]
        assert set(result["medians"]) == set(imports.COMMANDS)
        assert "--help" in _section(path, "imports")


class TestEvents:
    def test_chunks_are_sorted_absolute_and_tonic_typed(self):
        from benchmarks.library import events

        pieces = list(events.chunks(3 * events.CHUNK // 2))
        assert [len(c) for c in pieces] == [events.CHUNK, events.CHUNK // 2]
        t = np.concatenate([c["t"] for c in pieces])
        assert pieces[0].dtype == events.AEDAT4 and bool((np.diff(t.astype(np.int64)) >= 0).all())
        assert int(t[0]) >= events.START_US

    def test_child_bins_every_event(self, tmp_path):
        from benchmarks.library import events

        assert events.child("stream", 5_000, "", None)["events_binned"] == 5_000
        path = tmp_path / "e.npy"
        events.write_file(path, 5_000)
        assert events.child("mmap", 5_000, str(path), None)["events_binned"] == 5_000

    @pytest.mark.slow
    def test_quick_run(self, tmp_path):
        from benchmarks.library import events

        path = _results(tmp_path)
        result = events.main(["--quick", "--results", str(path)])
        assert len(result["rows"]) == 10 and "peak RSS" in _section(path, "events")


class TestEventsPipeline:
    def test_quick_run(self, tmp_path):
        from benchmarks.library import events_pipeline

        path = tmp_path / "RESULTS.md"
        result = events_pipeline.main(["--quick", "--results", str(path)])
        text = path.read_text()
        assert "EventBatch transforms + binning" in text and "host syncs" in text
        assert result["ratios"]["frames.clone() (baseline)"] == 1.0


class TestBinningBenchmarks:
    def test_binning_quick_run(self, tmp_path):
        from benchmarks.library import binning

        path = tmp_path / "RESULTS.md"
        result = binning.main(["--quick", "--results", str(path)])
        text = path.read_text()
        assert "tonic and the bincount floor" in text and "Goals:" in text
        assert result["ratios"]["frames.clone() (baseline)"] == 1.0

    def test_dataloader_quick_run(self, tmp_path):
        from benchmarks.library import dataloader

        path = tmp_path / "RESULTS.md"
        result = dataloader.main(["--quick", "--results", str(path)])
        assert "samples/s" in path.read_text()
        assert all(rate > 0 for rate in result["rates"].values()) and len(result["rates"]) >= 2


class TestReaders:
    @pytest.mark.slow  # a fresh process per format (about 2 s each)
    def test_quick_run_writes_its_section(self, tmp_path):
        pytest.importorskip("h5py")
        pytest.importorskip("rosbags")
        from benchmarks.library import readers

        path = tmp_path / "RESULTS.md"
        body = readers.main(["--quick", "--results", str(path), "--formats", "npy", "h5-rows", "bag1"])
        assert "## Reading recordings" in path.read_text() and body.count("\n| ") == 4


class TestTesMemory:
    def test_quick_run_writes_its_section(self, tmp_path):
        import subprocess
        import sys

        from benchmarks._common import child_env

        path = _results(tmp_path)
        subprocess.run([sys.executable, "-m", "benchmarks.library.tes_memory", "--quick", "--results", str(path)],
                       check=True, capture_output=True, text=True, env=child_env())
        section = _section(path, "tes-memory")
        assert "| TES exact | 200,000 |" in section and "x batch" in section


def test_the_emulation_benchmark_runs_quick(tmp_path):
    """``benchmarks/library/emulate.py --quick`` (no recorded data) prints its table and writes its own section."""
    from benchmarks.library import emulate as bench

    path = tmp_path / "RESULTS.md"
    bench.main(["--quick", "--results", str(path)])
    text = path.read_text()
    assert "<!-- emulate:start -->" in text and "real time / emulation" in text and "ideal" in text
