// Per-tick CSV log of the haptic loop: one row per core TickReport, for
// plotting force and region size against time.
//
// Written under "<path>.part" (io/atomic_file.hpp) and renamed to <path> by
// close(): a file named ticks.csv is always complete. The rows do not lag:
// each block of rows (kFlushRows, or whatever one second brought) is
// flushed to the .part file as whole lines, so a reader can follow a long
// run there (`tail -f ticks.csv.part`). A run ended by an exception or a
// signal still closes the log (the destructor renames); only a killed or
// crashed process leaves the .part file, whose last line is then whole.
#pragma once

#include <chrono>
#include <fstream>
#include <string>

#include "core/scheduler.hpp"

namespace tissue::io {

/// Writes a header row, then one row per tick with the columns
/// tick,time,tool_x,tool_y,tool_z,contact_nodes,force_x,force_y,force_z,grasp,
/// internal_x,internal_y,internal_z,region_nodes,region_elems,residual,
/// kinetic,max_disp,equilibrium,steps,strain_energy,kinetic_rel,front_disp,depth,visco_power,
/// visco_stored,dissipated
/// and, for every further tool k = 2, 3, ...: toolk_x,toolk_y,toolk_z,
/// toolk_contact_nodes,toolk_force_x,toolk_force_y,toolk_force_z,toolk_grasp.
/// SI units (s, m, N, J); tool_* is the tip of the first tool, force_* the
/// force on it, contact_nodes its surface nodes in contact, grasp its grasp
/// button (0/1); equilibrium 0/1; strain_energy and front_disp -1 where the
/// backend does not compute them; kinetic_rel the equilibrium test's
/// relative kinetic energy; depth the region's rings, -1 = the whole mesh;
/// visco_power (W), visco_stored and dissipated (J) the Prony terms' energy
/// (TickReport; 0 without Prony terms).
class TickLog {
 public:
  /// Rows between flushes (at most; a second of wall time flushes too).
  static constexpr long kFlushRows = 100;

  /// Creates (truncates) "<path>.part" and writes the header for n_tools
  /// tools (1..kMaxTools); throws std::runtime_error naming the path when it
  /// cannot be opened, std::invalid_argument for a tool count out of range.
  explicit TickLog(const std::string& path, int n_tools = 1);
  /// close(), swallowing errors (a destructor must not throw).
  ~TickLog();
  TickLog(const TickLog&) = delete;
  TickLog& operator=(const TickLog&) = delete;

  /// Appends one row (flushing every block); throws std::runtime_error
  /// naming the path when the write fails.
  void write(const TickReport& r);

  /// Flushes buffered rows to the .part file.
  void flush();

  /// Flushes, closes and renames the .part file to the final path; later
  /// calls do nothing. Throws std::runtime_error naming the path on failure.
  void close();

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
  long unflushed_ = 0;
  std::chrono::steady_clock::time_point last_flush_;
  bool closed_ = false;
};

}  // namespace tissue::io
