"""Figures on the docs pages come from committed runs; help texts point where the text lives;
the run's pictures are not clipped.

A *committed run* is a page the benchmark scripts write under ``benchmarks/`` (``*.md``):
``reproduce_quick.md`` (the README's results, ``python benchmarks/tactile/reproduce_quick.py``),
``RESULTS.md`` and the kernel-set reruns. A figure a page cites from elsewhere (the paper's
published numbers) sits in a paragraph marked ``<!-- cited: ... -->``.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
RUNS = sorted((ROOT / "benchmarks" / "tactile").glob("*.md"))
QUICK_RUN = ROOT / "benchmarks" / "tactile" / "reproduce_quick.md"
#: The pages that quote the quick model's MSEs.
QUICK_PAGES = ("docs/benchmark.md", "docs/results.md")

MEAN_SD = re.compile(r"[-+]?\d+\.\d+ ± \d+\.\d+")
DECIMAL = re.compile(r"(?<![\w.])[-+]?\d+\.\d\d(?![\d.])")
#: Seconds ("8.3 s", "0.15–0.16 s"): timings, which the pages round; not MSEs.
SECONDS = re.compile(r"\d+(?:\.\d+)?(?:–\d+(?:\.\d+)?)? s\b")


def _plain(text: str) -> str:
    return text.replace("−", "-")  # the pages write a typographic minus, the runs a hyphen


def _paragraphs(text: str) -> list[str]:
    """Prose paragraphs (tables and code blocks apart), without those marked as cited."""
    text = re.sub(r"```.*?```", "", text, flags=re.DOTALL)
    return [p for p in re.split(r"\n\s*\n", text) if "<!-- cited" not in p and not p.lstrip().startswith("|")]


def unbacked_mean_sd(page: str, runs: str) -> list[str]:
    """Every ``mean ± sd`` of ``page`` (prose and tables) that no run holds, verbatim."""
    text = "\n\n".join(p for p in re.split(r"\n\s*\n", _plain(page)) if "<!-- cited" not in p)
    return [figure for figure in MEAN_SD.findall(text) if figure not in runs]


def unbacked_mse(page: str, runs: str) -> list[str]:
    """Every two-decimal number of a prose paragraph about MSE (``N²`` or ``MSE``) that is no
    number of a run."""
    numbers = {n.lstrip("+-") for n in DECIMAL.findall(runs)}
    return [n for para in _paragraphs(_plain(page)) if "N²" in para or "MSE" in para
            for n in DECIMAL.findall(SECONDS.sub("", para)) if n.lstrip("+-") not in numbers]


def test_quick_model_mse_figures_are_the_committed_quick_run():
    """Every ``mean ± sd`` MSE these pages quote for the quick model is one of reproduce_quick.md."""
    # the results page also shows the optical generator's run, the recorded grasps', the version-1 quick run and
    # the kernel-set comparison (their own committed pages under benchmarks/tactile/)
    others = [ROOT / "benchmarks" / "tactile" / name for name in ("optical.md", "recorded_grasps.md", "reproduce_quick_v1.md")]
    others += sorted((ROOT / "benchmarks" / "tactile").glob("reproduce_kernel_*.md"))
    quick = "\n".join(_plain(path.read_text()) for path in [QUICK_RUN, *others] if path.is_file())
    for page in QUICK_PAGES:
        assert unbacked_mean_sd((ROOT / page).read_text(), quick) == [], \
            f"{page} quotes figures benchmarks/tactile/reproduce_quick.md (or the optical and kernel-set runs) lacks"


def test_mse_figures_in_the_prose_are_numbers_of_committed_runs():
    """Every two-decimal number of a paragraph about MSE on these pages (a baseline's MSE, a Δ, an
    interval's end; timings apart) is a number of a committed run."""
    runs = "\n".join(_plain(path.read_text()) for path in RUNS)
    for page in QUICK_PAGES:
        assert unbacked_mse((ROOT / page).read_text(), runs) == [], f"{page} quotes MSEs no committed run holds"


def test_every_mean_sd_figure_on_a_docs_page_is_a_committed_run():
    runs = "\n".join(_plain(path.read_text()) for path in RUNS)
    for page in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        assert unbacked_mean_sd(page.read_text(), runs) == [], f"{page.name} quotes figures no committed run holds"


def test_the_checks_find_figures_no_run_backs():
    """The text docs/benchmark.md had before issue 34 (a rerun nobody committed) fails both checks."""
    runs = "| control | none | 0.31 ± 0.03 |\n| control | *physics least-squares* (baseline) | 0.39 |\n"
    old = ("test MSE in N² against the ridge / the physics least-squares model: control 0.26 ± 0.01 "
           "(1.93 / 0.38), paper\n  1.35 ± 0.13 (1.99 / 1.21)")
    assert unbacked_mean_sd(old, runs) == ["0.26 ± 0.01", "1.35 ± 0.13"]
    assert unbacked_mse(old, runs) == ["0.26", "0.01", "1.93", "0.38", "1.35", "0.13", "1.99", "1.21"]
    assert unbacked_mean_sd("none 0.31 ± 0.03 (0.39)", runs) == [] and unbacked_mse("0.31 N² (0.39)", runs) == []
    assert unbacked_mse("MSE 0.31 in 8.25 s, online 0.15–0.16 s", runs) == []  # timings are not MSEs
    cited = "<!-- cited: the paper -->\nThe paper's MSE: none 7.89 ± 2.09."
    assert unbacked_mean_sd(cited, runs) == [] and unbacked_mse(cited, runs) == []


def test_help_texts_point_to_pages_that_exist():
    """A help text naming a page names one that exists; none points into the README by section
    (the README's long sections moved to docs/)."""
    from event_transforms.tactile import cli

    parser = cli.build_parser()
    subparsers = next(a for a in parser._actions if a.choices and isinstance(a.choices, dict))
    texts = [parser.format_help(), *(p.format_help() for p in subparsers.choices.values())]
    pages = {page for text in texts for page in re.findall(r"\b(?:docs/[\w./-]+\.md|[A-Z]+\.md)\b", " ".join(text.split()))}
    assert all((ROOT / page).is_file() for page in pages), pages
    assert not any(re.search(r"README\s+'", text) for text in texts)


def _scenes(count: int) -> dict:
    """Summaries of ``count`` scenes with one method at equal steps and at equal time."""
    delta = {"mean": 0.5, "ci95": [0.1, 0.9], "ci_family": [0.0, 1.0]}
    method = {"delta_vs_none": delta, "equal_time": {"steps": 150, "delta_vs_none": delta},
              "aug_s_once": 0.1, "train_s": 2.0, "single_wall_s": {"median": 2.0}, "online_wall_s": 3.0}
    none = {"delta_vs_none": None, "aug_s_once": 0.0, "train_s": 2.0, "single_wall_s": {"median": 2.0},
            "online_wall_s": 2.0}
    return {f"scene-{k}": {"methods": {"none": none, "stretch": method}} for k in range(count)}


@pytest.mark.parametrize("count", [1, 6])
def test_titles_and_legends_are_inside_the_saved_figures(tmp_path, monkeypatch, count):
    """One scene makes a 3.2-inch-wide figure under a title that is wider: the saved picture
    must still hold the title and the legend (the committed equal-time figure's were clipped)."""
    pytest.importorskip("matplotlib")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.figure
    import matplotlib.image

    from event_transforms.tactile import figures

    saved: dict[str, tuple] = {}
    original = matplotlib.figure.Figure.savefig

    def savefig(fig, path, **kwargs):
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        scale = kwargs.get("dpi", fig.dpi) / fig.dpi
        widths = [fig._suptitle.get_window_extent(renderer).width * scale,
                  *(legend.get_window_extent(renderer).width * scale for legend in fig.legends)]
        saved[Path(path).name] = (widths, len(fig.legends))
        return original(fig, path, **kwargs)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", savefig)
    paths = figures.plot_results({"scenes": _scenes(count)}, tmp_path)
    assert {p.name for p in paths} == {"accuracy_vs_time.png", "accuracy_vs_time_online.png",
                                       "accuracy_at_equal_time.png"}
    for name, (widths, legends) in saved.items():
        assert legends == 1
        width_px = matplotlib.image.imread(tmp_path / name).shape[1]
        assert width_px >= max(widths), f"{name}: {width_px} px wide, its title or legend {max(widths):.0f} px"
