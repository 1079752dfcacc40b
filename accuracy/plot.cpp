#include "accuracy/plot.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <tuple>
#include <stdexcept>

// Private copies of the stb functions (static), so that another library's
// stb_image_write implementation in the same program cannot clash.
#define STB_IMAGE_WRITE_STATIC
#define STB_IMAGE_WRITE_IMPLEMENTATION
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"
#pragma GCC diagnostic ignored "-Wunused-function"
#include <stb/stb_easy_font.h>
#include <stb/stb_image_write.h>
#pragma GCC diagnostic pop

#include <cstdio>

#include "io/atomic_file.hpp"

namespace tissue::accuracy {

Canvas::Canvas(int w, int h, Colour bg) : w_(w), h_(h) {
  if (w < 1 || h < 1) throw std::invalid_argument(fmt::format("canvas size {}x{} must be positive", w, h));
  rgb_.resize(3 * std::size_t(w) * h);
  fill_rect(0, 0, w, h, bg);
}

Canvas::Colour Canvas::at(int x, int y) const {
  const std::size_t k = 3 * (std::size_t(y) * w_ + x);
  return {rgb_[k], rgb_[k + 1], rgb_[k + 2]};
}

void Canvas::set(int x, int y, Colour c) {
  if (x < 0 || y < 0 || x >= w_ || y >= h_) return;
  const std::size_t k = 3 * (std::size_t(y) * w_ + x);
  rgb_[k] = c.r;
  rgb_[k + 1] = c.g;
  rgb_[k + 2] = c.b;
}

void Canvas::fill_rect(int x0, int y0, int x1, int y1, Colour c) {
  for (int y = std::max(0, y0); y < std::min(h_, y1); ++y)
    for (int x = std::max(0, x0); x < std::min(w_, x1); ++x) set(x, y, c);
}

void Canvas::line(double x0, double y0, double x1, double y1, Colour c, double width) {
  // distance-to-segment test over the segment's bounding box
  const double r = 0.5 * width;
  const int xa = int(std::floor(std::min(x0, x1) - r)), xb = int(std::ceil(std::max(x0, x1) + r));
  const int ya = int(std::floor(std::min(y0, y1) - r)), yb = int(std::ceil(std::max(y0, y1) + r));
  const double dx = x1 - x0, dy = y1 - y0, len2 = dx * dx + dy * dy;
  for (int y = std::max(0, ya); y <= std::min(h_ - 1, yb); ++y)
    for (int x = std::max(0, xa); x <= std::min(w_ - 1, xb); ++x) {
      const double t = len2 > 0 ? std::clamp(((x - x0) * dx + (y - y0) * dy) / len2, 0.0, 1.0) : 0.0;
      const double ex = x - (x0 + t * dx), ey = y - (y0 + t * dy);
      if (ex * ex + ey * ey <= r * r + 0.25) set(x, y, c);
    }
}

void Canvas::disc(double cx, double cy, double radius, Colour c) {
  for (int y = int(cy - radius - 1); y <= int(cy + radius + 1); ++y)
    for (int x = int(cx - radius - 1); x <= int(cx + radius + 1); ++x)
      if ((x - cx) * (x - cx) + (y - cy) * (y - cy) <= radius * radius) set(x, y, c);
}

void Canvas::ring(double cx, double cy, double radius, Colour c, double width) {
  const double lo = radius - 0.5 * width, hi = radius + 0.5 * width;
  for (int y = int(cy - hi - 1); y <= int(cy + hi + 1); ++y)
    for (int x = int(cx - hi - 1); x <= int(cx + hi + 1); ++x) {
      const double d = std::hypot(x - cx, y - cy);
      if (d >= lo && d <= hi) set(x, y, c);
    }
}

int Canvas::text(int x, int y, const std::string& s, Colour c, int scale) {
  std::vector<char> buf(s.begin(), s.end());
  buf.push_back('\0');
  std::vector<float> vb(std::max<std::size_t>(1024, 80 * s.size() + 64));
  const int quads = stb_easy_font_print(0, 0, buf.data(), nullptr, vb.data(), int(vb.size() * sizeof(float)));
  for (int q = 0; q < quads; ++q) {
    const float* v = vb.data() + 16 * q;  // 4 vertices of (x, y, z, rgba) = 4 floats each
    const float x0 = v[0], y0 = v[1], x1 = v[8], y1 = v[9];
    fill_rect(x + int(std::lround(scale * x0)), y + int(std::lround(scale * y0)), x + int(std::lround(scale * x1)),
              y + int(std::lround(scale * y1)), c);
  }
  return text_width(s, scale);
}

int Canvas::text_width(const std::string& s, int scale) {
  std::vector<char> buf(s.begin(), s.end());
  buf.push_back('\0');
  return scale * stb_easy_font_width(buf.data());
}

void Canvas::write_png(const std::string& path) const {
  const std::string part = io::part_path(path);  // renamed into place when whole
  if (!stbi_write_png(part.c_str(), w_, h_, 3, rgb_.data(), 3 * w_)) {
    std::remove(part.c_str());
    throw std::runtime_error(fmt::format("{}: cannot write the PNG", path));
  }
  io::rename_into_place(part, path);
}

namespace {

using Colour = Canvas::Colour;

const std::map<std::string, Colour>& group_colours() {
  static const std::map<std::string, Colour> c{
      {"baseline", {0, 0, 0}},       {"depth", {31, 119, 180}},   {"auto", {214, 39, 40}},
      {"precision", {148, 103, 189}}, {"safety", {44, 160, 44}},   {"mesh", {255, 127, 14}},
      {"tolerance", {140, 86, 75}},  {"anchor", {23, 190, 207}},  {"compare", {227, 119, 194}},
      {"mass", {188, 189, 34}}};
  return c;
}

/// Log10 axis range covering [lo, hi] with whole decades.
std::pair<double, double> decades(double lo, double hi) {
  double a = std::floor(std::log10(lo)), b = std::ceil(std::log10(hi));
  if (b <= a) b = a + 1;
  return {a, b};
}


/// A log-log plot area of a canvas: whole decades on both axes, a grid with
/// minor lines at 2..9, decade labels, the axes lines and their titles.
struct LogAxes {
  int left, top, pw, ph;
  double xa, xb, ya, yb;  // log10 ranges
  double floor_y = 1e-300;

  LogAxes(int left_, int top_, int pw_, int ph_, double xlo, double xhi, double ylo, double yhi)
      : left(left_), top(top_), pw(pw_), ph(ph_) {
    std::tie(xa, xb) = decades(xlo, xhi);
    std::tie(ya, yb) = decades(ylo, yhi);
  }
  double px(double x) const { return left + pw * (std::log10(std::max(x, 1e-300)) - xa) / (xb - xa); }
  double py(double y) const { return top + ph * (1 - (std::log10(std::max(y, floor_y)) - ya) / (yb - ya)); }

  /// Grid, decade labels ("1e-3" style unless `plain_x`), axes and titles.
  void draw(Canvas& cv, const std::string& x_title, const std::string& y_title, bool plain_x) const {
    const Colour grid{225, 225, 225}, axis{0, 0, 0}, grey{90, 90, 90};
    for (int d = int(xa); d <= int(xb); ++d) {
      for (int k = 1; k <= 9 && (d < xb || k == 1); ++k)
        cv.line(px(k * std::pow(10, d)), top, px(k * std::pow(10, d)), top + ph, grid);
      const std::string s = plain_x ? fmt::format("{:g}", std::pow(10.0, d)) : fmt::format("1e{}", d);
      cv.text(int(px(std::pow(10, d))) - Canvas::text_width(s, 2) / 2, top + ph + 8, s, grey, 2);
    }
    for (int d = int(ya); d <= int(yb); ++d) {
      for (int k = 1; k <= 9 && (d < yb || k == 1); ++k)
        cv.line(left, py(k * std::pow(10, d)), left + pw, py(k * std::pow(10, d)), grid);
      const std::string s = fmt::format("1e{}", d);
      cv.text(left - 10 - Canvas::text_width(s, 2), int(py(std::pow(10, d))) - 7, s, grey, 2);
    }
    cv.line(left, top, left, top + ph, axis, 2);
    cv.line(left, top + ph, left + pw, top + ph, axis, 2);
    cv.text(left + pw / 2 - Canvas::text_width(x_title, 2) / 2, top + ph + 36, x_title, axis, 2);
    cv.text(std::max(8, left - 82), top - 22, y_title, axis, 2);
  }
};

}  // namespace

void write_tradeoff_plot(const TradeoffResult& res, const std::string& path, int width, int height) {
  if (std::none_of(res.rows.begin(), res.rows.end(), [](const TradeoffRow& r) { return r.failed.empty(); }))
    throw std::invalid_argument("tradeoff plot: no successful rows to draw");
  Canvas cv(width, height);
  const int left = 90, right = 300, top = 64, bottom = 70;
  const int pw = width - left - right, ph = height - top - bottom;
  constexpr double kFloor = 1e-9;  // errors below are drawn at the floor
  double xlo = 1e300, xhi = 0, ylo = 1e300, yhi = 0;
  for (const TradeoffRow& r : res.rows) {
    if (!r.failed.empty()) continue;
    const double x = std::max(1e3 * r.wall_per_tick, 1e-6), y = std::max(r.disp_err, kFloor);
    xlo = std::min(xlo, x);
    xhi = std::max(xhi, x);
    ylo = std::min(ylo, y);
    yhi = std::max(yhi, y);
  }
  LogAxes ax(left, top, pw, ph, xlo, xhi, ylo, yhi);
  ax.floor_y = kFloor;
  const auto px = [&](double x) { return ax.px(std::max(x, 1e-6)); };
  const auto py = [&](double y) { return ax.py(y); };
  const Colour axis{0, 0, 0}, grey{90, 90, 90};
  ax.draw(cv, "wall time per 1 ms haptic tick (ms)",
          "max nodal displacement error / max displacement (vs same-mesh reference)", true);
  cv.text(left, 6, fmt::format("speed-accuracy tradeoff: {} ({})", res.scene, res.device.substr(0, 60)), axis, 2);
  // Pareto front, by cost
  std::vector<const TradeoffRow*> front;
  for (const TradeoffRow& r : res.rows)
    if (r.pareto) front.push_back(&r);
  std::sort(front.begin(), front.end(),
            [](const TradeoffRow* a, const TradeoffRow* b) { return a->wall_per_tick < b->wall_per_tick; });
  for (std::size_t k = 1; k < front.size(); ++k)
    cv.line(px(1e3 * front[k - 1]->wall_per_tick), py(front[k - 1]->disp_err), px(1e3 * front[k]->wall_per_tick),
            py(front[k]->disp_err), {120, 120, 120}, 2);
  // points, then labels placed beside them without overlapping each other
  struct Box {
    int x0, y0, x1, y1;
  };
  std::vector<Box> placed;
  for (const TradeoffRow& r : res.rows) {
    if (!r.failed.empty()) continue;
    const double x = px(1e3 * r.wall_per_tick), y = py(r.disp_err);
    placed.push_back({int(x) - 6, int(y) - 6, int(x) + 6, int(y) + 6});
  }
  auto free_at = [&](const Box& b) {
    if (b.x0 < 0 || b.x1 > width || b.y0 < 0 || b.y1 > height) return false;
    for (const Box& p : placed)
      if (b.x0 < p.x1 && p.x0 < b.x1 && b.y0 < p.y1 && p.y0 < b.y1) return false;
    return true;
  };
  for (const TradeoffRow& r : res.rows) {
    if (!r.failed.empty()) continue;
    const auto it = group_colours().find(r.setting.group);
    const Colour c = it != group_colours().end() ? it->second : grey;
    const double x = px(1e3 * r.wall_per_tick), y = py(r.disp_err);
    cv.disc(x, y, 5, c);
    if (r.pareto) cv.ring(x, y, 9, {0, 0, 0}, 2);
    const std::string label = r.setting.label.substr(0, r.setting.label.find(':'));
    const int w = Canvas::text_width(label), h = 9;
    Box best{int(x) + 11, int(y) - 5, int(x) + 11 + w, int(y) - 5 + h};
    for (int k = 0; k < 24; ++k) {  // right of the point, then left, stepping away vertically
      const int dy = (k / 2 % 2 ? -1 : 1) * (k / 4) * 10;
      const Box b = k % 2 ? Box{int(x) - 11 - w, int(y) - 5 + dy, int(x) - 11, int(y) - 5 + dy + h}
                          : Box{int(x) + 11, int(y) - 5 + dy, int(x) + 11 + w, int(y) - 5 + dy + h};
      if (free_at(b)) {
        best = b;
        break;
      }
    }
    placed.push_back(best);
    if (std::abs(best.y0 + 5 - int(y)) > 8) {  // a leader line to a displaced label
      const int lx = best.x0 > x ? best.x0 - 1 : best.x1 + 1;
      cv.line(x, y, lx, best.y0 + 4, {170, 170, 170}, 1);
    }
    cv.text(best.x0, best.y0, label, c, 1);
  }
  // legend
  int ly = top + 10;
  const int lx = left + pw + 25;
  for (const auto& [group, colour] : group_colours()) {
    bool used = false;
    for (const TradeoffRow& r : res.rows) used = used || r.setting.group == group;
    if (!used) continue;
    cv.disc(lx + 6, ly + 7, 5, colour);
    cv.text(lx + 18, ly, group, colour, 2);
    ly += 24;
  }
  cv.ring(lx + 6, ly + 7, 9, {0, 0, 0}, 2);
  cv.text(lx + 22, ly, "Pareto front", axis, 2);
  ly += 30;
  for (const std::string& line : {std::string("errors below 1e-9"), std::string("are drawn at 1e-9")}) {
    cv.text(lx, ly, line, grey, 1);
    ly += 12;
  }
  cv.write_png(path);
}

void write_hertz_plot(const std::vector<HertzStudy>& studies, const std::string& path) {
  if (studies.empty() || studies.front().levels.empty()) throw std::invalid_argument("hertz plot: nothing to draw");
  const int panel_w = 700, panel_h = 520, left = 100, right = 190, top = 70, bottom = 80;
  const int width = 2 * panel_w, height = panel_h * int(studies.size());
  Canvas cv(width, height);
  const Colour black{0, 0, 0}, grey{90, 90, 90};
  const Colour palette[] = {{31, 119, 180}, {255, 127, 14}, {44, 160, 44}, {214, 39, 40},
                            {148, 103, 189}, {140, 86, 75}, {227, 119, 194}, {23, 190, 207}};
  const auto colour = [&](std::size_t k) { return palette[k % std::size(palette)]; };
  for (std::size_t s = 0; s < studies.size(); ++s) {
    const HertzStudy& st = studies[s];
    const HertzOptions& o = st.options;
    const int y0 = int(s) * panel_h;
    // left: force against indentation, the closed form as a line
    double dlo = 1e300, dhi = 0, flo = 1e300, fhi = 0;
    for (const HertzLevel& l : st.levels)
      for (const HertzPoint& p : l.points) {
        dlo = std::min(dlo, 1e3 * p.delta);
        dhi = std::max(dhi, 1e3 * p.delta);
        flo = std::min({flo, p.force, p.hertz});
        fhi = std::max({fhi, p.force, p.hertz});
      }
    const int pw = panel_w - left - right, ph = panel_h - top - bottom;
    LogAxes f(left, y0 + top, pw, ph, dlo, dhi, flo, fhi);
    f.draw(cv, "indentation delta (mm)", "tool force F (N)", true);
    cv.text(left, y0 + 8,
            fmt::format("Hertz: sphere R = {:g} mm, E = {:g} Pa, nu = {:g}", 1e3 * o.R, o.E, o.nu), black, 2);
    const int samples = 60;
    for (int k = 0; k < samples; ++k) {
      const double d0 = dlo * std::pow(dhi / dlo, double(k) / samples), d1 = dlo * std::pow(dhi / dlo, double(k + 1) / samples);
      cv.line(f.px(d0), f.py(hertz_force(o.E, o.nu, o.R, 1e-3 * d0)), f.px(d1),
              f.py(hertz_force(o.E, o.nu, o.R, 1e-3 * d1)), black, 2.5);
    }
    int ly = y0 + top + 6;
    const int lx = left + pw + 20;
    cv.line(lx, ly + 7, lx + 14, ly + 7, black, 2.5);
    cv.text(lx + 20, ly, "Hertz", black, 2);
    ly += 24;
    for (std::size_t k = 0; k < st.levels.size(); ++k) {
      const HertzLevel& l = st.levels[k];
      for (std::size_t j = 0; j < l.points.size(); ++j) {
        const HertzPoint& p = l.points[j];
        cv.disc(f.px(1e3 * p.delta), f.py(p.force), 4.5, colour(k));
        if (j > 0)
          cv.line(f.px(1e3 * l.points[j - 1].delta), f.py(l.points[j - 1].force), f.px(1e3 * p.delta), f.py(p.force),
                  colour(k), 1.5);
      }
      cv.disc(lx + 7, ly + 7, 4.5, colour(k));
      cv.text(lx + 20, ly, fmt::format("{} cells", l.cells), colour(k), 2);
      ly += 24;
    }
    // right: |error| against the element edge under the tool, one line per
    // indentation, and the 5 % target
    double hlo = 1e300, hhi = 0, elo = 1e300, ehi = 0.05;
    for (const HertzLevel& l : st.levels) {
      hlo = std::min(hlo, 1e3 * l.h_contact);
      hhi = std::max(hhi, 1e3 * l.h_contact);
      for (const HertzPoint& p : l.points) {
        elo = std::min(elo, std::max(std::fabs(p.error), 1e-4));
        ehi = std::max(ehi, std::fabs(p.error));
      }
    }
    const int x1 = panel_w;
    LogAxes e(x1 + left, y0 + top, pw, ph, hlo, hhi, elo, ehi);
    e.floor_y = 1e-4;
    e.draw(cv, "element edge under the tool h (mm)", "|F - F_Hertz| / F_Hertz", true);
    cv.line(e.left, e.py(0.05), e.left + pw, e.py(0.05), {200, 0, 0}, 1.5);
    cv.text(e.left + 6, int(e.py(0.05)) - 16, "5 %", {200, 0, 0}, 2);
    const std::size_t n_points = st.levels.front().points.size();
    ly = y0 + top + 6;
    for (std::size_t j = 0; j < n_points; ++j) {
      for (std::size_t k = 0; k < st.levels.size(); ++k) {
        if (j >= st.levels[k].points.size()) continue;
        const double x = e.px(1e3 * st.levels[k].h_contact), y = e.py(std::fabs(st.levels[k].points[j].error));
        cv.disc(x, y, 4.5, colour(j + 4));
        if (k > 0 && j < st.levels[k - 1].points.size())
          cv.line(e.px(1e3 * st.levels[k - 1].h_contact), e.py(std::fabs(st.levels[k - 1].points[j].error)), x, y,
                  colour(j + 4), 1.5);
      }
      cv.disc(x1 + lx + 7, ly + 7, 4.5, colour(j + 4));
      cv.text(x1 + lx + 20, ly, fmt::format("d/R {:g}", o.ratios[j]), colour(j + 4), 2);
      ly += 24;
    }
    cv.text(x1 + lx, ly + 10, st.device.substr(0, 24), grey, 1);
  }
  cv.write_png(path);
}

}  // namespace tissue::accuracy
