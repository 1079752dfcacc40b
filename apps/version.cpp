// The version line of `tissue --version` and `tissue info`: the CMake
// project version and the git commit the build was configured from, both
// defined for this file alone by apps/CMakeLists.txt (a new commit then
// recompiles this file only).
#include <fmt/format.h>

#include "apps/commands.hpp"

#if !defined(TISSUE_VERSION) || !defined(TISSUE_GIT_COMMIT)
#error "the build defines TISSUE_VERSION and TISSUE_GIT_COMMIT for apps/version.cpp (apps/CMakeLists.txt)"
#endif

namespace tissue::app {

std::string version_line() {
  return fmt::format("tissue {} (commit {})", TISSUE_VERSION, TISSUE_GIT_COMMIT);
}

}  // namespace tissue::app
