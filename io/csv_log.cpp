#include "io/csv_log.hpp"

#include <fmt/format.h>

#include <stdexcept>

#include "io/atomic_file.hpp"

namespace tissue::io {

const char* TickLog::header() {
  return "tick,time,tool_x,tool_y,tool_z,contact_tri,force_x,force_y,force_z,internal_x,internal_y,internal_z,"
         "region_nodes,region_elems,residual,kinetic,max_disp,equilibrium,steps,strain_energy,kinetic_rel,front_disp,"
         "depth";
}

TickLog::TickLog(const std::string& path)
    : path_(path), out_(part_path(path)), last_flush_(std::chrono::steady_clock::now()) {
  if (!out_) throw std::runtime_error(fmt::format("{}: cannot open the tick log for writing", part_path(path_)));
  out_ << header() << '\n';
  flush();
}

TickLog::~TickLog() {
  try {
    close();
  } catch (const std::exception&) {
    // the .part file keeps the rows written
  }
}

void TickLog::write(const TickReport& r) {
  out_ << fmt::format(
      "{},{:.9g},{:.9g},{:.9g},{:.9g},{},{:.9g},{:.9g},{:.9g},{:.9g},{:.9g},{:.9g},{},{},{:.6g},{:.6g},{:.9g},{},{},"
      "{:.9g},{:.6g},{:.9g},{}\n",
      r.tick, r.time, r.tool.x, r.tool.y, r.tool.z, r.contact_tri, r.force.x, r.force.y, r.force.z, r.internal.x,
      r.internal.y, r.internal.z, r.region_nodes, r.region_elems, r.residual, r.kinetic, r.max_disp,
      r.equilibrium ? 1 : 0, r.steps, r.strain_energy, r.kinetic_rel, r.front_disp, r.depth);
  if (!out_) throw std::runtime_error(fmt::format("{}: write failed at tick {}", path_, r.tick));
  ++rows_;
  if (++unflushed_ >= kFlushRows || std::chrono::steady_clock::now() - last_flush_ > std::chrono::seconds(1)) flush();
}

void TickLog::flush() {
  out_.flush();
  if (!out_) throw std::runtime_error(fmt::format("{}: flush failed", part_path(path_)));
  unflushed_ = 0;
  last_flush_ = std::chrono::steady_clock::now();
}

void TickLog::close() {
  if (closed_) return;
  closed_ = true;
  out_.close();
  if (!out_) throw std::runtime_error(fmt::format("{}: write failed when closing", part_path(path_)));
  rename_into_place(part_path(path_), path_);
}

}  // namespace tissue::io
