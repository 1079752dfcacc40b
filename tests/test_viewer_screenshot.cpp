// Headless pictures of `tissue view` (apps/viewer): the built-in kidney
// rendered offscreen before the scripted press and while pressed, and with
// the mouse device pushed into the tissue by scripted wheel events. Checks
// that a picture shows the organ (enough organ-coloured pixels, inside the
// organ's projected bounds, background elsewhere) and that the pressed
// picture differs from the one before where the tool touched: the changed
// pixels gather around the contact point's projection (from the picture's
// JSON sidecar). The tool, the region tint and the overlay are left out of
// these pictures so that only the tissue's deformation can change pixels.
//
// The pictures are drawn by the `tissue` program beside this test's build
// folder, under xvfb-run (a hidden GLFW window, Mesa) when there is no
// display; where `tissue view` was not built the tests skip and say why.
#include <gtest/gtest.h>

#define STB_IMAGE_IMPLEMENTATION
#include <stb/stb_image.h>

#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;

/// The viewer's background (apps/viewer/renderer.hpp kBackground) in 0..255.
constexpr int kBackground[3] = {28, 31, 38};

struct Picture {
  int w = 0, h = 0;
  std::vector<unsigned char> rgb;  ///< w x h x 3, top row first
  std::string json;
  const unsigned char* at(int x, int y) const { return &rgb[3 * (size_t(y) * w + x)]; }
};

fs::path build_dir() { return fs::canonical("/proc/self/exe").parent_path().parent_path(); }
fs::path tissue_exe() { return build_dir() / "apps" / "tissue"; }

bool have(const char* program) {
  return std::system(("command -v " + std::string(program) + " > /dev/null 2>&1").c_str()) == 0;
}

/// How to get a GL context here: an existing display, xvfb-run, or none.
std::string launcher() {
  const char* display = std::getenv("DISPLAY");
  if (display && *display) return "";
  if (have("xvfb-run")) return "xvfb-run -a -s '-screen 0 1280x1024x24' ";
  return "none";
}

/// Runs the command; returns its exit code, output in *out.
int run(const std::string& cmd, std::string* out) {
  std::FILE* p = popen((cmd + " 2>&1").c_str(), "r");
  if (!p) return -1;
  char buf[4096];
  while (size_t n = std::fread(buf, 1, sizeof buf, p)) out->append(buf, n);
  return pclose(p);
}

std::string slurp(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

/// The numbers of the JSON array that follows "key": in the sidecar (empty for null).
std::vector<double> json_array(const std::string& json, const std::string& key) {
  const size_t k = json.find("\"" + key + "\":");
  if (k == std::string::npos) return {};
  const size_t open = json.find_first_not_of(' ', k + key.size() + 3);
  if (open == std::string::npos || json[open] != '[') return {};
  std::vector<double> v;
  std::stringstream in(json.substr(open + 1, json.find(']', open) - open - 1));
  for (std::string item; std::getline(in, item, ',');) v.push_back(std::stod(item));
  return v;
}

bool json_true(const std::string& json, const std::string& key) {
  return json.find("\"" + key + "\": true") != std::string::npos;
}

class ViewerPictures : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!fs::exists(tissue_exe())) GTEST_SKIP() << tissue_exe() << " is not built";
    std::string help;
    if (run(tissue_exe().string() + " view --help", &help) != 0 || help.find("--screenshot") == std::string::npos)
      GTEST_SKIP() << "`tissue view` is not built here: " << help;
    dir_ = fs::temp_directory_path() / ("tissue_view_test_" + std::to_string(getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override {
    if (!dir_.empty()) fs::remove_all(dir_);
  }

  /// Renders `tissue view @kidney --screenshot <name>.png <args>`, loads it.
  Picture render(const std::string& name, const std::string& args, const std::string& gl = "",
                 const std::string& size = "--width 480 --height 360") {
    std::string how = launcher();
    if (how == "none") {  // no X at all: EGL (Mesa's software device, or a GPU)
      how = "";
      gl_fallback_ = " --gl egl";
    }
    const fs::path png = dir_ / (name + ".png");
    const std::string cmd = how + tissue_exe().string() + " view @kidney " + size + " --screenshot " +
                            png.string() + " " + args + (gl.empty() ? gl_fallback_ : " --gl " + gl);
    std::string out;
    int rc = run(cmd, &out);
    // xvfb-run -a can pick the same display as a concurrent test: try again
    for (int retry = 0; retry < 3 && rc != 0 && out.find("Xvfb failed to start") != std::string::npos; ++retry) {
      out.clear();
      rc = run(cmd, &out);
    }
    EXPECT_EQ(rc, 0) << cmd << "\n" << out;
    Picture p;
    int n = 0;
    unsigned char* data = stbi_load(png.c_str(), &p.w, &p.h, &n, 3);
    if (!data) {
      ADD_FAILURE() << "no picture at " << png << ": " << cmd << "\n" << out;
      return p;
    }
    p.rgb.assign(data, data + 3 * size_t(p.w) * p.h);
    stbi_image_free(data);
    p.json = slurp(png.string() + ".json");
    std::printf("%s: %s", name.c_str(), out.c_str());
    return p;
  }

  fs::path dir_;
  std::string gl_fallback_;
};

bool is_background(const unsigned char* c) {
  for (int k = 0; k < 3; ++k)
    if (std::abs(int(c[k]) - kBackground[k]) > 3) return false;
  return true;
}

/// Reddish tissue: red clearly above green and blue (lit or in shade).
bool is_organ(const unsigned char* c) { return c[0] > c[1] + 20 && c[0] > c[2] + 20; }

/// The organ is there, inside its projected bounds, on the background.
void expect_shows_organ(const Picture& p) {
  ASSERT_EQ(p.w, 480);
  ASSERT_EQ(p.h, 360);
  const std::vector<double> box = json_array(p.json, "organ_px");
  ASSERT_EQ(box.size(), 4u) << p.json;
  long organ = 0, background = 0, organ_outside_box = 0;
  for (int y = 0; y < p.h; ++y)
    for (int x = 0; x < p.w; ++x) {
      const unsigned char* c = p.at(x, y);
      if (is_organ(c)) {
        ++organ;
        if (x < box[0] - 2 || x > box[2] + 2 || y < box[1] - 2 || y > box[3] + 2) ++organ_outside_box;
      }
      if (is_background(c)) ++background;
    }
  const double n = double(p.w) * p.h;
  EXPECT_GT(organ / n, 0.08) << "organ-coloured fraction";
  EXPECT_GT(background / n, 0.30) << "background fraction";
  EXPECT_LT(organ_outside_box, 0.002 * organ) << "organ colour outside the organ's projected bounds";
  for (auto [x, y] : {std::pair{0, 0}, {p.w - 1, 0}, {0, p.h - 1}, {p.w - 1, p.h - 1}})
    EXPECT_TRUE(is_background(p.at(x, y))) << "corner " << x << "," << y;
}

/// Pixels that changed between two pictures, and how many lie within
/// `radius` pixels of (cx, cy).
struct Difference {
  long changed = 0, near = 0;
  double max_distance = 0;
};

Difference difference(const Picture& a, const Picture& b, double cx, double cy, double radius) {
  Difference d;
  for (int y = 0; y < a.h; ++y)
    for (int x = 0; x < a.w; ++x) {
      int delta = 0;
      for (int k = 0; k < 3; ++k) delta = std::max(delta, std::abs(int(a.at(x, y)[k]) - int(b.at(x, y)[k])));
      if (delta <= 12) continue;
      ++d.changed;
      const double r = std::hypot(x - cx, y - cy);
      d.max_distance = std::max(d.max_distance, r);
      if (r <= radius) ++d.near;
    }
  return d;
}

// The locality checks below run the solver on a depth-5 region: the
// kidney's default (depth auto) solves the whole organ, which is held only
// at its hilum and tilts as a whole under the press (docs/accuracy.md), so
// its silhouette moves everywhere; a region pins everything beyond five
// rings and leaves only the indentation itself to show.
const std::string kLocal = " --depth 5";

TEST_F(ViewerPictures, ScriptedPressDeformsTheOrganWhereTheToolTouches) {
  const std::string plain = "--device scripted --hide tool,region,overlay" + kLocal;
  const Picture before = render("before", "--ticks 50 " + plain);
  const Picture pressed = render("pressed", "--ticks 300 " + plain);
  if (HasFailure()) return;
  EXPECT_FALSE(json_true(before.json, "contact")) << before.json;
  ASSERT_TRUE(json_true(pressed.json, "contact")) << pressed.json;
  expect_shows_organ(before);
  expect_shows_organ(pressed);
  const std::vector<double> c = json_array(pressed.json, "contact_px");
  const std::vector<double> box = json_array(pressed.json, "organ_px");
  ASSERT_EQ(c.size(), 2u);
  // within a fifth of the organ's projected size around the contact point
  const double radius = 0.2 * std::hypot(box[2] - box[0], box[3] - box[1]);
  const Difference d = difference(before, pressed, c[0], c[1], radius);
  std::printf("pressed vs before: %ld pixels changed, %ld within %.0f px of the contact (%.1f, %.1f), farthest %.0f px\n",
              d.changed, d.near, radius, c[0], c[1], d.max_distance);
  EXPECT_GT(d.changed, 100) << "the press should show";
  EXPECT_GT(d.near, 0.95 * d.changed) << "the change should gather around the contact point";
  // and a picture of the same state is the same picture
  const Picture again = render("pressed_again", "--ticks 300 " + plain);
  EXPECT_EQ(difference(pressed, again, 0, 0, 0).changed, 0);
}

/// Steps in brightness between horizontally neighbouring organ pixels (all
/// four of a row's pixels organ, so the silhouette does not count): pairs
/// whose green channel, the lit part of the organ's colour, differs by more
/// than 3 of 255 where the pixels on either side continue the same slope
/// by less.
long shading_steps(const Picture& p) {
  long steps = 0;
  for (int y = 0; y < p.h; ++y)
    for (int x = 1; x + 2 < p.w; ++x) {
      const unsigned char *a = p.at(x - 1, y), *b = p.at(x, y), *c = p.at(x + 1, y), *d = p.at(x + 2, y);
      if (!is_organ(a) || !is_organ(b) || !is_organ(c) || !is_organ(d)) continue;
      const int jump = std::abs(int(c[1]) - int(b[1]));
      if (jump > 3 && std::abs(int(b[1]) - int(a[1])) < jump && std::abs(int(d[1]) - int(c[1])) < jump) ++steps;
    }
  return steps;
}

// Smooth shading (the default) lights the organ by per-vertex normals made
// from the deformed surface: the brightness runs on across the faces,
// where flat shading steps at every edge between them.
TEST_F(ViewerPictures, SmoothShadingDoesNotStepAtTheFaces) {
  const std::string plain = "--device scripted --ticks 300 --hide tool,region,overlay" + kLocal;
  const Picture smooth = render("smooth", plain);
  const Picture flat = render("flat", plain + " --shading flat");
  if (HasFailure()) return;
  expect_shows_organ(smooth);
  expect_shows_organ(flat);
  const long s = shading_steps(smooth), f = shading_steps(flat);
  std::printf("brightness steps inside the organ: smooth %ld, flat %ld\n", s, f);
  EXPECT_GT(f, 300) << "flat shading shows its faces";
  EXPECT_LT(s, f / 5) << "smooth shading shows them too";
}

TEST_F(ViewerPictures, TheMouseWheelPushesTheToolIntoTheTissue) {
  const std::string plain = "--device mouse --ticks 250 --hide tool,region,overlay" + kLocal;
  const Picture rest = render("mouse_rest", plain);
  // 18 wheel notches of 0.9 mm along the view (the camera looks about 17
  // degrees off the tool's approach): the tool starts 1 cm off the surface
  // and ends ~4 mm inside
  const Picture pushed = render("mouse_pushed", plain + " --mouse-events '0 wheel 18'");
  if (HasFailure()) return;
  EXPECT_FALSE(json_true(rest.json, "contact")) << rest.json;
  ASSERT_TRUE(json_true(pushed.json, "contact")) << pushed.json;
  expect_shows_organ(pushed);
  const std::vector<double> c = json_array(pushed.json, "contact_px");
  const std::vector<double> box = json_array(pushed.json, "organ_px");
  ASSERT_EQ(c.size(), 2u);
  const double radius = 0.2 * std::hypot(box[2] - box[0], box[3] - box[1]);
  const Difference d = difference(rest, pushed, c[0], c[1], radius);
  std::printf("mouse push vs rest: %ld pixels changed, %ld near the contact, farthest %.0f px\n", d.changed, d.near,
              d.max_distance);
  EXPECT_GT(d.changed, 100);
  EXPECT_GT(d.near, 0.95 * d.changed);
  // a drag in the view plane moves the tool sideways: a different contact point
  const Picture dragged = render("mouse_dragged", plain + " --mouse-events '0 drag 240,180 300,180; 1 wheel 18'");
  const std::vector<double> c2 = json_array(dragged.json, "contact_px");
  ASSERT_EQ(c2.size(), 2u) << dragged.json;
  EXPECT_NEAR(c2[0] - c[0], 60, 6) << "60 px to the right on the screen";
  EXPECT_NEAR(c2[1], c[1], 8);
}

TEST_F(ViewerPictures, OverlayAndGlyphsAreDrawn) {
  const Picture full = render("full", "--device scripted --ticks 300");
  const Picture plain = render("plain", "--device scripted --ticks 300 --hide tool,region,overlay");
  if (HasFailure()) return;
  const std::vector<double> panel = json_array(full.json, "overlay_px");
  ASSERT_EQ(panel.size(), 4u) << full.json;
  // the panel covers its rectangle with something other than background
  long panel_background = 0, panel_pixels = 0;
  for (int y = int(panel[1]) + 2; y < std::min<int>(full.h, int(panel[3]) - 2); ++y)
    for (int x = int(panel[0]) + 2; x < std::min<int>(full.w, int(panel[2]) - 2); ++x) {
      ++panel_pixels;
      panel_background += is_background(full.at(x, y));
    }
  EXPECT_GT(panel_pixels, 1000);
  EXPECT_LT(panel_background, 0.05 * panel_pixels);
  // the tool and the force arrow change pixels around the tool, the region tint the organ
  const std::vector<double> tool = json_array(full.json, "tool_px");
  ASSERT_EQ(tool.size(), 2u);
  const Difference d = difference(plain, full, tool[0], tool[1], 40);
  EXPECT_GT(d.near, 50) << "tool, contact marker and arrow near the tool";
}

// --scalpel: the kidney's tool becomes a blade of the scalpel's size; on
// the scene's press (along the blade's own axis, its button up) it presses
// like a tool and cuts nothing, the mesh the kidney's own. (The cuts
// themselves: tests/test_viewer_session.cpp, through the haptic loop.)
TEST_F(ViewerPictures, TheScalpelPressesLikeAToolWithItsButtonUp) {
  const Picture probe = render("probe", "--device scripted --ticks 300");
  const Picture blade = render("blade", "--device scripted --ticks 300 --scalpel --hide overlay");
  if (HasFailure()) return;
  expect_shows_organ(blade);
  EXPECT_NE(probe.json.find("\"tool_radius\": 0.002,"), std::string::npos) << probe.json;
  EXPECT_NE(blade.json.find("\"tool_radius\": 0.0005,"), std::string::npos) << blade.json;
  EXPECT_TRUE(json_true(blade.json, "contact")) << blade.json;
  EXPECT_NE(blade.json.find("\"cuts\": 0,"), std::string::npos) << blade.json;
  EXPECT_NE(blade.json.find("\"cut_triangles\": 0\n"), std::string::npos) << blade.json;
  const auto nodes = [](const std::string& j) { return j.substr(j.find("\"nodes\":"), 16); };
  EXPECT_EQ(nodes(blade.json), nodes(probe.json));
}

TEST_F(ViewerPictures, TheSurfaceShowsTheDisplacementFieldWithALegendAndTheForcePlot) {
  const std::string args = "--device scripted --ticks 300 --hide tool,region,overlay" + kLocal;
  const Picture organ = render("organ", args);
  const Picture field = render("field", args + " --field displacement");
  if (HasFailure()) return;
  EXPECT_NE(field.json.find("\"field\": \"displacement\""), std::string::npos) << field.json;
  // the legend's top end is the largest |u| (mm) the press made
  const std::vector<double> range = json_array(field.json, "field_range");
  ASSERT_EQ(range.size(), 2u) << field.json;
  EXPECT_EQ(range[0], 0.0);
  const size_t k = field.json.find("\"max_displacement\": ");
  const double max_disp = std::stod(field.json.substr(k + 20));
  EXPECT_NEAR(range[1], 1e3 * max_disp, 1e-4 * range[1]);
  EXPECT_GT(range[1], 0.5);  // the press moved the surface by millimetres
  // 30 chunks of 10 ticks sampled for the force plot
  EXPECT_NE(field.json.find("\"force_samples\": 30"), std::string::npos) << field.json;
  // colours: the organ is red (R dominates); with the field, the still
  // tissue is the map's violet (B > R) and the dent its green-yellow (G > R)
  auto count = [](const Picture& p, auto pred) {
    long n = 0;
    for (int y = 0; y < p.h; ++y)
      for (int x = 0; x < p.w; ++x)
        if (!is_background(p.at(x, y)) && pred(p.at(x, y))) ++n;
    return n;
  };
  auto violet = [](const unsigned char* c) { return c[2] > c[0] + 10 && c[2] > c[1] + 10; };
  auto yellowish = [](const unsigned char* c) { return c[1] > c[0] + 5 && c[1] > c[2] + 20; };
  const long organ_violet = count(organ, violet), field_violet = count(field, violet);
  std::printf("violet pixels: organ %ld, field %ld; green-yellow: organ %ld, field %ld\n", organ_violet, field_violet,
              count(organ, yellowish), count(field, yellowish));
  EXPECT_GT(field_violet, 5 * organ_violet + 500);
  EXPECT_GT(count(field, yellowish), 20);
  EXPECT_EQ(count(organ, yellowish), 0);
  // with the overlay: the legend and the force plot make the panel taller
  const Picture panel = render("panel", "--device scripted --ticks 300 --field pressure", "", "--width 480 --height 900");
  const Picture bare = render("bare_panel", "--device scripted --ticks 300", "", "--width 480 --height 900");
  if (HasFailure()) return;
  const std::vector<double> a = json_array(panel.json, "overlay_px"), b = json_array(bare.json, "overlay_px");
  ASSERT_EQ(a.size(), 4u);
  ASSERT_EQ(b.size(), 4u);
  EXPECT_GT(a[3] - a[1], b[3] - b[1] + 20) << "legend rows";
}

TEST_F(ViewerPictures, EglAndHiddenWindowDrawTheSamePicture) {
  if (launcher() == "none") GTEST_SKIP() << "no X display or xvfb-run to compare with";
  const std::string args = "--device scripted --ticks 120 --hide overlay";
  const Picture x11 = render("x11", args, "hidden");
  const Picture egl = render("egl", args, "egl");
  if (HasFailure()) return;
  const Difference d = difference(x11, egl, 0, 0, 0);
  EXPECT_LT(d.changed, 0.001 * x11.w * x11.h) << "EGL (headless, no X) and GLFW pictures should match";
}

}  // namespace
