// bvhopt: a thin command line over the library. Each subcommand lives in its own file.
#include <CLI/CLI.hpp>

#include <exception>
#include <iostream>
#include <string>

#include "bvhopt/error.h"
#include "commands.h"

namespace {

// The exit codes (docs/errors.md): 0 success, 1 bad input or a failed run, 2 bad usage.
constexpr int kExitFailed = 1;
constexpr int kExitUsage = 2;

// CLI11 says "A subcommand is required" for a misspelt one; name it and the real ones.
bool is_unknown_subcommand(const CLI::App& app, int argc, char** argv) {
  if (argc < 2 || argv[1][0] == '-') return false;
  for (const CLI::App* sub : app.get_subcommands({}))
    if (sub->check_name(argv[1])) return false;
  return true;
}

int usage_error(const std::string& message) {
  std::cerr << "bvhopt: usage error: " << message << "\nRun 'bvhopt --help' (or 'bvhopt COMMAND --help') for more information.\n";
  return kExitUsage;
}

}  // namespace

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
  bvhopt::cli::register_export_command(app);
  bvhopt::cli::register_render_command(app);
  bvhopt::cli::register_demo_command(app);
  bvhopt::cli::register_experiment_command(app);
  std::string names;
  for (const CLI::App* sub : app.get_subcommands({})) names += (names.empty() ? "" : ", ") + sub->get_name();
  if (is_unknown_subcommand(app, argc, argv))
    return usage_error(std::string("unknown subcommand '") + argv[1] + "' (available: " + names + ")");
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    return usage_error(e.what());
  } catch (const bvhopt::Error& e) {
    std::cerr << "bvhopt: error: " << e.what() << "\n";
    return kExitFailed;
  } catch (const std::exception& e) {
    std::cerr << "bvhopt: unexpected error: " << e.what() << "\n";
    return kExitFailed;
  }
  return 0;
}
