"""bvhopt: build, optimize and measure bounding volume hierarchies for ray tracing.

    import bvhopt
    scene = bvhopt.load_scene("builtin")          # or a file assimp reads
    bvh = bvhopt.build(scene, builder="sweep")
    report = bvh.optimize("insertion", seed=1)    # report.cost: cost after each pass
    hits = bvh.trace(scene, bvhopt.rays(scene, "primary"))

Errors raise bvhopt.Error with the library's message (the file, the place, the problem).
"""
from ._bvhopt import Bvh, Error, Scene, build, builders, load, load_scene, ray_kinds, rays

OptimizeReport = Bvh.OptimizeReport
TraceResult = Bvh.TraceResult
methods = Bvh.methods
layouts = Bvh.layouts

__all__ = ["Bvh", "Error", "OptimizeReport", "Scene", "TraceResult", "build", "builders", "layouts", "load",
           "load_scene", "methods", "ray_kinds", "rays"]
