#include "io/surface_import.hpp"

#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <assimp/Importer.hpp>
#include <cmath>
#include <new>
#include <tuple>
#include <sstream>
#include <cstdint>
#include <cstdlib>
#include <cerrno>
#include <filesystem>
#include <fstream>
#include <map>
#include <unordered_map>

#include "core/vec.hpp"

namespace tissue::io {
namespace {

Vec3<double> vertex(const SurfaceMesh& s, index_t i) {
  return {s.vertices[3 * i], s.vertices[3 * i + 1], s.vertices[3 * i + 2]};
}

/// Length of the bounding-box diagonal (m); 0 for an empty mesh.
double bbox_diagonal(const SurfaceMesh& s) {
  if (s.vertices.empty()) return 0;
  double lo[3] = {s.vertices[0], s.vertices[1], s.vertices[2]}, hi[3] = {lo[0], lo[1], lo[2]};
  for (size_t k = 0; k < s.vertices.size(); ++k) {
    lo[k % 3] = std::min(lo[k % 3], s.vertices[k]);
    hi[k % 3] = std::max(hi[k % 3], s.vertices[k]);
  }
  return std::sqrt((hi[0] - lo[0]) * (hi[0] - lo[0]) + (hi[1] - lo[1]) * (hi[1] - lo[1]) +
                   (hi[2] - lo[2]) * (hi[2] - lo[2]));
}

/// Appends the triangles of every mesh under `node`, transformed by the
/// accumulated node transform; polygons are fanned from their first corner
/// here (Assimp 5.2's Triangulate step aborts the process on a malformed
/// PLY face list). Throws MeshError for a non-finite vertex, naming it.
void collect(const aiScene& scene, const aiNode& node, const aiMatrix4x4& parent, double scale, SurfaceMesh& out,
             const std::string& path) {
  const aiMatrix4x4 xf = parent * node.mTransformation;
  for (unsigned k = 0; k < node.mNumMeshes; ++k) {
    const aiMesh& mesh = *scene.mMeshes[node.mMeshes[k]];
    const index_t base = out.n_vertices();
    for (unsigned v = 0; v < mesh.mNumVertices; ++v) {
      const aiVector3D p = xf * mesh.mVertices[v];
      const double x = scale * p.x, y = scale * p.y, z = scale * p.z;
      if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z))
        throw MeshError(fmt::format("{}: vertex {} of mesh {} is not finite ({}, {}, {}) or overflows in metres", path,
                                    v, node.mMeshes[k], mesh.mVertices[v].x, mesh.mVertices[v].y,
                                    mesh.mVertices[v].z));
      out.vertices.insert(out.vertices.end(), {x, y, z});
    }
    for (unsigned f = 0; f < mesh.mNumFaces; ++f) {
      const aiFace& face = mesh.mFaces[f];
      if (face.mNumIndices < 3) continue;  // points and lines carry no surface
      for (unsigned c = 0; c < face.mNumIndices; ++c)
        if (face.mIndices[c] >= mesh.mNumVertices)
          throw MeshError(fmt::format("{}: face {} of mesh {} names vertex {} of {}", path, f, node.mMeshes[k],
                                      face.mIndices[c], mesh.mNumVertices));
      for (unsigned c = 1; c + 1 < face.mNumIndices; ++c)
        out.triangles.insert(out.triangles.end(), {base + static_cast<index_t>(face.mIndices[0]),
                                                   base + static_cast<index_t>(face.mIndices[c]),
                                                   base + static_cast<index_t>(face.mIndices[c + 1])});
    }
  }
  for (unsigned c = 0; c < node.mNumChildren; ++c) collect(scene, *node.mChildren[c], xf, scale, out, path);
}

/// Drops vertices no triangle uses and renumbers the triangles.
void compact_vertices(SurfaceMesh& s) {
  std::vector<index_t> map(s.n_vertices(), -1);
  std::vector<double> kept;
  for (index_t& v : s.triangles) {
    if (map[v] < 0) {
      map[v] = static_cast<index_t>(kept.size() / 3);
      kept.insert(kept.end(), s.vertices.begin() + 3 * v, s.vertices.begin() + 3 * v + 3);
    }
    v = map[v];
  }
  s.vertices.swap(kept);
}

/// The file's next line that is not blank or a '#' comment, without its
/// leading blanks and trailing '\r', with its 1-based number, from `text`
/// starting at `pos` (advanced).
std::pair<std::string, int> next_line(const std::string& text, std::size_t& pos, int& line) {
  while (pos < text.size()) {
    const std::size_t end = std::min(text.find('\n', pos), text.size());
    std::string l = text.substr(pos, end - pos);
    pos = end + 1;
    ++line;
    const auto first = l.find_first_not_of(" \t\r");
    if (first == std::string::npos || l[first] == '#') continue;
    l = l.substr(first);
    if (!l.empty() && l.back() == '\r') l.pop_back();
    return {l, line};
  }
  return {"", line};
}

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

/// A binary STL is an 80-byte header, a little-endian 32-bit triangle count
/// and 50 bytes per triangle; Assimp reads a .stl file as binary only when
/// its size is exactly 84 + 50 x count (computed in 32 bits, so a count
/// that wraps around can pass and make it allocate for billions), as ASCII
/// when it starts with "solid", and otherwise fails with "Failed to
/// determine STL storage representation". So a file that is not ASCII
/// (no "solid" start, or a NUL byte in its first MiB, which ASCII never
/// holds) is checked here: the count must match the size, computed in 64
/// bits. `head` is the file's first MiB, `size` its size in bytes.
void guard_binary_stl(const std::string& path, const std::string& head, unsigned long long size) {
  const auto first = head.find_first_not_of(" \t\r\n");
  const bool ascii = first != std::string::npos && lower(head.substr(first, 5)) == "solid" &&
                     head.find('\0') == std::string::npos;
  if (ascii) return;
  if (size < 84)
    throw MeshError(fmt::format("{}: not an ASCII STL (it does not start with 'solid'), and its {} bytes cannot hold "
                                "a binary STL's 80-byte header and 4-byte triangle count",
                                path, size));
  std::uint32_t count = 0;
  for (int k = 3; k >= 0; --k) count = count << 8 | static_cast<unsigned char>(head[80 + size_t(k)]);
  const unsigned long long need = 84ULL + 50ULL * count;
  if (need == size) return;
  const unsigned long long room = (size - 84) / 50, left = (size - 84) % 50;
  throw MeshError(fmt::format(
      "{}: the binary STL header claims {} triangles, which take 84 + 50 x {} = {} bytes, but the file has {} bytes "
      "(room for {} triangle{}{}): the file is truncated, padded or not a binary STL",
      path, count, count, need, size, room, room == 1 ? "" : "s",
      left ? fmt::format(" and {} bytes over", left) : std::string()));
}

/// Checks the element counts a PLY or OFF header claims before Assimp
/// allocates for them (docs/reliability.md, "Findings in surface import"):
///  - a PLY file (magic "ply" in any case, after blanks) must have an
///    end_header line (Assimp 5.2 loops forever without one), and its
///    elements must fit in the file: at least one byte each;
///  - an OFF file's vertex and face counts (a .off file's, with or without
///    the OFF keyword; a vertex count given alone as well) must fit in the
///    file: at least two bytes per number of each vertex and face line;
///  - a .stl file that is not ASCII: guard_binary_stl.
/// Headers are a few hundred bytes; the first 1 MiB is read.
void guard_header(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec))
    throw MeshError(fmt::format("{}: is a directory, not a surface file", path));
  std::ifstream f(path, std::ios::binary | std::ios::ate);
  if (!f) return;  // Assimp reports unreadable files itself
  const auto size = static_cast<unsigned long long>(std::max<std::streamoff>(f.tellg(), 0));
  f.seekg(0);
  std::string head(std::size_t(1) << 20, '\0');
  f.read(head.data(), static_cast<std::streamsize>(head.size()));
  head.resize(static_cast<size_t>(f.gcount()));
  std::size_t pos = 0;
  int line = 0;
  const auto [raw_magic, magic_line] = next_line(head, pos, line);
  const std::string magic = lower(raw_magic);
  auto count = [&](const std::string& word, int at) -> unsigned long long {
    errno = 0;
    char* end = nullptr;
    const unsigned long long n = std::strtoull(word.c_str(), &end, 10);
    if (errno == ERANGE)
      throw MeshError(fmt::format("{}:{}: the header claims {} elements; the file's {} bytes cannot hold them", path,
                                  at, word.substr(0, 40) + (word.size() > 40 ? "..." : ""), size));
    if (word.empty() || word[0] == '-' || *end != '\0')
      throw MeshError(fmt::format("{}:{}: '{}' is not an element count", path, at, word.substr(0, 40)));
    return n;
  };
  if (lower(std::filesystem::path(path).extension().string()) == ".stl") {
    guard_binary_stl(path, head, size);
    return;
  }
  if (magic.rfind("ply", 0) == 0) {
    // Assimp 5.2's PLY reader hangs on headers that bend the format (a magic or keyword in another
    // case, an end_header line with more on it, no end_header): only the format's exact lines pass
    if (raw_magic != "ply")
      throw MeshError(fmt::format("{}:{}: the PLY magic line is '{}', not 'ply'", path, magic_line,
                                  raw_magic.substr(0, 40)));
    unsigned long long total = 0;
    for (;;) {
      const auto [l, at] = next_line(head, pos, line);
      if (l.empty())
        throw MeshError(fmt::format("{}: cannot read the surface: PLY header has no end_header line", path));
      std::istringstream words(l);
      std::string first;
      words >> first;
      if (first == "end_header") {
        std::string more;
        if (words >> more)
          throw MeshError(fmt::format("{}:{}: PLY header line '{}' is not end_header", path, at, l.substr(0, 40)));
        break;
      }
      if (first != "format" && first != "comment" && first != "obj_info" && first != "element" && first != "property")
        throw MeshError(fmt::format("{}:{}: PLY header line '{}' starts with no PLY keyword", path, at,
                                    l.substr(0, 40)));
      if (first != "element") continue;
      std::istringstream in(l);
      std::string kw, name, n;
      in >> kw >> name >> n;
      const unsigned long long c = count(n, at);
      total += c;
      if (c > size || total > size)
        throw MeshError(fmt::format("{}:{}: the header claims {} {} elements; the file's {} bytes cannot hold them",
                                    path, at, c, name, size));
    }
  } else if (const bool keyword = magic.rfind("off", 0) == 0 ||
                                   (magic.size() > 3 && magic.find("off") != std::string::npos &&
                                    magic.find_first_not_of("stcn4off ") == std::string::npos);
             keyword || lower(std::filesystem::path(path).extension().string()) == ".off") {
    // counts on the keyword's line (after "OFF") or on the next one; a .off file without the keyword
    // (Assimp reads it) has them on its first line
    std::string rest = keyword ? magic.substr(magic.find("off") + 3) : magic;
    int at = magic_line;
    if (keyword && rest.find_first_not_of(" \t\r") == std::string::npos) std::tie(rest, at) = next_line(head, pos, line);
    std::istringstream in(rest);
    std::string nv, nf;
    in >> nv >> nf;
    const auto digits = [](const std::string& w) { return !w.empty() && w.find_first_not_of("0123456789") == std::string::npos; };
    if (nv.empty()) return;  // Assimp reports the malformed header
    if (!keyword && !digits(nv)) return;  // no counts: Assimp's call
    // Assimp reads the counts across line ends: a face count missing from the line may start the next one
    if (nf.empty()) std::istringstream(next_line(head, pos, line).first) >> nf;
    const unsigned long long v = count(nv, at), t = nf.empty() || (!keyword && !digits(nf)) ? 0 : count(nf, at);
    if (v > size / 6 || t > size / 6 || 6 * v + 8 * t > size)
      throw MeshError(fmt::format("{}:{}: the header claims {} vertices and {} faces; the file's {} bytes cannot "
                                  "hold them",
                                  path, at, v, t, size));
  }
}

struct CellHash {
  size_t operator()(const std::array<long long, 3>& c) const {  // unsigned: wraps, never overflows
    return std::hash<unsigned long long>()(static_cast<unsigned long long>(c[0]) * 73856093ULL ^
                                           static_cast<unsigned long long>(c[1]) * 19349663ULL ^
                                           static_cast<unsigned long long>(c[2]) * 83492791ULL);
  }
};

}  // namespace

double parse_unit(const std::string& unit) {
  if (unit == "m") return 1.0;
  if (unit == "cm") return 0.01;
  if (unit == "mm") return 0.001;
  throw MeshError(fmt::format("unknown length unit '{}' (use m, cm or mm)", unit));
}

index_t weld_vertices(SurfaceMesh& s, double tolerance) {
  for (std::size_t k = 0; k < s.vertices.size(); ++k)
    if (!std::isfinite(s.vertices[k]))
      throw MeshError(fmt::format("weld: vertex {} is not finite ({})", k / 3, s.vertices[k]));
  if (tolerance < 0) tolerance = 1e-9 * bbox_diagonal(s);
  const index_t n = s.n_vertices();
  std::vector<index_t> rep(n);
  double lo[3] = {0, 0, 0};
  for (std::size_t k = 0; k < s.vertices.size(); ++k)
    lo[k % 3] = k < 3 ? s.vertices[k] : std::min(lo[k % 3], s.vertices[k]);
  // cells are counted from the box's corner; a tolerance so small against the
  // box that the counts would leave the integers welds exact duplicates only
  if (tolerance > 0 && !(bbox_diagonal(s) / tolerance < 1e15)) tolerance = 0;
  if (tolerance > 0) {
    // Uniform grid of cell size `tolerance`: a vertex's partner lies in one of
    // the 27 cells around it.
    std::unordered_map<std::array<long long, 3>, std::vector<index_t>, CellHash> grid;
    for (index_t i = 0; i < n; ++i) {
      const Vec3<double> p = vertex(s, i);
      const std::array<long long, 3> cell{std::llround((p.x - lo[0]) / tolerance),
                                          std::llround((p.y - lo[1]) / tolerance),
                                          std::llround((p.z - lo[2]) / tolerance)};
      rep[i] = i;
      for (int dx = -1; dx <= 1 && rep[i] == i; ++dx)
        for (int dy = -1; dy <= 1 && rep[i] == i; ++dy)
          for (int dz = -1; dz <= 1 && rep[i] == i; ++dz) {
            auto it = grid.find({cell[0] + dx, cell[1] + dy, cell[2] + dz});
            if (it == grid.end()) continue;
            for (index_t j : it->second)
              if (norm(vertex(s, j) - p) <= tolerance) {
                rep[i] = j;
                break;
              }
          }
      if (rep[i] == i) grid[cell].push_back(i);
    }
  } else {  // zero tolerance: exact coordinate equality
    std::map<std::array<double, 3>, index_t> seen;
    for (index_t i = 0; i < n; ++i)
      rep[i] = seen.emplace(std::array<double, 3>{s.vertices[3 * i], s.vertices[3 * i + 1], s.vertices[3 * i + 2]}, i)
                   .first->second;
  }
  std::vector<index_t> tris;
  tris.reserve(s.triangles.size());
  index_t dropped = 0;
  for (index_t t = 0; t < s.n_triangles(); ++t) {
    const index_t a = rep[s.triangles[3 * t]], b = rep[s.triangles[3 * t + 1]], c = rep[s.triangles[3 * t + 2]];
    if (a == b || b == c || a == c) {
      ++dropped;
      continue;
    }
    tris.insert(tris.end(), {a, b, c});
  }
  s.triangles.swap(tris);
  compact_vertices(s);
  return dropped;
}

SurfaceMesh load_surface(const std::string& path, double metres_per_unit, index_t* merged) {
  if (!(metres_per_unit > 0) || !std::isfinite(metres_per_unit))
    throw MeshError(fmt::format("{}: unit scale {} m per unit must be > 0", path, metres_per_unit));
  guard_header(path);
  Assimp::Importer importer;
  const aiScene* scene = nullptr;
  try {
    scene = importer.ReadFile(path, aiProcess_JoinIdenticalVertices | aiProcess_ValidateDataStructure);
  } catch (const std::bad_alloc&) {
    throw MeshError(fmt::format("{}: cannot read the surface: the element counts in the file do not fit in memory",
                                path));
  }
  if (!scene) throw MeshError(fmt::format("{}: cannot read the surface: {}", path, importer.GetErrorString()));
  if ((scene->mFlags & AI_SCENE_FLAGS_INCOMPLETE) || !scene->mRootNode)
    throw MeshError(fmt::format("{}: the file holds no complete mesh (Assimp: {})", path,
                                *importer.GetErrorString() ? importer.GetErrorString() : "incomplete scene"));
  SurfaceMesh out;
  collect(*scene, *scene->mRootNode, aiMatrix4x4(), metres_per_unit, out, path);
  if (out.triangles.empty())
    throw MeshError(
        fmt::format("{}: the file holds no triangles ({} meshes, none with faces)", path, scene->mNumMeshes));
  const index_t raw = out.n_vertices();
  weld_vertices(out);
  if (merged) *merged = raw - out.n_vertices();
  if (out.triangles.empty()) throw MeshError(fmt::format("{}: every triangle is degenerate", path));
  return out;
}

void check_closed(const SurfaceMesh& s, const std::string& source) {
  const index_t n = s.n_vertices(), nt = s.n_triangles();
  if (nt == 0) throw MeshError(source + ": the surface has no triangles");
  if (s.triangles.size() % 3 != 0 || s.vertices.size() % 3 != 0)
    throw MeshError(source + ": vertex or corner count is not a multiple of 3");
  const double diag = bbox_diagonal(s);
  const double area_eps = 1e-14 * diag * diag;
  // directed edge (a, b) -> triangles using it; keyed by the sorted pair
  std::map<std::pair<index_t, index_t>, std::vector<std::pair<index_t, bool>>> edges;
  for (index_t t = 0; t < nt; ++t) {
    const index_t* c = &s.triangles[3 * t];
    for (int k = 0; k < 3; ++k)
      if (c[k] < 0 || c[k] >= n)
        throw MeshError(fmt::format("{}: triangle {}: corner {} refers to vertex {}, but there are {} vertices", source,
                                    t, k, c[k], n));
    if (c[0] == c[1] || c[1] == c[2] || c[0] == c[2])
      throw MeshError(fmt::format("{}: triangle {} ({}, {}, {}) repeats a vertex: degenerate triangles are not allowed",
                                  source, t, c[0], c[1], c[2]));
    const Vec3<double> p0 = vertex(s, c[0]);
    const double area = 0.5 * norm(cross(vertex(s, c[1]) - p0, vertex(s, c[2]) - p0));
    if (!(area > area_eps))
      throw MeshError(
          fmt::format("{}: triangle {} ({}, {}, {}) has zero area ({:.3g} m^2): degenerate triangles are "
                      "not allowed",
                      source, t, c[0], c[1], c[2], area));
    for (int k = 0; k < 3; ++k) {
      const index_t a = c[k], b = c[(k + 1) % 3];
      edges[{std::min(a, b), std::max(a, b)}].push_back({t, a < b});
    }
  }
  for (const auto& [e, uses] : edges) {
    if (uses.size() == 1)
      throw MeshError(fmt::format("{}: edge ({}, {}) is used by 1 triangle: the surface is open (triangle {})", source,
                                  e.first, e.second, uses[0].first));
    if (uses.size() > 2)
      throw MeshError(
          fmt::format("{}: edge ({}, {}) is used by {} triangles ({}, {}, ...): the surface is not a "
                      "manifold (each edge needs exactly 2)",
                      source, e.first, e.second, uses.size(), uses[0].first, uses[1].first));
    if (uses[0].second == uses[1].second)
      throw MeshError(
          fmt::format("{}: edge ({}, {}) is traversed in the same direction by triangles {} and {}: the "
                      "orientation is inconsistent",
                      source, e.first, e.second, uses[0].first, uses[1].first));
  }
}

double enclosed_volume(const SurfaceMesh& s) {
  double v = 0;
  for (index_t t = 0; t < s.n_triangles(); ++t) {
    const Vec3<double> a = vertex(s, s.triangles[3 * t]), b = vertex(s, s.triangles[3 * t + 1]),
                       c = vertex(s, s.triangles[3 * t + 2]);
    v += dot(a, cross(b, c));
  }
  return v / 6.0;
}

double winding_number(const SurfaceMesh& s, Vec3<double> p) {
  double sum = 0;
  for (index_t t = 0; t < s.n_triangles(); ++t) {
    const Vec3<double> a = vertex(s, s.triangles[3 * t]) - p, b = vertex(s, s.triangles[3 * t + 1]) - p,
                       c = vertex(s, s.triangles[3 * t + 2]) - p;
    const double la = norm(a), lb = norm(b), lc = norm(c);
    const double num = dot(a, cross(b, c));
    const double den = la * lb * lc + dot(a, b) * lc + dot(b, c) * la + dot(c, a) * lb;
    sum += 2 * std::atan2(num, den);
  }
  return sum / (4 * M_PI);
}

Vec3<double> interior_point(const SurfaceMesh& s, const std::string& source) {
  index_t best = -1;
  double best_area = 0;
  Vec3<double> normal{};
  for (index_t t = 0; t < s.n_triangles(); ++t) {
    const Vec3<double> a = vertex(s, s.triangles[3 * t]);
    const Vec3<double> n = cross(vertex(s, s.triangles[3 * t + 1]) - a, vertex(s, s.triangles[3 * t + 2]) - a);
    if (0.5 * norm(n) > best_area) {
      best_area = 0.5 * norm(n);
      best = t;
      normal = (1.0 / norm(n)) * n;
    }
  }
  if (best < 0) throw MeshError(source + ": the surface has no triangle of non-zero area");
  const Vec3<double> c = (1.0 / 3.0) * (vertex(s, s.triangles[3 * best]) + vertex(s, s.triangles[3 * best + 1]) +
                                        vertex(s, s.triangles[3 * best + 2]));
  for (double step = 0.1 * std::sqrt(best_area); step > 1e-6 * std::sqrt(best_area); step *= 0.5) {
    const Vec3<double> p = c - step * normal;
    if (winding_number(s, p) > 0.5) return p;
  }
  throw MeshError(source + ": found no point inside the surface (is it closed and outward?)");
}

Vec3<double> surface_extents(const SurfaceMesh& s) {
  if (s.vertices.empty()) return {0, 0, 0};
  double lo[3] = {s.vertices[0], s.vertices[1], s.vertices[2]}, hi[3] = {lo[0], lo[1], lo[2]};
  for (size_t k = 0; k < s.vertices.size(); ++k) {
    lo[k % 3] = std::min(lo[k % 3], s.vertices[k]);
    hi[k % 3] = std::max(hi[k % 3], s.vertices[k]);
  }
  return {hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]};
}

}  // namespace tissue::io
