// Cutting a tetrahedral mesh along the surface a blade sweeps
// (docs/cutting.md). The blade is a straight edge moved along a straight
// path; the surface it sweeps is the parallelogram
//     o + s a + t b,  s, t in [0, 1]
// (a: the blade's edge, b: its motion). The mesh is separated there without
// deleting an element, so its volume, and so its mass, is kept:
//  1. snap (CutMethod::Snap, SnapSplit): nodes closer to the cut's plane
//     than `snap` times their shortest edge move onto the plane (beyond the
//     parallelogram too, where step 2 may split elements), one at a time, unless that would leave one of their
//     elements under `keep` of its volume: an interior node along the
//     plane's normal (the mesh's volume is kept), a surface node along the
//     surface, where its faces turn less than 20 degrees from its normal
//     (a flat face keeps the volume exactly, a smooth organ to second
//     order in the move: 4e-10 of the kidney's); nodes on the surface's
//     edges and corners stay;
//  2. split (CutMethod::Split, SnapSplit): every element that the plane
//     still crosses over the parallelogram (nodes strictly on both sides;
//     its cut polygon's centroid over it) is split along the plane: a node
//     on each crossed edge (shared by the elements of that edge), and the
//     pieces (a tet, a prism, a pyramid) into tetrahedra, the prisms' and
//     pyramids' quadrilateral faces by the diagonal from their lowest node
//     id, so that neighbours agree (Dompierre et al., 1999);
//  3. separate: every interior face lying on the plane (three nodes on it)
//     whose centroid is over the parallelogram is cut; each node of a cut
//     face is copied once per group of its elements that stay joined
//     through faces that are not cut, so the cut opens there and the
//     tissue stays whole around the cut's edges (a partial incision).
// A node that stays within `touch` of its shortest edge from the plane
// (a surface node, or one whose snap was refused) counts as lying on it:
// the cut then passes through the node, a little off the plane, rather than
// splitting its edges a sliver's width from it.
// With Snap alone, an element that the plane crosses away from its nodes
// is left whole (counted in CutResult::unresolved): the tissue stays joined
// through it. The new nodes and elements come after the old ones; each
// keeps where it came from, so a caller carries materials, supports and
// state over.
#pragma once

#include <array>
#include <functional>
#include <span>
#include <stdexcept>
#include <vector>

#include "core/hd.hpp"
#include "core/vec.hpp"

namespace tissue {

/// The surface a blade sweeps: origin + s edge + t sweep, s, t in [0, 1] (m).
struct CutSurface {
  Vec3<double> origin = {0, 0, 0};
  Vec3<double> edge = {0, 0, 0};   ///< the blade's edge (m)
  Vec3<double> sweep = {0, 0, 0};  ///< the blade's motion while it cuts (m)
};

enum class CutMethod { Snap, Split, SnapSplit };

/// The defaults: the best of those measured on three cuts of the kidney
/// (docs/cutting.md).
struct CutOptions {
  CutMethod method = CutMethod::SnapSplit;
  double snap = 0.5;   ///< snap distance: this fraction of a node's shortest edge
  double keep = 0.5;   ///< a snap may leave each of the node's elements no smaller than this fraction of its volume
  double touch = 0.3;  ///< a node (not snapped) this close to the plane, a fraction of its shortest edge, counts as on it
};

/// A bad cut (zero-length blade, a cut that meets no element); the message names the rule.
struct CutError : std::invalid_argument {
  using std::invalid_argument::invalid_argument;
};

/// The cut mesh. Node i is (1 - weight[i]) X[from[i][0]] + weight[i]
/// X[from[i][1]] of the input's nodes X (after snapping: `snapped` of them
/// moved onto the plane): a kept or copied node has from = {k, k}, weight
/// 0; a node made on an edge lies between its two ends.
struct CutResult {
  std::vector<double> nodes;                 ///< x y z per node (m)
  std::vector<index_t> tets;                 ///< 4 per element, positively oriented
  std::vector<std::array<index_t, 2>> from;  ///< per node: the input nodes it lies between
  std::vector<double> weight;                ///< per node: its place between them
  std::vector<index_t> element_from;         ///< per element: the input element it is (part of)
  index_t snapped = 0;                       ///< nodes moved onto the plane
  index_t split = 0;                         ///< input elements split along the plane
  index_t edge_nodes = 0;                    ///< nodes made on crossed edges
  index_t copies = 0;                        ///< nodes copied to open the cut
  index_t cut_faces = 0;                     ///< interior faces opened
  index_t unresolved = 0;                    ///< elements the plane crosses, left whole (Snap)
  index_t n_nodes() const { return static_cast<index_t>(nodes.size() / 3); }
  index_t n_elements() const { return static_cast<index_t>(tets.size() / 4); }
};

/// Cuts the mesh (x y z per node, 4 node ids per positively oriented
/// tetrahedron) along `cut`. Throws CutError for a blade edge or sweep of
/// zero length or along one another, options out of range, or a cut
/// surface that crosses no element.
CutResult cut_along(std::span<const double> nodes, std::span<const index_t> tets, const CutSurface& cut,
                   const CutOptions& options = {});

/// Where a cut of a moving mesh is given and made (cut_moving).
enum class CutSpace {
  Deformed,   ///< on the positions x = X + u: where the tissue is now
  Reference,  ///< on the reference positions X (a blade's stroke, mapped back: pull_back)
};

/// A cut of a mesh in motion: cut_along on the deformed positions x = X + u
/// (or on X itself, CutSpace::Reference), its nodes then taken to the
/// reference configuration through the elements' own maps, which are affine
/// (linear tetrahedra):
/// every node of the cut mesh gets the old mesh's fields X, u and u_prev at
/// one place of the old mesh. A node made on an edge at weight w takes
/// (1 - w) of one end's and w of the other's; a snapped node takes them at
/// its new place, barycentrically from the element of its star that holds
/// it (its nearest point there when rounding leaves it outside) or, on the
/// surface, from the nearest of its boundary faces, so that the reference
/// mesh keeps the old boundary and its volume (the mass). Its deformed place
/// is then X + u, within rounding of where cut_along put it inside, and a
/// surface node's is on the surface as it is now. (u and u_prev are
/// component-major, 3 x n_nodes, as a backend's download; `nodes`
/// interleaved x y z per node.)
struct MovingCut {
  CutResult cut;              ///< cut.nodes: the reference positions of the cut mesh
  std::vector<double> u;      ///< u^n of the cut mesh (3 x its n_nodes, component-major)
  std::vector<double> u_prev; ///< u^(n-1), likewise
  /// How the cut mesh's fields come from the old mesh's, as a linear map
  /// fixed by the cut: u and u_prev above are it applied to the u and
  /// u_prev given. A cut prepared while the simulation runs on applies it
  /// to the motion of the moment it takes effect (Session's deferred cut).
  struct Transfer {
    /// The places of the old mesh the new nodes take their fields at: place
    /// p is sum over k in [start[p], start[p + 1]) of weight[k] f(node[k]).
    std::vector<index_t> start, node;
    std::vector<double> weight;
    /// Per new node: its two places and its weight between them (1 - w of
    /// the first, w of the second; one place for a kept or snapped node).
    std::vector<std::array<index_t, 2>> between;
    std::vector<double> w;
    index_t n_old = 0;
    /// A field of the old mesh (3 x n_old, component-major) on the cut
    /// mesh (3 x its n_nodes). Throws std::invalid_argument for a field of
    /// another size.
    std::vector<double> operator()(std::span<const double> field) const;
  } transfer;
};
MovingCut cut_moving(std::span<const double> nodes, std::span<const index_t> tets, std::span<const double> u,
                     std::span<const double> u_prev, const CutSurface& cut, const CutOptions& options = {},
                     CutSpace space = CutSpace::Deformed);

/// The reference position of the material point at deformed position p,
/// p - u(p): through the map of the element that holds p (the one whose
/// smallest barycentric weight is largest); outside the mesh, p less the
/// displacement of that element's nearest point. `nodes` interleaved, u
/// component-major, as cut_moving's.
Vec3<double> pull_back(std::span<const double> nodes, std::span<const index_t> tets, std::span<const double> u,
                       Vec3<double> p);

/// Each surface triangle's twin: another triangle on the same corner positions, or -1. A cut turns an
/// interior face into two such twins (its nodes copied at the same reference place), so a cut's faces are
/// the triangles with a twin. `tris` holds corner k of triangle t at k * n_tris + t (TissueModel::tris),
/// `position(a)` node a's reference position.
std::vector<index_t> twin_triangles(std::span<const index_t> tris,
                                    const std::function<Vec3<double>(index_t)>& position);

}  // namespace tissue
