// Surface mesh import through Assimp (OBJ, STL ascii and binary, PLY, OFF,
// 3DS and every other format Assimp reads) and the closed-surface check that
// TetGen needs.
//
// Units: surface files carry no unit. Anatomical meshes usually come in mm,
// CAD in mm or cm. load_surface() therefore takes the unit as an argument
// (metres per file unit, from parse_unit("mm") etc.); the caller chooses it
// and must say which unit it assumed (the `tissue mesh` command prints it).
#pragma once

#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/hd.hpp"
#include "core/vec.hpp"

namespace tissue::io {

/// A triangulated surface in SI units.
struct SurfaceMesh {
  std::vector<double> vertices;    ///< positions (n_vertices x 3, xyz interleaved) m
  std::vector<index_t> triangles;  ///< corner vertex ids (n_triangles x 3)

  index_t n_vertices() const { return static_cast<index_t>(vertices.size() / 3); }
  index_t n_triangles() const { return static_cast<index_t>(triangles.size() / 3); }
};

/// A progress line for long steps ("remeshing: pass 2 of 5, 31,208
/// triangles"); empty = silent.
using Progress = std::function<void(const std::string&)>;

/// Thrown for unreadable, empty or invalid surfaces and failed meshing; the
/// message names the file (or source) and the rule broken.
struct MeshError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// Thrown when a signal (SIGINT, SIGTERM, SIGHUP) stopped the meshing: the
/// TetGen child was killed for it (io/tetgen_mesher.cpp), so its end is the
/// user's request, not a crash. `signal` is the signal received; a command
/// exits with 128 + signal.
struct MeshInterrupted : MeshError {
  MeshInterrupted(int sig, const std::string& what) : MeshError(what), signal(sig) {}
  int signal;
};

/// Metres per unit for a unit name: "m" -> 1, "cm" -> 0.01, "mm" -> 0.001.
/// Throws MeshError naming the unit and the accepted names otherwise.
double parse_unit(const std::string& unit);

/// Reads every mesh of a surface file through Assimp (Triangulate,
/// JoinIdenticalVertices), applies the node transforms (a mesh referenced by
/// several nodes appears once per node), scales by metres_per_unit (> 0),
/// welds coincident vertices (weld_vertices) and drops vertices no triangle
/// uses. Point and line primitives are ignored. Throws MeshError naming the
/// file and Assimp's reason when the file cannot be read or holds no
/// triangles.
/// `merged`, when given, receives the number of vertices welding merged.
SurfaceMesh load_surface(const std::string& path, double metres_per_unit, index_t* merged = nullptr);

/// Merges vertices closer than `tolerance` (m; < 0 = 1e-9 times the
/// bounding-box diagonal) into one, keeping the first, and drops triangles
/// that collapse (two equal corners) and vertices no triangle uses. STL
/// repeats each vertex per triangle; welding restores the connectivity.
/// Returns the number of triangles dropped.
index_t weld_vertices(SurfaceMesh& mesh, double tolerance = -1);

/// Checks that the surface is a closed, consistently oriented 2-manifold:
/// every corner id is in range, no triangle is degenerate (repeated corner or
/// area <= 1e-14 times the squared bounding-box diagonal), and every edge is
/// used by exactly two triangles in opposite directions. Throws MeshError
/// starting with `source` and naming the edge's vertex ids or the triangle
/// and the rule, e.g. "edge (12, 40) is used by 1 triangle: the surface is
/// open".
void check_closed(const SurfaceMesh& mesh, const std::string& source);

/// Signed volume enclosed by a closed surface (m^3; > 0 when the triangles
/// are oriented outward), by the divergence theorem.
double enclosed_volume(const SurfaceMesh& mesh);

/// Generalised winding number of the closed surface around p: the sum of
/// the triangles' signed solid angles / 4 pi (van Oosterom and Strackee).
/// About 1 inside an outward surface, 0 outside, whatever the surface's
/// small defects.
double winding_number(const SurfaceMesh& mesh, Vec3<double> p);

/// A point strictly inside the closed, outward surface: from the centroid
/// of its largest triangle, a step inward (a tenth of that triangle's size,
/// halved until the winding number says inside). Throws MeshError naming
/// `source` when none is found (a surface of zero thickness).
Vec3<double> interior_point(const SurfaceMesh& mesh, const std::string& source);

/// Axis-aligned bounding box extents (m) along x, y, z.
Vec3<double> surface_extents(const SurfaceMesh& mesh);

}  // namespace tissue::io
