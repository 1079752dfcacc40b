#include "scene/validate.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>
#include <string_view>
#include <tuple>
#include <utility>
#include <vector>

#include "scene/constraints.hpp"
#include "scene/fibre_field.hpp"

namespace tissue::scene {
namespace {

[[noreturn]] void fail(const Scene& s, int line, const std::string& what) {
  throw SceneError(location(s, line) + ": " + what);
}

/// Throws unless `value` is finite; `what` names the owner, `field` the number.
void check_finite(const Scene& s, int line, const std::string& what, std::string_view field, double value) {
  if (!std::isfinite(value)) fail(s, line, fmt::format("{}: {} = {} is not a finite number", what, field, value));
}

index_t node_count(const Scene& s) {
  return static_cast<index_t>(s.nodes.size() / 3);
}
index_t elem_count(const Scene& s) {
  return static_cast<index_t>(s.tets.size() / 4);
}

// ---- mesh ------------------------------------------------------------------

void check_mesh(const Scene& s) {
  const int ln = s.mesh_line;
  if (s.nodes.size() % 3 != 0)
    fail(s, ln, fmt::format("mesh: {} node coordinates is not a multiple of 3 (x y z per node)", s.nodes.size()));
  if (s.tets.size() % 4 != 0)
    fail(s, ln,
         fmt::format("mesh: {} element corners is not a multiple of 4 (4 node ids per tetrahedron)", s.tets.size()));
  if (s.nodes.empty()) fail(s, ln, "mesh: no nodes; the mesh needs at least the 4 corners of one tetrahedron");
  if (s.tets.empty()) fail(s, ln, "mesh: no elements; the mesh needs at least one tetrahedron");
  for (size_t k = 0; k < s.nodes.size(); ++k)
    if (!std::isfinite(s.nodes[k]))
      fail(s, ln,
           fmt::format("mesh: node {} coordinate {} = {} is not a finite number", k / 3, "xyz"[k % 3], s.nodes[k]));
  // one node far beyond the others on an axis (a stray coordinate: 1e308 for 0.02): named, before the
  // mesh's size it would set misleads every later check
  const std::size_t count = s.nodes.size() / 3;
  const auto at = [&](std::size_t a, int c) { return s.nodes[3 * a + c]; };
  for (int c = 0; c < 3 && count >= 4; ++c) {
    std::vector<std::size_t> order(count);  // the two lowest and the two highest on this axis
    std::iota(order.begin(), order.end(), std::size_t(0));
    const auto below = [&](std::size_t p, std::size_t q) { return at(p, c) < at(q, c); };
    std::nth_element(order.begin(), order.begin() + 1, order.end(), below);
    std::nth_element(order.begin() + 2, order.end() - 2, order.end(), below);
    const std::size_t lo = order[0], lo2 = order[1], hi2 = order[count - 2], hi = order[count - 1];
    for (const auto& [stray, gap, others] : {std::tuple{hi, at(hi, c) - at(hi2, c), at(hi2, c) - at(lo, c)},
                                            std::tuple{lo, at(lo2, c) - at(lo, c), at(hi, c) - at(lo2, c)}})
      if (others > 0 && gap > kStrayNodeGap * others)
        fail(s, ln,
             fmt::format("mesh: node {} at ({:.4g}, {:.4g}, {:.4g}) m lies {:.4g} m beyond the other nodes on {} "
                         "(they span {:.4g} m): more than {:g} x their span; check its coordinates",
                         stray, at(stray, 0), at(stray, 1), at(stray, 2), gap, "xyz"[c], others, kStrayNodeGap));
  }
  const index_t n = node_count(s);
  for (size_t k = 0; k < s.tets.size(); ++k)
    if (s.tets[k] < 0 || s.tets[k] >= n)
      fail(s, ln,
           fmt::format("mesh: element {} corner {} refers to node {}, out of range (the mesh has {} nodes, "
                       "ids 0..{})",
                       k / 4, k % 4, s.tets[k], n, n - 1));
}

// ---- bodies ----------------------------------------------------------------

/// The ids [lo, hi) a set or selection of `body` may name: its body's
/// range (first, count members of Body), or all `total` (body -1).
std::pair<index_t, index_t> ids_of(const Scene& s, int body, index_t Body::*first, index_t Body::*count,
                                   index_t total) {
  if (body < 0) return {0, total};
  const Body& b = s.bodies[std::size_t(body)];
  return {b.*first, b.*first + b.*count};
}

/// "body 'name'" of index k (k in range).
std::string body_name(const Scene& s, int k) { return fmt::format("body '{}'", s.bodies[std::size_t(k)].name); }

/// A scene of bodies: names non-empty and unique, node and element ranges
/// contiguous in body order and covering the mesh, each body with an
/// element, its elements using only its own nodes, and every set,
/// constraint and load naming a body that exists.
void check_bodies(const Scene& s) {
  if (s.bodies.empty()) return;
  index_t node = 0, elem = 0;
  std::map<std::string, int> names;
  for (int k = 0; k < int(s.bodies.size()); ++k) {
    const Body& b = s.bodies[std::size_t(k)];
    if (b.name.empty()) fail(s, b.line, fmt::format("body {}: the name is empty; every body needs a name", k));
    if (const auto [it, fresh] = names.emplace(b.name, k); !fresh)
      fail(s, b.line, fmt::format("body '{}' is defined twice (first {}); body names must be unique", b.name,
                                  location(s, s.bodies[std::size_t(it->second)].line)));
    if (b.first_node != node || b.n_nodes < 0 || b.first_element != elem || b.n_elements < 0)
      fail(s, b.line,
           fmt::format("{}: nodes {}+{} and elements {}+{} do not follow the bodies before it (nodes from {}, "
                       "elements from {}); bodies hold consecutive ranges of the scene's nodes and elements",
                       body_name(s, k), b.first_node, b.n_nodes, b.first_element, b.n_elements, node, elem));
    if (b.n_elements == 0)
      fail(s, b.mesh_line ? b.mesh_line : b.line,
           fmt::format("{}: its mesh has no elements; a body needs at least one tetrahedron", body_name(s, k)));
    node += b.n_nodes;
    elem += b.n_elements;
  }
  if (node != node_count(s) || elem != elem_count(s))
    fail(s, s.bodies.back().line,
         fmt::format("the bodies hold {} nodes and {} elements, the scene's mesh {} and {}; every node and "
                     "element belongs to one body",
                     node, elem, node_count(s), elem_count(s)));
  for (int k = 0; k < int(s.bodies.size()); ++k) {
    const Body& b = s.bodies[std::size_t(k)];
    for (index_t e = b.first_element; e < b.first_element + b.n_elements; ++e)
      for (int c = 0; c < 4; ++c)
        if (const index_t v = s.tets[4 * std::size_t(e) + c]; v < b.first_node || v >= b.first_node + b.n_nodes)
          fail(s, b.mesh_line ? b.mesh_line : b.line,
               fmt::format("{}: element {} corner {} is node {} of the scene, outside the body's nodes {}..{}; a "
                           "body's elements use its own nodes",
                           body_name(s, k), e - b.first_element, c, v, b.first_node, b.first_node + b.n_nodes - 1));
  }
  const auto check_ref = [&](int body, int line, std::string_view what) {
    if (body < 0)
      fail(s, line, fmt::format("{} belongs to no body; in a scene of bodies each element set, <fixed> and <load> "
                                "belongs to one (its body's ids)",
                                what));
    if (body >= int(s.bodies.size()))
      fail(s, line, fmt::format("{} belongs to body {}, which does not exist (the scene has {} bodies)", what, body,
                                s.bodies.size()));
  };
  for (const ElementSet& es : s.sets) check_ref(es.body, es.line, fmt::format("element-set '{}'", es.name));
  for (const Constraint& c : s.constraints) check_ref(c.body, c.line, "a <fixed>");
  for (const Load& l : s.loads) check_ref(l.where.body, l.where.line, "a <load>");
}

// ---- materials -------------------------------------------------------------

void check_young_poisson(const Scene& s, const Material& m, const std::string& what) {
  if (!(m.a > 0)) fail(s, m.line, fmt::format("{}: Young's modulus E = {} Pa must be > 0", what, m.a));
  if (!(m.b > -1 && m.b < 0.5))
    fail(s, m.line,
         fmt::format("{}: Poisson ratio nu = {} must be in (-1, 0.5) (nu >= 0.5 is incompressible, "
                     "nu <= -1 unstable)",
                     what, m.b));
}

void check_shear_bulk(const Scene& s, const Material& m, const std::string& what) {
  if (!(m.a > 0)) fail(s, m.line, fmt::format("{}: shear modulus mu = {} Pa must be > 0", what, m.a));
  if (!(m.b > 0)) fail(s, m.line, fmt::format("{}: bulk modulus K = {} Pa must be > 0", what, m.b));
}

void check_lame(const Scene& s, const Material& m, const std::string& what) {
  if (!(m.b > 0)) fail(s, m.line, fmt::format("{}: Lame shear modulus mu = {} Pa must be > 0", what, m.b));
  const double K = m.a + 2 * m.b / 3;
  if (!(K > 0))
    fail(s, m.line,
         fmt::format("{}: bulk modulus K = lambda + 2 mu / 3 = {} Pa (lambda = {} Pa, mu = {} Pa) "
                     "must be > 0",
                     what, K, m.a, m.b));
}

/// The fibre and Prony terms (docs/materials.md), each error at its own element's line.
void check_law_terms(const Scene& s, const Material& m, const std::string& what) {
  const int fl = m.fibre_line ? m.fibre_line : m.line;
  check_finite(s, fl, what, "fibre stiffness", m.fibre_eta);
  if (!(m.fibre_eta >= 0))
    fail(s, fl, fmt::format("{}: fibre stiffness = {} Pa must be >= 0", what, m.fibre_eta));
  const Vec3<double> a = m.fibre_dir;
  if (m.fibre_line && !(std::isfinite(a.x) && std::isfinite(a.y) && std::isfinite(a.z) && norm(a) > 0))
    fail(s, fl,
         fmt::format("{}: fibre direction ({}, {}, {}) must be finite and non-zero", what, a.x, a.y, a.z));
  using Field = Material::FibreField;
  if (m.fibre_field == Field::Circumferential || m.fibre_field == Field::Radial) {
    const std::string field = fmt::format("{}: fibre field {}", what, to_string(m.fibre_field));
    const Vec3<double> n = m.fibre_axis, o = m.fibre_origin;
    for (int c = 0; c < 3; ++c) check_finite(s, fl, field, fmt::format("axis {}", "xyz"[c]), n[c]);
    for (int c = 0; c < 3; ++c) check_finite(s, fl, field, fmt::format("origin {}", "xyz"[c]), o[c]);
    if (!(norm(n) > 0))
      fail(s, fl,
           fmt::format("{}: axis ({}, {}, {}) must be non-zero (the fibres wind around it or point away from it)",
                       field, n.x, n.y, n.z));
  }
  if (m.fibre_field == Field::File) {
    if (m.fibre_file.empty())
      fail(s, fl, what + ": a fibre direction file needs a file name (file=\"dirs.csv\", relative to the scene)");
    if (m.fibre_rows.empty())
      fail(s, fl,
           fmt::format("{}: fibre file '{}' gives no directions; expected rows element,ax,ay,az", what, m.fibre_file));
  }
  if (m.prony.size() > size_t(kMaxProny))
    fail(s, m.prony[kMaxProny].line,
         fmt::format("{}: {} Prony terms; at most {} are allowed", what, m.prony.size(), kMaxProny));
  double sum = 0;
  for (size_t i = 0; i < m.prony.size(); ++i) {
    const Material::Prony& t = m.prony[i];
    const std::string term = fmt::format("{}: Prony term {}", what, i + 1);
    check_finite(s, t.line, term, "g", t.g);
    check_finite(s, t.line, term, "tau", t.tau);
    if (!(t.g > 0)) fail(s, t.line, fmt::format("{}: g = {} must be > 0 (a relative modulus)", term, t.g));
    if (!(t.tau > 0)) fail(s, t.line, fmt::format("{}: tau = {} s must be > 0", term, t.tau));
    sum += t.g;
    if (!(sum < 1))
      fail(s, t.line,
           fmt::format("{}: the Prony moduli g sum to {} by this term; the sum must be < 1 (the relaxed shear "
                       "modulus mu (1 - sum g) must stay > 0)",
                       what, sum));
  }
}

void check_material(const Scene& s, const Material& m) {
  const std::string what = fmt::format("material '{}'", m.name);
  if (m.name.empty()) fail(s, m.line, "material: the name is empty; element sets refer to materials by name");
  static constexpr std::string_view kNames[3][2] = {{"E", "nu"}, {"mu", "K"}, {"lambda", "mu"}};
  const auto& names = kNames[static_cast<int>(m.form)];
  check_finite(s, m.line, what, names[0], m.a);
  check_finite(s, m.line, what, names[1], m.b);
  check_finite(s, m.line, what, "rho", m.rho);
  switch (m.form) {
    case Material::Form::YoungPoisson:
      check_young_poisson(s, m, what);
      break;
    case Material::Form::ShearBulk:
      check_shear_bulk(s, m, what);
      break;
    case Material::Form::Lame:
      check_lame(s, m, what);
      break;
  }
  if (!(m.rho > 0)) fail(s, m.line, fmt::format("{}: density rho = {} kg/m^3 must be > 0", what, m.rho));
  check_law_terms(s, m, what);
}

/// Checks every material; returns name -> index into scene.materials.
std::map<std::string, index_t> check_materials(const Scene& s) {
  std::map<std::string, index_t> index;
  for (size_t k = 0; k < s.materials.size(); ++k) {
    const Material& m = s.materials[k];
    check_material(s, m);
    const auto [it, fresh] = index.emplace(m.name, static_cast<index_t>(k));
    if (!fresh)
      fail(s, m.line,
           fmt::format("material '{}' is defined twice (first {}); material names must be unique", m.name,
                       location(s, s.materials[it->second].line)));
  }
  return index;
}

// ---- element sets ----------------------------------------------------------

std::string known_materials(const Scene& s) {
  if (s.materials.empty()) return "none are defined";
  std::string out = "defined:";
  for (size_t k = 0; k < s.materials.size(); ++k) out += (k ? ", '" : " '") + s.materials[k].name + "'";
  return out;
}

/// The body holding element e (-1 in the single-mesh form).
int body_of_element(const Scene& s, index_t e) {
  for (int k = 0; k < int(s.bodies.size()); ++k)
    if (e < s.bodies[std::size_t(k)].first_element + s.bodies[std::size_t(k)].n_elements) return k;
  return -1;
}

/// Assigns the set's elements to `owner` (set index per element, -1 = none).
void claim_elements(const Scene& s, size_t set, std::vector<int>& owner) {
  const ElementSet& es = s.sets[set];
  const std::pair<index_t, index_t> range = ids_of(s, es.body, &Body::first_element, &Body::n_elements, elem_count(s));
  const index_t lo = range.first, ne = range.second;  // plain names: lambdas below capture them
  const std::string what = es.body >= 0 ? fmt::format("{}: element-set '{}'", body_name(s, es.body), es.name)
                                        : fmt::format("element-set '{}'", es.name);
  if (es.all && !es.elements.empty())
    fail(s, es.line, what + ": give either all elements or an element list, not both");
  if (!es.all && es.elements.empty())
    fail(s, es.line, what + ": the element list is empty; a set needs at least one element (or \"all\")");
  auto claim = [&](index_t e) {
    if (e < lo || e >= ne)
      fail(s, es.line,
           fmt::format("{}: element {} is out of range (the {} has {} elements, ids 0..{})", what, e - lo,
                       es.body >= 0 ? "body" : "mesh", ne - lo, ne - lo - 1));
    if (owner[e] == int(set)) fail(s, es.line, fmt::format("{}: element {} is listed twice", what, e - lo));
    if (owner[e] >= 0) {
      const ElementSet& other = s.sets[owner[e]];
      fail(s, es.line,
           fmt::format("{}: element {} is already in element-set '{}' ({}); an element belongs to "
                       "exactly one set",
                       what, e - lo, other.name, location(s, other.line)));
    }
    owner[e] = int(set);
  };
  if (es.all)
    for (index_t e = lo; e < ne; ++e) claim(e);
  else
    for (index_t e : es.elements) claim(e);
}

/// Material index per element (n_elems).
std::vector<index_t> resolve_sets(const Scene& s, const std::map<std::string, index_t>& materials) {
  const index_t ne = elem_count(s);
  std::vector<int> owner(ne, -1);
  for (size_t k = 0; k < s.sets.size(); ++k) {
    const ElementSet& es = s.sets[k];
    if (!materials.count(es.material))
      fail(
          s, es.line,
          fmt::format("element-set '{}': material '{}' is not defined ({})", es.name, es.material, known_materials(s)));
    claim_elements(s, k, owner);
  }
  std::vector<index_t> mat(ne);
  for (index_t e = 0; e < ne; ++e) {
    if (owner[e] < 0) {
      const auto missing = std::count(owner.begin(), owner.end(), -1);
      const int b = body_of_element(s, e);
      const index_t node0 = b >= 0 ? s.bodies[std::size_t(b)].first_node : 0;
      fail(s, b >= 0 ? s.bodies[std::size_t(b)].line : s.mesh_line,
           fmt::format("{}element {} (nodes {} {} {} {}) is in no element-set{}; every element needs "
                       "a material (list it in a set, or use elements=\"all\")",
                       b >= 0 ? body_name(s, b) + ": " : "", b >= 0 ? e - s.bodies[std::size_t(b)].first_element : e,
                       s.tets[4 * e] - node0, s.tets[4 * e + 1] - node0, s.tets[4 * e + 2] - node0,
                       s.tets[4 * e + 3] - node0,
                       missing > 1 ? fmt::format(" (nor are {} others)", missing - 1) : ""));
    }
    mat[e] = materials.at(s.sets[owner[e]].material);
  }
  return mat;
}

// ---- constraints -----------------------------------------------------------

/// The selection's words with the element's name ("fixed" or "load") first.
std::string describe_as(const Constraint& c, const std::string& noun) { return noun + describe(c).substr(5); }

/// What a selection must do, for messages.
std::string selection_rule(const std::string& noun) {
  return noun == "fixed" ? "a constraint must fix at least one node" : "a load must act on at least one node";
}

void check_constraint(const Scene& s, const Constraint& c, const std::string& noun = "fixed") {
  const std::string what = describe_as(c, noun);
  const std::pair<index_t, index_t> range = ids_of(s, c.body, &Body::first_node, &Body::n_nodes, node_count(s));
  const index_t lo = range.first, n = range.second;
  switch (c.kind) {
    case Constraint::Kind::Nodes:
      if (c.nodes.empty())
        fail(s, c.line, noun + " nodes: the node list is empty; " + selection_rule(noun));
      for (index_t i : c.nodes)
        if (i < lo || i >= n)
          fail(s, c.line,
               fmt::format("{}{} nodes: node {} is out of range (the {} has {} nodes, ids 0..{})",
                           c.body >= 0 ? body_name(s, c.body) + ": " : "", noun, i - lo,
                           c.body >= 0 ? "body" : "mesh", n - lo, n - lo - 1));
      break;
    case Constraint::Kind::Box:
      for (int k = 0; k < 3; ++k) {
        check_finite(s, c.line, noun + " box", fmt::format("box-min {}", "xyz"[k]), c.lo[k]);
        check_finite(s, c.line, noun + " box", fmt::format("box-max {}", "xyz"[k]), c.hi[k]);
      }
      for (int k = 0; k < 3; ++k)
        if (c.lo[k] > c.hi[k])
          fail(s, c.line,
               fmt::format("{}: box-min {} = {} is greater than box-max {} = {}; need min <= max", what, "xyz"[k],
                           c.lo[k], "xyz"[k], c.hi[k]));
      break;
    case Constraint::Kind::Plane:
      for (int k = 0; k < 3; ++k) {
        check_finite(s, c.line, noun + " plane", fmt::format("plane-point {}", "xyz"[k]), c.point[k]);
        check_finite(s, c.line, noun + " plane", fmt::format("plane-normal {}", "xyz"[k]), c.normal[k]);
      }
      if (c.normal[0] == 0 && c.normal[1] == 0 && c.normal[2] == 0)
        fail(s, c.line, what + ": the plane normal is zero; it must have a non-zero length");
      break;
  }
}

/// Fixed-node mask (n_nodes).
std::vector<std::uint8_t> resolve_constraints(const Scene& s) {
  const index_t n = node_count(s);
  const double tol = selection_tolerance(s.nodes);
  std::vector<std::uint8_t> fixed(n, 0);
  for (const Constraint& c : s.constraints) {
    check_constraint(s, c);
    const std::vector<index_t> sel = constrained_nodes(c, s.nodes, tol, s.bodies);
    if (sel.empty())
      fail(s, c.line,
           fmt::format("{} selects no node of the {}; a constraint must fix at least one node", describe(c),
                       c.body >= 0 ? body_name(s, c.body) : "mesh"));
    for (index_t i : sel) fixed[i] = 1;
  }
  return fixed;
}

// ---- loads -----------------------------------------------------------------

/// Checks one <load> (selection, force) and returns the nodes it selects.
std::vector<index_t> selected_load_nodes(const Scene& s, const Load& l, double tol) {
  const Constraint& c = l.where;
  check_constraint(s, c, "load");
  for (int k = 0; k < 3; ++k) check_finite(s, c.line, "load", fmt::format("force {}", "xyz"[k]), l.force[k]);
  std::vector<index_t> sel = constrained_nodes(c, s.nodes, tol, s.bodies);
  if (sel.empty())
    fail(s, c.line,
         fmt::format("{} selects no node of the {}; {}", describe_as(c, "load"),
                     c.body >= 0 ? body_name(s, c.body) : "mesh", selection_rule("load")));
  return sel;
}

/// The <load>s' rules that need no model (to_model_input checks them).
void check_loads(const Scene& s) {
  const double tol = selection_tolerance(s.nodes);
  for (const Load& l : s.loads) (void)selected_load_nodes(s, l, tol);
}

}  // namespace

SceneLoads resolve_loads(const Scene& s, const TissueModel<double>& m) {
  SceneLoads out;
  if (s.loads.empty()) return out;
  const index_t n = m.n_nodes, nt = m.n_tris;
  const double tol = selection_tolerance(s.nodes);
  std::vector<double> force(3 * std::size_t(n), 0.0);
  std::vector<std::uint8_t> loaded(n, 0);
  for (const Load& l : s.loads) {
    const std::vector<index_t> sel = selected_load_nodes(s, l, tol);
    if (l.each) {
      for (index_t a : sel) {
        loaded[a] = 1;
        for (int k = 0; k < 3; ++k) force[3 * std::size_t(a) + k] += l.force[k];
      }
      continue;
    }
    // the total spread by area over the model's surface triangles whose three corners are selected
    // (consistent nodal loads of a uniform traction: a third of each triangle's share per corner)
    std::vector<std::uint8_t> in(n, 0);
    for (index_t a : sel) in[a] = 1;
    std::vector<std::pair<index_t, double>> faces;  // (triangle, area)
    double total = 0;
    for (index_t t = 0; t < nt; ++t) {
      const index_t v[3] = {m.tris[t], m.tris[nt + t], m.tris[2 * std::size_t(nt) + t]};
      if (!(in[v[0]] && in[v[1]] && in[v[2]])) continue;
      Vec3<double> x[3];
      for (int k = 0; k < 3; ++k) x[k] = {m.X[v[k]], m.X[n + v[k]], m.X[2 * std::size_t(n) + v[k]]};
      const double area = 0.5 * norm(cross(x[1] - x[0], x[2] - x[0]));
      faces.emplace_back(t, area);
      total += area;
    }
    if (!(total > 0))
      fail(s, l.where.line,
           fmt::format("{} selects {} node(s) but no surface face (a boundary triangle with all three corners "
                       "selected) to spread the force over; select a patch of the surface, or give "
                       "distribute=\"each\" for a force on every selected node",
                       describe_as(l.where, "load"), sel.size()));
    for (const auto& [t, area] : faces)
      for (int corner = 0; corner < 3; ++corner) {
        const index_t a = m.tris[corner * std::size_t(nt) + t];
        loaded[a] = 1;
        for (int k = 0; k < 3; ++k) force[3 * std::size_t(a) + k] += l.force[k] * area / total / 3;
      }
  }
  for (index_t a = 0; a < n; ++a)
    if (loaded[a]) {
      out.nodes.push_back(a);
      out.force.insert(out.force.end(), {force[3 * std::size_t(a)], force[3 * std::size_t(a) + 1],
                                         force[3 * std::size_t(a) + 2]});
    }
  return out;
}

void apply_loads(const Scene& scene, const TissueModel<double>& model, Scheduler& scheduler) {
  const SceneLoads loads = resolve_loads(scene, model);
  if (!loads.nodes.empty()) scheduler.set_loads(loads.nodes, loads.force);
}

namespace {

// ---- tools -----------------------------------------------------------------

void check_path(const Scene& s, const Tool& t, const std::string& what) {
  for (size_t k = 0; k < t.path.size(); ++k) {
    const Waypoint& w = t.path[k];
    const std::string wp = fmt::format("{}: waypoint {}", what, k);
    check_finite(s, t.line, wp, "t", w.t);
    for (int c = 0; c < 3; ++c) check_finite(s, t.line, wp, std::string(1, "xyz"[c]), w.p[c]);
    for (int c = 0; c < 3; ++c) check_finite(s, t.line, wp, fmt::format("axis {}", "xyz"[c]), w.axis[c]);
    if (k > 0 && !(w.t > t.path[k - 1].t))
      fail(s, t.line,
           fmt::format("{} has t = {} s, not after waypoint {} (t = {} s); waypoint times must increase", wp, w.t,
                       k - 1, t.path[k - 1].t));
  }
}

/// The smallest tool radius, as a fraction of the body's largest extent: a
/// tool a millionth of the body's size presses no node of any mesh the
/// engine can hold (it falls between the nodes), so such a radius is a unit
/// or typing mistake rather than a tool.
constexpr double kMinToolRadius = 1e-6;

/// Every waypoint within kToolReach mesh sizes of the mesh's box (the rule at kToolReach).
void check_path_near_mesh(const Scene& s, const Tool& t, const std::string& what) {
  const MeshBox box = mesh_box(s.nodes);
  for (size_t k = 0; k < t.path.size(); ++k) {
    const Vec3<double>& p = t.path[k].p;
    const double d = box.distance(p);
    if (d > kToolReach * box.size)
      fail(s, t.line,
           fmt::format("{}: waypoint {} at ({}, {}, {}) m is {:.3g} m from the mesh, more than {:.0f} x its size "
                       "({:.3g} m); coordinates are metres",
                       what, k, p.x, p.y, p.z, d, kToolReach, box.size));
  }
}

void check_tool(const Scene& s, const Tool& t) {
  const std::string what = fmt::format("tool '{}'", t.name);
  if (t.kind == Tool::Kind::Blade) {
    check_finite(s, t.line, what, "length", t.shaft);
    check_finite(s, t.line, what, "thickness", 2 * t.radius);
    check_finite(s, t.line, what, "cut-resistance", t.cut_resistance);
    if (!(t.shaft > 0))
      fail(s, t.line, fmt::format("{}: length = {} m: a blade is a straight edge of length > 0", what, t.shaft));
    if (!(t.radius > 0))
      fail(s, t.line, fmt::format("{}: thickness = {} m must be > 0 (the blade's contact)", what, 2 * t.radius));
    if (!(t.cut_resistance >= 0))
      fail(s, t.line,
           fmt::format("{}: cut-resistance = {} N/m must be >= 0 (the force per metre of edge at which the tissue "
                       "gives; 0 = at any touch)",
                       what, t.cut_resistance));
    check_finite(s, t.line, what, "cut-delay", t.cut_delay);
    if (!(t.cut_delay >= 0 && t.cut_delay <= kMaxCutDelay))
      fail(s, t.line,
           fmt::format("{}: cut-delay = {} s must be in [0, {}] (how long after the tissue gives its cut takes "
                       "effect; 0 = within the tick)",
                       what, t.cut_delay, kMaxCutDelay));
  }
  const MeshBox b = mesh_box(s.nodes);
  const double ext = b.largest_extent();  // a tool wider than the body cannot touch it as a tool
  if (const std::string e = tool_shape_error({t.name, t.radius, t.shaft, t.friction}, ext); !e.empty()) fail(s, t.line, e);
  if (ext > 0 && t.radius < kMinToolRadius * ext)
    fail(s, t.line,
         fmt::format("{}: radius = {} m is below {:g} of the body's largest extent ({:.4g} m), the smallest "
                     "radius allowed ({:.4g} m): a tool that small falls between the nodes and presses nothing; "
                     "check the unit of the radius and of the mesh",
                     what, t.radius, kMinToolRadius, ext, kMinToolRadius * ext));
  if (const double size = b.size; t.shaft > kToolReach * size)
    fail(s, t.line,
         fmt::format("{}: shaft-length = {} m is longer than {:.0f} x the mesh's size ({:.3g} m, the limit "
                     "{:.3g} m); coordinates are metres",
                     what, t.shaft, kToolReach, size, kToolReach * size));
  for (int c = 0; c < 3; ++c) check_finite(s, t.line, what, fmt::format("direction {}", "xyz"[c]), t.direction[c]);
  if (!(norm(t.direction) > 0))
    fail(s, t.line, fmt::format("{}: direction (0, 0, 0) must be a non-zero vector (the shaft axis, tip to handle)", what));
  if (t.device != "scripted" && t.device != "mouse" && t.device != "phantom")
    fail(s, t.line, fmt::format("{}: unknown device '{}'; expected scripted, mouse or phantom", what, t.device));
  if (t.device == "scripted" && t.path.empty())
    fail(s, t.line,
         fmt::format("{}: a scripted device needs a path (path=\"file.csv\" or <waypoint> children){}", what,
                     t.path_file.empty() ? "" : fmt::format("; '{}' gave no waypoints", t.path_file)));
  check_path(s, t, what);
  check_path_near_mesh(s, t, what);
}

/// Every tool by the rules above, then their names: messages, warnings and
/// the run's summary name a tool by its name, so two of one name could not
/// be told apart.
void check_tools(const Scene& s) {
  std::map<std::string, const Tool*> seen;
  for (const Tool& t : s.tools) {
    check_tool(s, t);
    const auto [it, fresh] = seen.emplace(t.name, &t);
    if (!fresh)
      fail(s, t.line,
           fmt::format("tool '{}' is defined twice (first {}); tool names must be unique (a <tool> "
                       "without name= is 'probe'): give each its own name=", t.name,
                       location(s, it->second->line)));
  }
}

// ---- bodies that touch ------------------------------------------------------

/// The body named `name` (its index), or a failure at `line` naming the contact and the bodies there are.
int contact_body(const Scene& s, int line, const std::string& name) {
  std::string names;
  for (std::size_t k = 0; k < s.bodies.size(); ++k) {
    if (s.bodies[k].name == name) return int(k);
    names += (k ? ", " : "") + s.bodies[k].name;
  }
  fail(s, line, fmt::format("contact: no body '{}' (the bodies are {})", name, names));
  return -1;
}

void check_contacts(const Scene& s) {
  for (std::size_t i = 0; i < s.contacts.size(); ++i) {
    const BodyContact& c = s.contacts[i];
    if (s.bodies.empty()) fail(s, c.line, "contact: a scene of one <mesh> has no bodies to touch");
    const int a = contact_body(s, c.line, c.a), b = contact_body(s, c.line, c.b);
    if (a == b)
      fail(s, c.line, fmt::format("contact: bodies = '{} {}' names one body twice; a body against itself (a fold) "
                                  "is not modelled",
                                  c.a, c.b));
    check_finite(s, c.line, "contact", "friction", c.friction);
    if (!(c.friction >= 0)) fail(s, c.line, fmt::format("contact: friction = {} must be >= 0 (Coulomb's mu)", c.friction));
    for (std::size_t j = 0; j < i; ++j) {
      const BodyContact& d = s.contacts[j];
      if ((d.a == c.a && d.b == c.b) || (d.a == c.b && d.b == c.a))
        fail(s, c.line, fmt::format("contact: bodies '{}' and '{}' are already paired ({})", c.a, c.b,
                                    location(s, d.line)));
    }
  }
  if (!s.contacts.empty() && s.solver.depth >= 0)
    fail(s, s.solver.line,
         fmt::format("solver: depth = {}: a scene whose bodies touch (<contact>) computes the whole mesh (a region "
                     "of rings does not reach across to the other body); use depth=\"all\" or \"auto\"",
                     s.solver.depth));
}

// ---- solver ----------------------------------------------------------------

void check_solver(const Scene& s) {
  const Solver& v = s.solver;
  const int ln = v.line;
  if (v.backend != "cpu" && v.backend != "cuda")
    fail(s, ln, fmt::format("solver: unknown backend '{}'; expected cpu or cuda", v.backend));
  const std::pair<std::string_view, double> numbers[] = {
      {"dt", v.dt.value_or(1)}, {"dt-safety", v.dt_safety},       {"mass-scaling", v.mass_scaling},
      {"damping", v.damping.value_or(0)}, {"tick", v.tick}, {"residual-tol", v.residual_tol},
      {"kinetic-tol", v.kinetic_tol}};
  for (const auto& [name, value] : numbers) check_finite(s, ln, "solver", name, value);
  if (v.dt && !(*v.dt > 0))
    fail(s, ln, fmt::format("solver: dt = {} s must be > 0 (or \"auto\" = dt-safety x dt_crit)", *v.dt));
  if (!(v.dt_safety > 0 && v.dt_safety < 1))
    fail(s, ln, fmt::format("solver: dt-safety = {} must be in (0, 1) (a fraction of the critical step)", v.dt_safety));
  if (!(v.mass_scaling >= 0 && v.mass_scaling < 1))
    fail(s, ln,
         fmt::format("solver: mass-scaling = {} must be in [0, 1) (the added mass allowed, a fraction of the total)",
                     v.mass_scaling));
  if (v.damping && *v.damping < 0)
    fail(s, ln, fmt::format("solver: damping = {} 1/s must be >= 0 (or \"auto\")", *v.damping));
  if (v.depth < kDepthAuto)
    fail(s, ln, fmt::format("solver: depth = {} must be >= 0 (or \"all\" or \"auto\")", v.depth));
  if (!(v.tick > 0)) fail(s, ln, fmt::format("solver: tick = {} s must be > 0", v.tick));
  if (!(v.residual_tol > 0) || !(v.residual_tol < 1))
    fail(s, ln, fmt::format("solver: residual-tol = {} must be in (0, 1): it bounds the free nodes' residual "
                            "relative to the force on the held ones, which any state meets from 1 on",
                            v.residual_tol));
  if (!(v.kinetic_tol > 0)) fail(s, ln, fmt::format("solver: kinetic-tol = {} must be > 0", v.kinetic_tol));
}

}  // namespace

double MeshBox::distance(const Vec3<double>& p) const {
  const double out[3] = {std::max({lo.x - p.x, p.x - hi.x, 0.0}), std::max({lo.y - p.y, p.y - hi.y, 0.0}),
                         std::max({lo.z - p.z, p.z - hi.z, 0.0})};
  return std::hypot(out[0], out[1], out[2]);
}

MeshBox mesh_box(std::span<const double> nodes) {
  MeshBox b;
  b.lo = {INFINITY, INFINITY, INFINITY};
  b.hi = {-INFINITY, -INFINITY, -INFINITY};
  for (size_t k = 0; k + 2 < nodes.size(); k += 3) {
    b.lo = {std::min(b.lo.x, nodes[k]), std::min(b.lo.y, nodes[k + 1]), std::min(b.lo.z, nodes[k + 2])};
    b.hi = {std::max(b.hi.x, nodes[k]), std::max(b.hi.y, nodes[k + 1]), std::max(b.hi.z, nodes[k + 2])};
  }
  b.size = std::hypot(b.hi.x - b.lo.x, b.hi.y - b.lo.y, b.hi.z - b.lo.z);
  return b;
}

std::string location(const Scene& scene, int line) {
  return line > 0 ? fmt::format("{}:{}", scene.source, line) : scene.source;
}

void validate_material(const Scene& scene, const Material& material) { check_material(scene, material); }

void validate(const Scene& scene) {
  (void)to_model_input(scene);
}

ModelInput to_model_input(const Scene& scene) {
  check_mesh(scene);
  check_bodies(scene);
  const auto materials = check_materials(scene);
  ModelInput in;
  in.elem_material = resolve_sets(scene, materials);
  in.fibre_dirs = resolve_fibre_dirs(scene, in.elem_material);
  in.fixed = resolve_constraints(scene);
  check_loads(scene);  // the <load>s' rules, with file:line, before any work
  check_tools(scene);
  check_solver(scene);
  check_contacts(scene);
  in.nodes = scene.nodes;
  in.tets = scene.tets;
  for (const Material& m : scene.materials) {
    in.materials.push_back(m.params());
    in.material_names.push_back(m.name);
  }
  in.dt = scene.solver.dt.value_or(0);  // ModelInput: 0 = dt_safety x dt_crit
  in.dt_safety = scene.solver.dt_safety;
  in.mass_scaling = scene.solver.mass_scaling;
  in.tick = scene.solver.tick;
  in.damping = scene.solver.damping;
  in.ianp = scene.solver.ianp;
  in.source = scene.source;
  return in;
}

TissueModel<double> load_model(const Scene& scene) {
  const ModelInput in = to_model_input(scene);
  TissueModel<double> m;
  try {
    m = build_model(in);
  } catch (const ModelError& e) {  // the core names scene-wide ids: say where each body's lie
    if (scene.bodies.empty()) throw;
    std::string where;
    for (const Body& b : scene.bodies)
      where += fmt::format("{}body '{}' nodes {}..{}, elements {}..{}", where.empty() ? "" : "; ", b.name,
                           b.first_node, b.first_node + b.n_nodes - 1, b.first_element,
                           b.first_element + b.n_elements - 1);
    throw ModelError(fmt::format("{} (node and element ids of the whole scene: {})", e.what(), where));
  }
  try {
    align_time_step(m, scene.solver.tick);  // whole steps per haptic tick
  } catch (const ModelError& e) {
    throw ModelError(location(scene, scene.solver.line) + ": solver: " + e.what());
  }
  return m;
}

SchedulerSettings scheduler_settings(const Scene& scene) {
  check_solver(scene);
  check_tools(scene);
  SchedulerSettings st;
  st.tools.clear();
  for (const Tool& t : scene.tools)
    st.tools.push_back({{t.name, t.radius, t.shaft, t.friction}, t.direction, t.kind == Tool::Kind::Blade});
  st.depth = scene.solver.depth;
  check_contacts(scene);
  if (!scene.contacts.empty()) {
    for (const Body& b : scene.bodies) st.body_contact.first_node.push_back(b.first_node);
    st.body_contact.first_node.push_back(index_t(scene.nodes.size() / 3));
    for (const BodyContact& c : scene.contacts)
      st.body_contact.pairs.push_back({contact_body(scene, c.line, c.a), contact_body(scene, c.line, c.b), c.friction});
    if (st.depth == kDepthAuto) st.depth = kDepthAll;  // auto, in a scene whose bodies touch: the whole mesh
  }
  st.tick = scene.solver.tick;
  st.residual_tol = scene.solver.residual_tol;
  st.kinetic_tol = scene.solver.kinetic_tol;
  st.lip_contact = scene.solver.lip_contact;
  st.step_guard.on = scene.solver.step_guard;
  st.step_guard.budget = scene.solver.mass_scaling;
  return st;
}

}  // namespace tissue::scene
