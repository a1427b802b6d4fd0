// Each subcommand registers itself on the app; main.cpp calls these in order.
#pragma once

#include <CLI/CLI.hpp>

namespace bvhopt::cli {

void register_info_command(CLI::App& app);
void register_build_command(CLI::App& app);
void register_stats_command(CLI::App& app);
void register_demo_command(CLI::App& app);
void register_compact_command(CLI::App& app);
void register_experiment_command(CLI::App& app);

}  // namespace bvhopt::cli
