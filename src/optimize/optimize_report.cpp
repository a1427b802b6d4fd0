#include "bvhopt/optimize_report.h"

namespace bvhopt {

std::string_view stop_reason_name(StopReason r) {
  switch (r) {
    case StopReason::converged: return "converged";
    case StopReason::pass_limit: return "pass limit";
    case StopReason::time_limit: return "time limit";
    case StopReason::empty_tree: return "empty tree";
    case StopReason::nothing_to_optimize: return "nothing to optimize";
    case StopReason::interrupted: return "interrupted";
  }
  return "converged";
}

}  // namespace bvhopt
