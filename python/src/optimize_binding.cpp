// Bvh.optimize: the three optimizers by name, their options as keywords, the report with
// its per-pass arrays, and Ctrl-C ending a run with the best tree so far.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <functional>
#include <map>
#include <optional>
#include <string>

#include "bindings.h"
#include "bvhopt/error.h"
#include "bvhopt/insertion_optimizer.h"
#include "bvhopt/optimizer_method.h"
#include "bvhopt/tree_rotations.h"
#include "numpy_arrays.h"

namespace bvhopt::python {
namespace {

struct Report {
  std::string method;
  OptimizeReport report;
};

template <class Field>
py::array_t<double> per_pass(const Report& r, Field field) {
  std::vector<double> v;
  v.reserve(r.report.trace.size());
  for (const PassRecord& p : r.report.trace) v.push_back(static_cast<double>(field(p)));
  return take_array(std::move(v));
}

// Each method's keyword options, each writing into that method's config.
template <class Config>
using Setters = std::map<std::string, std::function<void(Config&, const py::handle&)>>;

template <class T, class Config>
std::function<void(Config&, const py::handle&)> set(T Config::*field) {
  return [field](Config& c, const py::handle& v) { c.*field = v.cast<T>(); };
}

template <class Config>
void apply_options(Config& config, const py::kwargs& options, const Setters<Config>& setters, const std::string& method) {
  for (const auto& [key, value] : options) {
    const std::string name = py::str(key);
    auto it = setters.find(name);
    if (it == setters.end()) {
      std::string known;
      for (const auto& [k, unused] : setters) known += (known.empty() ? "" : ", ") + k;
      throw Error("optimize: method '" + method + "' has no option '" + name + "' (its options: " +
                  (known.empty() ? "none" : known) + ")");
    }
    try {
      it->second(config, value);
    } catch (const py::cast_error&) {
      throw Error("optimize: option '" + name + "' of method '" + method + "' got " +
                  std::string(py::str(py::type::of(value).attr("__name__"))) + " " + std::string(py::repr(value)));
    }
  }
}

template <class Parse>
auto parse_named(const py::handle& value, Parse parse, const std::string& what) {
  const std::string name = py::str(value);
  auto parsed = parse(name);
  if (!parsed) throw Error("optimize: unknown " + what + " '" + name + "'");
  return *parsed;
}

const Setters<AnnealConfig>& anneal_options() {
  static const Setters<AnnealConfig> s{{"schedule_passes", set(&AnnealConfig::schedule_passes)},
                                       {"period", set(&AnnealConfig::period)},
                                       {"h", set(&AnnealConfig::h)},
                                       {"energy_scale", set(&AnnealConfig::energy_scale)},
                                       {"keep_best", set(&AnnealConfig::keep_best)}};
  return s;
}

const Setters<InsertionConfig>& insertion_options() {
  static const Setters<InsertionConfig> s{
      {"batch", set(&InsertionConfig::batch)},
      {"random_after", set(&InsertionConfig::random_after)},
      {"stop_after", set(&InsertionConfig::stop_after)},
      {"min_improvement", set(&InsertionConfig::min_improvement)},
      {"measure", [](InsertionConfig& c, const py::handle& v) { c.measure = parse_named(v, parse_measure, "measure"); }},
      {"form", [](InsertionConfig& c, const py::handle& v) { c.form = parse_named(v, parse_form, "form"); }},
      {"rotations", set(&InsertionConfig::rotations)},
      {"parallel_start", set(&InsertionConfig::parallel_start)}};
  return s;
}

// The shared settings over a method's own defaults (as the command line does: a method's
// own pass cap stays unless `passes` is given).
void apply_shared(OptimizerConfig& c, const CostModel& cost, uint64_t seed, std::optional<double> time_budget,
                  std::optional<uint32_t> passes) {
  c.cost = cost;
  c.seed = seed;
  if (time_budget) {
    if (!(*time_budget > 0.0)) throw Error("optimize: time_budget must be positive seconds (or None), got " + std::to_string(*time_budget));
    c.limits.time_budget = *time_budget;
  }
  if (passes) c.limits.max_passes = *passes;
}

// Asked after every pass, with the GIL taken back for the moment: a pending Ctrl-C (or any
// signal handler that raised) stops the run; the optimizer then keeps its best tree.
bool signal_arrived() {
  py::gil_scoped_acquire locked;
  if (PyErr_CheckSignals() == 0) return false;
  PyErr_Clear();
  return true;
}

Report optimize(Tree& t, const std::string& method, uint64_t seed, std::optional<double> time_budget,
                std::optional<uint32_t> passes, std::optional<int> threads, const py::kwargs& options) {
  const auto m = parse_optimizer_method(method);
  if (!m) throw Error("optimize: unknown method '" + method + "' (known: hill-climb, anneal, insertion)");
  Report out{method, {}};
  auto run = [&](auto& config, auto optimizer) {
    apply_shared(config, t.info.cost, seed, time_budget, passes);
    config.limits.stop_requested = signal_arrived;
    py::gil_scoped_release unlocked;
    auto limit = limit_threads(threads, "optimize");
    out.report = optimizer(t.bvh, config);
  };
  switch (*m) {
    case OptimizerMethod::hill_climb: {
      HillClimbConfig c;
      apply_options(c, options, Setters<HillClimbConfig>{}, method);
      run(c, [](Bvh& b, const HillClimbConfig& cfg) { return hill_climb(b, cfg); });
      break;
    }
    case OptimizerMethod::anneal: {
      AnnealConfig c;
      apply_options(c, options, anneal_options(), method);
      run(c, [](Bvh& b, const AnnealConfig& cfg) { return anneal(b, cfg); });
      break;
    }
    case OptimizerMethod::insertion: {
      InsertionConfig c;
      apply_options(c, options, insertion_options(), method);
      run(c, [](Bvh& b, const InsertionConfig& cfg) { return optimize_insertion(b, cfg); });
      break;
    }
  }
  t.info.method = (t.info.method.empty() ? std::string("unknown") : t.info.method) + "+" + method;
  return out;
}

}  // namespace

void register_optimize(py::class_<Tree>& tree) {
  py::class_<Report>(tree, "OptimizeReport", "What an optimizer did: a summary and one entry per pass")
      .def_property_readonly("method", [](const Report& r) { return r.method; })
      .def_property_readonly("initial_cost", [](const Report& r) { return r.report.initial_cost; })
      .def_property_readonly("final_cost", [](const Report& r) { return r.report.final_cost; })
      .def_property_readonly("passes", [](const Report& r) { return r.report.passes; })
      .def_property_readonly("moves", [](const Report& r) { return r.report.moves; })
      .def_property_readonly("seconds", [](const Report& r) { return r.report.seconds; })
      .def_property_readonly("stop_reason", [](const Report& r) { return std::string(stop_reason_name(r.report.stop_reason)); })
      .def_property_readonly("cost", [](const Report& r) { return per_pass(r, [](const PassRecord& p) { return p.cost; }); },
                             "Tree cost after each pass (float64, one per pass)")
      .def_property_readonly("best_cost", [](const Report& r) { return per_pass(r, [](const PassRecord& p) { return p.best_cost; }); })
      .def_property_readonly("temperature", [](const Report& r) { return per_pass(r, [](const PassRecord& p) { return p.temperature; }); })
      .def_property_readonly("pass_moves", [](const Report& r) { return per_pass(r, [](const PassRecord& p) { return p.moves; }); })
      .def_property_readonly("pass_seconds", [](const Report& r) { return per_pass(r, [](const PassRecord& p) { return p.seconds; }); },
                             "Seconds since the start at the end of each pass")
      .def_property_readonly("pass_stage", [](const Report& r) { return per_pass(r, [](const PassRecord& p) { return p.stage; }); },
                             "The method's stage that ran each pass, from 0 (insertion's forms run several in turn)")
      .def_property_readonly(
          "stages",
          [](const Report& r) {
            py::list out;
            for (const StageReport& st : r.report.stages) {
              py::dict d;
              d["name"] = std::string(st.name);
              d["passes"] = st.passes;
              d["seconds"] = st.seconds;
              d["cost"] = st.cost;
              out.append(d);
            }
            return out;
          },
          "Where the time went: one dict per stage, in the order they ran (name, passes, seconds, cost at its end)")
      .def_property_readonly("setup_seconds", [](const Report& r) { return r.report.setup_seconds; },
                             "Seconds before the first stage")
      .def_property_readonly("finish_seconds", [](const Report& r) { return r.report.finish_seconds; },
                             "Seconds after the last stage (insertion: the final renumbering)")
      .def("__repr__", [](const Report& r) {
        return "<OptimizeReport " + r.method + ": cost " + std::to_string(r.report.initial_cost) + " -> " +
               std::to_string(r.report.final_cost) + " in " + std::to_string(r.report.passes) + " passes (" +
               std::string(stop_reason_name(r.report.stop_reason)) + ")>";
      });
  tree.def("optimize", &optimize, py::arg("method") = "insertion", py::arg("seed") = 1,
           py::arg("time_budget") = py::none(), py::arg("passes") = py::none(), py::arg("threads") = py::none(),
           "Optimizes the tree in place with 'insertion' (options batch, measure, form, rotations, parallel_start, "
           "random_after, stop_after, min_improvement), 'anneal' (schedule_passes, period, h, energy_scale, keep_best) or 'hill-climb'. "
           "Ctrl-C stops after the current pass with the best tree so far (stop_reason 'interrupted').");
  tree.def_static("methods", [] {
    py::list names;
    for (OptimizerMethod m : optimizer_methods()) names.append(std::string(optimizer_method_name(m)));
    return names;
  });
}

}  // namespace bvhopt::python
