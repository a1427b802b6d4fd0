#!/usr/bin/env python3
"""Plots of a `bvhopt experiment` output folder, from its CSVs (PNG, matplotlib Agg).

    python3 scripts/plot_experiment.py --dir OUT [--out PLOTDIR]

Writes, for whichever CSVs are present and non-empty:
  fig_kensler_passes.png        Kensler Figures 3 and 4: cost per pass (hill climbing, annealing)
  fig_bittner_depth_<scene>.png Bittner Figure 7: area sums of inner nodes and leaves per depth
  fig_dk_t_sweep.png            Dammertz-Keller Figure 4: references and time against t
  fig_dk_rotation.png           Dammertz-Keller Figure 5: the rotating scene
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


def plot_kensler(src, out, written):
    path = os.path.join(src, "kensler_passes.csv")
    rows = [r for r in read_rows(path) if r.get("method") in ("hill", "anneal")]
    if not rows:
        return
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for ax, method, title in ((axes[0], "hill", "Figure 3: hill climbing"), (axes[1], "anneal", "Figure 4: annealing")):
        for (scene,), group in by([r for r in rows if r["method"] == method], "scene").items():
            ax.plot([number(r, "pass", path) for r in group], [number(r, "relative_cost", path) for r in group],
                    label=scene, linewidth=1)
        ax.set_title(title)
        ax.set_xlabel("pass")
        ax.set_ylabel("SAH cost / unoptimized")
        ax.grid(alpha=0.3)
    axes[1].legend(fontsize=7)
    save(fig, out, "fig_kensler_passes.png", written)


def plot_bittner(src, out, written):
    path = os.path.join(src, "bittner_depth_areas.csv")
    rows = read_rows(path)
    for (scene,), group in by(rows, "scene").items():
        fig, axes = plt.subplots(1, 2, figsize=(11, 4))
        for tree, style, label in (("sah", "r--", "SAH build"), ("insertion_sah", "g-", "after insertion")):
            g = [r for r in group if r["tree"] == tree]
            depths = [number(r, "depth", path) for r in g]
            axes[0].plot(depths, [number(r, "inner_area", path) for r in g], style, label=label)
            axes[1].plot(depths, [number(r, "leaf_area", path) for r in g], style, label=label)
        for ax, what in zip(axes, ("inner nodes", "leaves")):
            ax.set_title(f"Figure 7 ({scene}): {what}")
            ax.set_xlabel("depth")
            ax.set_ylabel("sum of surface areas / root area")
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8)
        save(fig, out, f"fig_bittner_depth_{scene}.png", written)


def plot_dk_sweep(src, out, written):
    path = os.path.join(src, "dk_t_sweep.csv")
    rows = [r for r in read_rows(path) if r.get("t") != "off"]
    if not rows:
        return
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for (scene,), group in by(rows, "scene").items():
        t = [number(r, "t", path) for r in group]
        axes[0].plot(t, [number(r, "ref_ratio", path) for r in group], "o-", label=scene)
        axes[1].plot(t, [number(r, "time_ratio", path) for r in group], "o-", label=scene)
    axes[0].set_ylabel("references / triangles")
    axes[1].set_ylabel("trace time / no subdivision")
    for ax in axes:
        ax.set_xlabel("threshold t")
        ax.grid(alpha=0.3)
    axes[0].set_title("Figure 4: references")
    axes[1].set_title("Figure 4: time")
    axes[1].legend(fontsize=7)
    save(fig, out, "fig_dk_t_sweep.png", written)


def plot_dk_rotation(src, out, written):
    path = os.path.join(src, "dk_rotation.csv")
    rows = read_rows(path)
    if not rows:
        return
    frame = [number(r, "frame", path) for r in rows]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    axes[0].plot(frame, [number(r, "base_seconds", path) for r in rows], "r-", label="base")
    axes[0].plot(frame, [number(r, "evh_seconds", path) for r in rows], "g-", label="EVH")
    axes[0].set_ylabel("trace time [s]")
    axes[1].plot(frame, [number(r, "base_references", path) for r in rows], "r-", label="base")
    axes[1].plot(frame, [number(r, "evh_references", path) for r in rows], "g-", label="EVH")
    axes[1].set_ylabel("references")
    for ax in axes:
        ax.set_xlabel("frame")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    scene = rows[0]["scene"]
    axes[0].set_title(f"Figure 5 ({scene}): time per frame")
    axes[1].set_title(f"Figure 5 ({scene}): references")
    save(fig, out, "fig_dk_rotation.png", written)


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
    plot_kensler(args.dir, out, written)
    plot_bittner(args.dir, out, written)
    plot_dk_sweep(args.dir, out, written)
    plot_dk_rotation(args.dir, out, written)
    for w in written:
        print(w)


if __name__ == "__main__":
    main()
