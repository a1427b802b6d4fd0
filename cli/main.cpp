// bvhopt: a thin command line over the library. Each subcommand lives in its own file.
#include <CLI/CLI.hpp>

#include <exception>
#include <iostream>

#include "bvhopt/error.h"
#include "commands.h"

int main(int argc, char** argv) {
  CLI::App app{"bvhopt: builds, optimizes and measures bounding volume hierarchies for ray tracing"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "bvhopt 0.1.0");
  bvhopt::cli::register_info_command(app);
  bvhopt::cli::register_build_command(app);
  bvhopt::cli::register_optimize_command(app);
  bvhopt::cli::register_bake_command(app);
  bvhopt::cli::register_compact_command(app);
  bvhopt::cli::register_stats_command(app);
  bvhopt::cli::register_trace_command(app);
  bvhopt::cli::register_render_command(app);
  bvhopt::cli::register_demo_command(app);
  bvhopt::cli::register_experiment_command(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const bvhopt::Error& e) {
    std::cerr << "bvhopt: error: " << e.what() << "\n";
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "bvhopt: unexpected error: " << e.what() << "\n";
    return 2;
  }
  return 0;
}
