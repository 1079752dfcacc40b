// Per-tick CSV log of the haptic loop: one row per core TickReport, for
// plotting force and region size against time.
#pragma once

#include <fstream>
#include <string>

#include "core/scheduler.hpp"

namespace tissue::io {

/// Writes a header row, then one row per tick with the columns
/// tick,time,tool_x,tool_y,tool_z,contact_tri,force_x,force_y,force_z,
/// internal_x,internal_y,internal_z,region_nodes,region_elems,residual,
/// kinetic,max_disp,equilibrium,steps,strain_energy,kinetic_rel,front_disp,depth
/// in SI units (s, m, N, J; equilibrium 0/1; contact_tri -1 = none;
/// strain_energy and front_disp -1 where the backend does not compute them;
/// kinetic_rel the equilibrium test's relative kinetic energy; depth the
/// region's rings, -1 = the whole mesh).
class TickLog {
 public:
  /// Creates (truncates) the file and writes the header; throws
  /// std::runtime_error naming the path when it cannot be opened.
  explicit TickLog(const std::string& path);

  /// Appends one row; throws std::runtime_error naming the path when the
  /// write fails.
  void write(const TickReport& r);

  /// Flushes buffered rows to the file.
  void flush();

  /// Rows written so far (header excluded).
  long rows() const { return rows_; }
  const std::string& path() const { return path_; }

  /// The header row, without the newline.
  static const char* header();

 private:
  std::string path_;
  std::ofstream out_;
  long rows_ = 0;
};

}  // namespace tissue::io
