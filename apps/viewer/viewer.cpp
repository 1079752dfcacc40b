#include "apps/viewer/viewer.hpp"

// clang-format off
#include <GL/glew.h>
#include <GLFW/glfw3.h>
// clang-format on

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <thread>

#include "apps/viewer/camera.hpp"
#include "apps/viewer/field_view.hpp"
#include "apps/viewer/gl_context.hpp"
#include "apps/viewer/mouse_controller.hpp"
#include "apps/viewer/mouse_device.hpp"
#include "apps/viewer/overlay.hpp"
#include "apps/viewer/phantom_device.hpp"
#include "apps/viewer/picture.hpp"
#include "apps/viewer/position_source.hpp"
#include "apps/viewer/renderer.hpp"
#include "apps/viewer/path_device.hpp"
#include "apps/viewer/session.hpp"
#include "apps/viewer/surface_rings.hpp"
#include "io/atomic_file.hpp"

namespace tissue::viewer {
namespace {

using Clock = std::chrono::steady_clock;

/// --shading: smooth | flat.
Shading parse_shading(const std::string& name) {
  if (name == "smooth") return Shading::Smooth;
  if (name == "flat") return Shading::Flat;
  throw std::invalid_argument(fmt::format("--shading '{}': expected smooth (per-vertex normals) or flat (per face)",
                                          name));
}

/// What to leave out of the picture (--hide).
struct Hidden {
  bool tool = false, region = false, overlay = false;
};

Hidden parse_hide(const std::string& list) {
  Hidden h;
  std::stringstream in(list);
  for (std::string item; std::getline(in, item, ',');) {
    if (item == "tool") h.tool = true;
    else if (item == "region") h.region = true;
    else if (item == "overlay") h.overlay = true;
    else if (!item.empty())
      throw std::invalid_argument(fmt::format("--hide '{}': '{}' is none of tool, region, overlay", list, item));
  }
  return h;
}

/// The device the first tool follows, the coupling's force limit for it,
/// and the scripted devices of the scene's further tools.
struct DeviceChoice {
  std::unique_ptr<Device> device;
  MouseDevice* mouse = nullptr;  ///< set when the device is the mouse
  double max_force = CouplingParams{}.max_force;
  std::vector<std::unique_ptr<Device>> others;  ///< tools 2, 3, ...: their scene paths
  std::vector<Device*> all() const {
    std::vector<Device*> d{device.get()};
    for (const auto& o : others) d.push_back(o.get());
    return d;
  }
};

DeviceChoice make_device(const std::string& kind, const Session& s, double mouse_speed, bool repeat) {
  DeviceChoice d;
  if (kind == "mouse") {
    auto m = std::make_unique<MouseDevice>(s.tool_start, mouse_speed);
    d.mouse = m.get();
    d.device = std::move(m);
  } else if (kind == "scripted") {
    if (s.scene.tools.empty() || s.scene.tools.front().path.empty())
      throw std::runtime_error(fmt::format("{}: --device scripted needs a tool with a path in the scene", s.scene.source));
    d.device = std::make_unique<PathDevice>(s.scene.tools.front().path, repeat);
  } else if (kind == "phantom") {
    d.device = make_phantom_device(WorkspaceMap{s.tool_start, 1.0}, &d.max_force);
  } else {
    throw std::invalid_argument(fmt::format("--device '{}' is none of scripted, mouse, phantom", kind));
  }
  for (std::size_t t = 1; t < s.scene.tools.size(); ++t) {
    const scene::Tool& tool = s.scene.tools[t];
    if (tool.path.empty())
      throw std::runtime_error(fmt::format("{}: tool '{}' has no path; the viewer drives the first tool by the {} "
                                           "and every further tool by its scripted path",
                                           s.scene.source, tool.name, kind));
    d.others.push_back(std::make_unique<PathDevice>(tool.path, repeat));
  }
  return d;
}

/// The parts of the model the renderer needs (mesh only; a cut changes it, a rebuild brings the scene's back).
TissueModel<double> mesh_of(HapticLoop& loop) {
  TissueModel<double> m;
  loop.post([&m](Engine& sim) {
        m.n_nodes = sim.model->n_nodes;
        m.n_elems = sim.model->n_elems;
        m.n_tris = sim.model->n_tris;
        m.X = sim.model->X;
        m.tris = sim.model->tris;
        m.node_elem_start = sim.model->node_elem_start;  // J from the elements to the nodes
        m.node_elem = sim.model->node_elem;
      }).get();
  return m;
}

OverlayFacts facts_of(HapticLoop& loop, const TissueModel<double>& mesh, const Session& s, const GlContext& ctx,
                      const PositionSource& positions) {
  OverlayFacts f;
  loop.post([&f](Engine& sim) {
        f.backend = sim.backend->name();
        f.device_name = sim.backend->device_name();
      }).get();
  f.gl = ctx.renderer();
  f.positions = positions.path();
  f.n_nodes = mesh.n_nodes;
  f.n_elems = mesh.n_elems;
  f.n_tris = mesh.n_tris;
  f.uniform_material = s.scene.materials.size() == 1;
  return f;
}

/// Refreshes the region tint when the region changed (downloads the roles only then).
void update_roles(HapticLoop& loop, Renderer& r, const HapticSnapshot& snap, bool show, long* shown_version) {
  if (snap.region_version == *shown_version) return;
  *shown_version = snap.region_version;
  if (!show || snap.region.whole() || snap.region.nodes() == 0) {
    r.upload_roles({});
    return;
  }
  std::vector<std::uint8_t> role;
  loop.post([&role](Engine& sim) { role = sim.backend->region().role; }).get();
  r.upload_roles(role);
}

Glyphs glyphs_of(const HapticSnapshot& snap, double arrow_scale, bool show_tool) {
  Glyphs g;
  g.show_tool = show_tool;
  for (int t = 0; t < snap.n_tools; ++t) {
    const ToolView& v = snap.tools[t];
    g.tools.push_back({v.tool, v.device, v.axis, v.radius, v.shaft, v.contact_nodes > 0, v.grasp, v.rendered_force});
  }
  g.metres_per_newton = arrow_scale;
  return g;
}

ContextKind context_kind(const ViewOptions& o) {
  if (!o.gl.empty()) return parse_context_kind(o.gl);
  if (o.screenshot.empty()) return ContextKind::Window;
  const char* display = std::getenv("DISPLAY");
  return display && *display ? ContextKind::HiddenWindow : ContextKind::Egl;
}

/// Everything both modes set up: session, device, loop, GL, renderer, positions.
struct Viewer {
  Session session;
  DeviceChoice device;
  std::unique_ptr<HapticLoop> loop;
  std::unique_ptr<GlContext> ctx;
  TissueModel<double> mesh;
  std::unique_ptr<Renderer> renderer;
  std::unique_ptr<PositionSource> positions;
  Camera camera;
  double arrow_scale = 0;
  double wheel_step = 0;
  NodeField field;                      ///< what the surface shows (kind None: the organ's colour)
  ForceHistory forces;                  ///< each tool's |force| for the overlay's plot
  long mesh_version = 1;                ///< the mesh the renderer holds (HapticSnapshot::mesh_version)
};

/// The mesh anew when a cut (or a rebuild after one) changed it: the renderer's buffers and the position
/// source made again, the region tint and the field shown afresh.
void update_mesh(Viewer& v, const HapticSnapshot& snap, long* shown_mesh, long* shown_region) {
  if (snap.mesh_version == *shown_mesh) return;
  *shown_mesh = snap.mesh_version;
  v.positions.reset();  // registered on the old buffer
  v.mesh = mesh_of(*v.loop);
  v.renderer->set_mesh(v.mesh);
  v.positions = make_position_source(*v.renderer, v.session.scene.solver.backend);
  v.field = NodeField{};
  *shown_region = -1;
}

/// Downloads the store (between two ticks, on the haptic thread) and
/// recolours the surface by v.field.kind; kind None restores the organ's
/// colour without a download.
void update_field(Viewer& v, FieldKind kind) {
  if (kind == FieldKind::None) {
    v.field = NodeField{};
    v.renderer->upload_field_colours({});
    return;
  }
  Fields f;
  v.loop->post([&f](Engine& sim) { f = sim.backend->download(); }).get();
  if (f.u.size() != 3 * std::size_t(v.mesh.n_nodes)) return;  // a cut landed first: the next frame's mesh
  v.field = node_field(kind, f, v.mesh.n_nodes, v.mesh.node_elem_start, v.mesh.node_elem);
  v.renderer->upload_field_colours(node_colours(v.field));
}

void sample_forces(Viewer& v, const HapticSnapshot& s) {
  std::vector<double> f;
  for (int t = 0; t < s.n_tools; ++t) f.push_back(norm(s.tools[t].rendered_force));
  v.forces.add(s.time, f);
}

std::unique_ptr<Viewer> make_viewer(const ViewOptions& o, scene::Scene scene) {
  auto v = std::make_unique<Viewer>();
  v->session = make_session(std::move(scene), o.backend, o.precision, o.depth);
  if (o.scalpel) {
    if (v->session.scene.tools.empty())
      throw std::invalid_argument(fmt::format("--scalpel: {} has no tool to make a scalpel", v->session.scene.source));
    v->session.params.scalpel = true;
  }
  // the mouse needs a window; pictures and windowless runs take the scene tool's device
  const bool windowless = !o.screenshot.empty() || o.gl == "egl";
  const std::string kind = !o.device.empty()                ? o.device
                           : !windowless                    ? "mouse"
                           : v->session.scene.tools.empty() ? "mouse"
                                                            : v->session.scene.tools.front().device;
  v->device = make_device(kind, v->session, o.mouse_speed, o.repeat);
  HapticLoop::Options opt;
  opt.coupling.max_force = v->device.max_force;
  opt.realtime = o.realtime;
  v->loop = std::make_unique<HapticLoop>(v->device.all(), v->session.factory(), v->session.params, opt);
  // A software renderer (Mesa's llvmpipe, under Xvfb or without a GPU)
  // starts a render thread per core; with the cpu backend's TBB pool on
  // every core too, they take turns and haptic ticks come late. Leave it one
  // thread (before the context exists, when Mesa reads it) unless the user
  // set LP_NUM_THREADS; hardware GL ignores the variable.
  if (v->session.scene.solver.backend == "cpu") setenv("LP_NUM_THREADS", "1", 0);
  v->ctx = std::make_unique<GlContext>(context_kind(o), o.width, o.height, "tissue view: " + o.scene);
  v->mesh = mesh_of(*v->loop);
  v->renderer = std::make_unique<Renderer>(v->mesh);
  v->renderer->set_shading(parse_shading(o.shading));
  v->positions = make_position_source(*v->renderer, v->session.scene.solver.backend);
  const Bounds& b = v->session.bounds;
  // From the tool's side, a little to its left and above, so that the dent
  // shows beside the tool; for the mouse, nearly along the tool's approach,
  // so that the wheel pushes the tool where the scene's probe presses.
  const bool mouse = v->device.mouse != nullptr;
  v->camera = frame_camera(b.center(), b.diagonal(), v->session.press_dir, mouse ? 0.0 : 0.35, mouse ? 0.3 : 0.75,
                           o.width, o.height);
  // the overlay panel (500 px) takes the left: centre the organ in what is left
  if (!parse_hide(o.hide).overlay && o.width >= 800) v->camera.pan(200, 0);
  v->arrow_scale = o.arrow_scale > 0 ? o.arrow_scale : 1.5 * b.diagonal();
  v->wheel_step = b.diagonal() / 150;
  return v;
}

void print_stats(const HapticSnapshot& s, const PositionSource& positions) {
  fmt::print("{}\n", describe(s.stats));
  fmt::print("haptic thread: {}\n", s.realtime ? "SCHED_FIFO (real-time)" : "normal priority");
  fmt::print("TLED {} steps/tick, {:.0f} steps/s; positions: {}\n", s.steps_per_tick, s.stats.steps_per_s,
             positions.path());
}

// ------------------------------------------------------------------ pictures

int run_picture(const ViewOptions& o, Viewer& v) {
  const Hidden hide = parse_hide(o.hide);
  HapticLoop& loop = *v.loop;
  long ticks = o.ticks;
  if (ticks < 0) {
    const auto* scripted = dynamic_cast<const PathDevice*>(v.device.device.get());
    ticks = scripted ? std::lround(scripted->duration() / loop.period()) : 0;
  }
  // the scripted mouse, if any, between chunks of ticks
  long done = 0;
  if (!o.mouse_events.empty()) {
    if (!v.device.mouse) throw std::invalid_argument("--mouse-events needs --device mouse");
    MouseController mouse(v.camera, *v.device.mouse, v.wheel_step);
    for (const MouseEvent& e : parse_mouse_events(o.mouse_events)) {
      if (e.tick > ticks) break;
      loop.run_ticks(e.tick - done);
      done = e.tick;
      apply(mouse, e);
    }
  }
  // the rest in chunks of 10 ticks, sampling the force plot between them
  while (done < ticks) {
    const long n = std::min(10L, ticks - done);
    loop.run_ticks(n);
    done += n;
    sample_forces(v, loop.snapshot());
  }
  const HapticSnapshot snap = loop.snapshot();

  OffscreenTarget target(o.width, o.height);
  long shown = -1;
  update_mesh(v, snap, &v.mesh_version, &shown);
  v.positions->update(loop);
  update_field(v, parse_field_kind(o.field));
  update_roles(loop, *v.renderer, snap, !hide.region, &shown);
  std::unique_ptr<Overlay> overlay = hide.overlay ? nullptr : std::make_unique<Overlay>(nullptr);
  const OverlayFacts facts = facts_of(loop, v.mesh, v.session, *v.ctx, *v.positions);
  for (int frame = 0; frame < (overlay ? 2 : 1); ++frame) {  // ImGui lays windows out on the first frame
    v.renderer->draw(v.camera, glyphs_of(snap, v.arrow_scale, !hide.tool));
    if (overlay)
      overlay->draw(facts, snap, loop.status(), o.width, o.height,
                    {&v.field, &v.forces, v.renderer->shading() == Shading::Smooth});
  }
  write_png(o.screenshot, o.width, o.height, target.read_rgb());

  PictureFacts pf;
  pf.width = o.width;
  pf.height = o.height;
  pf.backend = facts.backend;
  pf.precision = to_string(snap.params.precision);
  pf.positions = facts.positions;
  pf.snap = snap;
  v.camera.project(snap.tool, &pf.tool_px[0], &pf.tool_px[1], nullptr);
  v.camera.project(snap.device, &pf.device_px[0], &pf.device_px[1], nullptr);
  project_box(v.camera, v.session.bounds.lo, v.session.bounds.hi, pf.organ_px);
  pf.overlay = overlay != nullptr;
  if (overlay) overlay->panel_rect(pf.overlay_px);
  pf.tool_shown = !hide.tool;
  pf.region_shown = !hide.region;
  pf.field = field_name(v.field.kind);
  pf.field_range[0] = v.field.lo;
  pf.field_range[1] = v.field.hi;
  pf.force_samples = long(v.forces.size());
  pf.nodes = v.mesh.n_nodes;
  const std::vector<std::uint8_t> cut = cut_faces(v.mesh);
  pf.cut_triangles = long(std::count(cut.begin(), cut.end(), std::uint8_t(1)));
  const std::string json_path = o.screenshot + ".json";
  io::write_file_atomic(json_path, picture_json(pf));
  fmt::print("wrote {} ({}x{}, {} ticks, {}, |F| = {:.4f} N, {}) and {}\n", o.screenshot, o.width, o.height,
             snap.tick < 0 ? 0 : snap.tick, snap.contact_nodes > 0 ? fmt::format("{} nodes in contact", snap.contact_nodes) : "no contact",
             norm(snap.rendered_force), v.ctx->renderer(), json_path);
  return 0;
}

// ------------------------------------------------------------------ interactive

/// The window's input, reached from GLFW's C callbacks through the user pointer.
struct Input {
  MouseController* mouse = nullptr;
  Overlay* overlay = nullptr;
  bool reset = false;
  bool scalpel = false;  ///< C: the scalpel toggled
};

/// Cursor position in framebuffer pixels (the camera's units).
void cursor(GLFWwindow* w, double* x, double* y) {
  int ww, wh, fw, fh;
  glfwGetWindowSize(w, &ww, &wh);
  glfwGetFramebufferSize(w, &fw, &fh);
  glfwGetCursorPos(w, x, y);
  *x *= double(fw) / std::max(1, ww);
  *y *= double(fh) / std::max(1, wh);
}

void install_input(GLFWwindow* w, Input* in) {
  glfwSetWindowUserPointer(w, in);
  glfwSetMouseButtonCallback(w, [](GLFWwindow* win, int button, int action, int mods) {
    auto* in = static_cast<Input*>(glfwGetWindowUserPointer(win));
    const MouseButton b = button == GLFW_MOUSE_BUTTON_LEFT    ? MouseButton::Left
                          : button == GLFW_MOUSE_BUTTON_RIGHT ? MouseButton::Right
                                                              : MouseButton::Middle;
    if (!in->mouse) return;
    if (action == GLFW_RELEASE) {
      in->mouse->release(b);
      return;
    }
    if (in->overlay && in->overlay->wants_mouse()) return;
    double x, y;
    cursor(win, &x, &y);
    // shift + left drag orbits the camera; the right button is the grasp button
    in->mouse->press((mods & GLFW_MOD_SHIFT) && b == MouseButton::Left ? MouseButton::Orbit : b, x, y);
  });
  glfwSetCursorPosCallback(w, [](GLFWwindow* win, double, double) {
    auto* in = static_cast<Input*>(glfwGetWindowUserPointer(win));
    if (!in->mouse) return;
    double x, y;
    cursor(win, &x, &y);
    in->mouse->move(x, y);
  });
  glfwSetScrollCallback(w, [](GLFWwindow* win, double, double dy) {
    auto* in = static_cast<Input*>(glfwGetWindowUserPointer(win));
    if (!in->mouse || (in->overlay && in->overlay->wants_mouse())) return;
    const bool shift = glfwGetKey(win, GLFW_KEY_LEFT_SHIFT) == GLFW_PRESS || glfwGetKey(win, GLFW_KEY_RIGHT_SHIFT) == GLFW_PRESS;
    in->mouse->wheel(dy, shift);
  });
  glfwSetKeyCallback(w, [](GLFWwindow* win, int key, int, int action, int) {
    auto* in = static_cast<Input*>(glfwGetWindowUserPointer(win));
    if (action != GLFW_PRESS) return;
    if (key == GLFW_KEY_ESCAPE) glfwSetWindowShouldClose(win, GLFW_TRUE);
    if (key == GLFW_KEY_R) in->reset = true;
    if (key == GLFW_KEY_C) in->scalpel = true;
  });
}

int run_interactive(const ViewOptions& o, Viewer& v) {
  if (!o.mouse_events.empty()) throw std::invalid_argument("--mouse-events applies to --screenshot runs");
  const Hidden hide = parse_hide(o.hide);
  HapticLoop& loop = *v.loop;
  GLFWwindow* win = v.ctx->window();
  if (!win && !(o.seconds > 0))
    throw std::invalid_argument("without a window (--gl egl) the display loop needs --seconds (or --screenshot)");
  if (!win && v.device.mouse) throw std::invalid_argument("--device mouse needs a window (--gl window)");
  // a scripted or hardware tool leaves the mouse the camera only
  MouseDevice camera_only(v.session.tool_start, o.mouse_speed);
  MouseController mouse(v.camera, v.device.mouse ? *v.device.mouse : camera_only, v.wheel_step);
  Input input{&mouse, nullptr, false};
  if (win) install_input(win, &input);  // before ImGui, which chains these callbacks
  // without a window the frames go to an offscreen target, as pictures do
  std::unique_ptr<OffscreenTarget> offscreen = win ? nullptr : std::make_unique<OffscreenTarget>(o.width, o.height);
  std::unique_ptr<Overlay> overlay = hide.overlay ? nullptr : std::make_unique<Overlay>(win);
  input.overlay = overlay.get();
  OverlayFacts facts = facts_of(loop, v.mesh, v.session, *v.ctx, *v.positions);
  fmt::print("tissue view: {} on {} ({}); GL {}; positions: {}\n", v.session.scene.source, facts.backend,
             to_string(v.session.params.precision), facts.gl, facts.positions);
  loop.start();
  const auto t0 = Clock::now();
  const auto frame = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / std::max(1.0, o.fps)));
  auto next_frame = t0;
  long shown_region = -1, frames = 0;
  bool warned_realtime = false;
  FieldKind field = parse_field_kind(o.field);
  auto field_shown_at = t0 - std::chrono::seconds(1);
  long field_tick = -1;
  while (!v.ctx->should_close()) {
    if (o.seconds > 0 && std::chrono::duration<double>(Clock::now() - t0).count() > o.seconds) break;
    // pace the display (Xvfb and some drivers do not block on swap): the
    // haptic thread needs the core more than a software renderer does
    next_frame = std::max(next_frame + frame, Clock::now() - frame);
    std::this_thread::sleep_until(next_frame);
    if (win) glfwPollEvents();
    const HapticSnapshot snap = loop.snapshot();
    if (o.realtime && !warned_realtime && snap.tick > 0 && !snap.realtime) {
      fmt::print(stderr, "tissue view: warning: real-time scheduling refused; the haptic thread runs at normal priority\n");
      warned_realtime = true;
    }
    if (input.reset) {
      loop.request_params(snap.params);
      input.reset = false;
    }
    if (input.scalpel) {  // a rebuild: the tissue restarts from rest with the tool changed
      LiveParams p = snap.params;
      p.scalpel = !p.scalpel;
      loop.request_params(p);
      input.scalpel = false;
    }
    if (snap.mesh_version != v.mesh_version) {
      update_mesh(v, snap, &v.mesh_version, &shown_region);
      facts = facts_of(loop, v.mesh, v.session, *v.ctx, *v.positions);
    }
    update_roles(loop, *v.renderer, snap, !hide.region, &shown_region);
    v.positions->update(loop);
    sample_forces(v, snap);
    // the field: a download of the store at most 10 times a second (the
    // haptic thread does it between two ticks), and when it is switched
    if (field != v.field.kind ||
        (field != FieldKind::None && snap.tick != field_tick && Clock::now() - field_shown_at > std::chrono::milliseconds(100))) {
      update_field(v, field);
      field_shown_at = Clock::now();
      field_tick = snap.tick;
    }
    if (offscreen) offscreen->bind();
    else glBindFramebuffer(GL_FRAMEBUFFER, 0);
    v.ctx->framebuffer_size(&v.camera.width, &v.camera.height);
    v.renderer->draw(v.camera, glyphs_of(snap, v.arrow_scale, !hide.tool));
    if (overlay) {
      const OverlayActions act =
          overlay->draw(facts, snap, loop.status(), v.camera.width, v.camera.height,
                        {&v.field, &v.forces, v.renderer->shading() == Shading::Smooth});
      if (act.apply) loop.request_params(*act.apply);
      if (act.field) field = *act.field;
      if (act.friction) loop.set_friction(*act.friction);
      if (act.smooth) v.renderer->set_shading(*act.smooth ? Shading::Smooth : Shading::Flat);
      if (act.reset) loop.request_params(snap.params);
      if (act.scalpel) input.scalpel = true;  // the next frame rebuilds, as the C key does
    }
    if (win) v.ctx->swap_buffers();
    else glFinish();  // the frame's work is done, as a swap would have it
    ++frames;
  }
  const double wall = std::chrono::duration<double>(Clock::now() - t0).count();
  loop.stop();
  fmt::print("display: {} frames in {:.2f} s ({:.1f} frames/s){}\n", frames, wall, frames / std::max(wall, 1e-9),
             win ? "" : ", offscreen (EGL)");
  const HapticSnapshot last = loop.snapshot();
  print_stats(last, *v.positions);
  fmt::print("final: tool ({:.1f}, {:.1f}, {:.1f}) mm, {}, |F| = {:.4f} N to the device, region {} nodes\n",
             1e3 * last.tool.x, 1e3 * last.tool.y, 1e3 * last.tool.z,
             last.contact_nodes > 0 ? fmt::format("{} nodes in contact", last.contact_nodes) : "no contact",
             norm(last.rendered_force), last.region.nodes());
  if (!loop.status().empty()) fmt::print("status: {}\n", loop.status());
  return 0;
}

}  // namespace

int run_view(const ViewOptions& o, scene::Scene scene) {
  if (o.width < 16 || o.height < 16 || o.width > 8192 || o.height > 8192)
    throw std::invalid_argument(
        fmt::format("--width {} --height {}: each must lie in 16..8192 pixels", o.width, o.height));
  parse_hide(o.hide);  // option errors before the scene is built
  parse_field_kind(o.field);
  parse_shading(o.shading);
  if (!o.gl.empty()) parse_context_kind(o.gl);
  if (!o.mouse_events.empty()) parse_mouse_events(o.mouse_events);
  std::unique_ptr<Viewer> v = make_viewer(o, std::move(scene));
  return o.screenshot.empty() ? run_interactive(o, *v) : run_picture(o, *v);
}

}  // namespace tissue::viewer
