#include "apps/viewer/picture.hpp"

#include <fmt/format.h>
#include <stb/stb_image_write.h>

#include <algorithm>
#include <cstdio>
#include <limits>
#include <stdexcept>

#include "io/atomic_file.hpp"

namespace tissue::viewer {

void write_png(const std::string& path, int w, int h, const std::vector<std::uint8_t>& rgb) {
  if (rgb.size() != 3 * size_t(w) * size_t(h))
    throw std::invalid_argument(fmt::format("write_png: {} bytes for a {}x{} RGB picture", rgb.size(), w, h));
  const std::string part = io::part_path(path);  // renamed into place when whole
  if (!stbi_write_png(part.c_str(), w, h, 3, rgb.data(), 3 * w)) {
    std::remove(part.c_str());
    throw std::runtime_error(fmt::format("tissue view: cannot write the picture {}", path));
  }
  io::rename_into_place(part, path);
}

namespace {

/// A JSON string body: quotes and backslashes escaped, control characters dropped.
std::string escaped(const std::string& s) {
  std::string out;
  for (char c : s) {
    if (c == '"' || c == '\\') out += '\\';
    if (static_cast<unsigned char>(c) >= 0x20) out += c;
  }
  return out;
}

}  // namespace

std::string picture_json(const PictureFacts& f) {
  const HapticSnapshot& s = f.snap;
  const bool contact = s.contact_nodes > 0;
  auto vec = [](Vec3<double> v) { return fmt::format("[{:.9g}, {:.9g}, {:.9g}]", v.x, v.y, v.z); };
  return fmt::format(
      "{{\n"
      "  \"width\": {}, \"height\": {},\n"
      "  \"backend\": \"{}\", \"precision\": \"{}\", \"positions\": \"{}\",\n"
      "  \"ticks\": {}, \"time\": {:.6f},\n"
      "  \"contact\": {}, \"contact_nodes\": {}, \"tool_radius\": {:.9g},\n"
      "  \"tool\": {}, \"device\": {},\n"
      "  \"tool_px\": [{:.2f}, {:.2f}], \"device_px\": [{:.2f}, {:.2f}],\n"
      "  \"contact_px\": {},\n"
      "  \"organ_px\": [{:.2f}, {:.2f}, {:.2f}, {:.2f}],\n"
      "  \"overlay_px\": {},\n"
      "  \"tool_shown\": {}, \"region_shown\": {},\n"
      "  \"tissue_force\": {}, \"rendered_force\": {},\n"
      "  \"region_nodes\": {}, \"region_elements\": {}, \"max_displacement\": {:.9g},\n"
      "  \"field\": \"{}\", \"field_range\": [{:.9g}, {:.9g}], \"force_samples\": {},\n"
      "  \"nodes\": {}, \"cuts\": {}, \"cut_triangles\": {}\n"
      "}}\n",
      f.width, f.height, escaped(f.backend), escaped(f.precision), escaped(f.positions), s.tick, s.time, contact ? "true" : "false",
      s.contact_nodes, s.tools[0].radius, vec(s.tool), vec(s.device), f.tool_px[0], f.tool_px[1], f.device_px[0], f.device_px[1],
      contact ? fmt::format("[{:.2f}, {:.2f}]", f.tool_px[0], f.tool_px[1]) : "null", f.organ_px[0], f.organ_px[1],
      f.organ_px[2], f.organ_px[3],
      f.overlay ? fmt::format("[{:.1f}, {:.1f}, {:.1f}, {:.1f}]", f.overlay_px[0], f.overlay_px[1], f.overlay_px[2],
                              f.overlay_px[3])
                : "null",
      f.tool_shown ? "true" : "false", f.region_shown ? "true" : "false", vec(s.tissue_force), vec(s.rendered_force),
      s.region.nodes(), s.region.n_elems, s.max_disp, escaped(f.field), f.field_range[0], f.field_range[1],
      f.force_samples, f.nodes, s.cuts, f.cut_triangles);
}

void project_box(const Camera& c, Vec3<double> lo, Vec3<double> hi, double box[4]) {
  const double inf = std::numeric_limits<double>::infinity();
  box[0] = box[1] = inf;
  box[2] = box[3] = -inf;
  for (int k = 0; k < 8; ++k) {
    const Vec3<double> p{k & 1 ? hi.x : lo.x, k & 2 ? hi.y : lo.y, k & 4 ? hi.z : lo.z};
    double x, y;
    c.project(p, &x, &y, nullptr);
    box[0] = std::min(box[0], x);
    box[1] = std::min(box[1], y);
    box[2] = std::max(box[2], x);
    box[3] = std::max(box[3], y);
  }
}

}  // namespace tissue::viewer
