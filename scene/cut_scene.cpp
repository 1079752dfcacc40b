#include "scene/cut_scene.hpp"

#include <fmt/format.h>

#include <algorithm>

#include "scene/validate.hpp"

namespace tissue::scene {

void check_cuttable(const Scene& scene) {
  if (!scene.bodies.empty())
    throw SceneError(fmt::format("{}: a scene of {} bodies; cutting takes a scene of one mesh", scene.source,
                                 scene.bodies.size()));
}

Scene cut_scene(const Scene& scene, const CutSurface& cut, const CutOptions& options, CutResult* result) {
  check_cuttable(scene);
  CutResult r = cut_along(scene.nodes, scene.tets, cut, options);
  Scene s = scene_after_cut(scene, r);
  if (result) *result = std::move(r);
  return s;
}

Scene scene_after_cut(const Scene& scene, const CutResult& r) {
  Scene s = scene;
  s.nodes = r.nodes;
  s.tets = r.tets;
  s.mesh_file.clear();
  const index_t n0 = index_t(scene.nodes.size() / 3), ne0 = index_t(scene.tets.size() / 4);
  // new elements per input element, new nodes per input node (copies) and edge nodes by their ends
  const auto follow_nodes = [&](std::vector<index_t>& ids) {
    std::vector<std::uint8_t> in(n0, 0);
    for (index_t i : ids)
      if (i >= 0 && i < n0) in[i] = 1;
    std::vector<index_t> out;
    for (index_t i = 0; i < r.n_nodes(); ++i) {
      const auto [a, b] = r.from[i];
      if (in[a] && in[b]) out.push_back(i);
    }
    ids = std::move(out);
  };
  const auto follow_elements = [&](std::vector<index_t>& ids) {
    std::vector<std::uint8_t> in(ne0, 0);
    for (index_t e : ids)
      if (e >= 0 && e < ne0) in[e] = 1;
    std::vector<index_t> out;
    for (index_t e = 0; e < r.n_elements(); ++e)
      if (in[r.element_from[e]]) out.push_back(e);
    ids = std::move(out);
  };
  for (ElementSet& es : s.sets)
    if (!es.all) follow_elements(es.elements);
  for (Constraint& c : s.constraints)
    if (c.kind == Constraint::Kind::Nodes) follow_nodes(c.nodes);
  for (Load& l : s.loads)
    if (l.where.kind == Constraint::Kind::Nodes) follow_nodes(l.where.nodes);
  for (Material& m : s.materials) {
    if (m.fibre_rows.empty()) continue;
    std::vector<std::vector<index_t>> pieces(ne0);
    for (index_t e = 0; e < r.n_elements(); ++e) pieces[r.element_from[e]].push_back(e);
    std::vector<Material::FibreRow> rows;
    for (const Material::FibreRow& row : m.fibre_rows)
      if (row.element >= 0 && row.element < ne0)
        for (index_t e : pieces[row.element]) rows.push_back({e, row.dir, row.line});
    std::sort(rows.begin(), rows.end(), [](const auto& a, const auto& b) { return a.element < b.element; });
    m.fibre_rows = std::move(rows);
  }
  return s;
}

}  // namespace tissue::scene
