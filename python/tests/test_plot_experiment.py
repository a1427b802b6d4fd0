"""scripts/plot_experiment.py: every axis says its unit, and the papers' published values
are marked where the report compares with them (papers_comparison.csv)."""
import importlib.util
import pathlib
import re
import shutil

import pytest

matplotlib = pytest.importorskip("matplotlib")

ROOT = pathlib.Path(__file__).resolve().parents[2]
FIXTURES = ROOT / "tests" / "fixtures" / "experiment"


@pytest.fixture(scope="module")
def plots():
    spec = importlib.util.spec_from_file_location("plot_experiment", ROOT / "scripts" / "plot_experiment.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


# A unit in parentheses or brackets: "(s)", "(ratio)", "(count)", ...
UNIT = re.compile(r"\([^)]+\)|\[[^]]+\]")


def test_every_axis_is_labelled_with_its_unit(plots):
    figures = plots.make_figures(str(FIXTURES))
    names = [name for name, _ in figures]
    for expected in ("fig_kensler_passes.png", "fig_bittner_depth_builtin.png", "fig_dk_t_sweep.png",
                     "fig_dk_rotation.png", "fig_papers.png"):
        assert expected in names
    for name, fig in figures:
        for ax in fig.axes:
            for label in (ax.get_xlabel(), ax.get_ylabel()):
                assert UNIT.search(label), f"{name}: axis label '{label}' names no unit"


def test_published_values_are_marked(plots):
    figures = dict(plots.make_figures(str(FIXTURES)))
    hill, anneal = figures["fig_kensler_passes.png"].axes

    def marks(ax):
        return {round(line.get_ydata()[0], 3) for line in ax.get_lines() if line.get_label().startswith("Kensler 2008")}

    assert marks(hill) == {0.908}
    assert marks(anneal) == {0.842}
    # The comparison figure: one published mark per ratio compared (not the seconds row).
    papers = figures["fig_papers.png"].axes[0]
    published = [line for line in papers.get_lines() if line.get_label() == "published value"]
    assert len(published) == 1
    assert list(published[0].get_ydata()) == [0.908, 0.842, 0.827]


def test_no_comparison_means_no_marks(plots, tmp_path):
    for f in FIXTURES.glob("*.csv"):
        if f.name != "papers_comparison.csv":
            shutil.copy(f, tmp_path / f.name)
    figures = dict(plots.make_figures(str(tmp_path)))
    assert "fig_papers.png" not in figures
    for ax in figures["fig_kensler_passes.png"].axes:
        assert not [line for line in ax.get_lines() if line.get_label().startswith("Kensler")]
