// Shared between the experiment runner and its report writer (not installed).
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

namespace bvhopt::experiment_detail {

using nlohmann::json;

// Writes the CSVs, runs the plot script, writes report.md, from a complete or partial
// results document (the one run_experiment and merge_experiments save as results.json).
void write_outputs(const json& results, const std::filesystem::path& out, const std::filesystem::path& plot_script);

json read_json_file(const std::filesystem::path& path);
void write_text_file(const std::filesystem::path& path, const std::string& text);

// The papers' published figures, typed in from their tables.
json published_figures();

}  // namespace bvhopt::experiment_detail
