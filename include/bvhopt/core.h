// Everything of bvhopt::core (no file formats), in pipeline order:
// built-in scene -> primitive references (optionally subdivided) -> build -> optimize -> finalize -> layout -> trace / measure.
#pragma once

#include "bvhopt/error.h"
#include "bvhopt/vec3.h"
#include "bvhopt/box.h"
#include "bvhopt/triangle.h"
#include "bvhopt/camera.h"
#include "bvhopt/mesh.h"
#include "bvhopt/scene.h"

#include "bvhopt/references.h"
#include "bvhopt/edge_volume_subdivision.h"

#include "bvhopt/bvh.h"
#include "bvhopt/build.h"

#include "bvhopt/optimize_report.h"
#include "bvhopt/optimizer_config.h"
#include "bvhopt/optimizer_method.h"
#include "bvhopt/tree_rotations.h"
#include "bvhopt/insertion_optimizer.h"

#include "bvhopt/collapse_leaves.h"
#include "bvhopt/leaf_dedup.h"
#include "bvhopt/finalize.h"

#include "bvhopt/cost.h"
#include "bvhopt/stats.h"
#include "bvhopt/validate.h"

#include "bvhopt/ray.h"
#include "bvhopt/ray_sets.h"
#include "bvhopt/ray_triangle.h"
#include "bvhopt/binary_layout.h"
#include "bvhopt/tracer.h"
#include "bvhopt/ray_measure.h"
#include "bvhopt/images.h"
