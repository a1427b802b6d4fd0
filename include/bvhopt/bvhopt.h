// Everything public, in pipeline order.
#pragma once

#include "bvhopt/error.h"
#include "bvhopt/vec3.h"
#include "bvhopt/box.h"
#include "bvhopt/triangle.h"
#include "bvhopt/mesh.h"
#include "bvhopt/scene.h"
#include "bvhopt/references.h"
#include "bvhopt/bvh.h"
#include "bvhopt/build.h"
#include "bvhopt/cost.h"
#include "bvhopt/stats.h"
#include "bvhopt/validate.h"
#include "bvhopt/finalize.h"
#include "bvhopt/bvh_file.h"
