#include "optimize_progress.h"

#include <cmath>
#include <sstream>

#include "bvhopt/error.h"
#include "cli_common.h"

namespace bvhopt::cli {

double parse_time_budget(const std::string& text, double build_seconds) {
  const bool relative = !text.empty() && (text.back() == 'x' || text.back() == 'X');
  const std::string number = relative ? text.substr(0, text.size() - 1) : text;
  size_t used = 0;
  double v = -1.0;
  try {
    v = std::stod(number, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used == 0 || used != number.size() || !(v >= 0.0) || !std::isfinite(v))
    throw Error("--time-budget: '" + text + "' is neither seconds (e.g. 2.5) nor a multiple of the build time (e.g. 5x)");
  if (!relative) return v;
  if (build_seconds <= 0.0)
    throw Error("--time-budget " + text + ": a multiple of the build time needs a scene, not a BVH file");
  return v * build_seconds;
}

double GainEstimate::fraction() const {
  if (best_.size() < 2 * kWindow + 1) return -1.0;
  const size_t n = best_.size();
  const double recent = best_[n - 1 - kWindow] - best_[n - 1];
  const double before = best_[n - 1 - 2 * kWindow] - best_[n - 1 - kWindow];
  const double reached = initial_ - best_[n - 1];
  if (reached <= 0.0) return 0.0;
  if (recent <= 0.0) return 1.0;  // nothing gained for a whole window: as good as converged
  if (before <= recent) return -1.0;
  const double r = recent / before;
  const double left = recent * r / (1.0 - r);
  return reached / (reached + left);
}

std::string progress_text(const PassRecord& p, const GainEstimate& gain, bool with_temperature) {
  std::ostringstream line;
  line << "pass " << p.pass;
  if (!p.stage_name.empty()) line << "  " << p.stage_name;
  if (with_temperature) line << "  T " << format_double(p.temperature, 3);
  line << "  cost " << format_double(p.cost, 4) << "  best " << format_double(p.best_cost, 4);
  const double f = gain.fraction();
  line << "  gain " << (f < 0.0 ? std::string("?") : format_double(100.0 * f, 0)) << " %";
  line << "  " << format_double(p.seconds, 1) << " s";
  return line.str();
}

std::string stages_text(const OptimizeReport& report) {
  std::ostringstream line;
  for (size_t i = 0; i < report.stages.size(); ++i) {
    const StageReport& st = report.stages[i];
    line << (i ? ", " : "") << st.name << ' ' << st.passes << (st.passes == 1 ? " pass " : " passes ")
         << format_double(st.seconds, 2) << " s -> " << format_double(st.cost, 4);
  }
  line << (report.stages.empty() ? "" : "; ") << "setup " << format_double(report.setup_seconds, 2) << " s, finish "
       << format_double(report.finish_seconds, 2) << " s";
  return line.str();
}

nlohmann::json stages_json(const OptimizeReport& report) {
  nlohmann::json stages = nlohmann::json::array();
  for (const StageReport& st : report.stages)
    stages.push_back({{"name", std::string(st.name)}, {"passes", st.passes}, {"seconds", st.seconds}, {"cost", st.cost}});
  return {{"stages", stages}, {"setup_seconds", report.setup_seconds}, {"finish_seconds", report.finish_seconds}};
}

}  // namespace bvhopt::cli
