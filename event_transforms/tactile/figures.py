"""The figures of a protocol run: Δ test MSE vs ``none`` against cost (``accuracy_vs_time.png``,
``accuracy_vs_time_online.png``) and at equal wall time (``accuracy_at_equal_time.png``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

__all__ = ["plot_results", "plot_equal_time"]


def plot_results(results: dict[str, Any], out: Path) -> list[Path]:
    """Per scene: Δ test MSE vs none (family 95 % CI) against one model's wall seconds per run,
    with fixed copies (``accuracy_vs_time.png``, every method at equal steps) and with online
    augmentation (``accuracy_vs_time_online.png``: training plus the augmentation of every
    epoch's copies)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib not installed (pip install 'event-transforms[app]'): no figures")
        return []
    scenes = results["scenes"]
    names = list(dict.fromkeys(m for summary in scenes.values() for m in summary["methods"]))
    colours = plt.get_cmap("tab20")
    markers = "osD^v<>pPhX*"
    style = {m: (colours(k % 20), markers[k % len(markers)]) for k, m in enumerate(names)}

    def fixed_cost(s: dict[str, Any]) -> float:
        wall = s.get("single_wall_s")
        return s["aug_s_once"] + (wall["median"] if wall else s["train_s"])

    def online_cost(s: dict[str, Any]) -> float:
        return s["online_wall_s"] if s.get("online_wall_s") is not None else fixed_cost(s)

    paths = []
    for suffix, cost_of, xlabel, title in (
        ("", fixed_cost, "1 model: s per run (aug once + train)", "at equal steps, fixed copies"),
        ("_online", online_cost, "1 model: s per run, online aug", "at equal steps, online augmentation"),
    ):
        fig, axes = plt.subplots(1, len(scenes), figsize=(3.2 * len(scenes), 3.6), squeeze=False)
        for ax, (name, summary) in zip(axes[0], scenes.items()):
            for method, s in summary["methods"].items():
                original = s.get("duplicate_of")
                delta = s["delta_vs_none"] if original is None else summary["methods"][original]["delta_vs_none"]
                cost = cost_of(s)
                colour, marker = style[method]
                if delta is None:
                    ax.plot([cost], [0.0], marker=marker, color=colour, ls="none")
                    continue
                lo, hi = delta.get("ci_family") or delta["ci95"] or (delta["mean"], delta["mean"])
                ax.errorbar([cost], [delta["mean"]], yerr=[[delta["mean"] - lo], [hi - delta["mean"]]], fmt=marker,
                            color=colour, capsize=3)
            ax.axhline(0.0, color="0.6", lw=0.8)
            ax.set_title(name, fontsize=9)
            ax.set_xlabel(xlabel, fontsize=8)
            ax.tick_params(labelsize=7)
        axes[0][0].set_ylabel("Δ test MSE vs none (N²)")
        # one legend below the panels instead of labels beside the points: nothing can overlap
        handles = [plt.Line2D([], [], color=style[m][0], marker=style[m][1], ls="none") for m in names]
        fig.suptitle(f"What each augmentation buys (family 95 % CI) and costs, {title} — synthetic scenes", fontsize=9)
        fig.tight_layout()
        fig.legend(handles, names, loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=min(len(names), 7), fontsize=7,
                   frameon=False)
        path = out / f"accuracy_vs_time{suffix}.png"
        # "tight": the saved picture grows to hold the title and the legend below the panels, however
        # narrow the figure (one scene is 3.2 inches wide, its title is not)
        fig.savefig(path, dpi=120, bbox_inches="tight")
        plt.close(fig)
        paths.append(path)
    if any("equal_time" in s for summary in scenes.values() for s in summary["methods"].values()):
        paths.append(plot_equal_time(plt, scenes, out))
    return paths


def plot_equal_time(plt: Any, scenes: dict[str, Any], out: Path) -> Path:
    """Per scene and method: Δ test MSE vs none (family 95 % CI) at equal steps (open) and at
    equal wall time with online augmentation (filled), ``accuracy_at_equal_time.png``."""
    fig, axes = plt.subplots(1, len(scenes), figsize=(3.2 * len(scenes), 3.8), squeeze=False)
    for ax, (name, summary) in zip(axes[0], scenes.items()):
        methods = [m for m, s in summary["methods"].items() if m != "none" and not s.get("duplicate_of")]
        for k, method in enumerate(methods):
            s = summary["methods"][method]
            for offset, delta, fill in ((-0.15, s["delta_vs_none"], "none"),
                                        (0.15, (s.get("equal_time") or {}).get("delta_vs_none"), "full")):
                if not delta:
                    continue
                lo, hi = delta.get("ci_family") or delta["ci95"] or (delta["mean"], delta["mean"])
                ax.errorbar([k + offset], [delta["mean"]], yerr=[[delta["mean"] - lo], [hi - delta["mean"]]], fmt="o",
                            color="C0" if fill == "none" else "C1", mfc="white" if fill == "none" else None, capsize=3)
        ax.axhline(0.0, color="0.6", lw=0.8)
        ax.set_xticks(range(len(methods)))
        ax.set_xticklabels(
            [f"{m}\n{(summary['methods'][m].get('equal_time') or {}).get('steps', '—')}" for m in methods],
            rotation=90, fontsize=6)
        ax.set_title(name, fontsize=9)
        ax.tick_params(labelsize=7)
    axes[0][0].set_ylabel("Δ test MSE vs none (N²)")
    handles = [plt.Line2D([], [], color="C0", marker="o", mfc="white", ls="none"),
               plt.Line2D([], [], color="C1", marker="o", ls="none")]
    fig.suptitle("Δ at equal steps and at equal wall time with online augmentation (family 95 % CI) — synthetic "
                 "scenes", fontsize=9)
    fig.tight_layout()
    # below the panels and their rotated method names, never over them
    fig.legend(handles, ["equal steps", "equal wall time (steps under each name)"], loc="upper center",
               bbox_to_anchor=(0.5, 0.0), ncol=2, fontsize=7, frameon=False)
    path = out / "accuracy_at_equal_time.png"
    fig.savefig(path, dpi=120, bbox_inches="tight")  # the picture grows to hold the title and the legend
    plt.close(fig)
    return path
