// Each subcommand registers itself on the app; main.cpp calls these in pipeline order.
#pragma once

#include <CLI/CLI.hpp>

namespace bvhopt::cli {

void register_info_command(CLI::App& app);        // scene
void register_build_command(CLI::App& app);       // build
void register_optimize_command(CLI::App& app);    // optimize
void register_bake_command(CLI::App& app);        // build + optimize + collapse in one step
void register_compact_command(CLI::App& app);     // finalize
void register_stats_command(CLI::App& app);       // measure
void register_trace_command(CLI::App& app);       // trace
void register_export_command(CLI::App& app);      // layout, written for renderers
void register_render_command(CLI::App& app);
void register_demo_command(CLI::App& app);        // all of it on the built-in scene
void register_experiment_command(CLI::App& app);  // the papers' tables and figures

}  // namespace bvhopt::cli
