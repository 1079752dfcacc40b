// Result export for ParaView: VTK XML UnstructuredGrid files (.vtu, ASCII)
// of the tissue in its reference configuration with the solver's fields, and
// a frame series with a .pvd collection that carries the simulated times.
// In ParaView, "Warp By Vector" on "displacement" shows the deformed shape.
// Every file is written whole under "<name>.part" and renamed into place
// (io/atomic_file.hpp): a reader never sees a truncated frame or .pvd.
#pragma once

#include <span>
#include <string>
#include <vector>

#include "core/backend.hpp"
#include "core/model.hpp"
#include "scene/scene.hpp"

namespace tissue::io {

/// Writes one .vtu file: points = reference positions X (n_nodes), cells =
/// the tets as VTK_TETRA (type 10), PointData "displacement" (3 components,
/// m), "nodal_pressure" (Pa) and "internal_force" (3 components, N), CellData
/// "J" (det F). The fields' sizes must match the model (u, f: 3 x n_nodes
/// component-major as in core/backend.hpp; node_p: n_nodes; elem_J:
/// n_elems). The file holds one <Piece>, or, for a scene of bodies, one per
/// body in body order, each with its own nodes and elements (connectivity
/// counted from its first node) and a CellData "body" (Int32, the body's
/// index in `bodies`), so that ParaView's Threshold on "body" shows one.
/// Throws std::runtime_error naming the path on a size mismatch, bodies
/// that do not tile the model's nodes and elements in order, or a write
/// failure.
void write_vtu(const std::string& path, const TissueModel<double>& model, const Fields& fields,
               std::span<const scene::Body> bodies = {});

/// A numbered series of frames, frame_0000.vtu, frame_0001.vtu, ... in one
/// directory (created if missing), and series.pvd listing them with their
/// times. The .pvd is rewritten (atomically) after each frame, so it lists
/// exactly the complete frames if the run stops early.
class VtuSeries {
 public:
  /// Creates `directory` (and parents); throws std::runtime_error naming it
  /// when that fails. Every frame holds one piece per body (write_vtu).
  explicit VtuSeries(std::string directory, std::vector<scene::Body> bodies = {});

  /// Writes the next frame (write_vtu) at simulated time `time` (s, not
  /// before the previous frame's) and updates series.pvd. Returns the
  /// frame's path.
  std::string write(const TissueModel<double>& model, const Fields& fields, double time);

  /// Frames written so far.
  int frames() const { return static_cast<int>(times_.size()); }
  /// Path of the collection file (directory/series.pvd).
  std::string pvd_path() const;

 private:
  void write_pvd() const;

  std::string directory_;
  std::vector<scene::Body> bodies_;
  std::vector<double> times_;       ///< (frames) s
  std::vector<std::string> files_;  ///< frame file names, relative to directory_
};

}  // namespace tissue::io
