#include <CLI/CLI.hpp>
#include <iostream>
#include "bvhopt/bvhopt.h"
int main(int argc, char** argv) {
  CLI::App app{"bvhopt"};
  CLI11_PARSE(app, argc, argv);
  return 0;
}
