#include "apps/viewer/overlay.hpp"

#include <GLFW/glfw3.h>
#include <imgui.h>
#include <imgui_impl_glfw.h>
#include <imgui_impl_opengl3.h>

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace tissue::viewer {
namespace {

void row(const char* label, const std::string& value) {
  ImGui::TextUnformatted(label);
  ImGui::SameLine(84);
  ImGui::TextUnformatted(value.c_str());
}

ImU32 colour_u32(const std::array<std::uint8_t, 3>& c) { return IM_COL32(c[0], c[1], c[2], 255); }

/// The field's colour bar, its ends and its name.
void legend(const NodeField& f) {
  const float width = ImGui::GetContentRegionAvail().x, height = 14;
  const ImVec2 p = ImGui::GetCursorScreenPos();
  ImDrawList* dl = ImGui::GetWindowDrawList();
  constexpr int kSegments = 32;
  for (int k = 0; k < kSegments; ++k) {
    const ImU32 a = colour_u32(field_colour(f.kind, double(k) / kSegments)),
                b = colour_u32(field_colour(f.kind, double(k + 1) / kSegments));
    const float x0 = p.x + width * k / kSegments, x1 = p.x + width * (k + 1) / kSegments;
    dl->AddRectFilledMultiColor(ImVec2(x0, p.y), ImVec2(x1, p.y + height), a, b, b, a);
  }
  ImGui::Dummy(ImVec2(width, height));
  const std::string lo = fmt::format("{:.4g}", f.lo), mid = fmt::format("{:.4g}", 0.5 * (f.lo + f.hi)),
                    hi = fmt::format("{:.4g}", f.hi);
  ImGui::TextUnformatted(lo.c_str());
  ImGui::SameLine(0.5f * (width - ImGui::CalcTextSize(mid.c_str()).x));
  ImGui::TextUnformatted(mid.c_str());
  ImGui::SameLine(width - ImGui::CalcTextSize(hi.c_str()).x);
  ImGui::TextUnformatted(hi.c_str());
  ImGui::TextDisabled("%s", f.label.c_str());
}

/// Each tool's |force| over the history's window, on one scale from zero.
void force_plot(const ForceHistory& h) {
  if (h.size() < 2) return;
  double top = 0;
  for (int k = 0; k < h.n_tools(); ++k) top = std::max(top, h.peak(k));
  top = std::max(1.1 * top, 1e-3);
  ImGui::TextDisabled("force on the tool over the last %.1f s (0 to %.3g N)", h.span(), top);
  for (int k = 0; k < h.n_tools(); ++k) {
    const std::vector<float> v = h.series(k);
    const std::string label = h.n_tools() > 1 ? fmt::format("##force{}", k) : std::string("##force");
    const std::string now = fmt::format("{}{:.4f} N", h.n_tools() > 1 ? fmt::format("tool {}: ", k + 1) : "", h.latest(k));
    ImGui::PlotLines(label.c_str(), v.data(), int(v.size()), 0, now.c_str(), 0.0f, float(top),
                     ImVec2(ImGui::GetContentRegionAvail().x, 56));
  }
}

std::string mm(Vec3<double> p) { return fmt::format("({:.1f}, {:.1f}, {:.1f}) mm", 1e3 * p.x, 1e3 * p.y, 1e3 * p.z); }

}  // namespace

Overlay::Overlay(GLFWwindow* window) : glfw_(window != nullptr) {
  IMGUI_CHECKVERSION();
  ImGui::CreateContext();
  ImGui::GetIO().IniFilename = nullptr;  // no imgui.ini beside the user's files
  ImGui::StyleColorsDark();
  ImGui::GetStyle().WindowRounding = 4;
  ImGui::GetStyle().Alpha = 0.92f;
  if (glfw_) ImGui_ImplGlfw_InitForOpenGL(window, true);  // chains the viewer's own callbacks
  ImGui_ImplOpenGL3_Init("#version 330 core");
}

Overlay::~Overlay() {
  ImGui_ImplOpenGL3_Shutdown();
  if (glfw_) ImGui_ImplGlfw_Shutdown();
  ImGui::DestroyContext();
}

bool Overlay::wants_mouse() const { return ImGui::GetIO().WantCaptureMouse; }

void Overlay::panel_rect(float r[4]) const { std::copy_n(rect_, 4, r); }

void Overlay::show_status(const OverlayFacts& f, const HapticSnapshot& s) {
  const HapticStats& st = s.stats;
  row("backend", fmt::format("{} ({})", f.backend, to_string(s.params.precision)));
  row("device", f.device_name);
  row("GL", f.gl);
  row("positions", f.positions);
  row("mesh", fmt::format("{} nodes, {} tets, {} triangles", f.n_nodes, f.n_elems, f.n_tris));
  row("TLED", fmt::format("{} steps/tick, {:.0f} steps/s", s.steps_per_tick, st.steps_per_s));
  if (st.paced) {
    row("haptic", fmt::format("{:.1f} Hz, tick p50 {:.3f} p99 {:.3f} max {:.3f} ms{}", st.rate_hz, 1e3 * st.work_p50,
                              1e3 * st.work_p99, 1e3 * st.work_max, s.realtime ? ", SCHED_FIFO" : ""));
    row("jitter", fmt::format("p99 {:.3f} ms; late {} of {} (session {} of {})", 1e3 * st.wake_p99, st.window_late,
                              st.window_ticks, st.late, st.ticks));
  } else {
    row("haptic", fmt::format("offline: {} ticks, work p50 {:.3f} p99 {:.3f} ms", st.ticks, 1e3 * st.work_p50,
                              1e3 * st.work_p99));
  }
  if (st.paced && !st.keeping_up)
    ImGui::TextColored(ImVec4(1, 0.35f, 0.3f, 1), "%s: %ld of the last %ld ticks late",
                       st.work_p99 > st.period ? "SOLVER CANNOT KEEP UP" : "HAPTIC DEADLINES MISSED", st.window_late,
                       st.window_ticks);
  for (int t = 0; t < s.n_tools; ++t) {
    const ToolView& v = s.tools[t];
    const std::string name = s.n_tools > 1 ? fmt::format("tool {}", t + 1) : std::string("tool");
    row(name.c_str(), fmt::format("{}  {}{}", mm(v.tool),
                                  v.contact_nodes > 0 ? fmt::format("{} nodes in contact", v.contact_nodes) : "no contact",
                                  v.grasp ? fmt::format(", grasping {}", v.grasped) : ""));
    row(s.n_tools > 1 ? fmt::format("force {}", t + 1).c_str() : "force",
        fmt::format("{:.4f} N to the device (tissue {:.4f} N){}", norm(v.rendered_force), norm(v.tissue_force),
                    v.clamped ? "  CLAMPED" : ""));
  }
  row("region", s.region.whole() ? fmt::format("whole mesh, {} nodes, {} elements", s.region.nodes(), s.region.n_elems)
                                 : fmt::format("{} inner + {} halo nodes, {} elements ({}depth {})", s.region.n_inner,
                                               s.region.n_halo, s.region.n_elems,
                                               s.params.depth == kDepthAuto ? "auto, " : "", s.region.depth));
  row("time", fmt::format("{:.3f} s simulated, max |u| {:.2f} mm", s.time, 1e3 * s.max_disp));
  if (s.params.scalpel || s.cuts > 0)
    row("scalpel", fmt::format("{}{} cut{} made", s.params.scalpel ? "the right button cuts; " : "", s.cuts,
                               s.cuts == 1 ? "" : "s"));
}

bool Overlay::edit_material(const OverlayFacts& f) {
  bool changed = false;
  const double nu_min = 0.0, nu_max = 0.499;
  if (!f.uniform_material && edit_.E <= 0) ImGui::TextDisabled("E, nu: the scene's %s", "materials (several sets)");
  if (ImGui::InputDouble(f.uniform_material ? "E [Pa]" : "E [Pa] (all sets)", &edit_.E, 100, 1000, "%.0f")) {
    edit_.E = std::clamp(edit_.E, 10.0, 1e7);
    changed = true;
  }
  changed |= ImGui::SliderScalar("nu", ImGuiDataType_Double, &edit_.nu, &nu_min, &nu_max, "%.3f");
  if (edit_.fibre_eta >= 0 && ImGui::InputDouble("fibre eta [Pa]", &edit_.fibre_eta, 100, 1000, "%.0f")) {
    edit_.fibre_eta = std::clamp(edit_.fibre_eta, 0.0, 1e8);
    changed = true;
  }
  if (edit_.prony_terms >= 0) {  // the Prony series (docs/materials.md); the rules are checked on Apply
    if (ImGui::SliderInt("Prony terms", &edit_.prony_terms, 0, kMaxProny)) {
      for (int i = 0; i < edit_.prony_terms; ++i)
        if (!(edit_.prony_tau[i] > 0)) edit_.prony_g[i] = 0.1, edit_.prony_tau[i] = 1.0;
      changed = true;
    }
    for (int i = 0; i < edit_.prony_terms; ++i) {
      ImGui::PushID(i);
      ImGui::SetNextItemWidth(ImGui::GetContentRegionAvail().x * 0.3f);
      changed |= ImGui::InputDouble("g", &edit_.prony_g[i], 0, 0, "%.3f");
      ImGui::SameLine();
      ImGui::SetNextItemWidth(ImGui::GetContentRegionAvail().x * 0.45f);
      changed |= ImGui::InputDouble("tau [s]", &edit_.prony_tau[i], 0, 0, "%.3g");
      ImGui::PopID();
    }
  }
  return changed;
}

bool Overlay::edit_region_and_precision() {
  // the region: adaptive (grows until its front barely moves), the whole
  // mesh, or a fixed number of rings around the contact triangle
  bool changed = false;
  int mode = edit_.depth == kDepthAuto ? 0 : edit_.depth == kDepthAll ? 1 : 2;
  int rings = mode == 2 ? edit_.depth : 5;
  changed |= ImGui::Combo("region", &mode, "auto\0whole mesh\0rings\0");
  ImGui::BeginDisabled(mode != 2);
  changed |= ImGui::SliderInt("rings", &rings, 0, 20);
  ImGui::EndDisabled();
  edit_.depth = mode == 0 ? kDepthAuto : mode == 1 ? kDepthAll : rings;
  int precision = edit_.precision == Precision::Float ? 0 : 1;
  changed |= ImGui::Combo("precision", &precision, "float\0double\0");
  edit_.precision = precision == 0 ? Precision::Float : Precision::Double;
  return changed;
}

std::optional<double> Overlay::edit_friction(const HapticSnapshot& s) {
  if (friction_sent_ && std::fabs(s.params.friction - *friction_sent_) < 1e-12) friction_sent_.reset();
  double mu = friction_sent_.value_or(std::max(s.params.friction, 0.0));
  const double lo = 0, hi = 1.5;
  if (!ImGui::SliderScalar("tool friction", ImGuiDataType_Double, &mu, &lo, &hi, "mu %.2f")) return std::nullopt;
  friction_sent_ = mu;
  edit_.friction = mu;
  return mu;
}

OverlayActions Overlay::draw(const OverlayFacts& f, const HapticSnapshot& s, const std::string& status, int w, int h,
                             const DisplayState& display) {
  OverlayActions act;
  if (!editing_) edit_ = s.params;
  ImGui_ImplOpenGL3_NewFrame();
  if (glfw_) {
    ImGui_ImplGlfw_NewFrame();
  } else {
    ImGuiIO& io = ImGui::GetIO();
    io.DisplaySize = ImVec2(float(w), float(h));
    io.DeltaTime = 1.0f / 60;
  }
  ImGui::NewFrame();
  ImGui::SetNextWindowPos(ImVec2(10, 10), ImGuiCond_Always);
  ImGui::SetNextWindowSize(ImVec2(500, 0), ImGuiCond_Always);
  ImGui::Begin("tissue", nullptr, ImGuiWindowFlags_NoMove | ImGuiWindowFlags_NoResize | ImGuiWindowFlags_NoCollapse);
  show_status(f, s);
  if (display.forces) force_plot(*display.forces);
  ImGui::Separator();
  const FieldKind shown = display.field ? display.field->kind : FieldKind::None;
  int field = int(shown);
  if (ImGui::Combo("surface", &field, "organ\0|u| displacement\0pressure\0J = det F\0"))
    act.field = static_cast<FieldKind>(field);
  if (shown != FieldKind::None) legend(*display.field);
  bool smooth = display.smooth;
  if (ImGui::Checkbox("smooth shading", &smooth)) act.smooth = smooth;
  ImGui::SameLine();
  bool scalpel = s.params.scalpel;
  if (ImGui::Checkbox("scalpel (C)", &scalpel)) act.scalpel = true;
  ImGui::Separator();
  const bool material = edit_material(f);
  const bool region = edit_region_and_precision();
  act.friction = edit_friction(s);
  editing_ = editing_ || material || region;
  if (ImGui::Button("Apply (rebuild)")) {
    act.apply = edit_;
    editing_ = false;
  }
  ImGui::SameLine();
  if (ImGui::Button("Reset tissue")) act.reset = true;
  if (!status.empty()) {
    ImGui::PushTextWrapPos(0);
    ImGui::TextColored(ImVec4(1, 0.45f, 0.35f, 1), "%s", status.c_str());
    ImGui::PopTextWrapPos();
  }
  if (glfw_) {
    ImGui::Separator();
    ImGui::TextDisabled("left drag: tool in the view plane; wheel: push along the view");
    ImGui::TextDisabled("right button: grasp (the scalpel: cut); C: scalpel on / off");
    ImGui::TextDisabled("shift+left drag: orbit; middle drag: pan; shift+wheel: zoom");
  }
  const ImVec2 pos = ImGui::GetWindowPos(), size = ImGui::GetWindowSize();
  rect_[0] = pos.x;
  rect_[1] = pos.y;
  rect_[2] = pos.x + size.x;
  rect_[3] = pos.y + size.y;
  ImGui::End();
  ImGui::Render();
  ImGui_ImplOpenGL3_RenderDrawData(ImGui::GetDrawData());
  return act;
}

}  // namespace tissue::viewer
