// Runs another program (the plotting script's Python) and waits for it: arguments passed as
// a list, no shell in between, so no quoting of paths.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

namespace bvhopt::experiment_detail {

// argv[0] is looked up on the PATH. Standard output and error go to `log` (truncated), or
// are discarded when it is empty. Returns the exit status; -1 when the program could not
// be started or did not exit normally.
int run_program(const std::vector<std::string>& argv, const std::filesystem::path& log = {});

}  // namespace bvhopt::experiment_detail
