// Per-element fibre directions of a scene (docs/scene-format.md, <fibre>):
// a material's <fibre> gives one direction (direction=), a field evaluated
// at each element's centroid (field="circumferential" | "radial" with axis=
// and origin=), or a direction per element read from a CSV file (file=).
// to_model_input resolves them into ModelInput::fibre_dirs once the mesh
// and the element sets are known; build_model normalises them.
#pragma once

#include <optional>
#include <string_view>
#include <vector>

#include "scene/scene.hpp"

namespace tissue::scene {

/// The scene format's name of a field: "uniform", "circumferential",
/// "radial" or "file".
std::string_view to_string(Material::FibreField field);

/// The field named by `name` among those given by field= (circumferential,
/// radial); nullopt for any other name.
std::optional<Material::FibreField> parse_fibre_field(std::string_view name);

/// The (unnormalised) direction a Circumferential or Radial field gives at
/// point c, for an axis through `origin` along `axis` (any length but 0):
/// circumferential: a = axis^ x (c - origin); radial: d - (d . axis^) axis^
/// with d = c - origin. Its length is c's distance from the axis (zero on
/// the axis, where the direction is undefined). Uniform and File give {0, 0, 0}.
Vec3<double> fibre_field_direction(Material::FibreField field, Vec3<double> axis, Vec3<double> origin,
                                   Vec3<double> c);

/// The rows of the fibre file of a material, resolved per element, and the
/// fields evaluated at the centroids: one direction per element (n_elems x 3,
/// xyz interleaved, not normalised), elem_material[e] being the element's
/// index into scene.materials. Elements of a Uniform material, and those of
/// a File material that the file does not list, take the material's
/// fibre_dir. Empty when every material is Uniform (ModelInput: each set's
/// direction). Throws SceneError citing the file's line for a row whose
/// element is out of range or listed twice or whose direction is zero or not
/// finite, a file listing none of its material's elements, and, at the
/// <fibre>'s line, a field whose element centroid lies on the axis (within
/// 1e-9 x the mesh's bounding-box diagonal). Expects a checked mesh.
std::vector<double> resolve_fibre_dirs(const Scene& scene, const std::vector<index_t>& elem_material);

}  // namespace tissue::scene
