import json
import os
import pathlib
import runpy
import signal
import subprocess
import threading

import numpy as np
import pytest

import bvhopt
from conftest import SCENE

ROOT = pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def scene():
    return bvhopt.load_scene(SCENE)


def run_cli(cli, *args):
    out = subprocess.run([cli, *args, "--json"], check=True, capture_output=True, text=True).stdout
    return json.loads(out)


def test_scene_arrays_are_views_with_the_right_types(scene):
    v, i = scene.vertices, scene.indices
    assert v.dtype == np.float32 and v.shape == (scene.vertex_count, 3)
    assert i.dtype == np.uint32 and i.shape == (scene.triangle_count, 3)
    assert not v.flags.writeable and not v.flags.owndata
    assert i.max() < scene.vertex_count


def test_scene_from_arrays_round_trips(scene):
    copy = bvhopt.Scene(scene.vertices, scene.indices)
    np.testing.assert_array_equal(copy.vertices, scene.vertices)
    np.testing.assert_array_equal(copy.indices, scene.indices)
    assert bvhopt.build(copy).cost == bvhopt.build(scene).cost


@pytest.mark.parametrize("builder", ["sweep", "binned", "spatial-median", "object-median", "sbvh"])
def test_build_cost_equals_the_command_line(cli, tmp_path, scene, builder):
    ref = run_cli(cli, "build", SCENE, "--builder", builder, "--leaf-size", "4", "-o", str(tmp_path / "a.bvh"))
    bvh = bvhopt.build(scene, builder=builder, leaf_size=4)
    assert bvh.cost == ref["cost"]
    assert bvh.ocost == ref["ocost"]
    assert bvh.stats()["nodes"] == ref["nodes"]
    assert bvh.spatial_split == ref.get("spatial_split")  # None but for sbvh
    assert (bvh.spatial_split is not None) == (builder == "sbvh")
    bvh.save(tmp_path / "b.bvh")
    np.testing.assert_array_equal(bvhopt.load(tmp_path / "a.bvh").nodes, bvhopt.load(tmp_path / "b.bvh").nodes)


@pytest.mark.parametrize("option,value", [("budget", 1.1), ("split_alpha", 1.0), ("spatial_bins", 2),
                                          ("spatial_from", 0), ("split_node_alpha", 0.0)])
def test_sbvh_settings_equal_the_command_line(cli, tmp_path, scene, option, value):
    flag = "--" + option.replace("_", "-")
    ref = run_cli(cli, "build", SCENE, "--builder", "sbvh", flag, str(value), "-o", str(tmp_path / "a.bvh"))
    bvh = bvhopt.build(scene, builder="sbvh", **{option: value})
    assert bvh.cost == ref["cost"] and bvh.stats()["nodes"] == ref["nodes"]
    assert bvh.spatial_split == ref["spatial_split"]
    # Each setting changes the tree, so a binding that dropped it would fail above or here.
    assert bvh.cost != bvhopt.build(scene, builder="sbvh").cost


@pytest.mark.parametrize("method,args", [("insertion", []), ("insertion", ["--no-rotations"]), ("hill-climb", []),
                                         ("anneal", ["--schedule-passes", "60"])])
def test_optimize_equals_the_command_line(cli, tmp_path, scene, method, args):
    ref = run_cli(cli, "optimize", SCENE, "--method", method, "--seed", "7", *args, "-o", str(tmp_path / "a.bvh"))
    bvh = bvhopt.build(scene)
    options = {"schedule_passes": 60} if method == "anneal" else {"rotations": False} if args else {}
    report = bvh.optimize(method, seed=7, **options)
    # The optimizer's tracked cost is a running sum, added in the order of the moves: it
    # equals a fresh sum up to rounding, and the command line's exactly.
    assert report.final_cost == ref["cost_after"]
    assert report.final_cost == pytest.approx(bvh.cost, rel=1e-12)
    assert report.passes == ref["passes"] and report.moves == ref["moves"]
    assert report.cost.shape == (report.passes,) and report.cost.dtype == np.float64
    assert report.best_cost[-1] <= report.initial_cost
    # Stages from 0, in order; insertion on this scene runs the hybrid form's three (two
    # without the rotation sweeps).
    assert report.pass_stage[0] == 0 and (np.diff(report.pass_stage) >= 0).all()
    assert report.pass_stage[-1] == ((1 if args else 2) if method == "insertion" else 0)
    if method == "insertion":
        assert ref["insertion_rotations"] == (not args)
    # The stages the command line reports, by name and passes; their passes are the trace's.
    assert [(s["name"], s["passes"]) for s in report.stages] == [(s["name"], s["passes"]) for s in ref["stages"]]
    assert [s["passes"] for s in report.stages] == np.bincount(report.pass_stage.astype(np.int64)).tolist()
    assert report.stages[-1]["cost"] == report.final_cost
    expected = {"insertion": ["sequential", "parallel"] + ([] if args else ["sweeps"])}.get(method, [method])
    assert [s["name"] for s in report.stages] == expected
    bvh.validate()
    bvh.save(tmp_path / "b.bvh")
    np.testing.assert_array_equal(bvhopt.load(tmp_path / "a.bvh").nodes, bvhopt.load(tmp_path / "b.bvh").nodes)
    np.testing.assert_array_equal(bvhopt.load(tmp_path / "a.bvh").references, bvhopt.load(tmp_path / "b.bvh").references)


def test_nodes_describe_the_tree(scene):
    bvh = bvhopt.build(scene, leaf_size=4)
    nodes, refs = bvh.nodes, bvh.references
    leaves = nodes[nodes["count"] > 0]
    inner = nodes[nodes["count"] == 0]
    assert len(leaves) + len(inner) == len(nodes) and len(leaves) == len(inner) + 1
    assert sorted(refs.tolist()) == list(range(scene.triangle_count))
    # every leaf box holds its triangles' vertices; every inner box its children's boxes
    tri = scene.vertices[scene.indices]
    for leaf in leaves[:200]:
        pts = tri[refs[leaf["first"]:leaf["first"] + leaf["count"]]].reshape(-1, 3)
        assert (pts >= leaf["min"]).all() and (pts <= leaf["max"]).all()
    for node in inner[:200]:
        for c in (node["left"], node["right"]):
            assert (nodes[c]["min"] >= node["min"]).all() and (nodes[c]["max"] <= node["max"]).all()
    stats = bvh.stats()
    assert stats["inner_area_by_depth"].dtype == np.float64
    assert stats["inner_area_by_depth"].sum() == pytest.approx(stats["inner_area_sum"])


def test_collapse_reaches_ocost(scene):
    bvh = bvhopt.build(scene)
    ocost = bvh.ocost
    result = bvh.collapse_leaves()
    assert result["cost_after"] == pytest.approx(ocost) and bvh.cost == pytest.approx(ocost)
    assert bvh.method == "sweep+compact"
    bvh.validate()


def test_save_and_load_round_trip(tmp_path, scene):
    bvh = bvhopt.build(scene, evh=True)
    bvh.save(str(tmp_path / "t.bvh"))
    back = bvhopt.load(tmp_path / "t.bvh")
    assert back.cost == bvh.cost and back.method == "evh+sweep"
    np.testing.assert_array_equal(back.references, bvh.references)
    back.validate()


def test_rays_and_trace(cli, tmp_path, scene):
    bvh = bvhopt.build(scene)
    rays = bvhopt.rays(scene, "primary", count=4096, seed=3, bvh=bvh)
    n = len(rays)  # the resolution nearest 4096 pixels at the camera's aspect
    assert rays.dtype == np.float32 and rays.shape == (n, 8) and abs(n - 4096) < 100
    np.testing.assert_allclose(np.linalg.norm(rays[:, 4:7], axis=1), 1.0, rtol=1e-5)
    r = bvh.trace(scene, rays, layout="bvh2", repeats=1)
    assert r.t.shape == (n,) and r.t.dtype == np.float32
    assert r.triangle_id.dtype == np.uint32 and r.steps.dtype == np.uint32
    hit = r.triangle_id != 0xFFFFFFFF
    assert r.hit_rate == pytest.approx(hit.mean())
    assert np.isinf(r.t[~hit]).all() and (r.t[hit] > 0).all()
    assert r.mean_steps == pytest.approx(r.steps.mean()) and r.rays_per_second > 0
    # another tree over the same scene finds the same hits
    other = bvhopt.build(scene, builder="spatial-median").trace(scene, rays, layout="bvh2", repeats=1)
    np.testing.assert_array_equal(other.t, r.t)
    for layout in ("bvh4", "bvh8"):  # the wide layouts (their own triangle test) agree to rounding
        wide = bvh.trace(scene, rays, layout=layout, repeats=1)
        np.testing.assert_array_equal(wide.triangle_id != 0xFFFFFFFF, hit)
        np.testing.assert_allclose(wide.t[hit], r.t[hit], rtol=1e-4)
    # a dearer leaf block (c_blk, the command line's --wide-block) collapses into smaller
    # leaves: the same hits for fewer triangle tests
    dear = bvh.trace(scene, rays, layout="bvh8", repeats=1, wide_block=4.0)
    np.testing.assert_array_equal(dear.triangle_id, wide.triangle_id)
    np.testing.assert_array_equal(dear.t, wide.t)
    assert dear.triangle_tests.sum() < wide.triangle_tests.sum()
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(bvhopt.Error, match="wide_block"):
            bvh.trace(scene, rays, layout="bvh8", repeats=1, wide_block=bad)
    # timed in calls of one ray (a renderer's ray at a time): the same per-ray results
    one = bvh.trace(scene, rays, layout="bvh8", repeats=1, rays_per_call=1)
    np.testing.assert_array_equal(one.triangle_id, wide.triangle_id)
    assert one.rays_per_second > 0
    for bad in (-1, 1000001):
        with pytest.raises(bvhopt.Error, match="rays_per_call"):
            bvh.trace(scene, rays, layout="bvh8", repeats=1, rays_per_call=bad)
    # any-hit rays from either end, or (the default) in slot order where a batch mostly
    # misses: the same answers, walked in other orders
    shadow = bvhopt.rays(scene, "shadow", count=3000, seed=2, bvh=bvh)
    far = bvh.trace(scene, shadow, layout="bvh8", query="any", repeats=1, any_hit_order="far")
    near = bvh.trace(scene, shadow, layout="bvh8", query="any", repeats=1, any_hit_order="near")
    np.testing.assert_array_equal(far.triangle_id != 0xFFFFFFFF, near.triangle_id != 0xFFFFFFFF)
    ao_any = bvhopt.rays(scene, "ao", count=3000, seed=3, bvh=bvh)
    by_default = bvh.trace(scene, ao_any, layout="bvh8", query="any", repeats=1)
    asked_auto = bvh.trace(scene, ao_any, layout="bvh8", query="any", repeats=1, any_hit_order="auto")
    from_far = bvh.trace(scene, ao_any, layout="bvh8", query="any", repeats=1, any_hit_order="far")
    np.testing.assert_array_equal(by_default.triangle_id != 0xFFFFFFFF, from_far.triangle_id != 0xFFFFFFFF)
    np.testing.assert_array_equal(by_default.steps, asked_auto.steps)
    assert 0 < far.hit_rate < 1
    assert not np.array_equal(far.steps, near.steps)
    with pytest.raises(bvhopt.Error, match="any_hit_order"):
        bvh.trace(scene, shadow, layout="bvh8", query="any", repeats=1, any_hit_order="middle")
    # closest-hit rays that mostly hit nothing may take children in slot order: the same hits
    ao = bvhopt.rays(scene, "ao", count=3000, seed=2, bvh=bvh)
    auto = bvh.trace(scene, ao, layout="bvh8", repeats=1)
    nearest = bvh.trace(scene, ao, layout="bvh8", repeats=1, closest_hit_order="near")
    np.testing.assert_array_equal(auto.triangle_id, nearest.triangle_id)
    np.testing.assert_array_equal(auto.t, nearest.t)
    assert 0 < auto.hit_rate < 1
    with pytest.raises(bvhopt.Error, match="closest_hit_order"):
        bvh.trace(scene, ao, layout="bvh8", repeats=1, closest_hit_order="far")
    # a light of one's own: every shadow ray ends there, and another light lights other hits
    light = (0.5, 40.0, -0.25)
    lit = bvhopt.rays(scene, "shadow", count=3000, seed=2, bvh=bvh, light=light)
    np.testing.assert_allclose(lit[:, 0:3] + lit[:, 4:7], np.broadcast_to(light, (3000, 3)), atol=1e-3)
    assert bvh.trace(scene, lit, layout="bvh8", query="any", repeats=1).hit_rate != far.hit_rate
    with pytest.raises(bvhopt.Error, match="only shadow rays have a light"):
        bvhopt.rays(scene, "ao", count=100, light=light)
    with pytest.raises(bvhopt.Error, match="not a finite point"):
        bvhopt.rays(scene, "shadow", count=100, light=(0.0, float("nan"), 0.0))
    bvh.save(tmp_path / "t.bvh")
    ref = run_cli(cli, "trace", str(tmp_path / "t.bvh"), "--scene", SCENE, "--rays", "primary",
                  "--count", "4096", "--seed", "3", "--layout", "bvh2")
    assert ref["count"] == n and ref["hit_rate"] == pytest.approx(r.hit_rate)
    assert ref["steps"]["mean"] == pytest.approx(r.mean_steps)


def test_interrupt_keeps_the_best_tree_so_far(scene):
    bvh = bvhopt.build(scene)
    start = bvh.cost
    timer = threading.Timer(0.3, os.kill, (os.getpid(), signal.SIGINT))
    timer.start()
    try:
        report = bvh.optimize("anneal", schedule_passes=10**7)
    finally:
        timer.cancel()
    assert report.stop_reason == "interrupted"
    assert bvh.cost == report.final_cost <= start
    bvh.validate()


@pytest.mark.parametrize("call,message", [
    (lambda s: bvhopt.load_scene("/nonexistent/scene.obj"), "/nonexistent/scene.obj"),
    (lambda s: bvhopt.load_scene("builtin:nowhere"), "nowhere"),
    (lambda s: bvhopt.load("/nonexistent/t.bvh"), "/nonexistent/t.bvh"),
    (lambda s: bvhopt.Scene(np.zeros((3, 2), np.float32), np.zeros((1, 3), np.uint32)), "shape (3, 2)"),
    (lambda s: bvhopt.Scene(np.zeros((3, 3), np.float32), np.array([[0, 1, 5]])), "out of range"),
    (lambda s: bvhopt.Scene(np.zeros((3, 3), np.float32), np.array([[0, 1, -1]])), "-1"),
    (lambda s: bvhopt.build(s, builder="octree"), "unknown builder 'octree'"),
    (lambda s: bvhopt.build(s, leaf_size=0), "leaf"),
    (lambda s: bvhopt.build(s, threads=0), "threads"),
    (lambda s: bvhopt.build(s, evh=99), "0..62"),
    (lambda s: bvhopt.build(s, builder="sbvh", spatial_bins=1), "spatial_bins"),
    (lambda s: bvhopt.build(s, builder="sbvh", split_alpha=float("nan")), "alpha"),
    (lambda s: bvhopt.build(s, builder="sbvh", budget=0.5), "budget"),
    (lambda s: bvhopt.build(s).optimize("annealing"), "unknown method 'annealing'"),
    (lambda s: bvhopt.build(s).optimize("insertion", h=2), "has no option 'h'"),
    (lambda s: bvhopt.build(s).optimize("insertion", form="diagonal"), "unknown form 'diagonal'"),
    (lambda s: bvhopt.build(s).optimize("anneal", time_budget=-1), "time_budget"),
    (lambda s: bvhopt.rays(s, "sideways"), "unknown kind 'sideways'"),
    (lambda s: bvhopt.build(s).trace(s, np.zeros((4, 7), np.float32)), "shape (4, 7)"),
    (lambda s: bvhopt.build(s).trace(s, np.zeros((4, 8), np.float32), layout="bvh16"), "unknown layout 'bvh16'"),
    (lambda s: bvhopt.build(s).trace(bvhopt.load_scene("builtin?triangles=4000"), np.zeros((1, 8), np.float32)),
     "pass the scene the tree was built from"),
    (lambda s: bvhopt.build(s).save("/nonexistent/dir/t.bvh"), "/nonexistent/dir"),
])
def test_errors_raise_with_the_library_message(scene, call, message):
    with pytest.raises(bvhopt.Error, match=None) as info:
        call(scene)
    assert message in str(info.value)


def test_trace_refuses_a_scene_of_the_same_size_with_other_geometry(tmp_path):
    # Built-in seeds 1 and 2 have the same triangle count: only the fingerprint tells.
    a = bvhopt.load_scene("builtin?triangles=4000&seed=1")
    b = bvhopt.load_scene("builtin?triangles=4000&seed=2")
    tree = bvhopt.build(a)
    rays = bvhopt.rays(a, "random", count=10)
    tree.trace(a, rays)
    with pytest.raises(bvhopt.Error) as info:
        tree.trace(b, rays)
    assert "fingerprint" in str(info.value)
    path = tmp_path / "t.bvh"
    tree.save(str(path))
    with pytest.raises(bvhopt.Error):
        bvhopt.load(str(path)).trace(b, rays)


def test_example_compare_methods_runs(tmp_path):
    example = runpy.run_path(str(ROOT / "examples" / "python" / "compare_methods.py"))
    rows = example["main"]("builtin?triangles=4000", str(tmp_path / "methods.png"))
    assert [r[0] for r in rows] == ["sweep", "hill-climb", "anneal", "insertion"]
    assert all(cost <= rows[0][1] for _, cost, _ in rows[1:])
    assert (tmp_path / "methods.png").stat().st_size > 1000
