// Fuzzes the tool-path CSV reader (io/path_csv). Only PathCsvError may
// escape; a path that reads has at least one waypoint, every number (the
// shaft axis columns included) finite and strictly increasing times.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <sstream>
#include <string>

#include "io/path_csv.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace tissue;
  std::istringstream in(std::string(reinterpret_cast<const char*>(data), size));
  std::vector<Waypoint> path;
  try {
    path = io::parse_path_csv(in, "fuzz.csv");
  } catch (const io::PathCsvError&) {
    return 0;
  }
  if (path.empty()) __builtin_trap();
  for (size_t k = 0; k < path.size(); ++k) {
    const Waypoint& w = path[k];
    if (!std::isfinite(w.t) || !std::isfinite(w.p.x) || !std::isfinite(w.p.y) || !std::isfinite(w.p.z))
      __builtin_trap();
    if (!std::isfinite(w.axis.x) || !std::isfinite(w.axis.y) || !std::isfinite(w.axis.z)) __builtin_trap();
    if (k > 0 && !(w.t > path[k - 1].t)) __builtin_trap();
  }
  return 0;
}
