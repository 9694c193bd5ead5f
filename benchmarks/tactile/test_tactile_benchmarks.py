"""Smoke tests of the tactile application's benchmark scripts: each main() runs on a tiny
configuration; nothing asserts on timing."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
import torch

from benchmarks._sections import results_file as _results, section as _section
from benchmarks.tactile import accuracy, fidelity, size_confound, streaming, training


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


@pytest.mark.slow
class TestPhysicsSensitivity:
    def test_quick_run(self, tmp_path):
        """Under the default (Hertz) size model the stretch wins; the table names every model."""
        from benchmarks.tactile import physics_sensitivity

        path = _results(tmp_path)
        results = physics_sensitivity.main(["--quick", "--results", str(path)])
        assert set(results) == {"hertz", "thin-layer", "hertz-growing", "thin-layer-growing"}
        for scores in results["hertz"].values():
            assert physics_sensitivity.best(scores) == "stretch"
        assert "hertz-growing" in _section(path, "physics_sensitivity")


@pytest.mark.slow
class TestDetectionRate:
    def test_quick_run(self, tmp_path):
        from benchmarks.tactile import detection_rate

        path = _results(tmp_path)
        results = detection_rate.main(["--quick", "--results", str(path)])
        assert set(results) == set(detection_rate.POINTS)
        assert all(r["blocks"] == 2 for r in results.values())
        assert results["hot pixels 10×"]["detected"] == 2  # hot pixels declare a noise gap
        assert "detected" in _section(path, "detection_rate")


class TestSizeModelNetwork:
    """benchmarks/tactile/size_model_network.py without its training (the run takes minutes)."""

    def test_variant_changes_the_size_model_of_both_sessions_only(self):
        from benchmarks.tactile import size_model_network
        from event_transforms.tactile.benchmark_scenes import SCENES

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
        from benchmarks.tactile import size_model_network

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


#: The recorded GelSight Wedge grasps beside the repository (not ours: never committed).
DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "gelsight-wedge"


@pytest.mark.slow
@pytest.mark.skipif(not DATA.is_dir(), reason=f"the recorded GelSight Wedge grasps are not at {DATA}")
def test_the_recorded_vs_generators_benchmark_runs_quick(tmp_path):
    """``benchmarks/tactile/recorded_vs_generators.py --quick`` on three recorded grasps and two built-in ones."""
    from benchmarks.tactile import recorded_vs_generators as bench

    path = tmp_path / "RESULTS.md"
    bench.main(["--quick", "--no-optical", "--data", str(DATA), "--results", str(path)])
    text = path.read_text()
    assert "| recorded (GelSight Wedge) |          3 |" in text and "| built-in " in text


@pytest.mark.slow
@pytest.mark.skipif(not DATA.is_dir(), reason=f"the recorded GelSight Wedge grasps are not at {DATA}")
def test_the_recorded_vs_generators_sweep_marks_the_camera_of_the_smallest_distance(tmp_path):
    """The optical cameras of a sweep each get their distance to the recorded medians; the smallest is marked."""
    pytest.importorskip("taxim")
    import re

    from benchmarks.tactile import recorded_vs_generators as bench

    path = tmp_path / "RESULTS.md"
    bench.main(["--quick", "--data", str(DATA), "--results", str(path), "--optical-channels", "0",
                "--optical-thresholds", "0.05", "0.2", "--optical-shadows", "off"])
    text = path.read_text()
    rows = re.findall(r"^\| (optical \(red, threshold [\d.]+, shadows off\))( \*\*\(closest\)\*\*)? .*\| +([\d.]+) \|$", text,
                      re.MULTILINE)
    assert len(rows) == 2 and sum(bool(mark) for _, mark, _ in rows) == 1
    closest = min(rows, key=lambda row: float(row[2]))
    assert closest[1] and f": {closest[0]} (D {closest[2]})" in text


@pytest.mark.slow  # two fresh processes each compile taxim's renderer
def test_the_optical_render_benchmark_runs_quick(tmp_path):
    pytest.importorskip("taxim")
    pytest.importorskip("jax")
    from benchmarks.tactile import optical_render

    path = tmp_path / "RESULTS.md"
    optical_render.main(["--quick", "--results", str(path)])
    text = path.read_text()
    assert "<!-- optical-render:start -->" in text
    single = re.search(r"^\| single-threaded +\| +(\d+) of 2 \|", text, flags=re.M)
    assert single and single.group(1) == "1", text  # single-threaded: one image
