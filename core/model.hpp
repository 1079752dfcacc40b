// The read-only tissue model: reference geometry, connectivity, shape
// gradients, volumes, materials and integration constants, as one flat array
// per field (structure of arrays). Built once per scene in double precision
// by build_model(), then converted to the backend's scalar with convert().
//
// Array layouts ("component-major" keeps GPU loads coalesced):
//   per-node vectors   v[c * n_nodes + i]   (c = 0, 1, 2 for x, y, z)
//   element corners    elem_nodes[a * n_elems + e]   (a = 0..3)
//   shape gradients    dndx[k * n_elems + e]   (k = 3 * a + j, dN_a/dX_j)
#pragma once

#include <cmath>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/hd.hpp"
#include "core/material.hpp"
#include "core/store.hpp"
#include "core/tet.hpp"
#include "core/vec.hpp"

namespace tissue {

/// The law of one element set (core/material.hpp): Neo-Hookean, plus
/// optionally a tension-only fibre term and a Prony series on the
/// isochoric stress.
struct MaterialParams {
  double mu = 0;   ///< shear modulus (Pa); the instantaneous one for a viscoelastic set
  double K = 0;    ///< bulk modulus (Pa)
  double rho = 0;  ///< density (kg/m^3)
  double fibre_eta = 0;                  ///< fibre stiffness eta (Pa); 0 = no fibre term
  Vec3<double> fibre_dir = {1, 0, 0};    ///< fibre direction (reference configuration; normalised by build_model)
  int prony_terms = 0;                   ///< Prony terms (0..kMaxProny); 0 = elastic
  double prony_g[kMaxProny] = {};        ///< relative moduli g_i (> 0, sum < 1)
  double prony_tau[kMaxProny] = {};      ///< relaxation times tau_i (s, > 0)
};

/// Everything build_model() needs, in SI units, with no file format in it.
struct ModelInput {
  std::vector<double> nodes;             ///< reference positions (n_nodes x 3, xyz interleaved) m
  std::vector<index_t> tets;             ///< corner node ids (n_elems x 4)
  std::vector<index_t> elem_material;    ///< material index per element (n_elems); empty = all 0
  std::vector<MaterialParams> materials; ///< (n_materials)
  std::vector<std::uint8_t> fixed;       ///< 1 = node held at zero displacement (n_nodes); empty = none
  std::vector<std::uint8_t> fixed_axes;  ///< axis mask per node, bit c = component c held at zero (a symmetry
                                         ///< plane or roller: fix only the normal component) (n_nodes); empty = none
  double dt = 0;                         ///< requested step (s); 0 = safety * dt_crit
  double dt_safety = 0.5;                ///< fraction of dt_crit used when dt = 0
  std::optional<double> damping;         ///< mass-proportional damping alpha (1/s, >= 0); unset = 2 x the
                                         ///< lowest-mode estimate
  bool ianp = true;                      ///< improved average nodal pressure; false = plain (locking-prone) tets,
                                         ///< whose dt_crit uses 0.85 x the smallest altitude (their measured limit)
  double mass_scaling = 0;               ///< selective mass scaling budget: the most mass that may be added to the
                                         ///< elements that limit the step, as a fraction of the total mass (0 = off;
                                         ///< see choose_mass_scaling)
  double tick = 0;                       ///< haptic period (s): with mass scaling and dt = 0, dt = tick / n
  std::string source = "<model>";        ///< names the input in error messages
  std::vector<std::string> material_names;  ///< names of the materials, for messages (empty = by index)
  std::vector<double> fibre_dirs;        ///< fibre direction per element (n_elems x 3, xyz interleaved; any length
                                         ///< but 0, normalised by build_model), used for the elements whose material
                                         ///< has fibres (fibre_eta > 0) and ignored for the others; empty = each
                                         ///< element takes its material's fibre_dir (a scene's fibre field or file)
};

/// The most TLED steps one haptic tick may take (build_model,
/// align_time_step): beyond it the step count no longer fits the
/// scheduler's counters, and no run would finish.
inline constexpr double kMaxStepsPerTick = 1e9;

/// Thrown for invalid model input; the message names the source, the
/// element or node and the rule broken.
struct ModelError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// Node flags (bit set, one byte per node).
enum NodeFlag : std::uint8_t {
  kFixed = 1,     ///< held at zero displacement by a scene constraint
  kSurface = 2,   ///< a corner of a surface triangle
  kFixedX = 4,    ///< x component held at zero (symmetry plane / roller); kFixed wins
  kFixedY = 8,    ///< y component held at zero
  kFixedZ = 16,   ///< z component held at zero
};

/// Axis mask (one byte): bit c set = component c (x, y, z). kAllAxes = every component.
inline constexpr std::uint8_t kAllAxes = 7;

/// The components a node's flags hold at zero, as an axis mask: kAllAxes
/// for kFixed, else the kFixedX/Y/Z bits.
TISSUE_HD std::uint8_t fixed_axes(std::uint8_t flags) {
  return (flags & kFixed) ? kAllAxes : std::uint8_t((flags >> 2) & kAllAxes);
}

/// A node_elem entry (TissueModel::node_elem) packs an incident element and
/// the node's corner in it as element * 4 + corner: these take them apart
/// (entries are never negative: a shift and a mask, not a signed division).
/// The entry is also the (element, corner)'s force slot: the cpu's pass 4
/// reads slot `entry` of f_slot (4 per element) directly.
TISSUE_HD constexpr index_t incident_element(index_t entry) { return entry >> 2; }
TISSUE_HD constexpr int incident_corner(index_t entry) { return static_cast<int>(entry & 3); }
TISSUE_HD constexpr index_t incident_entry(index_t element, int corner) { return 4 * element + corner; }

template <class T>
struct TissueModel {
  index_t n_nodes = 0, n_elems = 0, n_tris = 0;
  index_t n_surf = 0;                ///< surface nodes (corners of surface triangles)

  // X, elem_nodes, dndx, volume, node_elem_start, node_elem, elem_slot,
  // tris, tri_elem, surf_nodes, surf_slot_start, surf_slot, node_flags (the
  // mesh) and mu, K, mass, cd_A, cd_B, cd_C (the material): one std::vector
  // each, declared in core/store.hpp with their shapes and units. Pass 3
  // writes a corner's force to its node's slot elem_slot[a * n_elems + e]
  // (node_elem[elem_slot[a * n_elems + e]] == 4 e + a), so that pass 4 sums
  // contiguous slots; the contact stage gathers a surface node's
  // triangles' proposals through surf_slot.
#define TISSUE_STORE_MEMBER(name, type, per, components, unit, what) std::vector<typename StoreTypes<T>::type> name;
  TISSUE_MODEL_ARRAYS(TISSUE_STORE_MEMBER)
#undef TISSUE_STORE_MEMBER
  // Optional terms (core/material.hpp), present only when a set uses them:
  index_t n_visco = 0;               ///< viscoelastic elements (slots)
  int n_prony = 0;                   ///< Prony terms stored per slot: the most any set gives (0..kMaxProny);
                                     ///< a set with fewer has g = 0 in the rest
  // fibre, visco_slot, prony_g, prony_tau, prony_decay, prony_gain: the law
  // arrays, one std::vector each (core/material.hpp TISSUE_LAW_MODEL_FIELDS)
#define TISSUE_LAW_MEMBER(kind, name, len) std::vector<typename LawFieldTypes<T>::kind> name;
  TISSUE_LAW_MODEL_FIELDS(TISSUE_LAW_MEMBER)
#undef TISSUE_LAW_MEMBER

  double dt = 0;            ///< time step (s)
  double dt_crit = 0;       ///< critical step min_e L_e / c_e (s)
  index_t dt_crit_elem = -1;///< element that sets dt_crit
  double damping = 0;       ///< alpha (1/s)
  double total_mass = 0;    ///< kg, physical (without mass scaling's added mass)
  double added_mass = 0;    ///< kg added by mass scaling (included in `mass`)
  index_t scaled_elems = 0; ///< elements whose density mass scaling raised
  double max_density_scale = 1;  ///< largest of their density factors
  /// With mass scaling: 2 / omega_max of the assembled lumped system at rest
  /// over the scaled elements' patch (plain tets; 0 when not computed), and
  /// the nodes given more mass to keep dt within 0.95 of it and that mass
  /// (kg, within added_mass; core/model.cpp hold_assembled_step).
  double assembled_step = 0;
  index_t assembled_nodes = 0;
  double assembled_mass = 0;
  double dt_crit_physical = 0;   ///< critical step without mass scaling (s)
  /// Each element's stable step L_e / c_e at rest with mass scaling's
  /// density (s), and its mass rho_e V_e with that density (kg): host only,
  /// the step guard's reference (core/step_guard.hpp).
  std::vector<double> elem_step, elem_mass;
  index_t reoriented = 0;   ///< inverted input tets whose corners were swapped
  bool ianp = true;         ///< pass 3 uses IANP (else plain tet forces, passes 1-2 unused)

  bool has_fibre() const { return !fibre.empty(); }
  bool has_visco() const { return n_visco > 0; }
};

/// Node a's reference position (m) from the component-major X.
template <class T>
Vec3<T> reference_position(const TissueModel<T>& m, index_t a) {
  return {m.X[a], m.X[std::size_t(m.n_nodes) + a], m.X[2 * std::size_t(m.n_nodes) + a]};
}

/// The median length of the surface triangles' edges (m) in the reference
/// configuration (0 without triangles).
template <class T>
double median_surface_edge(const TissueModel<T>& m);

/// Precomputes the model from the input; throws ModelError for zero-volume
/// tets (relative to the tet's size; coordinates whose volumes overflow or
/// underflow are named as such), two elements with the same four nodes,
/// unused nodes, bad materials, per-element fibre directions of the wrong
/// count or zero / non-finite in a fibre element (naming the element), a stable step so small that one haptic tick
/// would need more than kMaxStepsPerTick steps (naming the element, its
/// material and wave speed) or a dt above the stable limit (the message
/// names the limit and the element that sets it). Inverted tets
/// (V < 0) are reoriented by swapping corners 1 and 2 and counted.
TissueModel<double> build_model(const ModelInput& in);

/// Young's modulus E (Pa) and Poisson's ratio nu of a material, from its
/// mu and K: E = 9 K mu / (3 K + mu), nu = (3 K - 2 mu) / (2 (3 K + mu)),
/// written without the product K mu, which underflows for moduli near 1e-300.
inline double youngs_modulus(const MaterialParams& p) { return 9 * p.mu / (3 + p.mu / p.K); }
inline double poisson_ratio(const MaterialParams& p) { return (3 - 2 * p.mu / p.K) / (2 * (3 + p.mu / p.K)); }

/// The largest side of the model's bounding box (m).
double largest_extent(const TissueModel<double>& m);

/// Dilatational wave speed c = sqrt((lambda + 2 mu) / rho) of a material
/// (m/s), lambda = K - 2 mu / 3.
double wave_speed(const MaterialParams& p);

/// wave_speed(p) with the numbers it follows from, for messages: "c = sqrt((K
/// + 4 mu / 3) / rho) = sqrt((K Pa + 4 x mu Pa / 3) / rho kg/m^3) = c m/s",
/// with "+ 4 eta" and the fibre stiffness where p has a fibre term (its share
/// of the stable step, fibre_wave_modulus). Every number is printed to 4
/// significant digits, so the speed can be checked from the moduli printed.
std::string wave_speed_text(const MaterialParams& p);

/// An element's stable step L_e / c_e (s): L_e = tet_min_altitude of the tet
/// X (m) with volume V (m^3), times 0.85 for plain (non-IANP) tets (their
/// measured limit); c_e = wave_speed(p). build_model's dt_crit is the
/// smallest of these.
double element_time_step(const Vec3<double> X[4], double volume, const MaterialParams& p, bool ianp = true);

/// Selective mass scaling (the explicit-dynamics practice of LS-DYNA's and
/// Abaqus/Explicit's "mass scaling" for a target step): a few badly shaped
/// elements (slivers, with one tiny altitude) set dt_crit = min_e L_e / c_e
/// far below the typical element's. Raising the density of just those
/// elements by s_e = (need / dt_e)^2 lifts their dt_e = L_e / c_e to `need`
/// (c_e scales with 1 / sqrt(rho)); their nodes get the added mass. The
/// stiffness is untouched, so static equilibria do not change; the dynamics
/// change by the added inertia, which tissue tradeoff measures.
struct MassScaling {
  int steps = 0;            ///< TLED steps per tick chosen
  double dt = 0;            ///< s, = tick / steps
  double need = 0;          ///< s, the element step every element reaches (dt / safety)
  double added_mass = 0;    ///< kg
  index_t scaled_elems = 0;
  double max_scale = 1;     ///< largest density factor
};

/// Chooses the fewest steps per tick n whose dt = tick / n needs at most
/// budget x total_mass of added mass, with every element step lifted to
/// dt / safety. dt_e: the elements' steps L_e / c_e (s); rho_V: their masses
/// rho_e V_e (kg). n is at most the count without scaling (no mass added).
MassScaling choose_mass_scaling(const std::vector<double>& dt_e, const std::vector<double>& rho_V, double tick,
                                double safety, double budget);

/// Recomputes dt-dependent integration constants for a new step or damping
/// (checks dt against dt_crit as build_model does).
void set_time_step(TissueModel<double>& m, double dt, double damping);

/// Shortens dt (never lengthens it) so that a whole number of steps fills
/// one haptic tick: dt = tick / ceil(tick / dt). The tissue then keeps
/// time with the tool exactly.
void align_time_step(TissueModel<double>& m, double tick);

/// Lowest-mode estimate (rad/s) used for the default damping: the first
/// shear mode of a clamped-free body of the model's largest extent,
/// omega = (pi / 2) sqrt(mu / rho) / L, with the volume-weighted mean mu
/// and the mean density.
double lowest_mode_estimate(const TissueModel<double>& m);

/// IANP's nodal bulk modulus K_a (n_nodes, Pa): K of the node's elements
/// where they share one material, else their volume-weighted mean
/// sum_e K_e V_e / sum_e V_e. Pass 2 averages the elements' volume change
/// theta_a = sum_e (J_e - 1) V_e / sum_e V_e and gives the node the pressure
/// p_a = K_a theta_a: for one material this is the average of the element
/// pressures K (J_e - 1) V_e; where materials meet it is the volumetric term
/// of the nodal energy sum_a (V_a / 4) K_a theta_a^2 / 2, whose forces are
/// symmetric (averaging K_e (J_e - 1) instead couples a soft element to its
/// stiff neighbour ten times harder than the reverse, and the step diverges:
/// docs/meshing.md, inclusions).
template <class T>
std::vector<double> node_bulk_moduli(const TissueModel<T>& m) {
  std::vector<double> k(m.n_nodes, 0.0);
  for (index_t a = 0; a < m.n_nodes; ++a) {
    double kv = 0, v = 0;
    bool one = true;
    const index_t first = m.node_elem_start[a], end = m.node_elem_start[a + 1];
    for (index_t j = first; j < end; ++j) {
      const index_t e = incident_element(m.node_elem[j]);
      kv += double(m.K[e]) * double(m.volume[e]);
      v += double(m.volume[e]);
      one = one && m.K[e] == m.K[incident_element(m.node_elem[first])];
    }
    k[a] = end == first ? 0.0 : one ? double(m.K[incident_element(m.node_elem[first])]) : kv / v;
  }
  return k;
}

/// Pass 2's divisor per node, V_a / K_a (n_nodes, m^3/Pa) with V_a = sum_e
/// V_e over the node's node_elem list in stored order and in T: p_a =
/// sum_e (J_e - 1) V_e / divisor_a. Computed once per upload the same way by
/// every backend so that their nodal pressures agree to the bit.
template <class T>
std::vector<T> nodal_pressure_divisors(const TissueModel<T>& m) {
  const std::vector<double> k = node_bulk_moduli(m);
  std::vector<T> v(m.n_nodes, T(0));
  for (index_t a = 0; a < m.n_nodes; ++a) {
    for (index_t j = m.node_elem_start[a]; j < m.node_elem_start[a + 1]; ++j) v[a] += m.volume[incident_element(m.node_elem[j])];
    v[a] = v[a] / T(k[a]);
  }
  return v;
}

/// The same model in another scalar type.
template <class T>
TissueModel<T> convert(const TissueModel<double>& m);

/// The most steps a ReferenceGrid spans the mesh in: its points' integers
/// and their differences stay within 32 bits.
inline constexpr double kMaxGridSteps = 2147483646.0;  // 2^31 - 2

/// A fixed-point grid over a model's reference positions: node a lies within
/// half a step of origin + step * grid_point(a). The step is the smallest
/// power of two that spans the mesh's widest extent in at most kMaxGridSteps
/// steps, so that any two points' differences fit 32-bit integers
/// (core/tet.hpp tet_shape_gradients_on_grid; the cuda backend's float
/// passes). Rounding to the grid moves an edge by up to a step, at most
/// 2^-30 of the extent: 6e-8 of an edge 1/64 of the extent (half a float
/// ulp), up to 9e-6 of an edge 1/10,000 of it (docs/cuda.md, "Reference
/// positions on a grid").
struct ReferenceGrid {
  Vec3<double> origin = {};  ///< the mesh's lowest x, y and z (m)
  double step = 1;           ///< m
};

ReferenceGrid reference_grid(const TissueModel<double>& m);

/// Node a's reference position on the grid (rounded to the nearest step).
GridPoint grid_point(const ReferenceGrid& g, const TissueModel<double>& m, index_t a);

/// The largest gradient_deviation (core/tet.hpp) over a model's elements of
/// their recomputed gradients, and the (first) element that has it.
struct GradientDeviation {
  double deviation = 0;  ///< HUGE_VAL when an element's recomputation is not finite
  index_t elem = -1;     ///< -1: no element
};

/// How far gradients and volumes recomputed at precision p stray from the
/// model's (the cuda backend's test before it recomputes them instead of
/// loading them): in double from the double reference positions
/// (tet_shape_gradients_from), in float from the reference grid
/// (tet_shape_gradients_on_grid), as the backend's passes recompute them.
/// Stops at the first element beyond `stop_above`.
GradientDeviation worst_gradient_deviation(const TissueModel<double>& m, Precision p, double stop_above = HUGE_VAL);

}  // namespace tissue
