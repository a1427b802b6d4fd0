// The one exception type the library throws for bad input or failed I/O.
#pragma once

#include <stdexcept>
#include <string>

namespace bvhopt {

// The message always names the file (or input), the place in it and the problem,
// e.g. "scene.obj: triangle 17, vertex index 900 out of range (mesh has 512 vertices)".
class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

}  // namespace bvhopt
