// The Backend interface: the fixed, small set of operations the Scheduler
// runs on whichever backend is active (DESIGN.md section 4). A backend owns
// its store (host arrays or device buffers) in its own scalar type; values
// cross this interface in double. Implementations: cpu/ (TBB + Embree) and
// cuda/ (kernels); backends/registry.hpp creates them by name.
#pragma once

#include <cstdint>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/model.hpp"
#include "core/region.hpp"
#include "core/vec.hpp"

namespace tissue {

/// Result of a tool-segment query against the deformed surface.
struct Hit {
  index_t tri = -1;            ///< surface triangle hit nearest to A; -1 = no hit
  double t = 0;                ///< hit at A + t (B - A), t in [0, 1]
  double bary[2] = {0, 0};     ///< barycentric weights of the triangle's corners 1 and 2
  index_t nodes[3] = {-1, -1, -1};  ///< the triangle's nodes
  Vec3<double> u[3] = {};      ///< their displacements at the query (m)
  Vec3<double> point = {};     ///< hit point (m)
  Vec3<double> normal = {};    ///< outward unit normal of the deformed triangle
  bool hit() const { return tri >= 0; }
};

/// Reductions over the region after a batch of steps (one call per tick).
struct Reductions {
  Vec3<double> reaction = {};  ///< sum of internal forces on tool-driven nodes, driven components only (N)
  Vec3<double> internal = {};  ///< sum of internal forces on inner nodes (N): zero by construction over the
                               ///< whole mesh, minus the halo's support in a limited region; the
                               ///< equilibrium measure is the free-node residual below
  double free_force2 = 0;      ///< sum f_ac^2 over free (integrated) components of inner nodes (N^2)
  double held_force2 = 0;      ///< sum f_ac^2 over held components of inner nodes: fixed or driven (N^2)
  double kinetic = 0;          ///< 0.5 sum m_a |(u^n - u^{n-1}) / dt|^2 over region nodes (J)
  double max_disp = 0;         ///< max |u_a| over region nodes (m)
  double strain_energy = -1;   ///< sum_e V_e W(Fbar_e) over computed elements at the current u (J; plain
                               ///< tets: W(F_e)); W is DESIGN.md section 2's energy. -1 = not computed
                               ///< by this backend
  double front_disp = -1;      ///< max |u_a| over the region's front ring (Region::front; 0 when it is
                               ///< empty), the adaptive region's truncation indicator (m); -1 = not computed
  index_t bad_elem = -1;       ///< lowest element with J <= 0 or non-finite since the last reduce; -1 none
  double bad_J = 1;            ///< its J
  bool finite = true;          ///< every reduced value finite
};

/// Host<->device copies the backend made (0 for host backends).
struct TransferCounters {
  std::uint64_t h2d = 0, d2h = 0;
  std::uint64_t h2d_bytes = 0, d2h_bytes = 0;
};

/// Whole-store snapshot for output and tests (downloads; not for the tick loop).
struct Fields {
  std::vector<double> u;       ///< displacements (3 x n_nodes) m
  std::vector<double> node_p;  ///< nodal pressure (n_nodes) Pa
  std::vector<double> elem_J;  ///< J per element (n_elems), last computed value
  std::vector<double> f;       ///< internal nodal force (3 x n_nodes) N
};

class Backend {
 public:
  virtual ~Backend() = default;

  virtual std::string name() const = 0;         ///< "cpu", "cuda"
  virtual Precision precision() const = 0;
  virtual std::string device_name() const = 0;  ///< processor or GPU, for reports

  /// Loads the model (once per scene; allocates everything the loop needs)
  /// and resets the state to u = 0 with the whole mesh as region.
  virtual void upload(const TissueModel<double>& model) = 0;

  /// Replaces every displacement (u^n = u^{n-1} = given; 3 x n_nodes, m).
  virtual void set_displacements(std::span<const double> u) = 0;

  /// Flood-fills the region from seeds for depth rings (kDepthAll = whole
  /// mesh), holds the new halo at its current displacement, freezes nodes
  /// leaving the region and recomputes pass 1 over all elements. Returns
  /// the region's sizes only (a device backend keeps the lists on the
  /// device: nothing but these four counts comes back).
  virtual RegionSizes build_region(std::span<const index_t> seeds, int depth) = 0;

  /// The current region's full lists (downloads; for output and tests).
  virtual Region region() = 0;

  /// Prescribes the displacement (3 per node, m) of tool-driven nodes; these
  /// stay held until clear_driven(). Replaces the previous driven set.
  virtual void set_driven(std::span<const index_t> nodes, std::span<const double> u) = 0;
  virtual void clear_driven() = 0;

  /// set_driven with a component mask per node (a roller boundary): bit c of
  /// axes[k] (1..7) set = component c of nodes[k] is prescribed to u[3k + c];
  /// the other components are integrated. set_driven(nodes, u) is this with
  /// every mask kAllAxes. The reaction (Reductions::reaction) sums only the
  /// driven components. The default throws std::logic_error: a backend
  /// without per-component driving says so rather than driving all three.
  virtual void set_driven_axes(std::span<const index_t> nodes, std::span<const double> u,
                               std::span<const std::uint8_t> axes);

  /// The four IANP passes of DESIGN.md section 2 over the region.
  virtual void element_pressure() = 0;  ///< pass 1: J_e, p_e V_e
  virtual void nodal_pressure() = 0;    ///< pass 2: p_a
  virtual void element_forces() = 0;    ///< pass 3: Fbar, S, f_a^e
  virtual void node_update() = 0;       ///< pass 4: gather f_a, central difference, rotate u

  /// n TLED steps, each the four passes in order (backends may fuse or
  /// replay a captured graph; results are the same).
  virtual void advance(int steps) {
    for (int s = 0; s < steps; ++s) {
      element_pressure();
      nodal_pressure();
      element_forces();
      node_update();
    }
  }

  /// Segment A->B against every deformed surface triangle; nearest to A wins
  /// (ties: lowest triangle index).
  virtual Hit collide(Vec3<double> a, Vec3<double> b) = 0;

  /// Reaction, total internal force, residual parts, kinetic energy, max
  /// displacement and the bad-element flag (which it clears).
  virtual Reductions reduce() = 0;

  /// Copies the store's fields to the host (output, tests).
  virtual Fields download() = 0;

  /// Writes deformed positions X + u of all nodes as float xyz triples
  /// (n_nodes x 3) to dst: host memory for host backends, device memory for
  /// device backends (the viewer's mapped vertex buffer).
  virtual void write_positions(float* dst) = 0;

  virtual TransferCounters transfers() const { return {}; }
};

inline void Backend::set_driven_axes(std::span<const index_t>, std::span<const double>,
                                     std::span<const std::uint8_t>) {
  throw std::logic_error(name() + " backend: per-component driving (set_driven_axes) is not implemented");
}

}  // namespace tissue
