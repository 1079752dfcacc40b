// TetGen runs happen in a forked child process. Reason: libtet 1.5.0 (the
// Debian package) reports an error by terminatetetgen(), which frees the
// mesh's memory pools and throws an int; the exception then unwinds through
// tetrahedralize(), whose local tetgenmesh destructor frees the same pools a
// second time and the process dies (SIGSEGV in memorypool::~memorypool) before
// any catch can run. Isolating each run turns every TetGen failure, crash or
// error code, into the child's exit status, which the parent maps to a
// MeshError. The child sends its output back through a pipe.
#include "io/tetgen_mesher.hpp"

#include <fmt/format.h>
#include <sys/wait.h>
#include <tetgen.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <csignal>
#include <cstring>
#include <utility>

#include "core/tet.hpp"

namespace tissue::io {
namespace {

/// What one TetGen run returned.
struct TetgenOutput {
  std::vector<double> points;      ///< (n x 3) m
  std::vector<index_t> tets;       ///< (n_tets x 4)
  std::vector<index_t> face_tags;  ///< facet marker of each output face (d switch: the intersecting input faces)
};

/// Exit codes of the child: 0 success, kTetgenCodeBase + TetGen's code for a
/// thrown int, kUnknownException for anything else, kPipeFailed when the
/// result could not be written.
constexpr int kTetgenCodeBase = 100;
constexpr int kUnknownException = 90;
constexpr int kPipeFailed = 91;

/// Fills TetGen's input: the surface's points and one triangular facet per
/// triangle, tagged with its triangle id + 1.
void fill_input(const SurfaceMesh& s, tetgenio& in) {
  in.firstnumber = 0;
  in.numberofpoints = s.n_vertices();
  in.pointlist = new REAL[s.vertices.size()];
  for (size_t k = 0; k < s.vertices.size(); ++k) in.pointlist[k] = s.vertices[k];
  const index_t nf = s.n_triangles();
  in.numberoffacets = nf;
  in.facetlist = new tetgenio::facet[nf];
  in.facetmarkerlist = new int[nf];
  for (index_t f = 0; f < nf; ++f) {
    tetgenio::facet& facet = in.facetlist[f];
    tetgenio::init(&facet);
    facet.numberofpolygons = 1;
    facet.polygonlist = new tetgenio::polygon[1];
    tetgenio::init(&facet.polygonlist[0]);
    facet.polygonlist[0].numberofvertices = 3;
    facet.polygonlist[0].vertexlist = new int[3];
    for (int k = 0; k < 3; ++k) facet.polygonlist[0].vertexlist[k] = s.triangles[3 * f + k];
    in.facetmarkerlist[f] = f + 1;
  }
}

bool write_all(int fd, const void* data, size_t bytes) {
  const char* p = static_cast<const char*>(data);
  while (bytes > 0) {
    const ssize_t w = ::write(fd, p, bytes);
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) return false;
    p += w;
    bytes -= static_cast<size_t>(w);
  }
  return true;
}

template <class T>
bool write_array(int fd, const T* data, std::int64_t count) {
  return write_all(fd, &count, sizeof count) && write_all(fd, data, sizeof(T) * size_t(count));
}

/// The child's work: run TetGen and stream points, tets and face tags.
[[noreturn]] void child_run(const SurfaceMesh& s, const std::string& switches, int fd) {
  int code = 0;
  try {
    tetgenio in, out;
    fill_input(s, in);
    std::vector<char> sw(switches.begin(), switches.end());
    sw.push_back('\0');
    tetrahedralize(sw.data(), &in, &out);
    const int nf = out.trifacemarkerlist ? out.numberoftrifaces : 0;
    const bool ok = write_array(fd, out.pointlist, std::int64_t(3) * out.numberofpoints) &&
                    write_array(fd, out.tetrahedronlist, std::int64_t(out.numberofcorners) * out.numberoftetrahedra) &&
                    write_array(fd, out.trifacemarkerlist, std::int64_t(nf));
    code = ok ? 0 : kPipeFailed;
  } catch (int tetgen_code) {
    code = kTetgenCodeBase + tetgen_code;
  } catch (...) {
    code = kUnknownException;
  }
  ::close(fd);
  ::_exit(code);  // no atexit handlers, no stdio flush: the parent owns those
}

bool read_all(int fd, void* data, size_t bytes) {
  char* p = static_cast<char*>(data);
  while (bytes > 0) {
    const ssize_t r = ::read(fd, p, bytes);
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) return false;
    p += r;
    bytes -= static_cast<size_t>(r);
  }
  return true;
}

template <class T>
bool read_array(int fd, std::vector<T>& v) {
  std::int64_t count = 0;
  if (!read_all(fd, &count, sizeof count) || count < 0 || count > (std::int64_t(1) << 34)) return false;
  v.resize(size_t(count));
  return read_all(fd, v.data(), sizeof(T) * size_t(count));
}

/// What a TetGen error code means, in words.
std::string tetgen_reason(int code) {
  switch (code) {
    case 1:
      return "TetGen ran out of memory (use a larger maximum volume or a smaller target)";
    case 2:
      return "TetGen hit an internal error (often a nearly self-touching or degenerate surface)";
    case 3:
      return "the surface intersects itself";
    case 4:
      return "the surface has a feature smaller than TetGen's tolerance (vertices or edges almost touching)";
    case 5:
      return "two surface facets are too close to each other (almost touching)";
    case 10:
      return "TetGen rejected the input (invalid facet or point data)";
    default:
      return fmt::format("TetGen failed with code {}", code);
  }
}

/// One TetGen run in a child process; throws MeshError on any failure.
TetgenOutput run_tetgen(const SurfaceMesh& s, const std::string& switches, const std::string& source) {
  int fds[2];
  if (::pipe(fds) != 0)
    throw MeshError(fmt::format("{}: cannot create a pipe for TetGen: {}", source, std::strerror(errno)));
  const pid_t pid = ::fork();
  if (pid < 0) {
    ::close(fds[0]);
    ::close(fds[1]);
    throw MeshError(fmt::format("{}: cannot start TetGen (fork): {}", source, std::strerror(errno)));
  }
  if (pid == 0) {
    ::close(fds[0]);
    child_run(s, switches, fds[1]);
  }
  ::close(fds[1]);
  TetgenOutput out;
  const bool read_ok =
      read_array(fds[0], out.points) && read_array(fds[0], out.tets) && read_array(fds[0], out.face_tags);
  ::close(fds[0]);
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  if (WIFSIGNALED(status))
    throw MeshError(fmt::format("{}: TetGen crashed (signal {}, {}) with switches '{}'", source, WTERMSIG(status),
                                strsignal(WTERMSIG(status)), switches));
  const int code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  if (code >= kTetgenCodeBase) throw MeshError(source + ": " + tetgen_reason(code - kTetgenCodeBase));
  if (code != 0 || !read_ok)
    throw MeshError(fmt::format("{}: TetGen run failed (exit status {}) with switches '{}'", source, code, switches));
  return out;
}

/// Runs TetGen's self-intersection detection (d switch); throws naming the
/// first pair of intersecting input triangles.
void check_self_intersection(const SurfaceMesh& s, const std::string& source) {
  const TetgenOutput d = run_tetgen(s, "pzQd", source);
  if (d.face_tags.empty()) return;
  std::vector<index_t> tris;
  for (index_t tag : d.face_tags)
    if (tag > 0) tris.push_back(tag - 1);
  std::sort(tris.begin(), tris.end());
  tris.erase(std::unique(tris.begin(), tris.end()), tris.end());
  std::string which = fmt::format(" ({} triangles involved", tris.size());
  for (size_t k = 0; k < std::min<size_t>(tris.size(), 4); ++k)
    which += fmt::format("{}{}", k == 0 ? ", e.g. " : ", ", tris[k]);
  which += ")";
  throw MeshError(source + ": the surface intersects itself" + which);
}

/// Volume mesh from TetGen's output: drops unused points and turns every tet
/// positive (swapping corners 1 and 2); throws on a zero-volume tet.
VolumeMesh to_volume_mesh(const TetgenOutput& o, const std::string& source) {
  VolumeMesh m;
  const index_t np = static_cast<index_t>(o.points.size() / 3);
  std::vector<index_t> map(np, -1);
  m.tets.reserve(o.tets.size());
  for (size_t e = 0; e < o.tets.size() / 4; ++e) {
    index_t c[4];
    Vec3<double> X[4];
    for (int a = 0; a < 4; ++a) {
      c[a] = o.tets[4 * e + a];
      if (c[a] < 0 || c[a] >= np)
        throw MeshError(fmt::format("{}: TetGen returned tet {} with node {} of {}", source, e, c[a], np));
      X[a] = {o.points[3 * c[a]], o.points[3 * c[a] + 1], o.points[3 * c[a] + 2]};
    }
    double dN[12];
    const double V = tet_shape_gradients(X, dN);
    if (V == 0) throw MeshError(fmt::format("{}: TetGen returned tet {} with zero volume", source, e));
    if (V < 0) std::swap(c[1], c[2]);
    for (int a = 0; a < 4; ++a) {
      if (map[c[a]] < 0) {
        map[c[a]] = m.n_nodes();
        m.nodes.insert(m.nodes.end(), o.points.begin() + 3 * c[a], o.points.begin() + 3 * c[a] + 3);
      }
      m.tets.push_back(map[c[a]]);
    }
  }
  if (m.tets.empty()) throw MeshError(source + ": TetGen produced no tetrahedra");
  return m;
}

VolumeMesh mesh_once(const SurfaceMesh& s, const MeshingOptions& o, const std::string& source) {
  VolumeMesh m = to_volume_mesh(run_tetgen(s, tetgen_switches(o, source), source), source);
  m.max_volume = o.max_volume;
  m.runs = 1;
  return m;
}

/// The target-count iteration: a power law n ~ c a^beta fitted through the
/// last two runs (beta = -1 until there are two, clamped to [-2, -0.3]).
VolumeMesh mesh_to_target(const SurfaceMesh& s, MeshingOptions o, const std::string& source) {
  const double target = o.target_tets;
  double a = std::fabs(enclosed_volume(s)) / target;
  double beta = -1;
  double prev_a = 0, prev_n = 0;
  VolumeMesh best;
  int runs = 0;
  for (int round = 0; round < kTargetRounds; ++round) {
    o.max_volume = a;
    VolumeMesh m = mesh_once(s, o, source);
    ++runs;
    const double n = m.n_tets();
    if (best.tets.empty() || std::fabs(n - target) < std::fabs(best.n_tets() - target)) best = std::move(m);
    if (std::fabs(n - target) <= kTargetTolerance * target) break;
    if (prev_a > 0 && prev_n != n && prev_a != a)
      beta = std::clamp(std::log(n / prev_n) / std::log(a / prev_a), -2.0, -0.3);
    prev_a = a;
    prev_n = n;
    a *= std::pow(target / n, 1.0 / beta);
  }
  best.runs = runs;
  return best;
}

}  // namespace

std::string tetgen_switches(const MeshingOptions& o, const std::string& source) {
  std::string sw = "pzQ";
  if (!(o.quality == 0 || o.quality >= 1.0) || !std::isfinite(o.quality))
    throw MeshError(
        fmt::format("{}: quality (radius-edge ratio) {} must be >= 1, or 0 for none (TetGen may not "
                    "terminate below 1)",
                    source, o.quality));
  if (!(o.max_volume >= 0) || !std::isfinite(o.max_volume))
    throw MeshError(fmt::format("{}: maximum tet volume {} m^3 must be >= 0 (0 = none)", source, o.max_volume));
  if (o.quality > 0) sw += fmt::format("q{:.6g}", o.quality);
  if (o.max_volume > 0) sw += fmt::format("a{:.9g}", o.max_volume);
  return sw;
}

VolumeMesh tetrahedralize_surface(const SurfaceMesh& surface, const MeshingOptions& options,
                                  const std::string& source) {
  if (options.target_tets < 0)
    throw MeshError(fmt::format("{}: target tet count {} must be >= 0 (0 = off)", source, options.target_tets));
  tetgen_switches(options, source);  // validates the options before any work
  check_closed(surface, source);
  check_self_intersection(surface, source);
  if (options.target_tets > 0) return mesh_to_target(surface, options, source);
  return mesh_once(surface, options, source);
}

double total_volume(const VolumeMesh& m) {
  double v = 0;
  for (index_t e = 0; e < m.n_tets(); ++e) {
    Vec3<double> X[4];
    for (int a = 0; a < 4; ++a) {
      const index_t c = m.tets[4 * e + a];
      X[a] = {m.nodes[3 * c], m.nodes[3 * c + 1], m.nodes[3 * c + 2]};
    }
    double dN[12];
    v += tet_shape_gradients(X, dN);
  }
  return v;
}

}  // namespace tissue::io
