"""benchmarks/tactile/resampling_coverage.py: what the protocol's bootstrap intervals cover, against new
data sets the simulator draws (the under-coverage stated beside every table)."""

from __future__ import annotations

import math
import statistics

import pytest

from benchmarks.tactile.resampling_coverage import coverage, dataset_deltas


def test_coverage_by_hand():
    results = [{"full": 0.1, "per_seed": [0.0, 0.2, 0.1, 0.1]}, {"full": 0.9, "per_seed": [1.0, 1.2, 0.9, 1.3]},
               {"full": 0.4, "per_seed": [0.4, 0.6, 0.5, 0.3]}]
    out = coverage(results)
    means = [0.1, 1.1, 0.45]
    ses = [statistics.stdev(r["per_seed"]) / 2 for r in results]
    assert out["spread_of_means"] == pytest.approx(statistics.stdev(means))
    assert out["nominal_se"] == pytest.approx(statistics.fmean(ses))
    assert out["ratio"] == pytest.approx(out["spread_of_means"] / out["nominal_se"])
    assert out["spread_of_full"] == pytest.approx(statistics.stdev([0.1, 0.9, 0.4]))
    assert 0.0 <= out["covered"] <= 1.0 and not math.isnan(out["centre"])


@pytest.mark.slow
def test_two_data_sets_differ_and_their_resamples_centre_on_each(tmp_path):
    first, second = (dataset_deltas("control", d, str(tmp_path), seeds=(0, 1, 2)) for d in (0, 1))
    assert first["full"] != second["full"] and len(first["per_seed"]) == 3
    assert len(set(first["per_seed"])) == 3  # each seed its own resample


def test_every_page_states_the_measured_under_coverage():
    """The figure the report and the pages state is the one the committed benchmark page measured."""
    import re
    from pathlib import Path

    from event_transforms.tactile import resampling
    from event_transforms.tactile.report import interval_coverage

    root = Path(__file__).resolve().parents[2]
    measured = re.search(r"\*\*(\d+\.\d)×\*\* too small", (root / "benchmarks" / "tactile" / "resampling_coverage.md").read_text())
    assert measured is not None
    stated = f"{measured[1]}× the nominal standard error"
    for text in (interval_coverage("bootstrap"), resampling.__doc__ or "",
                 (root / "docs" / "results.md").read_text(), (root / "docs" / "benchmark.md").read_text()):
        assert stated in " ".join(text.split())
