// Tracing ray sets in parallel and measuring the work and the speed.
#include "bvhopt/ray_measure.h"

#include <tbb/blocked_range.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <memory>
#include <numeric>
#include <random>

#include "bvhopt/ray_triangle.h"
#include "bvhopt/testing/brute_force.h"

namespace bvhopt {

void trace_rays(const AnyTracer& tracer, const std::vector<Ray>& rays, RayQuery query, std::vector<Hit>& hits,
                std::vector<TraceCounters>* counters, size_t block, size_t rays_per_call) {
  hits.resize(rays.size());
  if (counters) counters->assign(rays.size(), TraceCounters{});
  const Ray* in = rays.data();
  Hit* out = hits.data();
  TraceCounters* per_ray = counters ? counters->data() : nullptr;
  tbb::parallel_for(tbb::blocked_range<size_t>(0, rays.size(), std::max<size_t>(block, 1)),
                    [=, &tracer](const tbb::blocked_range<size_t>& r) {
                      TraceCounters scratch;
                      if (!per_ray) {
                        const size_t call = rays_per_call ? rays_per_call : r.size();
                        std::vector<uint8_t> occluded(query == RayQuery::any ? std::min(call, r.size()) : 0);
                        for (size_t b = r.begin(); b < r.end(); b += call) {
                          const size_t n = std::min(call, r.end() - b);
                          if (query == RayQuery::closest) {
                            tracer.closest(in + b, n, out + b, scratch);
                          } else {
                            tracer.any(in + b, n, occluded.data(), scratch);
                            for (size_t i = 0; i < n; ++i) {
                              out[b + i] = Hit{};
                              if (occluded[i]) out[b + i].triangle_id = 0;
                            }
                          }
                        }
                        return;
                      }
                      for (size_t i = r.begin(); i < r.end(); ++i) {
                        TraceCounters& c = per_ray ? per_ray[i] : scratch;
                        if (query == RayQuery::closest) {
                          out[i] = tracer.closest(in[i], c);
                        } else {
                          Hit h;
                          if (tracer.any(in[i], c)) h.triangle_id = 0;
                          out[i] = h;
                        }
                      }
                    });
}

void trace_rays(const Tracer& tracer, const std::vector<Ray>& rays, RayQuery query, std::vector<Hit>& hits,
                std::vector<TraceCounters>* counters, ChildOrder order, size_t block) {
  trace_rays(AnyTracer(tracer, order), rays, query, hits, counters, block);
}

CountDistribution distribution_of(const std::vector<uint32_t>& values) {
  CountDistribution d;
  d.histogram.assign(21, 0);
  if (values.empty()) return d;
  std::vector<uint32_t> sorted = values;
  std::sort(sorted.begin(), sorted.end());
  double sum = 0.0;
  for (uint32_t v : sorted) {
    sum += v;
    ++d.histogram[std::min<size_t>(v / 10, 20)];
  }
  d.mean = sum / double(sorted.size());
  auto pct = [&](double q) { return sorted[std::min(sorted.size() - 1, size_t(q * double(sorted.size())))]; };
  d.p50 = pct(0.5);
  d.p90 = pct(0.9);
  d.p99 = pct(0.99);
  d.max = sorted.back();
  return d;
}

RayMeasurement measure_rays(const Tracer& tracer, const std::vector<Ray>& rays, RayQuery query,
                            const MeasureOptions& options) {
  return measure_rays(AnyTracer(tracer, options.order), rays, query, options);
}

RayMeasurement measure_rays(const AnyTracer& tracer, const std::vector<Ray>& rays, RayQuery query,
                            const MeasureOptions& options) {
  std::unique_ptr<tbb::global_control> limit;
  if (options.threads > 0)
    limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, options.threads);
  RayMeasurement m;
  m.rays = rays.size();
  m.threads = static_cast<int>(tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism));
  m.threads = std::min(m.threads, tbb::this_task_arena::max_concurrency());

  std::vector<Hit> hits;
  std::vector<TraceCounters> counters;
  trace_rays(tracer, rays, query, hits, &counters);
  std::vector<uint32_t> steps(rays.size()), tests(rays.size());
  uint64_t hit_count = 0;
  for (size_t i = 0; i < rays.size(); ++i) {
    steps[i] = counters[i].steps;
    tests[i] = counters[i].triangle_tests;
    hit_count += hits[i].hit() ? 1 : 0;
  }
  m.steps = distribution_of(steps);
  m.triangle_tests = distribution_of(tests);
  m.hit_rate = rays.empty() ? 0.0 : double(hit_count) / double(rays.size());

  std::vector<double> times;
  for (int r = 0; r < std::max(options.repeats, 1); ++r) {
    const auto start = std::chrono::steady_clock::now();
    trace_rays(tracer, rays, query, hits, nullptr, std::max<size_t>(256, options.rays_per_call), options.rays_per_call);
    times.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
  }
  std::sort(times.begin(), times.end());
  m.seconds = times[times.size() / 2];
  m.rays_per_second = m.seconds > 0.0 ? double(rays.size()) / m.seconds : 0.0;
  return m;
}

BruteForceCheck check_against_brute_force(const Tracer& tracer, const Mesh& mesh, const std::vector<Ray>& rays,
                                          RayQuery query, uint64_t sample, uint64_t seed, ChildOrder order) {
  return check_against_brute_force(AnyTracer(tracer, order), mesh, rays, query, sample, seed);
}

BruteForceCheck check_against_brute_force(const AnyTracer& tracer, const Mesh& mesh, const std::vector<Ray>& rays,
                                          RayQuery query, uint64_t sample, uint64_t seed) {
  BruteForceCheck check;
  std::vector<size_t> picks;
  if (sample >= rays.size()) {
    picks.resize(rays.size());
    std::iota(picks.begin(), picks.end(), size_t(0));
  } else {
    std::mt19937_64 rng(seed);
    std::uniform_int_distribution<size_t> pick(0, rays.size() - 1);
    for (uint64_t i = 0; i < sample; ++i) picks.push_back(pick(rng));
    std::sort(picks.begin(), picks.end());
  }
  std::vector<int> bad(picks.size(), 0);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, picks.size(), 16), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t k = r.begin(); k < r.end(); ++k) {
      const Ray& ray = rays[picks[k]];
      TraceCounters c;
      const Hit expect = tracer.brute_force(mesh, ray);
      if (query == RayQuery::any) {
        bad[k] = tracer.any(ray, c) != expect.hit();
        continue;
      }
      const Hit got = tracer.closest(ray, c);
      if (got.hit() != expect.hit()) {
        bad[k] = 1;
      } else if (got.hit() && (got.t != expect.t)) {
        bad[k] = 1;
      } else if (got.hit() && got.triangle_id != expect.triangle_id) {
        // Honest tie check: the traversal's triangle must itself be hit at the same t.
        bad[k] = !tracer.hits_at(mesh, ray, got.triangle_id, expect.t);
      }
    }
  });
  check.checked = picks.size();
  for (size_t k = 0; k < picks.size(); ++k) {
    if (!bad[k]) continue;
    if (check.mismatches++ == 0) {
      const Ray& ray = rays[picks[k]];
      TraceCounters c;
      const Hit got = tracer.closest(ray, c);
      const Hit expect = tracer.brute_force(mesh, ray);
      char buf[256];
      std::snprintf(buf, sizeof buf, "ray %zu: traversal triangle %d t=%.9g, brute force triangle %d t=%.9g",
                    picks[k], got.hit() ? int(got.triangle_id) : -1, double(got.t),
                    expect.hit() ? int(expect.triangle_id) : -1, double(expect.t));
      check.first_mismatch = buf;
    }
  }
  return check;
}

}  // namespace bvhopt
