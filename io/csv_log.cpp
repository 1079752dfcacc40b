#include "io/csv_log.hpp"

#include <fmt/format.h>

#include <stdexcept>

#include "io/atomic_file.hpp"

namespace tissue::io {

std::string TickLog::header(int n_tools) {
  std::string h =
      "tick,time,tool_x,tool_y,tool_z,contact_nodes,force_x,force_y,force_z,grasp,internal_x,internal_y,internal_z,"
      "region_nodes,region_elems,residual,kinetic,max_disp,equilibrium,steps,strain_energy,kinetic_rel,front_disp,"
      "depth,visco_power,visco_stored,dissipated";
  for (int k = 2; k <= n_tools; ++k)
    h += fmt::format(",tool{0}_x,tool{0}_y,tool{0}_z,tool{0}_contact_nodes,tool{0}_force_x,tool{0}_force_y,"
                     "tool{0}_force_z,tool{0}_grasp",
                     k);
  return h;
}

TickLog::TickLog(const std::string& path, int n_tools) : path_(path), n_tools_(n_tools) {
  // checked before the .part file is created: a refused count leaves nothing behind
  if (n_tools < 1 || n_tools > kMaxTools)
    throw std::invalid_argument(fmt::format("{}: {} tools; the tick log takes 1 to {}", path_, n_tools, kMaxTools));
  out_.open(part_path(path_));
  if (!out_) throw std::runtime_error(fmt::format("{}: cannot open the tick log for writing", part_path(path_)));
  last_flush_ = std::chrono::steady_clock::now();
  out_ << header(n_tools) << '\n';
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
  const ToolReport& t0 = r.tools[0];
  out_ << fmt::format(
      "{},{:.9g},{:.9g},{:.9g},{:.9g},{},{:.9g},{:.9g},{:.9g},{},{:.9g},{:.9g},{:.9g},{},{},{:.6g},{:.6g},{:.9g},{},{},"
      "{:.9g},{:.6g},{:.9g},{},{:.9g},{:.9g},{:.9g}",
      r.tick, r.time, t0.tip.x, t0.tip.y, t0.tip.z, t0.contact_nodes, t0.force.x, t0.force.y, t0.force.z,
      t0.grasp ? 1 : 0, r.internal.x, r.internal.y, r.internal.z, r.region_nodes, r.region_elems, r.residual,
      r.kinetic, r.max_disp, r.equilibrium ? 1 : 0, r.steps, r.strain_energy, r.kinetic_rel, r.front_disp, r.depth,
      r.visco_power, r.visco_stored, r.dissipated);
  for (int k = 1; k < n_tools_; ++k) {
    const ToolReport& t = r.tools[k];
    out_ << fmt::format(",{:.9g},{:.9g},{:.9g},{},{:.9g},{:.9g},{:.9g},{}", t.tip.x, t.tip.y, t.tip.z,
                        t.contact_nodes, t.force.x, t.force.y, t.force.z, t.grasp ? 1 : 0);
  }
  out_ << '\n';
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
