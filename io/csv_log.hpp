// Per-tick CSV log of the haptic loop: one row per core TickReport, for
// plotting force and region size against time.
#pragma once

#include <fstream>
#include <string>

#include "core/scheduler.hpp"

namespace tissue::io {

/// Writes a header row, then one row per tick with the columns
/// tick,time,tool_x,tool_y,tool_z,contact_nodes,force_x,force_y,force_z,grasp,
/// internal_x,internal_y,internal_z,region_nodes,region_elems,residual,
/// kinetic,max_disp,equilibrium,steps,strain_energy,kinetic_rel,front_disp,depth
/// and, for every further tool k = 2, 3, ...: toolk_x,toolk_y,toolk_z,
/// toolk_contact_nodes,toolk_force_x,toolk_force_y,toolk_force_z,toolk_grasp.
/// SI units (s, m, N, J); tool_* is the tip of the first tool, force_* the
/// force on it, contact_nodes its surface nodes in contact, grasp its grasp
/// button (0/1); equilibrium 0/1; strain_energy and front_disp -1 where the
/// backend does not compute them; kinetic_rel the equilibrium test's
/// relative kinetic energy; depth the region's rings, -1 = the whole mesh.
class TickLog {
 public:
  /// Creates (truncates) the file and writes the header for n_tools tools
  /// (1..kMaxTools); throws std::runtime_error naming the path when it
  /// cannot be opened.
  explicit TickLog(const std::string& path, int n_tools = 1);

  /// Appends one row; throws std::runtime_error naming the path when the
  /// write fails.
  void write(const TickReport& r);

  /// Flushes buffered rows to the file.
  void flush();

  /// Rows written so far (header excluded).
  long rows() const { return rows_; }
  const std::string& path() const { return path_; }

  /// The header row for n_tools tools, without the newline.
  static std::string header(int n_tools = 1);

 private:
  std::string path_;
  int n_tools_;
  std::ofstream out_;
  long rows_ = 0;
};

}  // namespace tissue::io
