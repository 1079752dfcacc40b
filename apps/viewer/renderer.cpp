#include "apps/viewer/renderer.hpp"

#include <GL/glew.h>
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>

namespace tissue::viewer {
namespace {

constexpr double kPi = 3.14159265358979323846;

const char* kVertexShader = R"(#version 330 core
layout(location = 0) in vec3 a_pos;
layout(location = 1) in vec2 a_role;  // (inner, halo) in 0..1
layout(location = 2) in vec3 a_field; // the field's colour at the node
layout(location = 3) in ivec2 a_ring; // (first, count) of the node's surface triangles in u_corners
uniform mat4 u_mvp;
uniform mat4 u_mv;
uniform int u_smooth;
uniform samplerBuffer u_pos;       // the position buffer itself, one float per texel
uniform isamplerBuffer u_corners;  // per (triangle, corner): the other two corners, outward order
out vec3 v_view;
out vec2 v_role;
out vec3 v_field;
out vec3 v_normal;
vec3 node(int i) {
  return vec3(texelFetch(u_pos, 3 * i).r, texelFetch(u_pos, 3 * i + 1).r, texelFetch(u_pos, 3 * i + 2).r);
}
void main() {
  v_view = (u_mv * vec4(a_pos, 1.0)).xyz;
  v_role = a_role;
  v_field = a_field;
  vec3 n = vec3(0.0);  // the area-weighted normal of the node's triangles, from the deformed positions
  if (u_smooth != 0)
    for (int k = 0; k < a_ring.y; ++k) {
      ivec2 bc = texelFetch(u_corners, a_ring.x + k).rg;
      n += cross(node(bc.x) - a_pos, node(bc.y) - a_pos);
    }
  v_normal = mat3(u_mv) * n;
  gl_Position = u_mvp * vec4(a_pos, 1.0);
}
)";

// The vertex's smooth normal, or (flat shading, and the glyphs) the normal
// from the derivatives of the view-space position turned to the viewer
// (two-sided); a key light above-right of the eye, a fill light from
// the eye, a little specular. Region tint: inner warm, halo blue. With a
// field shown, the field's colour replaces the organ's (and the tint).
const char* kFragmentShader = R"(#version 330 core
in vec3 v_view;
in vec2 v_role;
in vec3 v_field;
in vec3 v_normal;
uniform vec3 u_color;
uniform float u_tint;
uniform float u_field;
uniform int u_smooth;
out vec4 frag;
void main() {
  vec3 v = normalize(-v_view);
  vec3 n;
  if (u_smooth != 0 && dot(v_normal, v_normal) > 0.0) {
    n = normalize(v_normal);         // outward; seen from inside the body, the inner side's
    if (!gl_FrontFacing) n = -n;
  } else {
    n = normalize(cross(dFdx(v_view), dFdy(v_view)));
    if (dot(n, v) < 0.0) n = -n;
  }
  vec3 L = normalize(vec3(0.35, 0.55, 1.0));
  float key = max(dot(n, L), 0.0);
  float fill = max(dot(n, v), 0.0);
  float spec = pow(max(dot(n, normalize(L + v)), 0.0), 48.0);
  vec3 base = mix(u_color, vec3(1.0, 0.80, 0.30), 0.45 * u_tint * v_role.x);
  base = mix(base, vec3(0.35, 0.60, 1.0), 0.45 * u_tint * v_role.y);
  base = mix(base, v_field, u_field);
  frag = vec4(base * (0.18 + 0.62 * key + 0.25 * fill) + vec3(0.18) * spec, 1.0);
}
)";

constexpr float kOrgan[3] = {0.66f, 0.25f, 0.21f};
constexpr float kCutFace[3] = {0.93f, 0.62f, 0.52f};  // a cut's faces: the paler parenchyma under the capsule
constexpr float kTool[3] = {0.76f, 0.78f, 0.82f};
constexpr float kDevice[3] = {0.36f, 0.37f, 0.42f};
constexpr float kContact[3] = {0.25f, 0.90f, 0.35f};
constexpr float kGrasp[3] = {0.98f, 0.62f, 0.20f};
constexpr float kArrow[3] = {0.20f, 0.78f, 0.98f};

unsigned compile(GLenum type, const char* src) {
  const unsigned s = glCreateShader(type);
  glShaderSource(s, 1, &src, nullptr);
  glCompileShader(s);
  GLint ok = 0;
  glGetShaderiv(s, GL_COMPILE_STATUS, &ok);
  if (!ok) {
    char log[2048];
    glGetShaderInfoLog(s, sizeof log, nullptr, log);
    throw std::runtime_error(fmt::format("tissue view: shader compilation failed: {}", log));
  }
  return s;
}

unsigned link_program() {
  const unsigned vs = compile(GL_VERTEX_SHADER, kVertexShader), fs = compile(GL_FRAGMENT_SHADER, kFragmentShader);
  const unsigned p = glCreateProgram();
  glAttachShader(p, vs);
  glAttachShader(p, fs);
  glLinkProgram(p);
  glDeleteShader(vs);
  glDeleteShader(fs);
  GLint ok = 0;
  glGetProgramiv(p, GL_LINK_STATUS, &ok);
  if (!ok) {
    char log[2048];
    glGetProgramInfoLog(p, sizeof log, nullptr, log);
    throw std::runtime_error(fmt::format("tissue view: shader link failed: {}", log));
  }
  return p;
}

void put(std::vector<float>& v, double x, double y, double z) {
  v.push_back(float(x));
  v.push_back(float(y));
  v.push_back(float(z));
}

/// Unit sphere (radius 1 at the origin), latitude-longitude.
void sphere(std::vector<float>& xyz, std::vector<unsigned>& idx, int stacks, int slices) {
  for (int i = 0; i <= stacks; ++i)
    for (int j = 0; j <= slices; ++j) {
      const double th = kPi * i / stacks, ph = 2 * kPi * j / slices;
      put(xyz, std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph), std::cos(th));
    }
  for (int i = 0; i < stacks; ++i)
    for (int j = 0; j < slices; ++j) {
      const unsigned a = i * (slices + 1) + j, b = a + slices + 1;
      idx.insert(idx.end(), {a, b, a + 1, a + 1, b, b + 1});
    }
}

/// Unit cylinder (radius 1, z in [0, 1]) with caps; or a cone (tip at z = 1).
void cylinder(std::vector<float>& xyz, std::vector<unsigned>& idx, int slices, bool cone) {
  for (int j = 0; j <= slices; ++j) {
    const double ph = 2 * kPi * j / slices, c = std::cos(ph), s = std::sin(ph);
    put(xyz, c, s, 0);
    put(xyz, cone ? 0 : c, cone ? 0 : s, 1);
  }
  const unsigned bottom = unsigned(xyz.size() / 3), top = bottom + 1;
  put(xyz, 0, 0, 0);
  put(xyz, 0, 0, 1);
  for (int j = 0; j < slices; ++j) {
    const unsigned a = 2 * j, b = a + 2;
    idx.insert(idx.end(), {a, b, a + 1, a + 1, b, b + 1, bottom, b, a});
    if (!cone) idx.insert(idx.end(), {top, a + 1, b + 1});
  }
}

}  // namespace

Renderer::Renderer(const TissueModel<double>& model) : n_nodes_(model.n_nodes) {
  program_ = link_program();
  u_mvp_ = glGetUniformLocation(program_, "u_mvp");
  u_mv_ = glGetUniformLocation(program_, "u_mv");
  u_color_ = glGetUniformLocation(program_, "u_color");
  u_tint_ = glGetUniformLocation(program_, "u_tint");
  u_field_ = glGetUniformLocation(program_, "u_field");
  u_smooth_ = glGetUniformLocation(program_, "u_smooth");
  glUseProgram(program_);
  glUniform1i(glGetUniformLocation(program_, "u_pos"), 0);      // texture unit 0
  glUniform1i(glGetUniformLocation(program_, "u_corners"), 1);  // texture unit 1
  glUseProgram(0);

  // the tissue's buffers, filled by set_mesh
  glGenVertexArrays(1, &vao_);
  glBindVertexArray(vao_);
  glGenBuffers(1, &vbo_pos_);
  glBindBuffer(GL_ARRAY_BUFFER, vbo_pos_);
  glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 3 * sizeof(float), nullptr);
  glEnableVertexAttribArray(0);
  glGenBuffers(1, &vbo_role_);
  glBindBuffer(GL_ARRAY_BUFFER, vbo_role_);
  glVertexAttribPointer(1, 2, GL_UNSIGNED_BYTE, GL_TRUE, 2, nullptr);
  glEnableVertexAttribArray(1);
  glGenBuffers(1, &vbo_field_);
  glBindBuffer(GL_ARRAY_BUFFER, vbo_field_);
  glVertexAttribPointer(2, 3, GL_UNSIGNED_BYTE, GL_TRUE, 3, nullptr);
  glEnableVertexAttribArray(2);
  glGenBuffers(1, &vbo_ring_);
  glBindBuffer(GL_ARRAY_BUFFER, vbo_ring_);
  glVertexAttribIPointer(3, 2, GL_INT, 2 * sizeof(std::int32_t), nullptr);
  glEnableVertexAttribArray(3);
  glGenBuffers(1, &tbo_corners_);
  glGenTextures(1, &tex_pos_);
  glGenTextures(1, &tex_corners_);
  glGenBuffers(1, &ibo_);
  glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, ibo_);
  glBindVertexArray(0);
  set_mesh(model);

  std::vector<float> v;
  std::vector<unsigned> i;
  sphere(v, i, 16, 32);
  sphere_ = make_mesh(v, i);
  v.clear();
  i.clear();
  cylinder(v, i, 24, false);
  cylinder_ = make_mesh(v, i);
  v.clear();
  i.clear();
  cylinder(v, i, 24, true);
  cone_ = make_mesh(v, i);
}

Renderer::~Renderer() {
  for (Mesh* m : {&sphere_, &cylinder_, &cone_}) {
    glDeleteVertexArrays(1, &m->vao);
    glDeleteBuffers(1, &m->vbo);
    glDeleteBuffers(1, &m->ibo);
  }
  glDeleteVertexArrays(1, &vao_);
  const unsigned textures[2] = {tex_pos_, tex_corners_};
  glDeleteTextures(2, textures);
  const unsigned buffers[6] = {vbo_pos_, vbo_role_, vbo_field_, vbo_ring_, tbo_corners_, ibo_};
  glDeleteBuffers(6, buffers);
  glDeleteProgram(program_);
}

void Renderer::set_mesh(const TissueModel<double>& model) {
  n_nodes_ = model.n_nodes;
  // positions of all nodes (reference until the first upload)
  std::vector<float> xyz(3 * size_t(n_nodes_));
  for (index_t i = 0; i < n_nodes_; ++i)
    for (int c = 0; c < 3; ++c) xyz[3 * i + c] = float(model.X[c * size_t(n_nodes_) + i]);
  // the surface triangles, those a cut made after the others (drawn in their own colour)
  const std::vector<std::uint8_t> cut = cut_faces(model);
  std::vector<unsigned> idx;
  idx.reserve(3 * size_t(model.n_tris));
  for (int pass = 0; pass < 2; ++pass)
    for (index_t t = 0; t < model.n_tris; ++t)
      if (cut[std::size_t(t)] == pass)
        for (int v = 0; v < 3; ++v) idx.push_back(unsigned(model.tris[v * size_t(model.n_tris) + t]));
  n_indices_ = int(idx.size());
  n_cut_indices_ = 3 * int(std::count(cut.begin(), cut.end(), std::uint8_t(1)));
  glBindVertexArray(vao_);
  glBindBuffer(GL_ARRAY_BUFFER, vbo_pos_);
  glBufferData(GL_ARRAY_BUFFER, xyz.size() * sizeof(float), xyz.data(), GL_DYNAMIC_DRAW);
  glBindBuffer(GL_ARRAY_BUFFER, vbo_role_);
  glBufferData(GL_ARRAY_BUFFER, 2 * size_t(n_nodes_), nullptr, GL_DYNAMIC_DRAW);
  glBindBuffer(GL_ARRAY_BUFFER, vbo_field_);
  glBufferData(GL_ARRAY_BUFFER, 3 * size_t(n_nodes_), nullptr, GL_DYNAMIC_DRAW);
  const SurfaceRings rings = surface_rings(model);
  glBindBuffer(GL_ARRAY_BUFFER, vbo_ring_);
  glBufferData(GL_ARRAY_BUFFER, rings.range.size() * sizeof(std::int32_t), rings.range.data(), GL_STATIC_DRAW);
  glBindBuffer(GL_TEXTURE_BUFFER, tbo_corners_);
  glBufferData(GL_TEXTURE_BUFFER, std::max<std::size_t>(rings.corners.size(), 2) * sizeof(std::int32_t),
               rings.corners.empty() ? nullptr : rings.corners.data(), GL_STATIC_DRAW);
  glBindBuffer(GL_TEXTURE_BUFFER, 0);
  glBindTexture(GL_TEXTURE_BUFFER, tex_pos_);
  glTexBuffer(GL_TEXTURE_BUFFER, GL_R32F, vbo_pos_);
  glBindTexture(GL_TEXTURE_BUFFER, tex_corners_);
  glTexBuffer(GL_TEXTURE_BUFFER, GL_RG32I, tbo_corners_);
  glBindTexture(GL_TEXTURE_BUFFER, 0);
  glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, ibo_);
  glBufferData(GL_ELEMENT_ARRAY_BUFFER, idx.size() * sizeof(unsigned), idx.data(), GL_STATIC_DRAW);
  glBindVertexArray(0);
  glBindBuffer(GL_ARRAY_BUFFER, 0);
  field_shown_ = false;
  upload_roles({});
}

Renderer::Mesh Renderer::make_mesh(const std::vector<float>& xyz, const std::vector<unsigned>& idx) {
  Mesh m;
  m.count = int(idx.size());
  glGenVertexArrays(1, &m.vao);
  glBindVertexArray(m.vao);
  glGenBuffers(1, &m.vbo);
  glBindBuffer(GL_ARRAY_BUFFER, m.vbo);
  glBufferData(GL_ARRAY_BUFFER, xyz.size() * sizeof(float), xyz.data(), GL_STATIC_DRAW);
  glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 3 * sizeof(float), nullptr);
  glEnableVertexAttribArray(0);
  glVertexAttrib2f(1, 0, 0);  // no region role on glyphs
  glVertexAttrib3f(2, 0, 0, 0);  // nor a field
  glVertexAttribI2i(3, 0, 0);    // nor a ring (they are shaded flat)
  glGenBuffers(1, &m.ibo);
  glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, m.ibo);
  glBufferData(GL_ELEMENT_ARRAY_BUFFER, idx.size() * sizeof(unsigned), idx.data(), GL_STATIC_DRAW);
  glBindVertexArray(0);
  return m;
}

void Renderer::upload_positions(const float* xyz) {
  glBindBuffer(GL_ARRAY_BUFFER, vbo_pos_);
  glBufferSubData(GL_ARRAY_BUFFER, 0, 3 * sizeof(float) * size_t(n_nodes_), xyz);
  glBindBuffer(GL_ARRAY_BUFFER, 0);
}

void Renderer::upload_roles(std::span<const std::uint8_t> role) {
  std::vector<std::uint8_t> pairs(2 * size_t(n_nodes_), 0);
  if (role.size() == size_t(n_nodes_))
    for (index_t i = 0; i < n_nodes_; ++i) {
      pairs[2 * i] = role[i] == kInner ? 255 : 0;
      pairs[2 * i + 1] = role[i] == kHalo ? 255 : 0;
    }
  glBindBuffer(GL_ARRAY_BUFFER, vbo_role_);
  glBufferSubData(GL_ARRAY_BUFFER, 0, pairs.size(), pairs.data());
  glBindBuffer(GL_ARRAY_BUFFER, 0);
}

void Renderer::upload_field_colours(std::span<const std::uint8_t> rgb) {
  field_shown_ = rgb.size() == 3 * size_t(n_nodes_);
  if (!field_shown_) return;
  glBindBuffer(GL_ARRAY_BUFFER, vbo_field_);
  glBufferSubData(GL_ARRAY_BUFFER, 0, rgb.size(), rgb.data());
  glBindBuffer(GL_ARRAY_BUFFER, 0);
}

void Renderer::draw_glyph(const Mesh& mesh, const Mat4& view_proj, const Mat4& view, const Mat4& model,
                          const float rgb[3]) {
  const Mat4 mvp = view_proj * model, mv = view * model;
  glUniformMatrix4fv(u_mvp_, 1, GL_FALSE, mvp.m);
  glUniformMatrix4fv(u_mv_, 1, GL_FALSE, mv.m);
  glUniform3fv(u_color_, 1, rgb);
  glUniform1f(u_tint_, 0);
  glUniform1f(u_field_, 0);
  glUniform1i(u_smooth_, 0);
  glBindVertexArray(mesh.vao);
  glDrawElements(GL_TRIANGLES, mesh.count, GL_UNSIGNED_INT, nullptr);
}

void Renderer::draw(const Camera& camera, const Glyphs& g) {
  glViewport(0, 0, camera.width, camera.height);
  glClearColor(kBackground[0], kBackground[1], kBackground[2], 1);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  glEnable(GL_DEPTH_TEST);
  glDisable(GL_CULL_FACE);
  glDisable(GL_BLEND);
  glUseProgram(program_);
  const Mat4 view = camera.view(), view_proj = camera.projection() * view;
  // the tissue
  glUniformMatrix4fv(u_mvp_, 1, GL_FALSE, view_proj.m);
  glUniformMatrix4fv(u_mv_, 1, GL_FALSE, view.m);
  glUniform3fv(u_color_, 1, kOrgan);
  glUniform1f(u_tint_, 1);
  glUniform1f(u_field_, field_shown_ ? 1.0f : 0.0f);
  glUniform1i(u_smooth_, shading_ == Shading::Smooth ? 1 : 0);
  glActiveTexture(GL_TEXTURE0);
  glBindTexture(GL_TEXTURE_BUFFER, tex_pos_);
  glActiveTexture(GL_TEXTURE1);
  glBindTexture(GL_TEXTURE_BUFFER, tex_corners_);
  glActiveTexture(GL_TEXTURE0);
  glBindVertexArray(vao_);
  glDrawElements(GL_TRIANGLES, n_indices_ - n_cut_indices_, GL_UNSIGNED_INT, nullptr);
  if (n_cut_indices_ > 0) {  // the faces a cut opened, after the others in the index buffer
    glUniform3fv(u_color_, 1, kCutFace);
    glDrawElements(GL_TRIANGLES, n_cut_indices_, GL_UNSIGNED_INT,
                   reinterpret_cast<const void*>(std::uintptr_t(n_indices_ - n_cut_indices_) * sizeof(unsigned)));
  }
  if (!g.show_tool) {
    glBindVertexArray(0);
    return;
  }
  for (const ToolGlyph& t : g.tools) draw_tool(t, g.metres_per_newton, view_proj, view);
  glBindVertexArray(0);
}

void Renderer::draw_tool(const ToolGlyph& t, double metres_per_newton, const Mat4& view_proj, const Mat4& view) {
  // the capsule at its real size, coloured by its contact state
  const double r = t.radius;
  const Vec3<double> a = t.axis;
  const float* body = t.grasp && t.contact ? kGrasp : t.contact ? kContact : kTool;
  draw_glyph(sphere_, view_proj, view, glyph_matrix(t.tool, a, r, r), body);
  if (t.shaft > 0) {
    draw_glyph(cylinder_, view_proj, view, glyph_matrix(t.tool, a, r, t.shaft), body);
    draw_glyph(sphere_, view_proj, view, glyph_matrix(t.tool + t.shaft * a, a, r, r), body);
  }
  // a thin handle beyond the capsule shows the axis (it does not touch the tissue)
  draw_glyph(cylinder_, view_proj, view, glyph_matrix(t.tool + (t.shaft + r) * a, a, 0.35 * r, 12 * r), kTool);
  if (norm(t.device - t.tool) > 0.25 * r)  // the hand, where the coupling pulls the tool
    draw_glyph(sphere_, view_proj, view, glyph_matrix(t.device, a, 0.6 * r, 0.6 * r), kDevice);
  // the force on the tool, from the tip
  const double f = norm(t.force), length = f * metres_per_newton;
  if (length > 0.5 * r) {
    const Vec3<double> d = (1.0 / f) * t.force;
    const double head = std::min(0.35 * length, 5 * r);
    draw_glyph(cylinder_, view_proj, view, glyph_matrix(t.tool, d, 0.3 * r, length - head), kArrow);
    draw_glyph(cone_, view_proj, view, glyph_matrix(t.tool + (length - head) * d, d, 0.9 * r, head), kArrow);
  }
}

OffscreenTarget::OffscreenTarget(int width, int height) : w_(width), h_(height) {
  glGenFramebuffers(1, &fbo_ms_);
  glBindFramebuffer(GL_FRAMEBUFFER, fbo_ms_);
  glGenRenderbuffers(1, &color_ms_);
  glBindRenderbuffer(GL_RENDERBUFFER, color_ms_);
  glRenderbufferStorageMultisample(GL_RENDERBUFFER, 4, GL_RGBA8, w_, h_);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, color_ms_);
  glGenRenderbuffers(1, &depth_ms_);
  glBindRenderbuffer(GL_RENDERBUFFER, depth_ms_);
  glRenderbufferStorageMultisample(GL_RENDERBUFFER, 4, GL_DEPTH_COMPONENT24, w_, h_);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, depth_ms_);
  if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
    throw std::runtime_error(fmt::format("tissue view: the {}x{} multisampled framebuffer is incomplete", w_, h_));
  glGenFramebuffers(1, &fbo_);
  glBindFramebuffer(GL_FRAMEBUFFER, fbo_);
  glGenRenderbuffers(1, &color_);
  glBindRenderbuffer(GL_RENDERBUFFER, color_);
  glRenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, w_, h_);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, color_);
  if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
    throw std::runtime_error(fmt::format("tissue view: the {}x{} framebuffer is incomplete", w_, h_));
  bind();
}

OffscreenTarget::~OffscreenTarget() {
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  const unsigned fbos[2] = {fbo_ms_, fbo_}, rbs[3] = {color_ms_, depth_ms_, color_};
  glDeleteFramebuffers(2, fbos);
  glDeleteRenderbuffers(3, rbs);
}

void OffscreenTarget::bind() { glBindFramebuffer(GL_FRAMEBUFFER, fbo_ms_); }

std::vector<std::uint8_t> OffscreenTarget::read_rgb() {
  glBindFramebuffer(GL_READ_FRAMEBUFFER, fbo_ms_);
  glBindFramebuffer(GL_DRAW_FRAMEBUFFER, fbo_);
  glBlitFramebuffer(0, 0, w_, h_, 0, 0, w_, h_, GL_COLOR_BUFFER_BIT, GL_NEAREST);
  glBindFramebuffer(GL_READ_FRAMEBUFFER, fbo_);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  std::vector<std::uint8_t> bottom_up(3 * size_t(w_) * h_), rows(bottom_up.size());
  glReadPixels(0, 0, w_, h_, GL_RGB, GL_UNSIGNED_BYTE, bottom_up.data());
  const size_t stride = 3 * size_t(w_);
  for (int y = 0; y < h_; ++y)
    std::copy_n(bottom_up.begin() + long((h_ - 1 - y) * stride), stride, rows.begin() + long(y * stride));
  bind();
  return rows;
}

}  // namespace tissue::viewer
