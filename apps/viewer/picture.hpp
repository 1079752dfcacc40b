// Headless pictures: the PNG (stb_image_write from libstb-dev) and a JSON
// sidecar "<picture>.json" with what a test needs to judge it: where the
// tool, the contact point and the organ's bounds project in pixels, the
// overlay's rectangle, the force and the contact state.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "apps/viewer/camera.hpp"
#include "haptics/haptic_loop.hpp"

namespace tissue::viewer {

/// Writes rgb (w x h x 3 bytes, top row first) as a PNG; throws
/// std::runtime_error naming the path when it cannot.
void write_png(const std::string& path, int w, int h, const std::vector<std::uint8_t>& rgb);

/// The sidecar's content.
struct PictureFacts {
  int width = 0, height = 0;
  std::string backend, precision, positions;
  HapticSnapshot snap;
  double tool_px[2] = {0, 0};
  double device_px[2] = {0, 0};
  double organ_px[4] = {0, 0, 0, 0};   ///< projected bounds: x0, y0, x1, y1
  bool overlay = false;
  float overlay_px[4] = {0, 0, 0, 0};  ///< x0, y0, x1, y1
  bool tool_shown = true, region_shown = true;
  std::string field = "none";           ///< the surface's field (field_name)
  double field_range[2] = {0, 0};       ///< its colour map's ends
  long force_samples = 0;               ///< points of the overlay's force plot
  long nodes = 0, cut_triangles = 0;    ///< the mesh drawn: its nodes, the surface triangles a cut made
};

/// The sidecar as JSON text.
std::string picture_json(const PictureFacts& f);

/// Pixel box of the 8 corners of [lo, hi] seen by the camera.
void project_box(const Camera& c, Vec3<double> lo, Vec3<double> hi, double box[4]);

}  // namespace tissue::viewer
