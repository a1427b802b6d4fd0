// Measuring a tree by tracing: rays per second, work per ray, hit rate, and a check of the
// traversal against brute force.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "bvhopt/mesh.h"
#include "bvhopt/ray.h"
#include "bvhopt/any_tracer.h"
#include "bvhopt/tracer.h"

namespace bvhopt {

// Traces every ray, spread over the threads oneTBB allows (tbb::parallel_for over blocks
// of `block` rays). For RayQuery::any only triangle_id tells hit (any id) or miss, and the
// id is of whichever triangle was found first. `counters`, when given, gets one entry per ray
// (traced one call a ray). Without `counters` the rays go to the tracer's batch form in calls
// of `rays_per_call` rays, or a whole block a call when 0; 1 is what a renderer tracing one
// ray at a time gets. The hits are the same either way.
void trace_rays(const AnyTracer& tracer, const std::vector<Ray>& rays, RayQuery query, std::vector<Hit>& hits,
                std::vector<TraceCounters>* counters = nullptr, size_t block = 256, size_t rays_per_call = 0);
void trace_rays(const Tracer& tracer, const std::vector<Ray>& rays, RayQuery query, std::vector<Hit>& hits,
                std::vector<TraceCounters>* counters = nullptr, ChildOrder order = ChildOrder::split_axis,
                size_t block = 256);

// A distribution of a per-ray count: mean, percentiles and a histogram of 10-wide bins,
// the last bin holding everything from 10 * (bins - 1) up.
struct CountDistribution {
  double mean = 0.0;
  uint32_t p50 = 0, p90 = 0, p99 = 0, max = 0;
  std::vector<uint64_t> histogram;  // 21 bins: [0,10), [10,20), ..., [200, inf)
};
CountDistribution distribution_of(const std::vector<uint32_t>& values);

// The most rays per call MeasureOptions::rays_per_call, the command line and Python accept.
inline constexpr size_t kMaxRaysPerCall = 1000000;

struct MeasureOptions {
  ChildOrder order = ChildOrder::split_axis;  // for a binary Tracer
  int threads = 0;   // 0: whatever oneTBB allows now; otherwise a tbb::global_control limit
  int repeats = 3;   // timed passes; the median is reported
  // Rays per tracer call in the timed passes (trace_rays); 0: a block of 256 rays a call.
  size_t rays_per_call = 0;
};

struct RayMeasurement {
  uint64_t rays = 0;
  int threads = 0;              // threads the timed passes ran on
  double seconds = 0.0;         // median over the timed passes
  double rays_per_second = 0.0;
  double hit_rate = 0.0;        // fraction of rays with a hit (occluded, for any-hit)
  CountDistribution steps;      // traversal steps per ray (TraceCounters::steps)
  CountDistribution triangle_tests;
};

// One untimed pass for the counters and hits, then `repeats` timed passes.
RayMeasurement measure_rays(const AnyTracer& tracer, const std::vector<Ray>& rays, RayQuery query,
                            const MeasureOptions& options = {});
RayMeasurement measure_rays(const Tracer& tracer, const std::vector<Ray>& rays, RayQuery query,
                            const MeasureOptions& options = {});

struct BruteForceCheck {
  uint64_t checked = 0;
  uint64_t mismatches = 0;
  std::string first_mismatch;  // empty when all agree
};
// On `sample` rays chosen by `seed` (all when sample >= rays.size()): the traversal's hit
// must have the brute-force distance exactly, and be the brute-force triangle or another
// at the very same distance (a tie on a shared edge or a duplicate); any-hit must agree
// with brute force on occlusion. Brute force uses the tracer's triangle test
// (AnyTracer::brute_force).
BruteForceCheck check_against_brute_force(const AnyTracer& tracer, const Mesh& mesh, const std::vector<Ray>& rays,
                                          RayQuery query, uint64_t sample, uint64_t seed);
BruteForceCheck check_against_brute_force(const Tracer& tracer, const Mesh& mesh, const std::vector<Ray>& rays,
                                          RayQuery query, uint64_t sample, uint64_t seed,
                                          ChildOrder order = ChildOrder::split_axis);

}  // namespace bvhopt
