// SPDX-License-Identifier: Apache-2.0
#pragma once
// SVG plots for armctl (plan --svg, kin workspace --svg), written as text: panels with
// axis ticks at round values (1-2-5 steps) labelled with as many digits as the step
// needs, axis titles with units, legends; every text inside the canvas (margins sized
// for the labels). Non-real-time: allocates.
#include <string>
#include <vector>

namespace servoarm::fw::svg {

/// The round step (1, 2 or 5 x 10^k) that divides `span` into at most `max_ticks` steps.
double nice_step(double span, int max_ticks);
/// Tick values: the multiples of `step` within [lo, hi] (with a tolerance of step/1000).
std::vector<double> ticks(double lo, double hi, double step);
/// A tick label with the decimals `step` needs and no more: 0.35 (step 0.05), 1200, -0.002.
std::string tick_text(double v, double step);
/// Widen [lo, hi] to multiples of a nice step (about `max_ticks` ticks); a zero span
/// becomes a unit-wide one. Returns the step.
double nice_range(double& lo, double& hi, int max_ticks);
/// XML-escape text (&, <, >, ").
std::string escape(const std::string& s);

/// Colours of the series (joint 1, 2, ...).
const char* color(int i);

/// A plotting area on the canvas (pixels) showing [x0, x1] x [y0, y1] (data units).
struct Panel {
  double px = 0, py = 0, pw = 100, ph = 100;
  double x0 = 0, x1 = 1, y0 = 0, y1 = 1;
  double xstep = 0.2, ystep = 0.2;
  double X(double x) const { return px + pw * (x - x0) / (x1 - x0); }
  double Y(double y) const { return py + ph - ph * (y - y0) / (y1 - y0); }
};

/// A panel for the data range [xlo, xhi] x [ylo, yhi] in the pixel box (px, py, pw, ph):
/// nice ranges and steps on both axes. With `equal` the two axes get one scale (a
/// workspace, a tool path): the box shrinks along one axis and is centred.
Panel make_panel(double px, double py, double pw, double ph, double xlo, double xhi, double ylo, double yhi,
                 bool equal = false, int max_ticks_x = 6, int max_ticks_y = 5);

class Doc {
 public:
  Doc(double width, double height);
  /// Frame, grid lines, ticks and their labels, the axis titles ("time [s]").
  void axes(const Panel& p, const std::string& xtitle, const std::string& ytitle);
  /// A line through the points (data units), clipped to the panel by a clipPath.
  void polyline(const Panel& p, const std::vector<double>& x, const std::vector<double>& y, const char* stroke,
                double width = 1.5, const char* dash = nullptr);
  void text(double x, double y, const std::string& s, const char* anchor = "start", double size = 12,
            const char* fill = "#000", const char* extra = "");
  /// A legend box at (x, y): one row per entry, a swatch ("line", "fill", "dot") and a label.
  struct Entry {
    std::string label;
    const char* color;
    const char* kind;  // "line", "fill", "dot", "dash"
  };
  void legend(double x, double y, const std::vector<Entry>& entries, double size = 12);
  /// Raw SVG (shapes written by the caller in pixels).
  void raw(const std::string& s) { body_ += s; }
  std::string str() const;
  bool write(const std::string& path) const;
  double width() const { return w_; }
  double height() const { return h_; }

 private:
  std::string clip_id(const Panel& p);
  double w_, h_;
  std::string defs_, body_;
  int clips_ = 0;
};

/// Approximate width in pixels of `s` in the sans-serif font at `size` (for layout).
double text_width(const std::string& s, double size = 12);

}  // namespace servoarm::fw::svg
