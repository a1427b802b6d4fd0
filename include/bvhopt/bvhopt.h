// Everything public: bvhopt::core (bvhopt/core.h) and the file formats of bvhopt::io.
// scene -> primitive references (optionally subdivided) -> build -> optimize -> finalize -> layout -> trace / measure / save.
#pragma once

#include "bvhopt/core.h"

#include "bvhopt/scene_file.h"
#include "bvhopt/bvh_file.h"
#include "bvhopt/ray_file.h"
#include "bvhopt/png_file.h"
#include "bvhopt/font.h"
#include "bvhopt/image_legend.h"
#include "bvhopt/atomic_file.h"
