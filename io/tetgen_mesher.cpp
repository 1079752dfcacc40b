// TetGen runs happen in a forked child process. Reason: libtet 1.5.0 (the
// Debian package) reports an error by terminatetetgen(), which frees the
// mesh's memory pools and throws an int; the exception then unwinds through
// tetrahedralize(), whose local tetgenmesh destructor frees the same pools a
// second time and the process dies (SIGSEGV in memorypool::~memorypool) before
// any catch can run. Isolating each run turns every TetGen failure, crash or
// error code, into the child's exit status, which the parent maps to a
// MeshError. The child sends its output back through a pipe.
//
// The child must not outlive the parent: it asks the kernel for SIGKILL when
// the parent dies (PR_SET_PDEATHSIG), and while a run is in flight the
// parent's SIGINT/SIGTERM/SIGHUP handler kills the child first and then
// lets the signal take its usual course. Where that course returns (a
// command's handler that only records the request, apps/interrupt.hpp), the
// run throws MeshInterrupted naming the signal, not a TetGen crash.
#include "io/tetgen_mesher.hpp"

#include <fmt/format.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/time.h>
#include <sys/wait.h>
#include <tetgen.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <fstream>
#include <numeric>
#include <cmath>
#include <csignal>
#include <cstdlib>
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
  std::vector<double> attributes;  ///< region attribute per tet (A switch), else empty
  double peak_bytes = 0;           ///< the child's peak resident size
};

/// Exit codes of the child: 0 success, kTetgenCodeBase + TetGen's code for a
/// thrown int, kUnknownException for anything else, kPipeFailed when the
/// result could not be written.
constexpr int kTetgenCodeBase = 100;
constexpr int kUnknownException = 90;
constexpr int kPipeFailed = 91;

/// Fills TetGen's input: the surface's points and one triangular facet per
/// triangle, tagged with its triangle id + 1.
void fill_input(const SurfaceMesh& s, const std::vector<RegionSeed>& regions, tetgenio& in) {
  if (!regions.empty()) {
    in.numberofregions = int(regions.size());
    in.regionlist = new REAL[5 * regions.size()];
    for (size_t k = 0; k < regions.size(); ++k) {
      const RegionSeed& r = regions[k];
      const REAL v[5] = {r.point.x, r.point.y, r.point.z, REAL(r.attribute), 0};
      std::copy(v, v + 5, in.regionlist + 5 * k);
    }
  }
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

/// The child's work: run TetGen and stream points, tets, face tags and tet
/// attributes.
[[noreturn]] void child_run(const SurfaceMesh& s, const MeshingOptions& o, const std::string& switches, int fd,
                            pid_t parent, double address_cap) {
  ::prctl(PR_SET_PDEATHSIG, SIGKILL);
  if (::getppid() != parent) ::_exit(kUnknownException);  // the parent died before prctl
  for (int sig : {SIGINT, SIGTERM, SIGHUP}) std::signal(sig, SIG_DFL);
  // TetGen's pools grow without bound on an absurd request: past the memory
  // available, its allocation fails and it reports "out of memory".
  const rlimit limit{rlim_t(address_cap), rlim_t(address_cap)};
  ::setrlimit(RLIMIT_AS, &limit);
  int code = 0;
  try {
    tetgenio in, out;
    fill_input(s, o.regions, in);
    std::vector<char> sw(switches.begin(), switches.end());
    sw.push_back('\0');
    tetrahedralize(sw.data(), &in, &out);
    const int nf = out.trifacemarkerlist ? out.numberoftrifaces : 0;
    const bool ok = write_array(fd, out.pointlist, std::int64_t(3) * out.numberofpoints) &&
                    write_array(fd, out.tetrahedronlist, std::int64_t(out.numberofcorners) * out.numberoftetrahedra) &&
                    write_array(fd, out.trifacemarkerlist, std::int64_t(nf)) &&
                    write_array(fd, out.tetrahedronattributelist,
                                out.tetrahedronattributelist
                                    ? std::int64_t(out.numberoftetrahedronattributes) * out.numberoftetrahedra
                                    : 0);
    code = ok ? 0 : kPipeFailed;
  } catch (int tetgen_code) {
    code = kTetgenCodeBase + tetgen_code;
  } catch (const std::bad_alloc&) {
    code = kTetgenCodeBase + 1;  // TetGen's own code for "out of memory"
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

/// This process's virtual size (bytes; VmSize of /proc/self/status), 0 if unknown.
double process_virtual_size() {
  std::ifstream f("/proc/self/status");
  std::string line;
  while (std::getline(f, line))
    if (line.rfind("VmSize:", 0) == 0) return 1024.0 * std::atof(line.c_str() + 7);
  return 0;
}

/// The child of the run in flight (0 = none), for the signal handler.
std::atomic<pid_t> g_child{0};
/// The signal the handler forwarded during the run in flight (0 = none): the
/// child's end is then the user's request, not a crash.
std::atomic<int> g_forwarded{0};
struct sigaction g_previous[3];
constexpr int kForwarded[3] = {SIGINT, SIGTERM, SIGHUP};

/// Kills the child, puts the previous disposition back and re-raises: the
/// parent then ends (or handles the signal) as it would have without us.
extern "C" void kill_child_and_reraise(int sig) {
  const pid_t child = g_child.load();
  g_forwarded = sig;
  if (child > 0) ::kill(child, SIGKILL);
  for (int k = 0; k < 3; ++k)
    if (kForwarded[k] == sig) ::sigaction(sig, &g_previous[k], nullptr);
  ::raise(sig);
}

/// Installs the handler for the lifetime of one run.
struct ChildGuard {
  explicit ChildGuard(pid_t child) {
    g_child = child;
    g_forwarded = 0;
    struct sigaction sa {};
    sa.sa_handler = kill_child_and_reraise;
    sigemptyset(&sa.sa_mask);
    for (int k = 0; k < 3; ++k) ::sigaction(kForwarded[k], &sa, &g_previous[k]);
  }
  ~ChildGuard() {
    for (int k = 0; k < 3; ++k) ::sigaction(kForwarded[k], &g_previous[k], nullptr);
    g_child = 0;
  }
};

/// One TetGen run in a child process; throws MeshError on any failure.
TetgenOutput run_tetgen(const SurfaceMesh& s, const MeshingOptions& o, const std::string& switches,
                        const std::string& source) {
  int fds[2];
  if (::pipe(fds) != 0)
    throw MeshError(fmt::format("{}: cannot create a pipe for TetGen: {}", source, std::strerror(errno)));
  const pid_t parent = ::getpid();
  // the child's address-space cap: what it inherits plus the memory available
  const double address_cap = process_virtual_size() + available_memory();
  // Block the forwarded signals across fork so that none arrives between the
  // fork and the guard's installation with nobody to kill the child.
  sigset_t block, old_mask;
  sigemptyset(&block);
  for (int sig : kForwarded) sigaddset(&block, sig);
  ::pthread_sigmask(SIG_BLOCK, &block, &old_mask);
  const pid_t pid = ::fork();
  if (pid < 0) {
    ::pthread_sigmask(SIG_SETMASK, &old_mask, nullptr);
    ::close(fds[0]);
    ::close(fds[1]);
    throw MeshError(fmt::format("{}: cannot start TetGen (fork): {}", source, std::strerror(errno)));
  }
  if (pid == 0) {
    ::pthread_sigmask(SIG_SETMASK, &old_mask, nullptr);
    ::close(fds[0]);
    child_run(s, o, switches, fds[1], parent, address_cap);
  }
  ChildGuard guard(pid);
  ::pthread_sigmask(SIG_SETMASK, &old_mask, nullptr);
  ::close(fds[1]);
  TetgenOutput out;
  const bool read_ok = read_array(fds[0], out.points) && read_array(fds[0], out.tets) &&
                       read_array(fds[0], out.face_tags) && read_array(fds[0], out.attributes);
  ::close(fds[0]);
  int status = 0;
  rusage usage{};
  while (::wait4(pid, &status, 0, &usage) < 0 && errno == EINTR) {
  }
  out.peak_bytes = 1024.0 * double(usage.ru_maxrss);
  if (const int sig = g_forwarded.load(); sig != 0)  // a handler that returned (a command's InterruptGuard)
    throw MeshInterrupted(sig, fmt::format("{}: meshing interrupted by {}: the TetGen run in progress was stopped",
                                           source, sig == SIGINT    ? "SIGINT"
                                                       : sig == SIGTERM ? "SIGTERM"
                                                                        : "SIGHUP"));
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
  const TetgenOutput d = run_tetgen(s, {}, "pzQd", source);
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
  m.peak_bytes = o.peak_bytes;
  const size_t n_tets = o.tets.size() / 4;
  if (!o.attributes.empty()) {
    const size_t per = o.attributes.size() / std::max<size_t>(1, n_tets);
    for (size_t e = 0; e < n_tets; ++e) m.tet_region.push_back(int(std::lround(o.attributes[per * e])));
  }
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
  VolumeMesh m = to_volume_mesh(run_tetgen(s, o, tetgen_switches(o, source), source), source);
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
    const auto start = std::chrono::steady_clock::now();
    VolumeMesh m = mesh_once(s, o, source);
    ++runs;
    const double n = m.n_tets();
    if (o.progress)
      o.progress(fmt::format("tetgen run {} (at most {}): max volume {:.3g} mm^3 -> {} tets (target {}), {:.1f} s, "
                             "{:.0f} MB",
                             runs, kTargetRounds, 1e9 * a, m.n_tets(), o.target_tets,
                             std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(),
                             m.peak_bytes / 1e6));
    if (best.tets.empty() || std::fabs(n - target) < std::fabs(best.n_tets() - target)) best = std::move(m);
    if (std::fabs(n - target) <= kTargetTolerance * target) break;
    if (n > target && prev_n == n) break;  // the surface alone forces this many: larger tets change nothing
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
  if (!(o.min_dihedral >= 0 && o.min_dihedral <= 30))
    throw MeshError(fmt::format("{}: minimum dihedral angle {} degrees must be in [0, 30] (TetGen may not terminate "
                                "above)",
                                source, o.min_dihedral));
  if (o.optimise < 0 || o.optimise > 10)
    throw MeshError(fmt::format("{}: optimisation level {} must be in 0..10", source, o.optimise));
  if (o.quality > 0) sw += fmt::format("q{:.6g}", o.quality);
  if (o.quality > 0 && o.min_dihedral > 0) sw += fmt::format("/{:.6g}", o.min_dihedral);
  if (o.optimise != 2) sw += fmt::format("O{}", o.optimise);
  if (o.max_volume > 0) sw += fmt::format("a{:.9g}", o.max_volume);
  if (!o.regions.empty()) sw += "A";
  return sw;
}

VolumeMesh tetrahedralize_surface(const SurfaceMesh& surface, const MeshingOptions& options,
                                  const std::string& source) {
  if (options.target_tets < 0)
    throw MeshError(fmt::format("{}: target tet count {} must be >= 0 (0 = off)", source, options.target_tets));
  tetgen_switches(options, source);  // validates the options before any work
  if (options.target_tets > 0)
    check_tet_memory(options.target_tets, kBytesPerTet, fmt::format("a target of {} tets", options.target_tets),
                     source);
  else if (options.max_volume > 0)
    check_tet_memory(std::fabs(enclosed_volume(surface)) / options.max_volume, kBytesPerTet,
                     fmt::format("--max-volume {:g} m^3", options.max_volume), source);
  for (const RegionSeed& r : options.regions)
    if (r.attribute <= 0 || !std::isfinite(r.point.x + r.point.y + r.point.z))
      throw MeshError(fmt::format("{}: region attribute {} must be > 0 with a finite seed point", source, r.attribute));
  check_closed(surface, source);
  check_self_intersection(surface, source);
  VolumeMesh m;
  if (options.target_tets > 0) {
    m = mesh_to_target(surface, options, source);  // (it reports each run)
  } else {
    m = mesh_once(surface, options, source);
    if (options.progress) options.progress(fmt::format("tetgen: {} tets, {:.0f} MB", m.n_tets(), m.peak_bytes / 1e6));
  }
  sort_for_locality(m);
  return m;
}

void check_tet_memory(double tets, double bytes_per_tet, const std::string& what, const std::string& source) {
  const double need = tets * bytes_per_tet, have = available_memory();
  if (need > have)
    throw MeshError(fmt::format(
        "{}: {} means about {:.3g} million tets, which need about {:.3g} GB of memory ({} bytes per tet); only "
        "{:.3g} GB are available: ask for fewer tets",
        source, what, tets / 1e6, need / 1e9, bytes_per_tet, have / 1e9));
}

double available_memory() {
  std::ifstream f("/proc/meminfo");
  std::string key;
  double kb = 0;
  std::string unit;
  while (f >> key >> kb >> unit)
    if (key == "MemAvailable:") return 1024.0 * kb;
  return double(::sysconf(_SC_PHYS_PAGES)) * double(::sysconf(_SC_PAGESIZE));
}

namespace {

/// x in [0, 1] quantised to 21 bits, spread to every third bit.
std::uint64_t spread_bits(double x) {
  std::uint64_t v = static_cast<std::uint64_t>((x > 0 ? std::min(x, 1.0) : 0.0) * double((1u << 21) - 1));
  v = (v | v << 32) & 0x1f00000000ffffull;
  v = (v | v << 16) & 0x1f0000ff0000ffull;
  v = (v | v << 8) & 0x100f00f00f00f00full;
  v = (v | v << 4) & 0x10c30c30c30c30c3ull;
  v = (v | v << 2) & 0x1249249249249249ull;
  return v;
}

/// The order (new -> old) that sorts items by key, ties kept in their old order.
std::vector<index_t> order_by(const std::vector<std::uint64_t>& key) {
  std::vector<index_t> order(key.size());
  std::iota(order.begin(), order.end(), index_t(0));
  std::stable_sort(order.begin(), order.end(), [&](index_t a, index_t b) { return key[a] < key[b]; });
  return order;
}

}  // namespace

void sort_for_locality(VolumeMesh& m) {
  const index_t n = m.n_nodes(), ne = m.n_tets();
  if (!m.tet_region.empty() && m.tet_region.size() != std::size_t(ne))
    throw MeshError(fmt::format("sort_for_locality: {} region attributes for {} tets", m.tet_region.size(), ne));
  if (n == 0 || !std::all_of(m.nodes.begin(), m.nodes.end(), [](double x) { return std::isfinite(x); }))
    return;  // (nothing to order; a non-finite position is the caller's to report)
  Vec3<double> lo = m.node(0), hi = lo;
  for (index_t i = 1; i < n; ++i) {
    const Vec3<double> x = m.node(i);
    for (int c = 0; c < 3; ++c) {
      lo[c] = std::min(lo[c], x[c]);
      hi[c] = std::max(hi[c], x[c]);
    }
  }
  const double size = std::max({hi.x - lo.x, hi.y - lo.y, hi.z - lo.z, 1e-300});
  const auto key = [&](Vec3<double> x) {  // Morton: x in the lowest bit of each triple
    return spread_bits((x.x - lo.x) / size) | spread_bits((x.y - lo.y) / size) << 1 |
           spread_bits((x.z - lo.z) / size) << 2;
  };
  std::vector<std::uint64_t> node_key(n);
  for (index_t i = 0; i < n; ++i) node_key[i] = key(m.node(i));
  const std::vector<index_t> node_order = order_by(node_key);
  std::vector<index_t> new_id(n);
  std::vector<double> nodes(m.nodes.size());
  for (index_t k = 0; k < n; ++k) {
    new_id[node_order[k]] = k;
    std::copy_n(&m.nodes[3 * node_order[k]], 3, &nodes[3 * k]);
  }
  m.nodes = std::move(nodes);
  std::vector<std::uint64_t> tet_key(ne);
  for (index_t e = 0; e < ne; ++e) {
    Vec3<double> g{0, 0, 0};
    for (int a = 0; a < 4; ++a) {
      index_t& c = m.tets[4 * e + a];
      c = new_id[c];
      g = g + 0.25 * m.node(c);
    }
    tet_key[e] = key(g);
  }
  const std::vector<index_t> tet_order = order_by(tet_key);
  std::vector<index_t> tets(m.tets.size());
  std::vector<int> region(m.tet_region.size());
  for (index_t k = 0; k < ne; ++k) {
    std::copy_n(&m.tets[4 * tet_order[k]], 4, &tets[4 * k]);
    if (!region.empty()) region[k] = m.tet_region[tet_order[k]];
  }
  m.tets = std::move(tets);
  m.tet_region = std::move(region);
}

double total_volume(const VolumeMesh& m) {
  double v = 0;
  for (index_t e = 0; e < m.n_tets(); ++e) {
    Vec3<double> X[4];
    for (int a = 0; a < 4; ++a) X[a] = m.node(m.tets[4 * e + a]);
    double dN[12];
    v += tet_shape_gradients(X, dN);
  }
  return v;
}

}  // namespace tissue::io
