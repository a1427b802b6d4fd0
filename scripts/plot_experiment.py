#!/usr/bin/env python3
"""Plots of a `bvhopt experiment` output folder, from its CSVs (PNG, matplotlib Agg).

    python3 scripts/plot_experiment.py --dir OUT [--out PLOTDIR]

Writes, for whichever CSVs are present and non-empty:
  fig_kensler_passes.png        Kensler Figures 3 and 4: cost per pass (hill climbing, annealing)
  fig_bittner_depth_<scene>.png Bittner Figure 7: area sums of inner nodes and leaves per depth
  fig_dk_t_sweep.png            Dammertz-Keller Figure 4: references and time against t
  fig_dk_rotation.png           Dammertz-Keller Figure 5: the rotating scene
  fig_papers.png                our figures beside the papers' published ones (papers_comparison.csv)
Every axis says its unit; where the report compares a quantity with a paper
(papers_comparison.csv), the published value is marked on the plot of that quantity.
Prints the name of every file written. Exits 1 with a message on a malformed CSV.
"""

import argparse
import csv
import os
import sys
from collections import OrderedDict, defaultdict

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def read_rows(path):
    if not os.path.exists(path):
        return []
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def number(row, key, path):
    try:
        return float(row[key])
    except (KeyError, TypeError, ValueError):
        sys.exit(f"plot_experiment: {path}: column '{key}' missing or not a number in row {row}")


def by(rows, *keys):
    groups = OrderedDict()
    for r in rows:
        groups.setdefault(tuple(r[k] for k in keys), []).append(r)
    return groups


def save(fig, out, name, written):
    path = os.path.join(out, name)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    written.append(path)


def paper_rows(src):
    """Rows of papers_comparison.csv: the papers' published values the report compares with."""
    path = os.path.join(src, "papers_comparison.csv")
    rows = read_rows(path)
    for r in rows:
        r["paper_value"] = number(r, "paper_value", path)
        r["our_value"] = number(r, "our_value", path)
    return rows


def mark_published(ax, papers, scene, quantity, color):
    """A dashed line at each published value of `quantity` compared with `scene`."""
    for r in papers:
        if r["our_scene"] == scene and r["quantity"] == quantity:
            ax.axhline(r["paper_value"], color=color, linestyle="--", linewidth=1,
                       label=f"{r['paper']}, {r['paper_scene']}: {r['paper_value']:.3f}")


def plot_kensler(src, papers):
    path = os.path.join(src, "kensler_passes.csv")
    rows = [r for r in read_rows(path) if r.get("method") in ("hill", "anneal")]
    if not rows:
        return []
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    quantities = {"hill": "hill climbing relative cost", "anneal": "annealing relative cost"}
    for ax, method, title in ((axes[0], "hill", "Figure 3: hill climbing"), (axes[1], "anneal", "Figure 4: annealing")):
        for (scene,), group in by([r for r in rows if r["method"] == method], "scene").items():
            line, = ax.plot([number(r, "pass", path) for r in group],
                            [number(r, "relative_cost", path) for r in group], label=scene, linewidth=1)
            mark_published(ax, papers, scene, quantities[method], line.get_color())
        ax.set_title(title)
        ax.set_xlabel("optimization pass (count)")
        ax.set_ylabel("SAH cost / SAH cost of the build (ratio)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    return [("fig_kensler_passes.png", fig)]


def plot_bittner(src, papers):
    path = os.path.join(src, "bittner_depth_areas.csv")
    rows = read_rows(path)
    figures = []
    for (scene,), group in by(rows, "scene").items():
        fig, axes = plt.subplots(1, 2, figsize=(11, 4))
        for tree, style, label in (("sah", "r--", "SAH build"), ("insertion_sah", "g-", "after insertion")):
            g = [r for r in group if r["tree"] == tree]
            depths = [number(r, "depth", path) for r in g]
            axes[0].plot(depths, [number(r, "inner_area", path) for r in g], style, label=label)
            axes[1].plot(depths, [number(r, "leaf_area", path) for r in g], style, label=label)
        for ax, what in zip(axes, ("inner nodes", "leaves")):
            ax.set_title(f"Figure 7 ({scene}): {what}")
            ax.set_xlabel("depth (levels below the root)")
            ax.set_ylabel("sum of surface areas / root area (ratio)")
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8)
        figures.append((f"fig_bittner_depth_{scene}.png", fig))
    return figures


def plot_dk_sweep(src, papers):
    path = os.path.join(src, "dk_t_sweep.csv")
    rows = [r for r in read_rows(path) if r.get("t") != "off"]
    if not rows:
        return []
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for (scene,), group in by(rows, "scene").items():
        t = [number(r, "t", path) for r in group]
        axes[0].plot(t, [number(r, "ref_ratio", path) for r in group], "o-", label=scene)
        axes[1].plot(t, [number(r, "time_ratio", path) for r in group], "o-", label=scene)
    axes[0].set_ylabel("references / triangles (ratio)")
    axes[1].set_ylabel("trace time / time without subdivision (ratio)")
    for ax in axes:
        ax.set_xlabel("threshold t (edge volume limit V / 2^t)")
        ax.grid(alpha=0.3)
    axes[0].set_title("Figure 4: references")
    axes[1].set_title("Figure 4: time")
    axes[1].legend(fontsize=7)
    return [("fig_dk_t_sweep.png", fig)]


def plot_dk_rotation(src, papers):
    path = os.path.join(src, "dk_rotation.csv")
    rows = read_rows(path)
    if not rows:
        return []
    frame = [number(r, "frame", path) for r in rows]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    axes[0].plot(frame, [number(r, "base_seconds", path) for r in rows], "r-", label="base")
    axes[0].plot(frame, [number(r, "evh_seconds", path) for r in rows], "g-", label="EVH")
    axes[0].set_ylabel("trace time (s)")
    axes[1].plot(frame, [number(r, "base_references", path) for r in rows], "r-", label="base")
    axes[1].plot(frame, [number(r, "evh_references", path) for r in rows], "g-", label="EVH")
    axes[1].set_ylabel("references (count)")
    for ax in axes:
        ax.set_xlabel("frame (rotation step)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    scene = rows[0]["scene"]
    axes[0].set_title(f"Figure 5 ({scene}): time per frame")
    axes[1].set_title(f"Figure 5 ({scene}): references")
    return [("fig_dk_rotation.png", fig)]


def plot_papers(src, papers):
    """Every ratio the report compares with a paper: ours as a bar, the published value as a mark."""
    rows = [r for r in papers if "relative" in r["quantity"] or "ratio" in r["quantity"]
            or r["quantity"].startswith("area reduction")]
    if not rows:
        return []
    fig, ax = plt.subplots(figsize=(max(6, 0.55 * len(rows) + 2), 4.5))
    x = range(len(rows))
    ax.bar(x, [r["our_value"] for r in rows], color="tab:blue", label="bvhopt (ours)")
    ax.plot(x, [r["paper_value"] for r in rows], "k_", markersize=22, markeredgewidth=2,
            label="published value")
    ax.set_xticks(list(x))
    ax.set_xticklabels([f"{r['our_scene']}: {r['quantity']}\n({r['paper']}, {r['paper_scene']})" for r in rows],
                       rotation=60, ha="right", fontsize=7)
    ax.set_ylabel("value (ratio, as each quantity says)")
    ax.set_xlabel("quantity compared (paper, its scene)")
    ax.set_title("Our figures beside the papers' published ones")
    ax.grid(alpha=0.3, axis="y")
    ax.legend(fontsize=8)
    return [("fig_papers.png", fig)]


def make_figures(src):
    """Every figure the CSVs of `src` allow, as (file name, matplotlib figure) pairs."""
    papers = paper_rows(src)
    figures = []
    for plot in (plot_kensler, plot_bittner, plot_dk_sweep, plot_dk_rotation, plot_papers):
        figures += plot(src, papers)
    return figures


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dir", required=True, help="experiment output folder holding the CSVs")
    parser.add_argument("--out", help="folder for the PNGs (default: --dir)")
    args = parser.parse_args()
    if not os.path.isdir(args.dir):
        sys.exit(f"plot_experiment: {args.dir}: not a folder")
    out = args.out or args.dir
    os.makedirs(out, exist_ok=True)
    written = []
    for name, fig in make_figures(args.dir):
        save(fig, out, name, written)
    for w in written:
        print(w)


if __name__ == "__main__":
    main()
