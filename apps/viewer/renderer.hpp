// Draws the tissue surface and the glyphs (tool, contact point, force arrow)
// with OpenGL 3.3 core. The tissue is one vertex buffer of the deformed
// positions X + u of all nodes (n_nodes x 3 floats, what
// Backend::write_positions writes) drawn through an index buffer of the
// surface triangles. Smooth shading: the vertex shader forms each node's
// normal from the deformed positions themselves, summing the area-weighted
// normals of its surface triangles (the position buffer read again as a
// texture buffer, the triangles' other corners from a static ring list:
// surface_rings), so no normal buffer has to follow the deformation and
// both the host and the CUDA-interop position paths get it for nothing;
// flat shading takes the normal from screen-space derivatives of the
// position in the fragment shader. A second per-node buffer holds the region role (outside,
// inner, halo) that tints the active region; it changes only when the
// region does. A third holds a colour per node when a field is shown. The
// faces a cut opened (surface_rings.hpp cut_faces) are drawn in a paler
// colour of their own.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "apps/viewer/camera.hpp"
#include "apps/viewer/surface_rings.hpp"
#include "core/model.hpp"
#include "core/region.hpp"

namespace tissue::viewer {

/// What to draw besides the tissue (positions in m, forces in N).
/// One tool as drawn: its capsule at its real size (the tip sphere of
/// radius r and the shaft of length l along the axis), a thin handle beyond
/// it, the hand where the coupling pulls, and the force arrow.
struct ToolGlyph {
  Vec3<double> tool = {};          ///< proxy: the tip centre the tissue feels (m)
  Vec3<double> device = {};        ///< the hand (device) position (m)
  Vec3<double> axis = {0, 0, 1};   ///< unit shaft axis, tip -> handle
  double radius = 1e-3, shaft = 0; ///< m
  bool contact = false, grasp = false;
  Vec3<double> force = {};         ///< force on the tool (N), drawn from the tip
};

struct Glyphs {
  bool show_tool = true;
  std::vector<ToolGlyph> tools;
  double metres_per_newton = 0.05; ///< arrow length per newton
};

/// How the tissue is shaded.
enum class Shading { Smooth, Flat };

class Renderer {
 public:
  /// Creates the buffers for the model's surface (GL context current).
  explicit Renderer(const TissueModel<double>& model);
  ~Renderer();
  Renderer(const Renderer&) = delete;
  Renderer& operator=(const Renderer&) = delete;

  /// The tissue's mesh anew (after a cut): its node buffers resized, its
  /// surface and rings rebuilt, the roles and the field cleared. A position
  /// source registered on the old buffer must be made again.
  void set_mesh(const TissueModel<double>& model);
  /// The tissue's position buffer (GL name), for CUDA registration.
  unsigned position_buffer() const { return vbo_pos_; }
  index_t n_nodes() const { return n_nodes_; }
  /// Replaces the positions from host memory (n_nodes x 3 floats).
  void upload_positions(const float* xyz);
  /// Replaces the node roles (NodeRole, n_nodes); empty: no highlight.
  void upload_roles(std::span<const std::uint8_t> role);
  /// Colours the surface by a field: RGB bytes per node (3 x n_nodes,
  /// apps/viewer/field_view.hpp); empty: the organ's own colour.
  void upload_field_colours(std::span<const std::uint8_t> rgb);
  /// Smooth (per-vertex normals, the default) or flat (per-face) shading.
  void set_shading(Shading s) { shading_ = s; }
  Shading shading() const { return shading_; }

  /// Clears to the background and draws tissue and glyphs into the bound
  /// framebuffer (viewport = camera size).
  void draw(const Camera& camera, const Glyphs& glyphs);

  /// Background colour (linear RGB in 0..1), also what screenshots test for.
  static constexpr float kBackground[3] = {0.11f, 0.12f, 0.15f};

 private:
  struct Mesh {
    unsigned vao = 0, vbo = 0, ibo = 0;
    int count = 0;
  };
  Mesh make_mesh(const std::vector<float>& xyz, const std::vector<unsigned>& idx);
  void draw_glyph(const Mesh& mesh, const Mat4& view_proj, const Mat4& view, const Mat4& model, const float rgb[3]);
  void draw_tool(const ToolGlyph& t, double metres_per_newton, const Mat4& view_proj, const Mat4& view);

  index_t n_nodes_ = 0;
  int n_indices_ = 0;
  int n_cut_indices_ = 0;  ///< the last indices: the faces a cut made (cut_faces)
  unsigned program_ = 0;
  unsigned vao_ = 0, vbo_pos_ = 0, vbo_role_ = 0, vbo_field_ = 0, vbo_ring_ = 0, ibo_ = 0;
  unsigned tbo_corners_ = 0, tex_pos_ = 0, tex_corners_ = 0;  ///< the ring list and the texture views
  bool field_shown_ = false;
  Shading shading_ = Shading::Smooth;
  Mesh sphere_, cylinder_, cone_;
  int u_mvp_ = -1, u_mv_ = -1, u_color_ = -1, u_tint_ = -1, u_field_ = -1, u_smooth_ = -1;
};

/// An offscreen render target of the given size (4x multisampled colour and
/// depth, resolved for reading). Binds itself for drawing on construction.
class OffscreenTarget {
 public:
  OffscreenTarget(int width, int height);
  ~OffscreenTarget();
  OffscreenTarget(const OffscreenTarget&) = delete;
  OffscreenTarget& operator=(const OffscreenTarget&) = delete;
  void bind();
  /// Resolves and reads the picture as RGB rows, top row first (w x h x 3).
  std::vector<std::uint8_t> read_rgb();
  int width() const { return w_; }
  int height() const { return h_; }

 private:
  int w_, h_;
  unsigned fbo_ms_ = 0, color_ms_ = 0, depth_ms_ = 0, fbo_ = 0, color_ = 0;
};

}  // namespace tissue::viewer
