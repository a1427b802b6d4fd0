// Which wide kernel this CPU runs: cpuid through the compiler's builtins, overridable by
// $BVHOPT_ISA for measurements and tests.
#include <cstdlib>
#include <string>

#include "bvhopt/error.h"
#include "bvhopt/wide_tracer.h"

namespace bvhopt {

std::string_view isa_name(Isa isa) {
  switch (isa) {
    case Isa::sse42: return "sse";
    case Isa::avx2: return "avx2";
    case Isa::avx512: return "avx512";
  }
  return "?";
}

std::optional<Isa> parse_isa(std::string_view name) {
  for (Isa isa : {Isa::sse42, Isa::avx2, Isa::avx512})
    if (name == isa_name(isa)) return isa;
  return std::nullopt;
}

bool isa_supported(Isa isa) {
  __builtin_cpu_init();
  switch (isa) {
    case Isa::sse42: return __builtin_cpu_supports("sse4.2");
    case Isa::avx2: return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
    case Isa::avx512:
      return __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") &&
             __builtin_cpu_supports("avx512bw") && __builtin_cpu_supports("avx512dq") && isa_supported(Isa::avx2);
  }
  return false;
}

namespace {
Isa pick_isa() {
  if (const char* forced = std::getenv("BVHOPT_ISA"); forced && *forced) {
    const std::optional<Isa> isa = parse_isa(forced);
    if (!isa) throw Error(std::string("BVHOPT_ISA=") + forced + ": unknown (sse, avx2 or avx512)");
    if (!isa_supported(*isa)) throw Error(std::string("BVHOPT_ISA=") + forced + ": this CPU does not support it");
    return *isa;
  }
  for (Isa isa : {Isa::avx512, Isa::avx2, Isa::sse42})
    if (isa_supported(isa)) return isa;
  throw Error("wide tracer: the CPU lacks SSE4.2");
}
}  // namespace

Isa default_isa() {
  static const Isa isa = pick_isa();
  return isa;
}

}  // namespace bvhopt
