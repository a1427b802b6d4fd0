// The experiment's outputs: CSVs (one per table or figure), plots through the script,
// report.md, and the papers' published figures beside ours.
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iomanip>
#include <sstream>

#include "bvhopt/error.h"
#include "experiment/experiment_internal.h"
#include "experiment/run_program.h"
#include "bvhopt/atomic_file.h"

namespace bvhopt::experiment_detail {
namespace {

namespace fs = std::filesystem;

std::string num(double v, int precision = 4) {
  if (!std::isfinite(v)) return "nan";
  std::ostringstream s;
  s << std::setprecision(precision) << std::fixed << v;
  return s.str();
}

double get(const json& j, const std::string& a, double fallback = NAN) {
  return j.contains(a) && j[a].is_number() ? j[a].get<double>() : fallback;
}
double get(const json& j, const std::string& a, const std::string& b, double fallback = NAN) {
  return j.contains(a) ? get(j[a], b, fallback) : fallback;
}

// A CSV and the markdown table of the same rows.
class Table {
 public:
  explicit Table(std::vector<std::string> header) : header_(std::move(header)) {}
  void add(std::vector<std::string> row) { rows_.push_back(std::move(row)); }
  bool empty() const { return rows_.empty(); }
  std::string csv() const {
    std::string s = join(header_, ",") + "\n";
    for (const auto& r : rows_) {
      std::vector<std::string> quoted;
      for (const std::string& cell : r) quoted.push_back(csv_cell(cell));
      s += join(quoted, ",") + "\n";
    }
    return s;
  }
  std::string markdown() const {
    std::string s = "| " + join(header_, " | ") + " |\n|";
    for (size_t i = 0; i < header_.size(); ++i) s += "---|";
    s += "\n";
    for (const auto& r : rows_) s += "| " + join(r, " | ") + " |\n";
    return s;
  }

 private:
  // RFC 4180: a cell holding a comma or a quote is quoted, quotes doubled.
  static std::string csv_cell(const std::string& c) {
    if (c.find_first_of(",\"\n") == std::string::npos) return c;
    std::string q = "\"";
    for (char ch : c) q += ch == '"' ? std::string("\"\"") : std::string(1, ch);
    return q + "\"";
  }
  static std::string join(const std::vector<std::string>& v, const std::string& sep) {
    std::string s;
    for (size_t i = 0; i < v.size(); ++i) s += (i ? sep : "") + v[i];
    return s;
  }
  std::vector<std::string> header_;
  std::vector<std::vector<std::string>> rows_;
};

const char* const kTreeLabels[][2] = {{"sah", "SAH (sweep) without optimization"},
                                      {"hill", "SAH + hill climbing (Kensler)"},
                                      {"anneal", "SAH + annealing (Kensler)"},
                                      {"insertion_sah", "SAH + insertion (Bittner as published)"},
                                      {"insertion_hybrid", "SAH + insertion (our hybrid form)"},
                                      {"median", "spatial median without optimization"},
                                      {"insertion_median", "spatial median + insertion (Bittner as published)"}};

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// The Python that has matplotlib: $BVHOPT_PYTHON, else python3 on the PATH, else Debian's own
// (a pyenv or venv python3 earlier on the PATH often lacks the python3-matplotlib package).
// Empty when none has it.
std::string python_with_matplotlib() {
  std::vector<std::string> candidates;
  if (const char* env = std::getenv("BVHOPT_PYTHON"); env && *env) candidates.push_back(env);
  candidates.push_back("python3");
  candidates.push_back("/usr/bin/python3");
  for (const std::string& py : candidates)
    if (run_program({py, "-c", "import matplotlib"}) == 0) return py;
  return {};
}

}  // namespace

json read_json_file(const fs::path& path) {
  std::ifstream in(path);
  if (!in) throw Error(path.string() + ": cannot open (is this an experiment output folder?)");
  try {
    return json::parse(in);
  } catch (const json::exception& e) {
    throw Error(path.string() + ": not valid JSON: " + e.what());
  }
}

void write_text_file(const fs::path& path, const std::string& text) {
  write_text_atomically(path, text);
}

json published_figures() {
  // Kensler 2008, Table 1 (costs with C_t = C_i = 10; only ratios are compared).
  json kensler = json::array({
      {{"scene", "Happy Buddha"}, {"key", "buddha"}, {"triangles", 1087474}, {"hill_rel", 0.995}, {"anneal_rel", 0.995},
       {"hill_seconds", 1.71}, {"anneal_seconds", 528.26}, {"hill_raycast_rel", 1.002}, {"anneal_raycast_rel", 1.002}, {"hill_path_rel", 1.007}, {"anneal_path_rel", 1.007}},
      {{"scene", "Dragon"}, {"key", "dragon"}, {"triangles", 871306}, {"hill_rel", 0.997}, {"anneal_rel", 0.997},
       {"hill_seconds", 1.23}, {"anneal_seconds", 426.48}, {"hill_raycast_rel", 1.0}, {"anneal_raycast_rel", 1.0}, {"hill_path_rel", 1.008}, {"anneal_path_rel", 1.008}},
      {{"scene", "Fairy Forest"}, {"key", "fairy"}, {"triangles", 174117}, {"hill_rel", 0.984}, {"anneal_rel", 0.955},
       {"hill_seconds", 0.24}, {"anneal_seconds", 74.11}, {"hill_raycast_rel", 1.001}, {"anneal_raycast_rel", 1.004}, {"hill_path_rel", 1.016}, {"anneal_path_rel", 0.996}},
      {{"scene", "Sponza Atrium"}, {"key", "sponza"}, {"triangles", 76065}, {"hill_rel", 0.908}, {"anneal_rel", 0.842},
       {"hill_seconds", 0.13}, {"anneal_seconds", 28.51}, {"hill_raycast_rel", 1.045}, {"anneal_raycast_rel", 1.073}, {"hill_path_rel", 0.993}, {"anneal_path_rel", 0.967}},
      {{"scene", "Conference"}, {"key", "conference"}, {"triangles", 282664}, {"hill_rel", 0.895}, {"anneal_rel", 0.845},
       {"hill_seconds", 0.68}, {"anneal_seconds", 119.26}, {"hill_raycast_rel", 0.978}, {"anneal_raycast_rel", 0.944}, {"hill_path_rel", 0.886}, {"anneal_path_rel", 0.824}},
      {{"scene", "Soda Hall"}, {"key", "soda"}, {"triangles", 2169132}, {"hill_rel", 0.914}, {"anneal_rel", 0.818},
       {"hill_seconds", 4.93}, {"anneal_seconds", 857.57}, {"hill_raycast_rel", 0.983}, {"anneal_raycast_rel", 0.939}, {"hill_path_rel", 0.986}, {"anneal_path_rel", 0.977}},
  });
  // Bittner et al. 2013, Table 1 (c_T = 3, c_I = 2 as ours); triangle counts not printed.
  json bittner = json::array({
      {{"scene", "Conference"}, {"key", "conference"}, {"sah_cost", 130.30}, {"rel_cost", 0.7866}, {"sah_seconds", 3.45}, {"rel_time", 1.3130}},
      {{"scene", "Fairy Forest"}, {"key", "fairy"}, {"sah_cost", 95.10}, {"rel_cost", 0.9621}, {"sah_seconds", 1.96}, {"rel_time", 1.2092}},
      {{"scene", "Sibenik Cathedral"}, {"key", "sibenik"}, {"sah_cost", 82.30}, {"rel_cost", 0.8445}, {"sah_seconds", 0.66}, {"rel_time", 2.0909}},
      {{"scene", "Sponza"}, {"key", "sponza"}, {"sah_cost", 220.20}, {"rel_cost", 0.8274}, {"sah_seconds", 0.56}, {"rel_time", 1.8036}},
      {{"scene", "Soda Hall"}, {"key", "soda"}, {"sah_cost", 216.50}, {"rel_cost", 0.7640}, {"sah_seconds", 40.96}, {"rel_time", 1.3760}},
      {{"scene", "Power Plant, sec. 9"}, {"key", "powerplant9"}, {"sah_cost", 57.90}, {"rel_cost", 0.8946}, {"sah_seconds", 1.36}, {"rel_time", 1.1912}},
      {{"scene", "Power Plant, sec. 16"}, {"key", "powerplant16"}, {"sah_cost", 93.50}, {"rel_cost", 0.8535}, {"sah_seconds", 4.70}, {"rel_time", 1.5957}},
      {{"scene", "Power Plant"}, {"key", "powerplant"}, {"sah_cost", 115.80}, {"rel_cost", 0.8446}, {"sah_seconds", 396.00}, {"rel_time", 1.2146}},
      {{"scene", "Pompeii Ten"}, {"key", "pompeii"}, {"sah_cost", 252.90}, {"rel_cost", 0.8620}, {"sah_seconds", 102.00}, {"rel_time", 1.7549}},
  });
  // Dammertz and Keller 2008, Table 1 (triangle counts from their Figure 1).
  json dk = json::array({
      {{"scene", "Space Ship"}, {"key", "ship"}, {"triangles", 1554416}, {"best", 0.25}, {"average", 0.435}, {"worst", 1.0}},
      {{"scene", "Kitchen"}, {"key", "kitchen"}, {"triangles", 110561}, {"best", 0.25}, {"average", 0.463}, {"worst", 0.992}},
      {{"scene", "Sponza (Frame 16)"}, {"key", "sponza"}, {"triangles", 66454}, {"best", 0.25}, {"average", 0.457}, {"worst", 0.99}},
  });
  return json{{"kensler", kensler}, {"bittner", bittner}, {"dammertz_keller", dk}};
}

namespace {

// The tables of the report, filled task by task; each is written as a CSV and shown in
// report.md.
struct ReportTables {
  Table kensler{{"scene", "triangles", "method", "sah_cost", "cost_ratio", "primary_seconds", "primary_ratio",
                 "path_seconds", "path_ratio", "optimize_seconds", "passes"}};
  Table passes{{"scene", "method", "pass", "cost", "relative_cost", "temperature", "seconds"}};
  Table bittner{{"scene", "triangles", "tree", "cost", "rel_cost", "ocost", "update_seconds", "build_seconds",
                 "total_seconds", "rel_time", "primary_seconds", "random_seconds", "ao_seconds", "primary_steps",
                 "random_steps", "ao_steps"}};
  Table depth{{"scene", "tree", "depth", "inner_area", "leaf_area"}};
  Table sweep{{"scene", "triangles", "t", "effective_t", "references", "ref_ratio", "steps", "steps_ratio", "seconds", "time_ratio"}};
  Table area{{"scene", "pose", "splits", "best", "average", "worst"}};
  Table rotation{{"scene", "frame", "angle_x", "angle_y", "angle_z", "base_references", "evh_references",
                  "base_seconds", "evh_seconds", "time_ratio", "base_steps", "evh_steps"}};
  Table papers{{"paper", "paper_scene", "our_scene", "quantity", "paper_value", "our_value", "ratio_ours_to_paper",
                "paper_triangles", "our_triangles"}};
  Table budget{{"scene", "anneal_passes", "anneal_period", "scaled_by_budget", "paper_passes",
                "estimated_full_schedule_seconds", "anneal_stop_reason"}};
  std::vector<std::string> heatmaps;      // image files, unoptimized and best tree per scene
  std::vector<std::string> depth_scenes;  // scenes with a Figure 7 plot
};

// An optimizers task of results.json, with the baselines that its rows are relative to.
struct OptimizerTask {
  std::string scene, tris;
  const json& det;
  const json& timing;
  const json& trees;  // det["trees"]
  const json& tt;     // timing["trees"]
  double c0, p0, q0;  // the SAH tree's cost, primary and path ray seconds
  double b_sah, b_med;  // build seconds of the SAH and the median tree
};

OptimizerTask optimizer_task(const json& task) {
  const json& det = task["det"];
  const json& timing = task["timing"];
  const json& trees = det["trees"];
  const json& tt = timing["trees"];
  return {task["scene"].get<std::string>(), std::to_string(det["triangles"].get<uint64_t>()), det, timing, trees, tt,
          get(trees["sah"], "cost"), get(tt["sah"], "ray_seconds", "primary"), get(tt["sah"], "ray_seconds", "path"),
          get(timing, "build_seconds", "sah"), get(timing, "build_seconds", "median")};
}

// Kensler's Table 1 and the cost per pass of his Figures 3 and 4.
void add_kensler_rows(ReportTables& t, const OptimizerTask& o) {
  const std::string& scene = o.scene;
  const std::string& tris = o.tris;
  const json& det = o.det;
  const json& timing = o.timing;
  const json& trees = o.trees;
  const json& tt = o.tt;
  const double c0 = o.c0;
  const double p0 = o.p0;
  const double q0 = o.q0;
  for (const char* key : {"sah", "hill", "anneal"}) {
    const json& tr = trees[key];
    const double c = get(tr, "cost"), p = get(tt[key], "ray_seconds", "primary"), q = get(tt[key], "ray_seconds", "path");
    const std::string method = std::string(key) == "sah" ? "none" : (std::string(key) == "hill" ? "hill climbing" : "annealing");
    t.kensler.add({scene, tris, method, num(c), num(c / c0), num(p, 6), num(p / p0), num(q, 6), num(q / q0),
                   num(get(tt[key], "optimize_seconds"), 6), tr.contains("passes") ? std::to_string(tr["passes"].get<uint64_t>()) : "0"});
  }
  for (const char* key : {"hill", "anneal", "insertion_sah", "insertion_median", "insertion_hybrid"}) {
    if (!det["traces"].contains(key)) continue;
    const json& costs = det["traces"][key];
    const json& secs = timing["traces"][key];
    const double start = std::string(key) == "insertion_median" ? get(trees["median"], "cost") : c0;
    for (size_t i = 0; i < costs.size(); ++i) {
      const double temp = std::string(key) == "anneal" && det["traces"].contains("anneal_temperature")
                              ? det["traces"]["anneal_temperature"][i].get<double>() : 0.0;
      t.passes.add({scene, key, std::to_string(i + 1), num(costs[i].get<double>(), 5),
                    num(costs[i].get<double>() / start, 6), num(temp, 4), num(secs[i].get<double>(), 4)});
    }
  }
}

// Bittner's Table 1, the area sums of his Figure 7, the annealing budget and the heat maps.
void add_bittner_rows(ReportTables& t, const OptimizerTask& o, const json& task) {
  const std::string& scene = o.scene;
  const std::string& tris = o.tris;
  const json& det = o.det;
  const json& trees = o.trees;
  const json& tt = o.tt;
  const double c0 = o.c0;
  const double b_sah = o.b_sah;
  const double b_med = o.b_med;
  for (const auto& lab : kTreeLabels) {
    const std::string key = lab[0];
    const json& tr = trees[key];
    const double upd = get(tt[key], "optimize_seconds", 0.0);
    const double build = (key == "median" || key == "insertion_median") ? b_med : b_sah;
    t.bittner.add({scene, tris, lab[1], num(get(tr, "cost")), num(get(tr, "cost") / c0), num(get(tr, "ocost")),
                   num(upd, 6), num(build, 6), num(build + upd, 6), num((build + upd) / b_sah, 3),
                   num(get(tt[key], "ray_seconds", "primary"), 6), num(get(tt[key], "ray_seconds", "random"), 6),
                   num(get(tt[key], "ray_seconds", "ao"), 6), num(get(tr, "steps", "primary"), 2),
                   num(get(tr, "steps", "random"), 2), num(get(tr, "steps", "ao"), 2)});
  }
  for (const char* key : {"sah", "insertion_sah"}) {
    const json& tr = trees[key];
    const double root = get(tr, "root_area", 1.0);
    const json& in = tr["inner_area_by_depth"];
    const json& lf = tr["leaf_area_by_depth"];
    for (size_t d = 0; d < std::max(in.size(), lf.size()); ++d)
      t.depth.add({scene, key, std::to_string(d), num(d < in.size() ? in[d].get<double>() / root : 0.0, 6),
                   num(d < lf.size() ? lf[d].get<double>() / root : 0.0, 6)});
  }
  t.depth_scenes.push_back(scene);
  const json& sch = det["anneal_schedule"];
  t.budget.add({scene, std::to_string(sch["passes"].get<uint64_t>()), std::to_string(sch["period"].get<uint64_t>()),
                sch["scaled_by_budget"].get<bool>() ? "yes" : "no", "1250", num(get(sch, "estimated_full_seconds"), 1),
                trees["anneal"]["stop_reason"].get<std::string>()});
  for (const json& img : task["images"]) t.heatmaps.push_back(img.get<std::string>());
}

// The papers' published figures beside ours, for scenes sharing a name with theirs.
void add_paper_rows(ReportTables& t, const OptimizerTask& o, const json& pub) {
  const std::string& scene = o.scene;
  const std::string& tris = o.tris;
  const json& trees = o.trees;
  const json& tt = o.tt;
  const double c0 = o.c0;
  const double p0 = o.p0;
  const double q0 = o.q0;
  const double b_sah = o.b_sah;
  const std::string lname = lower(scene);
  for (const json& k : pub["kensler"]) {
    if (lname.find(k["key"].get<std::string>()) == std::string::npos) continue;
    const std::string pt = std::to_string(k["triangles"].get<uint64_t>());
    auto row = [&](const std::string& q, double paper, double ours) {
      t.papers.add({"Kensler 2008", k["scene"].get<std::string>(), scene, q, num(paper, 3), num(ours, 3), num(ours / paper, 3), pt, tris});
    };
    row("hill climbing relative cost", get(k, "hill_rel"), get(trees["hill"], "cost") / c0);
    row("annealing relative cost", get(k, "anneal_rel"), get(trees["anneal"], "cost") / c0);
    row("hill climbing seconds", get(k, "hill_seconds"), get(tt["hill"], "optimize_seconds"));
    row("annealing seconds", get(k, "anneal_seconds"), get(tt["anneal"], "optimize_seconds"));
    row("annealing primary time ratio", get(k, "anneal_raycast_rel"), get(tt["anneal"], "ray_seconds", "primary") / p0);
    row("annealing path time ratio", get(k, "anneal_path_rel"), get(tt["anneal"], "ray_seconds", "path") / q0);
  }
  for (const json& b : pub["bittner"]) {
    const std::string key = b["key"].get<std::string>();
    if (lname.find(key) == std::string::npos) continue;
    t.papers.add({"Bittner 2013", b["scene"].get<std::string>(), scene, "insertion relative cost", num(get(b, "rel_cost"), 3),
                  num(get(trees["insertion_sah"], "cost") / c0, 3),
                  num(get(trees["insertion_sah"], "cost") / c0 / get(b, "rel_cost"), 3), "not stated", tris});
    const double ours_rel_time = (b_sah + get(tt["insertion_sah"], "optimize_seconds")) / b_sah;
    t.papers.add({"Bittner 2013", b["scene"].get<std::string>(), scene, "insertion relative build time", num(get(b, "rel_time"), 3),
                  num(ours_rel_time, 3), num(ours_rel_time / get(b, "rel_time"), 3), "not stated", tris});
  }
  // The target of the issue: our best method against the best the papers report for the
  // scene of that name.
  double paper_best = INFINITY;
  std::string paper_scene;
  for (const char* paper : {"kensler", "bittner"})
    for (const json& p : pub[paper]) {
      if (lname.find(p["key"].get<std::string>()) == std::string::npos) continue;
      const double v = std::string(paper) == "kensler" ? get(p, "anneal_rel") : get(p, "rel_cost");
      if (v < paper_best) {
        paper_best = v;
        paper_scene = p["scene"].get<std::string>() + (std::string(paper) == "kensler" ? " (Kensler)" : " (Bittner)");
      }
    }
  if (std::isfinite(paper_best)) {
    double ours = INFINITY;
    for (const char* key : {"hill", "anneal", "insertion_sah", "insertion_median", "insertion_hybrid"})
      ours = std::min(ours, get(trees[key], "cost") / c0);
    t.papers.add({"best of the papers", paper_scene, scene, "best relative cost", num(paper_best, 3), num(ours, 3),
                  num(ours / paper_best, 3), "see above", tris});
  }
}

// Dammertz and Keller's Figure 4 (t sweep) and Table 1 (area reduction), with their figures.
void add_evh_rows(ReportTables& t, const json& task, const json& pub) {
  const std::string scene = task["scene"].get<std::string>();
  const json& det = task["det"];
  const json& timing = task["timing"];
  const std::string tris = std::to_string(det["triangles"].get<uint64_t>());
  const double s0 = get(det["off"], "steps"), t0 = get(timing, "off_seconds");
  t.sweep.add({scene, tris, "off", "off", std::to_string(det["off"]["references"].get<uint64_t>()), "1.0000",
               num(s0, 2), "1.0000", num(t0, 6), "1.0000"});
  for (size_t i = 0; i < det["sweep"].size(); ++i) {
    const json& r = det["sweep"][i];
    const double secs = timing["sweep_seconds"][i].get<double>();
    t.sweep.add({scene, tris, std::to_string(r["t"].get<int>()), std::to_string(r["effective_t"].get<int>()),
               std::to_string(r["references"].get<uint64_t>()),
               num(get(r, "ratio")), num(get(r, "steps"), 2), num(get(r, "steps") / s0), num(secs), num(secs / t0)});
  }
  for (const char* pose : {"as_loaded", "frame16"}) {
    const json& a = det["area_reduction"][pose];
    t.area.add({scene, pose, std::to_string(a["splits"].get<uint64_t>()), num(get(a, "best")),
                num(get(a, "average")), num(get(a, "worst"))});
    if (std::string(pose) != "frame16") continue;
    for (const json& d : pub["dammertz_keller"]) {
      if (lower(scene).find(d["key"].get<std::string>()) == std::string::npos) continue;
      const std::string pt = std::to_string(d["triangles"].get<uint64_t>());
      for (const char* q : {"best", "average", "worst"})
        t.papers.add({"Dammertz-Keller 2008", d["scene"].get<std::string>(), scene + " (frame-16 pose)",
                    std::string("area reduction ") + q, num(get(d, q), 3), num(get(a, q), 3),
                    num(get(a, q) / get(d, q), 3), pt, tris});
    }
  }
}

// Dammertz and Keller's Figure 5: the rotating scene, frame by frame.
void add_rotation_rows(ReportTables& t, const json& task) {
  const std::string scene = task["scene"].get<std::string>();
  const json& det = task["det"];
  const json& timing = task["timing"];
  for (size_t i = 0; i < det["frames"].size(); ++i) {
    const json& f = det["frames"][i];
    const json& ft = timing["frames"][i];
    const double bs = get(ft, "base_seconds"), es = get(ft, "evh_seconds");
    t.rotation.add({scene, std::to_string(f["frame"].get<int>()), num(f["angles"][0].get<double>(), 2),
                    num(f["angles"][1].get<double>(), 2), num(f["angles"][2].get<double>(), 2),
                  std::to_string(f["base_references"].get<uint64_t>()),
                  std::to_string(f["evh_references"].get<uint64_t>()), num(bs, 6), num(es, 6), num(es / bs),
                  num(get(f, "base_steps"), 2), num(get(f, "evh_steps"), 2)});
  }
}

void write_csvs(const ReportTables& t, const fs::path& out) {
  const std::pair<const char*, const Table*> csvs[] = {
      {"kensler_table1.csv", &t.kensler}, {"kensler_passes.csv", &t.passes}, {"bittner_table1.csv", &t.bittner},
      {"bittner_depth_areas.csv", &t.depth}, {"dk_t_sweep.csv", &t.sweep}, {"dk_area_reduction.csv", &t.area},
      {"dk_rotation.csv", &t.rotation}, {"papers_comparison.csv", &t.papers}, {"anneal_budget.csv", &t.budget}};
  for (const auto& [file, table] : csvs) write_text_file(out / file, table->csv());
}

// Plots: only through the script, run as a program of its own, and only when Python with
// matplotlib is there. Returns the report's note when there are none; empty when drawn.
std::string draw_plots(const fs::path& out, const fs::path& plot_script) {
  if (plot_script.empty() || !fs::exists(plot_script))
    return "No plots: the plotting script (scripts/plot_experiment.py) was not found" +
           (plot_script.empty() ? std::string(".") : " at " + plot_script.string() + ".");
  const std::string py = python_with_matplotlib();
  if (py.empty())
    return "No plots: python3 with matplotlib is not installed (Debian: apt-get install python3-matplotlib); "
           "run `python3 scripts/plot_experiment.py --dir <this folder>` once it is.";
  if (run_program({py, plot_script.string(), "--dir", out.string()}, out / "plot.log") != 0)
    return "The plotting script failed; see plot.log.";
  return {};
}

// report.md: the settings, then every table, with the plots that exist.
void write_report(const json& results, const ReportTables& t, const fs::path& out, const std::string& plot_note) {
  const json& m = results["machine"];
  const json& s = results["settings"];
  std::ostringstream r;
  r << "# bvhopt experiment report\n\n";
  r << "Machine: " << m["cpu"].get<std::string>() << ", " << m["cores"] << " cores; run on " << m["threads"]
    << " threads. bvhopt " << m["bvhopt"].get<std::string>() << ", compiler " << m["compiler"].get<std::string>()
    << ", oneTBB " << m["tbb"].get<std::string>() << ". Date " << m["date"].get<std::string>() << ".\n\n";
  r << "Grid: " << results["grid"]["tasks"] << " tasks (scene x protocol)";
  if (results["grid"]["shard_count"].get<int>() > 1)
    r << "; **this is shard " << results["grid"]["shard_index"].get<int>() + 1 << " of "
      << results["grid"]["shard_count"] << " only** (join the shards with `bvhopt experiment merge`)";
  if (results["grid"].contains("merged_from")) r << "; merged from " << results["grid"]["merged_from"] << " parts";
  r << ".\n\nSettings: seed " << s["seed"] << ", time budget " << s["time_budget"] << " s per scene, "
    << s["rays"] << " rays per set (primary, random, ao, path), " << s["repeats"]
    << " timed passes per measurement (median), EVH rays " << s["evh_rays"] << ", t values " << s["evh_t_values"].dump()
    << ", " << s["rotation_frames"] << " rotation frames at t = " << s["rotation_t"] << ", cost model c_T = "
    << s["cost_model"]["c_T"] << ", c_I = " << s["cost_model"]["c_I"] << ". Ray times are traced on each tree "
    << "compacted to leaves of up to " << s["traced_leaf_size"] << " triangles (the same for every method) in the "
    << (s.contains("layout") ? s["layout"].get<std::string>() : std::string("bvh2")) << " layout"
    << (s.contains("wide_block_cost") && s.value("layout", "bvh2") != "bvh2"
            ? " (collapsed with c_blk = " + s["wide_block_cost"].dump() + ")"
            : std::string())
    << "; "
    << "times are seconds for the whole ray set, on all threads.\n\n";
  r << "Costs, reference counts, traversal steps and per-pass costs are deterministic (the same on any machine, "
       "thread count and shard split); times are not. `results.json` keeps them apart (`det` and `timing`).\n\n";
  r << "## Time budget\n\nAnnealing is shortened first: its schedule (Kensler's N = 1250 passes, period f = 50) is "
       "scaled so that its estimated time fits "
    << num(100.0 * s["anneal_budget_fraction"].get<double>(), 0)
    << "% of the per-scene budget (estimate: inner nodes x " << s["anneal_seconds_per_node_pass"]
    << " s per node per pass, a fixed calibration so trees do not depend on the clock).\n\n"
    << t.budget.markdown() << "\n";
  r << "## Kensler 2008, Table 1\n\nRatios are to the unoptimized SAH tree (lower is better).\n\n" << t.kensler.markdown() << "\n";
  r << "Figures 3 and 4 (cost per pass, hill climbing and annealing): `kensler_passes.csv`.\n\n";
  if (fs::exists(out / "fig_kensler_passes.png")) r << "![Kensler Figures 3 and 4](fig_kensler_passes.png)\n\n";
  r << "## Bittner et al. 2013, Table 1\n\n`cost` of the tree with one triangle per leaf, `rel_cost` to the SAH tree, "
       "`ocost` after the best collapse into leaves; `update` is the optimization time, `build` the builder's, "
       "`rel_time` the total to the SAH build; ray times for primary, random and AO rays; mean traversal steps per ray. "
       "Kensler's methods as the paper's reference rows.\n\n"
    << t.bittner.markdown() << "\n";
  r << "Figure 7 (area sums of inner nodes and leaves per depth, relative to the root, before and after): "
       "`bittner_depth_areas.csv`.\n\n";
  for (const std::string& sc : t.depth_scenes)
    if (fs::exists(out / ("fig_bittner_depth_" + sc + ".png")))
      r << "![Figure 7, " << sc << "](fig_bittner_depth_" << sc << ".png)\n\n";
  r << "## Dammertz and Keller 2008\n\n### Figure 4: t against references and time\n\nBinned SAH, leaves of up to "
    << s["evh_leaf_size"] << " references, one reference per triangle kept per leaf; primary rays. `effective_t` is below `t` where the reference budget (8 references per triangle) lowered it.\n\n"
    << t.sweep.markdown() << "\n";
  if (fs::exists(out / "fig_dk_t_sweep.png")) r << "![DK Figure 4](fig_dk_t_sweep.png)\n\n";
  r << "### Figure 5: the rotating scene\n\n";
  if (t.rotation.empty()) r << "(not in this part of the grid)\n\n";
  else r << t.rotation.markdown() << "\n";
  if (fs::exists(out / "fig_dk_rotation.png")) r << "![DK Figure 5](fig_dk_rotation.png)\n\n";
  r << "### Table 1: area reduction factors (t = 14)\n\n`frame16` is the scene rotated by (45, 10, 15) degrees, the "
       "pose of the paper's Sponza row; unrotated architecture is mostly axis-aligned and splits little.\n\n"
    << t.area.markdown() << "\n";
  r << "## Heat maps\n\nTraversal steps per primary ray of the unoptimized SAH tree and the lowest-cost tree of "
       "each scene, the two on one scale (0 blue, red at the 99th percentile of both, rounded up; each image's colour "
       "bar gives it in steps and its caption the mean).\n\n";
  for (size_t i = 0; i + 1 < t.heatmaps.size(); i += 2)
    r << "![" << t.heatmaps[i] << "](" << t.heatmaps[i] << ") ![" << t.heatmaps[i + 1] << "](" << t.heatmaps[i + 1] << ")\n\n";
  r << "## The papers beside us\n\nPublished figures (typed in from the papers) next to ours for scenes sharing a name. "
       "The scene versions differ: compare the triangle counts. Kensler's costs used other constants, so only his "
       "ratios are compared; his and Bittner's times are from 2008/2013 single-threaded machines, and Bittner's relative build time is to an SAH builder the paper calls unoptimized (ours builds in a fraction of the time, so the same optimization time is a much larger ratio).\n\n";
  if (t.papers.empty()) r << "(no scene here shares a name with the papers' scenes)\n\n";
  else r << t.papers.markdown() << "\n";
  if (fs::exists(out / "fig_papers.png")) r << "![Our figures beside the papers' published ones](fig_papers.png)\n\n";
  r << "## Plots\n\n" << (plot_note.empty() ? "Plots made by scripts/plot_experiment.py from the CSVs." : plot_note) << "\n";
  write_text_file(out / "report.md", r.str());
}
}  // namespace

void write_outputs(const json& results, const fs::path& out, const fs::path& plot_script) {
  const json pub = published_figures();
  ReportTables t;
  for (const json& task : results["tasks"]) {
    const std::string kind = task["kind"].get<std::string>();
    if (kind == "optimizers") {
      const OptimizerTask o = optimizer_task(task);
      add_kensler_rows(t, o);
      add_bittner_rows(t, o, task);
      add_paper_rows(t, o, pub);
    } else if (kind == "evh") {
      add_evh_rows(t, task, pub);
    } else if (kind == "rotation") {
      add_rotation_rows(t, task);
    }
  }
  write_csvs(t, out);
  const std::string plot_note = draw_plots(out, plot_script);
  write_report(results, t, out, plot_note);
}

}  // namespace bvhopt::experiment_detail
