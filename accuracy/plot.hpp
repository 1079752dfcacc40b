// PNG plots: the tradeoff sweep (error against cost on log-log axes, one
// colour per group, the Pareto front joined by a line and ringed, and
// labels) and the Hertz verification (force against indentation).
// Drawn by a tiny software rasteriser (Canvas: pixels, lines, discs, text
// from stb_easy_font) and written with stb_image_write (libstb-dev).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "accuracy/hertz.hpp"
#include "accuracy/tradeoff.hpp"

namespace tissue::accuracy {

/// An RGB picture (w x h pixels, 3 bytes each, rows top to bottom).
class Canvas {
 public:
  struct Colour {
    std::uint8_t r, g, b;
  };

  /// A w x h canvas filled with `background`.
  Canvas(int w, int h, Colour background = {255, 255, 255});

  int width() const { return w_; }
  int height() const { return h_; }
  const std::vector<std::uint8_t>& pixels() const { return rgb_; }
  Colour at(int x, int y) const;

  /// Sets one pixel (ignored outside the canvas).
  void set(int x, int y, Colour c);
  /// Fills [x0, x1) x [y0, y1) (clipped).
  void fill_rect(int x0, int y0, int x1, int y1, Colour c);
  /// A line of the given width (pixels) between two points (pixel coordinates).
  void line(double x0, double y0, double x1, double y1, Colour c, double width = 1);
  /// A filled disc.
  void disc(double x, double y, double radius, Colour c);
  /// A ring (circle outline) of the given width.
  void ring(double x, double y, double radius, Colour c, double width = 1.5);
  /// Text with its top-left corner at (x, y), glyphs scaled by `scale`
  /// (stb_easy_font's 1 = about 7 pixels high). Returns its width in pixels.
  int text(int x, int y, const std::string& s, Colour c, int scale = 1);
  /// Width of `s` in pixels at `scale`.
  static int text_width(const std::string& s, int scale = 1);

  /// Writes the canvas as a PNG; throws std::runtime_error naming the path on failure.
  void write_png(const std::string& path) const;

 private:
  int w_, h_;
  std::vector<std::uint8_t> rgb_;
};

/// Draws the sweep (x = wall time per haptic tick in ms, y = max nodal
/// displacement error against the same mesh's reference; both log10) and
/// writes it to `path` (PNG, width x height pixels).
void write_tradeoff_plot(const TradeoffResult& result, const std::string& path, int width = 1100,
                         int height = 760);

/// Draws the Hertz studies (one row per Poisson's ratio: the tool force
/// against the indentation on every mesh with the closed form, and the
/// force error against the element edge under the tool, one line per
/// indentation, with the 5 % target) and writes them to `path` (PNG).
void write_hertz_plot(const std::vector<HertzStudy>& studies, const std::string& path);

}  // namespace tissue::accuracy
