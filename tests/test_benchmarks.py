"""Smoke tests of the benchmark scripts: each main() runs on a tiny configuration.

Nothing here asserts on timing: the scripts measure, the tests only check that they run,
print a table, and write their own section of a results file without touching others.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

from benchmarks import _common, accuracy, fidelity, kornia_warp, peers, scaling, size_confound, streaming, training, transforms


def _results(tmp_path):
    path = tmp_path / "RESULTS.md"
    path.write_text(
        "# Benchmark results\n\n<!-- simulation:start -->\nkept as is\n<!-- simulation:end -->\n"
    )
    return path


def _section(path, name):
    text = path.read_text()
    start, end = f"<!-- {name}:start -->", f"<!-- {name}:end -->"
    assert text.count(start) == 1 and text.count(end) == 1
    assert "<!-- simulation:start -->\nkept as is\n<!-- simulation:end -->" in text
    return text[text.index(start) + len(start) : text.index(end)]


class TestCommon:
    def test_write_section_replaces_only_its_own(self, tmp_path):
        path = _results(tmp_path)
        _common.write_section("transforms", "first", path)
        _common.write_section("scaling", "other", path)
        _common.write_section("transforms", "second\n| a | b |", path)
        assert _section(path, "transforms").strip() == "second\n| a | b |"
        assert _section(path, "scaling").strip() == "other"

    def test_write_section_creates_the_file(self, tmp_path):
        path = tmp_path / "new.md"
        _common.write_section("peers", "body", path)
        assert "<!-- peers:start -->\nbody\n<!-- peers:end -->" in path.read_text()

    def test_write_section_rejects_odd_names(self, tmp_path):
        with pytest.raises(ValueError, match="name"):
            _common.write_section("a b", "x", tmp_path / "r.md")

    def test_write_section_keeps_backslashes_literal(self, tmp_path):
        path = _results(tmp_path)
        _common.write_section("x", r"a \1 \n b", path)
        _common.write_section("x", r"c \g<0>", path)
        assert _section(path, "x").strip() == r"c \g<0>"

    def test_loglog_slope(self):
        xs = [1, 2, 4, 8]
        assert _common.loglog_slope(xs, [3 * x**2 for x in xs]) == pytest.approx(2.0)
        assert math.isnan(_common.loglog_slope([2, 2], [1, 3]))

    def test_markdown_table_shape(self):
        table = _common.markdown_table(["a", "b"], [["x", 1], ["yy", 22]])
        lines = table.splitlines()
        assert len(lines) == 4 and all(line.count("|") == 3 for line in lines)

    def test_synthetic_frames_are_sparse_whole_counts(self):
        frames = _common.synthetic_frames((2, 6, 2, 20, 30), seed=3)
        assert frames.dtype == torch.float32
        assert torch.equal(frames, frames.round()) and bool((frames >= 0).all())
        assert 0.02 < float((frames > 0).float().mean()) < 0.08
        assert torch.equal(frames, _common.synthetic_frames((2, 6, 2, 20, 30), seed=3))

    def test_time_interleaved_ratios(self):
        timings, ratios = _common.time_interleaved(
            {"a": lambda: None, "b": lambda: sum(range(100))}, baseline="a", rounds=2,
            min_run_time=0.001, progress=False,
        )
        assert ratios["a"] == 1.0 and set(timings) == {"a", "b"}
        with pytest.raises(ValueError, match="baseline"):
            _common.time_interleaved({"a": lambda: None}, baseline="z")


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
        frames = _common.synthetic_frames(transforms.QUICK_SHAPE)
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
        sample = _common.synthetic_frames((6, 2, 9, 7))
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


class TestStreaming:
    def test_quick_run(self, tmp_path):
        path = _results(tmp_path)
        threads = torch.get_num_threads()
        result = streaming.main(["--quick", "--results", str(path)])
        assert torch.get_num_threads() == threads  # restored
        assert result["frames_timed"] == 72 and result["median"] <= result["p99"] <= result["max"]
        assert "p99" in _section(path, "streaming")


class TestTraining:
    def test_quick_run(self, tmp_path):
        path = _results(tmp_path)
        result = training.main(["--quick", "--results", str(path), "--methods", "none", "fs-1"])
        section = _section(path, "training")
        assert "aug share of epoch" in section
        assert result["methods"]["none"]["on_the_fly"]["augmentation_s_per_epoch"] == 0.0


def _fake_results(path):
    methods = {}
    for name, mse, cost in (("none", 8.0, 10.0), ("fs-1", 5.5, 11.0), ("hybrid", 7.2, 12.0), ("tes-2:0.5", 6.0, 10.5)):
        methods[name] = {
            "seeds": [0, 1], "copies": 1, "test_mse": [mse + 1, mse + 1.2], "val_mse": [mse, mse + 0.2],
            "converged": [True, True], "steps": 10, "delta_vs_none": None,
            "train_s": cost, "aug_s_once": 0.01, "aug_s_per_epoch": 0.0,
        }
    scene = {"gaps": ["size"], "matched_methods": [], "split_sizes": {}, "baselines": {}, "methods": methods}
    path.write_text(json.dumps({"config": {}, "wall_s": 1.0, "scenes": {"paper": scene}}))
    return path


class TestAccuracy:
    def test_pareto_front(self):
        rows = [
            {"method": "a", "time_s": 1.0, "test_mean": 5.0},
            {"method": "b", "time_s": 2.0, "test_mean": 4.0},
            {"method": "c", "time_s": 3.0, "test_mean": 6.0},  # dominated by a and b
            {"method": "d", "time_s": 1.0, "test_mean": 5.0},  # ties with a: neither dominates
        ]
        assert accuracy.pareto_front(rows) == {"a", "b", "d"}

    def test_quick_run(self, tmp_path):
        results_json = _fake_results(tmp_path / "results.json")
        path = _results(tmp_path)
        result = accuracy.main([str(results_json), "--quick", "--results", str(path), "--png", str(tmp_path / "a.png")])
        section = _section(path, "accuracy")
        assert "| fs-1" in section and "Pareto" in section and "TES mode" in section
        front = accuracy.pareto_front(result["methods"])
        assert front == {"none", "fs-1", "tes-2:0.5"}
        tes = result["tes"]
        assert tes["exact"]["max_abs_error"] <= 0.5 + 1e-9  # k = round(ζN)
        assert tes["expected"]["max_abs_error"] < 1e-6
        if result["figure"] is not None:
            assert (tmp_path / "a.png").stat().st_size > 0

    def test_rejects_other_json(self, tmp_path):
        path = tmp_path / "x.json"
        path.write_text("{}")
        with pytest.raises(ValueError, match="results.json"):
            accuracy.load_methods(path)


class TestImports:
    def test_quick_run(self, tmp_path):
        from benchmarks import imports

        path = _results(tmp_path)
        result = imports.main(["--quick", "--results", str(path)])
        assert not result["help_imports_torch"]
        assert set(result["medians"]) == set(imports.COMMANDS)
        assert "--help" in _section(path, "imports")


class TestEvents:
    def test_chunks_are_sorted_absolute_and_tonic_typed(self):
        from benchmarks import events

        pieces = list(events.chunks(3 * events.CHUNK // 2))
        assert [len(c) for c in pieces] == [events.CHUNK, events.CHUNK // 2]
        t = np.concatenate([c["t"] for c in pieces])
        assert pieces[0].dtype == events.AEDAT4 and bool((np.diff(t.astype(np.int64)) >= 0).all())
        assert int(t[0]) >= events.START_US

    def test_child_bins_every_event(self, tmp_path):
        from benchmarks import events

        assert events.child("stream", 5_000, "", None)["events_binned"] == 5_000
        path = tmp_path / "e.npy"
        events.write_file(path, 5_000)
        assert events.child("mmap", 5_000, str(path), None)["events_binned"] == 5_000

    @pytest.mark.slow
    def test_quick_run(self, tmp_path):
        from benchmarks import events

        path = _results(tmp_path)
        result = events.main(["--quick", "--results", str(path)])
        assert len(result["rows"]) == 10 and "peak RSS" in _section(path, "events")


class TestSizeConfound:
    def test_quick_run(self, tmp_path):
        """Mixed bolt sizes make force ambiguous from the events; knowing the size removes it."""
        path = _results(tmp_path)
        rows = size_confound.main(["--quick", "--results", str(path)])
        mixed, single = rows["12 + 18 mm"], rows["15 mm only"]
        assert mixed["events only"] > 3 * mixed["events + bolt size"]
        assert single["events only"] < 2 * single["events + bolt size"]
        assert "events + bolt size" in _section(path, "size_confound")


@pytest.mark.slow
class TestFidelity:
    def test_quick_run(self, tmp_path):
        """The stretch scores near real deployment grasps, the paper's zoom far from them."""
        path = _results(tmp_path)
        results = fidelity.main(["--quick", "--results", str(path)])
        for scores in results["paper"].values():
            assert scores["stretch"] < 2 * scores["real deployment"] + 0.5
            assert scores["resize"] > 5 * scores["stretch"] and scores["none"] > 3 * scores["stretch"]
        lag = results["paper-offset"]["12 + 18 mm"]
        assert lag["fs-1 + stretch"] < lag["stretch"]  # a clock offset is undone by a frame shift
        assert set(results["paper-membrane"]["12 + 18 mm"]) >= {"fs1", "tes1:0.5 + stretch"}
        assert "stretch" in _section(path, "fidelity")


class TestEventsPipeline:
    def test_quick_run(self, tmp_path):
        from benchmarks import events_pipeline

        path = tmp_path / "RESULTS.md"
        result = events_pipeline.main(["--quick", "--results", str(path)])
        text = path.read_text()
        assert "EventBatch transforms + binning" in text and "host syncs" in text
        assert result["ratios"]["frames.clone() (baseline)"] == 1.0


class TestBinningBenchmarks:
    def test_binning_quick_run(self, tmp_path):
        from benchmarks import binning

        path = tmp_path / "RESULTS.md"
        result = binning.main(["--quick", "--results", str(path)])
        text = path.read_text()
        assert "tonic and the bincount floor" in text and "Goals (issue 26)" in text
        assert result["ratios"]["frames.clone() (baseline)"] == 1.0

    def test_dataloader_quick_run(self, tmp_path):
        from benchmarks import dataloader

        path = tmp_path / "RESULTS.md"
        result = dataloader.main(["--quick", "--results", str(path)])
        assert "samples/s" in path.read_text()
        assert all(rate > 0 for rate in result["rates"].values()) and len(result["rates"]) >= 2

@pytest.mark.slow
class TestPhysicsSensitivity:
    def test_quick_run(self, tmp_path):
        """Under the default (Hertz) size model the stretch wins; the table names every model."""
        from benchmarks import physics_sensitivity

        path = _results(tmp_path)
        results = physics_sensitivity.main(["--quick", "--results", str(path)])
        assert set(results) == {"hertz", "thin-layer", "hertz-growing", "thin-layer-growing"}
        for scores in results["hertz"].values():
            assert physics_sensitivity.best(scores) == "stretch"
        assert "hertz-growing" in _section(path, "physics_sensitivity")


@pytest.mark.slow
class TestDetectionRate:
    def test_quick_run(self, tmp_path):
        from benchmarks import detection_rate

        path = _results(tmp_path)
        results = detection_rate.main(["--quick", "--results", str(path)])
        assert set(results) == set(detection_rate.POINTS)
        assert all(r["blocks"] == 2 for r in results.values())
        assert results["hot pixels 10×"]["detected"] == 2  # hot pixels declare a noise gap
        assert "detected" in _section(path, "detection_rate")


class TestSizeModelNetwork:
    """benchmarks/size_model_network.py without its training (the run takes minutes)."""

    def test_variant_changes_the_size_model_of_both_sessions_only(self):
        from benchmarks import size_model_network
        from event_transforms.tactile.scenes import SCENES

        for name in size_model_network.METHODS:
            scene = SCENES[name]
            thin = size_model_network.variant(scene, "thin-layer")
            assert thin.name == f"{name}@thin-layer" and thin.gaps == scene.gaps
            assert thin.train.config.width_exponent == thin.deploy.config.width_exponent == pytest.approx(1 / 3)
            assert thin.train.diameters_mm == scene.train.diameters_mm
            assert thin.deploy.diameters_mm == scene.deploy.diameters_mm
            assert thin.matched_methods == scene.matched_methods
            grow = size_model_network.variant(scene, "hertz-growing")
            assert grow.deploy.config.strip_length_exponent == grow.deploy.config.contrast_exponent == 0.5
            assert size_model_network.variant(scene, "hertz").train == scene.train

    def test_rows_pair_by_seed(self):
        from benchmarks import size_model_network

        def method(values, delta=None):
            return {"test_mse": values, "delta_vs_none": delta}

        scenes = {
            "paper@thin-layer": {"methods": {
                "none": method([2.0, 2.2, 2.1]),
                "resize": method([2.0, 2.3, 2.0], {"mean": 0.0, "ci_family": [-0.3, 0.3]}),
                "stretch": method([1.0, 1.25, 1.1], {"mean": -1.0, "ci_family": [-1.2, -0.8]}),
            }},
            "paper-offset@thin-layer": {"methods": {
                "none": method([4.0, 4.0, 4.1]), "fs-1": method([3.0, 3.1, 3.0], {"mean": -1.0, "ci_family": [-1.3, -0.7]})}},
            "paper-membrane@thin-layer": {"methods": {
                "none": method([9.0, 9.0, 9.1]), "fs-1": method([9.5, 9.0, 9.9], {"mean": 0.4, "ci_family": [-0.6, 1.4]})}},
        }
        rows = {(r[1], r[2]): r for r in size_model_network.verdict_rows({"thin-layer": {"scenes": scenes}})}
        stretch_vs_resize = rows[("paper", "stretch − resize")]
        # paired: differences -1.0, -1.05, -0.9 → mean -0.983, a narrow interval below 0
        assert stretch_vs_resize[4].startswith("**-0.98 [") and stretch_vs_resize[5] == "3/3"
        assert stretch_vs_resize[6] == "better"
        assert rows[("paper-membrane", "fs-1 − none")][6] == "not resolved"
        assert rows[("paper-membrane", "fs-1 − none")][5] == "0/3"
        assert rows[("paper-offset", "fs-1 − none")][4] == "**-1.00 [-1.30, -0.70]**"


class TestReaders:
    @pytest.mark.slow  # a fresh process per format (about 2 s each)
    def test_quick_run_writes_its_section(self, tmp_path):
        pytest.importorskip("h5py")
        pytest.importorskip("rosbags")
        from benchmarks import readers

        path = tmp_path / "RESULTS.md"
        body = readers.main(["--quick", "--results", str(path), "--formats", "npy", "h5-rows", "bag1"])
        assert "## Reading recordings" in path.read_text() and body.count("\n| ") == 4
