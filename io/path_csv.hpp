// Scripted tool paths as CSV: a header line "t,x,y,z", optionally followed
// by the columns "grasp" (0/1, the grasp button from this waypoint on) and
// "ax,ay,az" (the shaft axis, tip to handle; 0,0,0 = the scene's direction),
// then one waypoint per line,
// time in s and tip position in m (SI). Blank lines and lines starting
// with '#' are skipped; fields may carry surrounding blanks. Times must
// increase strictly. Every error names file:line.
#pragma once

#include <iosfwd>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/device.hpp"

namespace tissue::io {

/// A malformed path CSV; the message starts with "<file>:<line>: ".
struct PathCsvError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// Parses path CSV text (at least one waypoint). `source` names it in errors.
std::vector<Waypoint> parse_path_csv(std::istream& in, const std::string& source);

/// Reads a path CSV file.
std::vector<Waypoint> read_path_csv(const std::string& path);

/// Writes waypoints as path CSV with round-trip precision.
void write_path_csv(const std::string& path, std::span<const Waypoint> waypoints);

}  // namespace tissue::io
