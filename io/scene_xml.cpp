#include "io/scene_xml.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <limits>
#include <pugixml.hpp>
#include <span>
#include <sstream>

#include "io/atomic_file.hpp"
#include "io/fibre_csv.hpp"
#include "io/path_csv.hpp"
#include "io/tetgen_files.hpp"
#include "scene/fibre_field.hpp"
#include "scene/text.hpp"

namespace tissue::io {
namespace {

namespace fs = std::filesystem;
using scene::Constraint;
using scene::Material;
using scene::SceneError;
using Names = std::initializer_list<std::string_view>;

std::string join(Names names) {
  std::string out;
  for (std::string_view n : names) out += (out.empty() ? "" : ", ") + std::string(n);
  return out;
}

std::string resolve(const std::string& base_dir, const std::string& file) {
  return base_dir.empty() ? file : (fs::path(base_dir) / file).string();
}

// ---- reading ---------------------------------------------------------------

/// Parses one document; knows the source name and turns offsets into lines.
class Reader {
 public:
  Reader(std::string_view xml, std::string source, std::string base_dir)
      : xml_(xml), source_(std::move(source)), base_dir_(std::move(base_dir)) {
    for (size_t i = 0; i < xml_.size(); ++i)
      if (xml_[i] == '\n') newlines_.push_back(i);
  }

  scene::Scene read();

 private:
  // -- locations and errors
  int line_of(std::ptrdiff_t offset) const {
    if (offset < 0) return 0;
    return 1 + int(std::lower_bound(newlines_.begin(), newlines_.end(), size_t(offset)) - newlines_.begin());
  }
  int line(pugi::xml_node n) const { return line_of(n.offset_debug()); }
  [[noreturn]] void fail_at(int line, const std::string& what) const {
    throw SceneError(line > 0 ? fmt::format("{}:{}: {}", source_, line, what) : fmt::format("{}: {}", source_, what));
  }
  [[noreturn]] void fail(pugi::xml_node n, const std::string& what) const {
    fail_at(line(n), fmt::format("<{}>: {}", n.name(), what));
  }

  // -- structure checks (each throws naming the element and its line)
  /// Every attribute of n is in `allowed`, none twice.
  void check_attributes(pugi::xml_node n, Names allowed) const;
  /// Every child element of n is in `allowed`; n holds no text.
  void check_children(pugi::xml_node n, Names allowed) const;
  /// n has no child elements and no text.
  void check_no_text(pugi::xml_node n) const;

  // -- attribute values (strict: the whole text must be the value)
  /// The attribute's text; throws when it is missing.
  std::string required(pugi::xml_node n, const char* name) const;
  /// A required real number.
  double real(pugi::xml_node n, const char* name) const;
  /// An optional real number (fallback when absent).
  double real_or(pugi::xml_node n, const char* name, double fallback) const;
  /// An optional real number or the keyword "auto" (-> nullopt); fallback when absent.
  std::optional<double> real_or_auto(pugi::xml_node n, const char* name, std::optional<double> fallback) const;
  /// A required "x y z" triple.
  void triple(pugi::xml_node n, const char* name, double out[3]) const;
  /// A blank-separated list of ids (node or element) held by attribute `name`.
  std::vector<index_t> ids(pugi::xml_node n, const char* name, std::string_view text) const;

  // -- one reader per element kind
  void read_mesh(pugi::xml_node n, scene::Scene& s) const;
  void read_body(pugi::xml_node n, scene::Scene& s) const;
  /// A <body>'s local ids made the scene's: each checked against the
  /// body's count (an error naming the body, what, and n's line), then
  /// shifted by first.
  void body_ids(pugi::xml_node n, const scene::Body& b, const char* what, index_t count, index_t first,
                std::vector<index_t>& ids) const;
  std::vector<double> read_node_text(pugi::xml_node n) const;
  std::vector<index_t> read_element_text(pugi::xml_node n) const;
  Material read_material(pugi::xml_node n) const;
  scene::ElementSet read_set(pugi::xml_node n) const;
  Constraint read_fixed(pugi::xml_node n) const;
  Constraint read_selection(pugi::xml_node n) const;
  scene::Load read_load(pugi::xml_node n) const;
  scene::Tool read_tool(pugi::xml_node n) const;
  scene::Solver read_solver(pugi::xml_node n) const;

  template <class F>
  void for_tokens(pugi::xml_node n, F&& f) const;

  std::string_view xml_;
  std::string source_, base_dir_;
  std::vector<size_t> newlines_;
};

void Reader::check_attributes(pugi::xml_node n, Names allowed) const {
  for (pugi::xml_attribute a : n.attributes()) {
    if (std::find(allowed.begin(), allowed.end(), std::string_view(a.name())) == allowed.end())
      fail(n, fmt::format("unknown attribute '{}'; allowed: {}", a.name(), allowed.size() ? join(allowed) : "none"));
    for (pugi::xml_attribute b = a.next_attribute(); b; b = b.next_attribute())
      if (std::string_view(a.name()) == b.name()) fail(n, fmt::format("attribute '{}' is given twice", a.name()));
  }
}

void Reader::check_children(pugi::xml_node n, Names allowed) const {
  for (pugi::xml_node c : n.children()) {
    if (c.type() == pugi::node_element) {
      if (std::find(allowed.begin(), allowed.end(), std::string_view(c.name())) == allowed.end())
        fail_at(line(c), fmt::format("unknown element <{}> in <{}>; allowed: {}", c.name(), n.name(),
                                     allowed.size() ? join(allowed) : "none"));
    } else if (c.type() == pugi::node_pcdata || c.type() == pugi::node_cdata) {
      if (!scene::trim(c.value()).empty())
        fail(n, fmt::format("unexpected text '{}'; this element holds no text", scene::trim(c.value()).substr(0, 40)));
    }
  }
}

void Reader::check_no_text(pugi::xml_node n) const {
  check_children(n, {});
}

std::string Reader::required(pugi::xml_node n, const char* name) const {
  const pugi::xml_attribute a = n.attribute(name);
  if (!a) fail(n, fmt::format("missing required attribute '{}'", name));
  return a.value();
}

double Reader::real(pugi::xml_node n, const char* name) const {
  const std::string text = required(n, name);
  const auto v = scene::parse_real(text);
  if (!v) fail(n, fmt::format("attribute {} = '{}' is not a number", name, text));
  return *v;
}

double Reader::real_or(pugi::xml_node n, const char* name, double fallback) const {
  return n.attribute(name) ? real(n, name) : fallback;
}

std::optional<double> Reader::real_or_auto(pugi::xml_node n, const char* name,
                                           std::optional<double> fallback) const {
  const pugi::xml_attribute a = n.attribute(name);
  if (!a) return fallback;
  if (scene::trim(a.value()) == "auto") return std::nullopt;
  const auto v = scene::parse_real(a.value());
  if (!v) fail(n, fmt::format("attribute {} = '{}' is neither a number nor \"auto\"", name, a.value()));
  return *v;
}

void Reader::triple(pugi::xml_node n, const char* name, double out[3]) const {
  const std::string text = required(n, name);
  const auto tok = scene::split_blanks(text);
  if (tok.size() != 3) fail(n, fmt::format("attribute {} = '{}' must be three numbers \"x y z\"", name, text));
  for (int k = 0; k < 3; ++k) {
    const auto v = scene::parse_real(tok[k]);
    if (!v) fail(n, fmt::format("attribute {}: {} = '{}' is not a number", name, "xyz"[k], tok[k]));
    out[k] = *v;
  }
}

std::vector<index_t> Reader::ids(pugi::xml_node n, const char* name, std::string_view text) const {
  std::vector<index_t> out;
  for (std::string_view tok : scene::split_blanks(text)) {
    const auto v = scene::parse_integer(tok);
    if (!v) fail(n, fmt::format("attribute {}: '{}' is not a whole number", name, tok));
    if (*v < std::numeric_limits<index_t>::min() || *v > std::numeric_limits<index_t>::max())
      fail(n, fmt::format("attribute {}: id {} is out of range", name, *v));
    out.push_back(static_cast<index_t>(*v));
  }
  return out;
}

/// Calls f(token, line) for each blank-separated token of n's text.
template <class F>
void Reader::for_tokens(pugi::xml_node n, F&& f) const {
  check_attributes(n, {});
  for (pugi::xml_node c : n.children()) {
    if (c.type() == pugi::node_element)
      fail_at(line(c), fmt::format("unknown element <{}> in <{}>; it holds numbers only", c.name(), n.name()));
    if (c.type() != pugi::node_pcdata && c.type() != pugi::node_cdata) continue;
    const std::string_view text = c.value();
    int ln = line(c);
    size_t pos = 0;
    for (std::string_view tok : scene::split_blanks(text)) {
      const size_t at = size_t(tok.data() - text.data());
      if (ln > 0) ln += int(std::count(text.begin() + pos, text.begin() + at, '\n'));
      pos = at;
      f(tok, ln);
    }
  }
}

std::vector<double> Reader::read_node_text(pugi::xml_node n) const {
  std::vector<double> xyz;
  for_tokens(n, [&](std::string_view tok, int ln) {
    const auto v = scene::parse_real(tok);
    if (!v)
      fail_at(ln, fmt::format("<nodes>: node {} coordinate {} = '{}' is not a number", xyz.size() / 3,
                              "xyz"[xyz.size() % 3], tok));
    xyz.push_back(*v);
  });
  if (xyz.size() % 3 != 0)
    fail(n, fmt::format("{} numbers is not a multiple of 3; write x y z for every node", xyz.size()));
  return xyz;
}

std::vector<index_t> Reader::read_element_text(pugi::xml_node n) const {
  std::vector<index_t> tets;
  for_tokens(n, [&](std::string_view tok, int ln) {
    const auto v = scene::parse_integer(tok);
    if (!v || *v < std::numeric_limits<index_t>::min() || *v > std::numeric_limits<index_t>::max())
      fail_at(ln, fmt::format("<elements>: element {} corner {} = '{}' is not a node id (a whole number)",
                              tets.size() / 4, tets.size() % 4, tok));
    tets.push_back(static_cast<index_t>(*v));
  });
  if (tets.size() % 4 != 0)
    fail(n, fmt::format("{} node ids is not a multiple of 4; write 4 corner ids for every tetrahedron", tets.size()));
  return tets;
}

void Reader::read_mesh(pugi::xml_node n, scene::Scene& s) const {
  check_attributes(n, {"file"});
  s.mesh_line = line(n);
  if (n.attribute("file")) {
    check_no_text(n);
    s.mesh_file = n.attribute("file").value();
    try {
      TetgenFiles m = read_tetgen(resolve(base_dir_, s.mesh_file));
      s.nodes = std::move(m.nodes);
      s.tets = std::move(m.tets);
    } catch (const TetgenFileError& e) {
      fail(n, fmt::format("mesh file '{}': {}", s.mesh_file, e.what()));
    }
    return;
  }
  check_children(n, {"nodes", "elements"});
  const pugi::xml_node nodes = n.child("nodes"), elems = n.child("elements");
  if (!nodes || !elems) fail(n, "needs a <nodes> and an <elements> child, or a file=\"x.node\" attribute");
  if (nodes.next_sibling("nodes")) fail_at(line(nodes.next_sibling("nodes")), "<mesh> has a second <nodes>");
  if (elems.next_sibling("elements")) fail_at(line(elems.next_sibling("elements")), "<mesh> has a second <elements>");
  s.nodes = read_node_text(nodes);
  s.tets = read_element_text(elems);
}

void Reader::body_ids(pugi::xml_node n, const scene::Body& b, const char* what, index_t count, index_t first,
                      std::vector<index_t>& ids) const {
  for (index_t& i : ids) {
    if (i < 0 || i >= count)
      fail(n, fmt::format("body '{}': {} {} is out of range (its mesh has {} {}s, ids 0..{}; ids in a <body> are "
                          "its own mesh's)",
                          b.name, what, i, count, what, count - 1));
    i += first;
  }
}

void Reader::read_body(pugi::xml_node n, scene::Scene& s) const {
  check_attributes(n, {"name"});
  check_children(n, {"mesh", "element-set", "fixed", "load"});
  scene::Body b;
  b.line = line(n);
  b.name = required(n, "name");
  for (const scene::Body& other : s.bodies)
    if (other.name == b.name)
      fail(n, fmt::format("body '{}' is defined twice (first at line {}); body names must be unique", b.name,
                          other.line));
  const pugi::xml_node mesh = n.child("mesh");
  if (!mesh) fail(n, fmt::format("body '{}' has no <mesh>; a body needs one", b.name));
  if (mesh.next_sibling("mesh"))
    fail_at(line(mesh.next_sibling("mesh")), fmt::format("body '{}' has a second <mesh>; a body has one", b.name));
  scene::Scene own;
  read_mesh(mesh, own);
  b.mesh_file = own.mesh_file;
  b.mesh_line = own.mesh_line;
  b.first_node = static_cast<index_t>(s.nodes.size() / 3);
  b.first_element = static_cast<index_t>(s.tets.size() / 4);
  b.n_nodes = static_cast<index_t>(own.nodes.size() / 3);
  b.n_elements = static_cast<index_t>(own.tets.size() / 4);
  if (own.nodes.size() % 3 == 0 && own.tets.size() % 4 == 0)  // else scene validation names the count
    for (size_t k = 0; k < own.tets.size(); ++k)
      if (own.tets[k] < 0 || own.tets[k] >= b.n_nodes)
        fail(mesh, fmt::format("body '{}': element {} corner {} refers to node {}, out of range (its mesh has {} "
                               "nodes, ids 0..{})",
                               b.name, k / 4, k % 4, own.tets[k], b.n_nodes, b.n_nodes - 1));
  const int index = static_cast<int>(s.bodies.size());
  s.nodes.insert(s.nodes.end(), own.nodes.begin(), own.nodes.end());
  for (index_t v : own.tets) s.tets.push_back(v + b.first_node);
  for (pugi::xml_node c : n.children("element-set")) {
    scene::ElementSet es = read_set(c);
    body_ids(c, b, "element", b.n_elements, b.first_element, es.elements);
    es.body = index;
    s.sets.push_back(std::move(es));
  }
  for (pugi::xml_node c : n.children("fixed")) {
    Constraint f = read_fixed(c);
    body_ids(c, b, "node", b.n_nodes, b.first_node, f.nodes);
    f.body = index;
    s.constraints.push_back(std::move(f));
  }
  for (pugi::xml_node c : n.children("load")) {
    scene::Load l = read_load(c);
    body_ids(c, b, "node", b.n_nodes, b.first_node, l.where.nodes);
    l.where.body = index;
    s.loads.push_back(std::move(l));
  }
  s.bodies.push_back(std::move(b));
}

Material Reader::read_material(pugi::xml_node n) const {
  check_attributes(n, {"name", "E", "nu", "mu", "K", "lambda", "rho"});
  check_children(n, {"fibre", "prony"});
  Material m;
  m.line = line(n);
  m.name = required(n, "name");
  const auto has = [&](const char* a) { return bool(n.attribute(a)); };
  const int given = has("E") + has("nu") + has("mu") + has("K") + has("lambda");
  if (given == 2 && has("E") && has("nu")) {
    m.form = Material::Form::YoungPoisson;
    m.a = real(n, "E");
    m.b = real(n, "nu");
  } else if (given == 2 && has("mu") && has("K")) {
    m.form = Material::Form::ShearBulk;
    m.a = real(n, "mu");
    m.b = real(n, "K");
  } else if (given == 2 && has("lambda") && has("mu")) {
    m.form = Material::Form::Lame;
    m.a = real(n, "lambda");
    m.b = real(n, "mu");
  } else {
    fail(n, fmt::format("material '{}' must give exactly one pair of elastic constants: E and nu, mu and K, or "
                        "lambda and mu",
                        m.name));
  }
  m.rho = real(n, "rho");
  const pugi::xml_node fibre = n.child("fibre");
  if (fibre) {
    if (fibre.next_sibling("fibre")) fail_at(line(fibre.next_sibling("fibre")), "a material has one <fibre>");
    check_attributes(fibre, {"stiffness", "direction", "field", "axis", "origin", "file"});
    check_no_text(fibre);
    m.fibre_line = line(fibre);
    m.fibre_eta = real(fibre, "stiffness");
    const bool field = fibre.attribute("field"), file = fibre.attribute("file");
    if (field && file)
      fail(fibre, "give either field= (a direction field) or file= (a direction per element), not both");
    if (!field && (fibre.attribute("axis") || fibre.attribute("origin")))
      fail(fibre, "axis= and origin= belong to a direction field: give field=\"circumferential\" or "
                  "field=\"radial\" with them");
    double a[3];
    if (field) {
      const std::string_view name = scene::trim(fibre.attribute("field").value());
      const auto f = scene::parse_fibre_field(name);
      if (!f) fail(fibre, fmt::format("field = '{}' is unknown; expected circumferential or radial", name));
      if (fibre.attribute("direction"))
        fail(fibre, fmt::format("direction= is not used with field= (the {} field gives every element its "
                                "direction); remove one",
                                name));
      m.fibre_field = *f;
      triple(fibre, "axis", a);
      m.fibre_axis = {a[0], a[1], a[2]};
      if (fibre.attribute("origin")) {
        triple(fibre, "origin", a);
        m.fibre_origin = {a[0], a[1], a[2]};
      }
    } else {
      if (!file || fibre.attribute("direction")) {  // with file=: the direction of the elements it does not list
        triple(fibre, "direction", a);
        m.fibre_dir = {a[0], a[1], a[2]};
      }
      if (file) {
        m.fibre_field = Material::FibreField::File;
        m.fibre_file = fibre.attribute("file").value();
        m.fibre_file_path = resolve(base_dir_, m.fibre_file);
        try {
          m.fibre_rows = read_fibre_csv(m.fibre_file_path);
        } catch (const FibreCsvError& e) {
          fail(fibre, fmt::format("material '{}' fibre file '{}': {}", m.name, m.fibre_file, e.what()));
        }
      }
    }
  }
  for (pugi::xml_node t : n.children("prony")) {
    check_attributes(t, {"g", "tau"});
    check_no_text(t);
    m.prony.push_back({real(t, "g"), real(t, "tau"), line(t)});
  }
  return m;
}

scene::ElementSet Reader::read_set(pugi::xml_node n) const {
  check_attributes(n, {"name", "material", "elements"});
  check_no_text(n);
  scene::ElementSet es;
  es.line = line(n);
  es.material = required(n, "material");
  es.name = n.attribute("name") ? n.attribute("name").value() : es.material;
  const std::string list = required(n, "elements");
  if (scene::trim(list) == "all")
    es.all = true;
  else
    es.elements = ids(n, "elements", list);
  return es;
}

Constraint Reader::read_fixed(pugi::xml_node n) const {
  check_attributes(n, {"nodes", "box-min", "box-max", "plane-point", "plane-normal"});
  return read_selection(n);
}

scene::Load Reader::read_load(pugi::xml_node n) const {
  check_attributes(n, {"force", "distribute", "nodes", "box-min", "box-max", "plane-point", "plane-normal"});
  scene::Load l;
  l.where = read_selection(n);
  if (!n.attribute("force")) fail(n, "a <load> needs force=\"fx fy fz\" (N)");
  triple(n, "force", l.force);
  if (n.attribute("distribute")) {
    const std::string d = n.attribute("distribute").value();
    if (d != "area" && d != "each")
      fail(n, "distribute=\"" + d + "\": use \"area\" (the force is the total, spread over the selected surface by "
                                     "area) or \"each\" (every selected node gets the force)");
    l.each = d == "each";
  }
  return l;
}

Constraint Reader::read_selection(pugi::xml_node n) const {
  check_no_text(n);
  Constraint c;
  c.line = line(n);
  const bool nodes = n.attribute("nodes"), box = n.attribute("box-min") || n.attribute("box-max"),
             plane = n.attribute("plane-point") || n.attribute("plane-normal");
  if (nodes + box + plane != 1)
    fail(n, "give exactly one kind: nodes=\"ids\", box-min= and box-max=, or plane-point= and plane-normal=");
  if (nodes) {
    c.kind = Constraint::Kind::Nodes;
    c.nodes = ids(n, "nodes", n.attribute("nodes").value());
  } else if (box) {
    c.kind = Constraint::Kind::Box;
    triple(n, "box-min", c.lo);
    triple(n, "box-max", c.hi);
  } else {
    c.kind = Constraint::Kind::Plane;
    triple(n, "plane-point", c.point);
    triple(n, "plane-normal", c.normal);
  }
  return c;
}

scene::Tool Reader::read_tool(pugi::xml_node n) const {
  check_attributes(n, {"name", "kind", "radius", "shaft-length", "length", "thickness", "cut-resistance", "cut-delay",
                       "friction", "direction", "device", "path"});
  check_children(n, {"waypoint"});
  scene::Tool t;
  t.line = line(n);
  if (n.attribute("name")) t.name = n.attribute("name").value();
  if (const pugi::xml_attribute k = n.attribute("kind")) {
    const std::string_view kind = scene::trim(k.value());
    if (kind != "probe" && kind != "blade") fail(n, fmt::format("kind = '{}' must be probe or blade", k.value()));
    if (kind == "blade") t.kind = scene::Tool::Kind::Blade;
  }
  const bool blade = t.kind == scene::Tool::Kind::Blade;
  static constexpr const char* kProbeOnly[] = {"radius", "shaft-length"};
  static constexpr const char* kBladeOnly[] = {"length", "thickness", "cut-resistance", "cut-delay"};
  for (const char* a : blade ? std::span<const char* const>(kProbeOnly) : std::span<const char* const>(kBladeOnly))
    if (n.attribute(a))
      fail(n, blade ? fmt::format("{}= is a probe's; a blade takes length= (its edge, m) and thickness= (m)", a)
                    : fmt::format("{}= is a blade's (kind=\"blade\"); a probe takes radius= and shaft-length=", a));
  if (blade) {
    if (!n.attribute("length")) fail(n, "a blade needs length= (its edge, m)");
    t.shaft = real(n, "length");
    t.radius = 0.5 * real_or(n, "thickness", scene::kDefaultBladeThickness);
    t.cut_resistance = real_or(n, "cut-resistance", t.cut_resistance);
    t.cut_delay = real_or(n, "cut-delay", t.cut_delay);
  } else {
    t.radius = real_or(n, "radius", t.radius);
    t.shaft = real_or(n, "shaft-length", t.shaft);
  }
  t.friction = real_or(n, "friction", t.friction);
  if (n.attribute("direction")) {
    double d[3];
    triple(n, "direction", d);
    t.direction = {d[0], d[1], d[2]};
  }
  if (n.attribute("device")) t.device = n.attribute("device").value();
  // the button: a probe's grasp, a blade's cut
  const char* button = blade ? "cut" : "grasp";
  for (pugi::xml_node w : n.children("waypoint")) {
    check_attributes(w, {"t", "x", "y", "z", "grasp", "cut", "axis"});
    check_no_text(w);
    if (w.attribute(blade ? "grasp" : "cut"))
      fail(w, blade ? "a blade does not grasp: its button is cut=\"true\""
                    : "cut= is a blade's button (kind=\"blade\"); a probe's is grasp=");
    Waypoint wp{real(w, "t"), {real(w, "x"), real(w, "y"), real(w, "z")}};
    if (const pugi::xml_attribute g = w.attribute(button)) {
      const std::string b = g.value();
      if (b != "true" && b != "false" && b != "1" && b != "0")
        fail(w, fmt::format("waypoint {} = '{}' must be true or false (the {} button)", button, g.value(), button));
      wp.grasp = b == "true" || b == "1";
    }
    if (w.attribute("axis")) {
      double a[3];
      triple(w, "axis", a);
      wp.axis = {a[0], a[1], a[2]};
    }
    t.path.push_back(wp);
  }
  if (n.attribute("path")) {
    if (!t.path.empty()) fail(n, "give either path=\"file.csv\" or <waypoint> children, not both");
    t.path_file = n.attribute("path").value();
    try {
      t.path = read_path_csv(resolve(base_dir_, t.path_file));
    } catch (const PathCsvError& e) {
      fail(n, fmt::format("tool '{}' path file '{}': {}", t.name, t.path_file, e.what()));
    }
  }
  return t;
}

scene::Solver Reader::read_solver(pugi::xml_node n) const {
  check_attributes(n, {"backend", "precision", "dt", "dt-safety", "mass-scaling", "damping", "depth", "tick",
                       "residual-tol", "kinetic-tol", "ianp", "lip-contact", "step-guard"});
  check_no_text(n);
  scene::Solver v;
  v.line = line(n);
  if (n.attribute("backend")) v.backend = n.attribute("backend").value();
  if (const pugi::xml_attribute a = n.attribute("precision")) {
    const std::string_view p = scene::trim(a.value());
    if (p != "float" && p != "double") fail(n, fmt::format("precision = '{}' must be float or double", a.value()));
    v.precision = p == "float" ? Precision::Float : Precision::Double;
  }
  v.dt = real_or_auto(n, "dt", v.dt);
  v.dt_safety = real_or(n, "dt-safety", v.dt_safety);
  if (const pugi::xml_attribute a = n.attribute("mass-scaling")) {
    const auto f = scene::parse_real(a.value());
    if (scene::trim(a.value()) == "off")
      v.mass_scaling = 0;
    else if (f)
      v.mass_scaling = *f;
    else
      fail(n, fmt::format("mass-scaling = '{}' is neither a number (a fraction of the total mass) nor \"off\"",
                          a.value()));
  }
  v.damping = real_or_auto(n, "damping", v.damping);
  if (const pugi::xml_attribute a = n.attribute("depth")) {
    const std::string_view d = scene::trim(a.value());
    const auto k = scene::parse_integer(d);
    if (d == "all")
      v.depth = kDepthAll;
    else if (d == "auto")
      v.depth = kDepthAuto;
    else if (k && *k >= 0 && *k <= std::numeric_limits<int>::max())
      v.depth = int(*k);
    else if (k)
      fail(n, fmt::format("depth = {} must be >= 0 (rings around the contact), or \"all\" or \"auto\"", *k));
    else
      fail(n, fmt::format("depth = '{}' is neither a whole number nor \"all\" nor \"auto\"", a.value()));
  }
  v.tick = real_or(n, "tick", v.tick);
  v.residual_tol = real_or(n, "residual-tol", v.residual_tol);
  v.kinetic_tol = real_or(n, "kinetic-tol", v.kinetic_tol);
  if (const pugi::xml_attribute a = n.attribute("ianp")) {
    const std::string_view b = scene::trim(a.value());
    if (b != "true" && b != "false") fail(n, fmt::format("ianp = '{}' must be true or false", a.value()));
    v.ianp = b == "true";
  }
  if (const pugi::xml_attribute a = n.attribute("lip-contact")) {
    const std::string_view b = scene::trim(a.value());
    if (b != "true" && b != "false") fail(n, fmt::format("lip-contact = '{}' must be true or false", a.value()));
    v.lip_contact = b == "true";
  }
  if (const pugi::xml_attribute a = n.attribute("step-guard")) {
    const std::string_view b = scene::trim(a.value());
    if (b != "true" && b != "false") fail(n, fmt::format("step-guard = '{}' must be true or false", a.value()));
    v.step_guard = b == "true";
  }
  return v;
}

scene::Scene Reader::read() {
  pugi::xml_document doc;
  const pugi::xml_parse_result r = doc.load_buffer(xml_.data(), xml_.size(), pugi::parse_default);
  if (!r) fail_at(line_of(r.offset), fmt::format("malformed XML: {}", r.description()));
  pugi::xml_node root;
  for (pugi::xml_node c : doc.children()) {
    if (c.type() != pugi::node_element) continue;
    if (root) fail_at(line(c), fmt::format("a second root element <{}>; a file holds one <tissue-scene>", c.name()));
    if (std::string_view(c.name()) != "tissue-scene")
      fail_at(line(c), fmt::format("the root element is <{}>; expected <tissue-scene>", c.name()));
    root = c;
  }
  if (!root) fail_at(0, "no <tissue-scene> element");
  check_attributes(root, {"version"});
  if (root.attribute("version") && scene::trim(root.attribute("version").value()) != "1")
    fail(root, fmt::format("version = '{}' is not supported; this reader knows version 1",
                           root.attribute("version").value()));
  check_children(root, {"mesh", "body", "material", "element-set", "fixed", "load", "tool", "contact", "solver"});

  scene::Scene s;
  s.source = source_;
  const pugi::xml_node mesh = root.child("mesh"), body = root.child("body");
  if (body) {  // several bodies: each holds its mesh, element sets, supports and loads
    if (mesh)
      fail_at(line(mesh), "a <mesh> beside <body> elements; a scene has either one <mesh> or <body>s each with "
                          "its own <mesh>");
    for (const char* inner : {"element-set", "fixed", "load"})
      if (const pugi::xml_node c = root.child(inner))
        fail_at(line(c), fmt::format("<{}> outside a <body>; in a scene of bodies it goes inside the <body> whose "
                                     "mesh it refers to",
                                     inner));
    for (pugi::xml_node n : root.children("body")) read_body(n, s);
  } else {
    if (!mesh) fail(root, "no <mesh>; a scene needs one (or <body>s, each with its own <mesh>)");
    if (mesh.next_sibling("mesh"))
      fail_at(line(mesh.next_sibling("mesh")),
              "a second <mesh>; a scene has one (for several bodies, give each its <body>)");
    read_mesh(mesh, s);
    for (pugi::xml_node n : root.children("material")) s.materials.push_back(read_material(n));
    for (pugi::xml_node n : root.children("element-set")) s.sets.push_back(read_set(n));
    for (pugi::xml_node n : root.children("fixed")) s.constraints.push_back(read_fixed(n));
    for (pugi::xml_node n : root.children("load")) s.loads.push_back(read_load(n));
  }
  if (body)
    for (pugi::xml_node n : root.children("material")) s.materials.push_back(read_material(n));
  for (pugi::xml_node n : root.children("tool")) s.tools.push_back(read_tool(n));
  for (pugi::xml_node n : root.children("contact")) {
    if (!body) fail(n, "<contact> names bodies that touch; a scene of one <mesh> has none (give each its <body>)");
    check_attributes(n, {"bodies", "friction"});
    check_children(n, {});
    check_no_text(n);
    scene::BodyContact c;
    c.line = line(n);
    if (!n.attribute("bodies")) fail(n, "<contact> needs bodies=\"a b\": the two bodies that touch");
    std::istringstream names(n.attribute("bodies").value());
    std::vector<std::string> got;
    for (std::string w; names >> w;) got.push_back(w);
    if (got.size() != 2)
      fail(n, fmt::format("<contact> bodies = '{}' names {} bodies; it names two", n.attribute("bodies").value(),
                          got.size()));
    c.a = got[0];
    c.b = got[1];
    c.friction = real_or(n, "friction", c.friction);
    s.contacts.push_back(c);
  }
  if (const pugi::xml_node n = root.child("solver")) {
    if (n.next_sibling("solver")) fail_at(line(n.next_sibling("solver")), "a second <solver>; a scene has one");
    s.solver = read_solver(n);
  }
  return s;
}

// ---- writing ---------------------------------------------------------------

std::string num(double v) {
  return fmt::format("{}", v);
}

std::string triple_text(const double v[3]) {
  return fmt::format("{} {} {}", v[0], v[1], v[2]);
}

std::string triple_text(const Vec3<double>& v) {
  return fmt::format("{} {} {}", v.x, v.y, v.z);
}

std::string id_list(const std::vector<index_t>& ids) {
  return fmt::format("{}", fmt::join(ids, " "));
}

void set(pugi::xml_node n, const char* name, const std::string& value) {
  n.append_attribute(name) = value.c_str();
}

/// A <mesh> under `parent`: `file` when given, else inline; nodes xyz, tets
/// less `first` (a body's local ids).
void write_mesh(pugi::xml_node parent, std::span<const double> nodes, std::span<const index_t> tets, index_t first,
                const std::string& file) {
  pugi::xml_node mesh = parent.append_child("mesh");
  if (!file.empty()) {
    set(mesh, "file", file);
    return;
  }
  std::string text = "\n";
  for (size_t i = 0; i + 2 < nodes.size(); i += 3)
    text += fmt::format("      {} {} {}\n", nodes[i], nodes[i + 1], nodes[i + 2]);
  mesh.append_child("nodes").text() = (text + "    ").c_str();
  text = "\n";
  for (size_t e = 0; e + 3 < tets.size(); e += 4)
    text += fmt::format("      {} {} {} {}\n", tets[e] - first, tets[e + 1] - first, tets[e + 2] - first,
                        tets[e + 3] - first);
  mesh.append_child("elements").text() = (text + "    ").c_str();
}

std::span<const double> body_nodes(const scene::Scene& s, const scene::Body& b) {
  return std::span<const double>(s.nodes).subspan(3 * size_t(b.first_node), 3 * size_t(b.n_nodes));
}
std::span<const index_t> body_tets(const scene::Scene& s, const scene::Body& b) {
  return std::span<const index_t>(s.tets).subspan(4 * size_t(b.first_element), 4 * size_t(b.n_elements));
}

/// The mesh file of body k beside a scene whose single mesh would be `file`:
/// the body's own, else "<stem of file>-<body name>.node" (characters other
/// than letters, digits, '-' and '_' in the name become '_').
std::string body_mesh_file(const scene::Body& b, const std::string& file) {
  if (!b.mesh_file.empty()) return b.mesh_file;
  std::string name = b.name;
  for (char& c : name)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '_') c = '_';
  const fs::path p(file);
  return (p.parent_path() / (p.stem().string() + "-" + name + ".node")).string();
}

void write_material(pugi::xml_node root, const Material& m) {
  static constexpr const char* kNames[3][2] = {{"E", "nu"}, {"mu", "K"}, {"lambda", "mu"}};
  pugi::xml_node n = root.append_child("material");
  set(n, "name", m.name);
  set(n, kNames[int(m.form)][0], num(m.a));
  set(n, kNames[int(m.form)][1], num(m.b));
  set(n, "rho", num(m.rho));
  if (m.fibre_eta > 0 || m.fibre_line > 0 || m.fibre_field != Material::FibreField::Uniform) {
    pugi::xml_node f = n.append_child("fibre");
    set(f, "stiffness", num(m.fibre_eta));
    switch (m.fibre_field) {
      case Material::FibreField::Uniform:
        set(f, "direction", triple_text(m.fibre_dir));
        break;
      case Material::FibreField::Circumferential:
      case Material::FibreField::Radial:
        set(f, "field", std::string(scene::to_string(m.fibre_field)));
        set(f, "axis", triple_text(m.fibre_axis));
        set(f, "origin", triple_text(m.fibre_origin));
        break;
      case Material::FibreField::File:
        set(f, "file", m.fibre_file);
        set(f, "direction", triple_text(m.fibre_dir));
        break;
    }
  }
  for (const Material::Prony& t : m.prony) {
    pugi::xml_node p = n.append_child("prony");
    set(p, "g", num(t.g));
    set(p, "tau", num(t.tau));
  }
}

/// A selection's attributes; node ids less `first` (a body's local ids).
void write_selection(pugi::xml_node n, const Constraint& c, index_t first);

void write_constraint(pugi::xml_node root, const Constraint& c, index_t first) {
  write_selection(root.append_child("fixed"), c, first);
}

void write_load(pugi::xml_node root, const scene::Load& l, index_t first) {
  pugi::xml_node n = root.append_child("load");
  set(n, "force", triple_text(l.force));
  if (l.each) set(n, "distribute", "each");
  write_selection(n, l.where, first);
}

void write_selection(pugi::xml_node n, const Constraint& c, index_t first) {
  switch (c.kind) {
    case Constraint::Kind::Nodes: {
      std::vector<index_t> ids = c.nodes;
      for (index_t& i : ids) i -= first;
      set(n, "nodes", id_list(ids));
      break;
    }
    case Constraint::Kind::Box:
      set(n, "box-min", triple_text(c.lo));
      set(n, "box-max", triple_text(c.hi));
      break;
    case Constraint::Kind::Plane:
      set(n, "plane-point", triple_text(c.point));
      set(n, "plane-normal", triple_text(c.normal));
      break;
  }
}

void write_tool(pugi::xml_node root, const scene::Tool& t) {
  pugi::xml_node n = root.append_child("tool");
  set(n, "name", t.name);
  const bool blade = t.kind == scene::Tool::Kind::Blade;
  if (blade) {
    set(n, "kind", "blade");
    set(n, "length", num(t.shaft));
    set(n, "thickness", num(2 * t.radius));
    set(n, "cut-resistance", num(t.cut_resistance));
    set(n, "cut-delay", num(t.cut_delay));
  } else {
    set(n, "radius", num(t.radius));
    if (t.shaft != 0) set(n, "shaft-length", num(t.shaft));
  }
  if (t.friction != 0) set(n, "friction", num(t.friction));
  set(n, "direction", triple_text(t.direction));
  set(n, "device", t.device);
  if (!t.path_file.empty()) {
    set(n, "path", t.path_file);
    return;
  }
  for (const Waypoint& w : t.path) {
    pugi::xml_node p = n.append_child("waypoint");
    set(p, "t", num(w.t));
    set(p, "x", num(w.p.x));
    set(p, "y", num(w.p.y));
    set(p, "z", num(w.p.z));
    if (w.grasp) set(p, blade ? "cut" : "grasp", "true");
    if (norm(w.axis) > 0) set(p, "axis", triple_text(w.axis));
  }
}

void write_solver(pugi::xml_node root, const scene::Solver& v) {
  pugi::xml_node n = root.append_child("solver");
  set(n, "backend", v.backend);
  set(n, "precision", to_string(v.precision));
  set(n, "dt", v.dt ? num(*v.dt) : "auto");
  set(n, "dt-safety", num(v.dt_safety));
  set(n, "mass-scaling", v.mass_scaling == 0 ? "off" : num(v.mass_scaling));
  set(n, "damping", v.damping ? num(*v.damping) : "auto");
  set(n, "depth", v.depth == kDepthAll ? "all" : v.depth == kDepthAuto ? "auto" : std::to_string(v.depth));
  set(n, "tick", num(v.tick));
  set(n, "residual-tol", num(v.residual_tol));
  set(n, "kinetic-tol", num(v.kinetic_tol));
  set(n, "ianp", v.ianp ? "true" : "false");
  set(n, "lip-contact", v.lip_contact ? "true" : "false");
  set(n, "step-guard", v.step_guard ? "true" : "false");
}

}  // namespace

scene::Scene parse_scene(std::string_view xml, const std::string& source, const std::string& base_dir) {
  return Reader(xml, source, base_dir).read();
}

scene::Scene read_scene(const std::string& path) {
  if (path.empty()) throw SceneError("the scene file's name is empty: give a scene file or @kidney");
  if (const std::string why = io::not_a_file(path); !why.empty()) throw SceneError(path + ": " + why + ", not a scene file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw SceneError(path + ": cannot open the scene file");
  std::ostringstream text;
  text << in.rdbuf();
  return parse_scene(text.str(), path, fs::path(path).parent_path().string());
}

std::string format_scene(const scene::Scene& s, const std::string& mesh_file) {
  pugi::xml_document doc;
  pugi::xml_node decl = doc.append_child(pugi::node_declaration);
  decl.append_attribute("version") = "1.0";
  decl.append_attribute("encoding") = "UTF-8";
  pugi::xml_node root = doc.append_child("tissue-scene");
  root.append_attribute("version") = "1";
  const auto write_set = [](pugi::xml_node parent, const scene::ElementSet& es, index_t first) {
    pugi::xml_node n = parent.append_child("element-set");
    set(n, "name", es.name);
    set(n, "material", es.material);
    std::vector<index_t> ids = es.elements;
    for (index_t& e : ids) e -= first;
    set(n, "elements", es.all ? "all" : id_list(ids));
  };
  if (s.bodies.empty()) {
    write_mesh(root, s.nodes, s.tets, 0, mesh_file);
    for (const Material& m : s.materials) write_material(root, m);
    for (const scene::ElementSet& es : s.sets) write_set(root, es, 0);
    for (const Constraint& c : s.constraints) write_constraint(root, c, 0);
    for (const scene::Load& l : s.loads) write_load(root, l, 0);
  } else {
    for (size_t k = 0; k < s.bodies.size(); ++k) {
      const scene::Body& b = s.bodies[k];
      pugi::xml_node body = root.append_child("body");
      set(body, "name", b.name);
      write_mesh(body, body_nodes(s, b), body_tets(s, b), b.first_node,
                 mesh_file.empty() ? std::string() : body_mesh_file(b, mesh_file));
      for (const scene::ElementSet& es : s.sets)
        if (es.body == int(k)) write_set(body, es, b.first_element);
      for (const Constraint& c : s.constraints)
        if (c.body == int(k)) write_constraint(body, c, b.first_node);
      for (const scene::Load& l : s.loads)
        if (l.where.body == int(k)) write_load(body, l, b.first_node);
    }
    for (const Material& m : s.materials) write_material(root, m);
  }
  for (const scene::Tool& t : s.tools) write_tool(root, t);
  for (const scene::BodyContact& c : s.contacts) {
    pugi::xml_node n = root.append_child("contact");
    set(n, "bodies", c.a + " " + c.b);
    if (c.friction != 0) set(n, "friction", num(c.friction));
  }
  write_solver(root, s.solver);
  std::ostringstream out;
  doc.save(out, "  ", pugi::format_indent, pugi::encoding_utf8);
  return out.str();
}

void write_scene(const scene::Scene& s, const std::string& path, bool inline_mesh) {
  const fs::path dir = fs::path(path).parent_path();
  std::string mesh_file;
  if (!inline_mesh) {
    mesh_file = s.mesh_file.empty() ? fs::path(path).stem().string() + ".node" : s.mesh_file;
    if (s.bodies.empty()) write_tetgen((dir / mesh_file).string(), s.nodes, s.tets);
    for (const scene::Body& b : s.bodies) {
      const auto tets = body_tets(s, b);
      std::vector<index_t> local(tets.begin(), tets.end());
      for (index_t& v : local) v -= b.first_node;
      write_tetgen((dir / body_mesh_file(b, mesh_file)).string(), body_nodes(s, b), local);
    }
  }
  for (const scene::Tool& t : s.tools)
    if (!t.path_file.empty() && !t.path.empty()) write_path_csv((dir / t.path_file).string(), t.path);
  for (const Material& m : s.materials)
    if (m.fibre_field == Material::FibreField::File && !m.fibre_file.empty() && !m.fibre_rows.empty())
      write_fibre_csv((dir / m.fibre_file).string(), m.fibre_rows);
  write_file_atomic(path, format_scene(s, mesh_file));
}

}  // namespace tissue::io
