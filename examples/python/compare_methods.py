"""Every optimizer on one scene: cost per pass and rays per second, as a notebook would.

    PYTHONPATH=build/release/python python3 examples/python/compare_methods.py [SCENE] [OUT.png]
"""
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

import bvhopt


def main(scene_spec="builtin?triangles=20000", out="compare_methods.png"):
    scene = bvhopt.load_scene(scene_spec)
    rays = bvhopt.rays(scene, "random", count=20000, seed=1)
    start = bvhopt.build(scene, builder="sweep")
    rows = [("sweep", start.cost, start.trace(scene, rays, repeats=1).rays_per_second)]
    fig, (costs, speed) = plt.subplots(1, 2, figsize=(10, 4))
    for method in bvhopt.methods():
        bvh = start.copy()
        options = {"schedule_passes": 100} if method == "anneal" else {}
        report = bvh.optimize(method, seed=1, **options)
        rows.append((method, bvh.cost, bvh.trace(scene, rays, repeats=1).rays_per_second))
        costs.plot(range(1, report.passes + 1), report.cost, label=method)
    costs.set_xlabel("pass")
    costs.set_ylabel("SAH cost (c_T = 3, c_I = 2)")
    costs.set_title(scene.name)
    costs.legend()
    speed.bar([r[0] for r in rows], [r[2] / 1e6 for r in rows])
    speed.set_ylabel("random rays per second (millions)")
    fig.tight_layout()
    fig.savefig(out, dpi=80)
    for name, cost, rps in rows:
        print(f"{name:12s} cost {cost:9.3f}  {rps / 1e6:7.2f} Mrays/s")
    return rows


if __name__ == "__main__":
    main(*sys.argv[1:])
