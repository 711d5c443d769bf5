// SPDX-License-Identifier: Apache-2.0
// SVG plot helpers (see cli_svg.hpp): round ticks, labels, panels, legends.
#include "servoarm/armctl/cli_svg.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace servoarm::fw::svg {

double nice_step(double span, int max_ticks) {
  if (!(span > 0) || !std::isfinite(span)) return 1;
  const double raw = span / std::max(1, max_ticks);
  const double mag = std::pow(10.0, std::floor(std::log10(raw)));
  for (double m : {1.0, 2.0, 5.0, 10.0})
    if (m * mag >= raw * (1 - 1e-9)) return m * mag;
  return 10 * mag;
}

std::vector<double> ticks(double lo, double hi, double step) {
  std::vector<double> t;
  if (!(step > 0) || !(hi >= lo)) return t;
  const double first = std::ceil(lo / step - 1e-3);
  for (double k = first; k * step <= hi + step * 1e-3 && t.size() < 200; k += 1) t.push_back(k * step);
  return t;
}

std::string tick_text(double v, double step) {
  if (std::abs(v) < step * 1e-6) v = 0;
  char b[40];
  if (step >= 1e5 || step < 1e-5) {
    std::snprintf(b, sizeof b, "%.3g", v);
    return b;
  }
  const int decimals = step >= 1 ? 0 : static_cast<int>(std::ceil(-std::log10(step) - 1e-9));
  std::snprintf(b, sizeof b, "%.*f", decimals, v);
  return b;
}

double nice_range(double& lo, double& hi, int max_ticks) {
  if (!std::isfinite(lo) || !std::isfinite(hi)) lo = 0, hi = 1;
  if (hi < lo) std::swap(lo, hi);
  if (hi - lo < 1e-12 * std::max(1.0, std::abs(lo))) {
    const double c = lo;
    const double h = std::abs(c) > 0 ? 0.1 * std::abs(c) : 0.5;
    lo = c - h;
    hi = c + h;
  }
  const double step = nice_step(hi - lo, max_ticks);
  lo = std::floor(lo / step + 1e-9) * step;
  hi = std::ceil(hi / step - 1e-9) * step;
  return step;
}

std::string escape(const std::string& s) {
  std::string o;
  for (char c : s) {
    switch (c) {
      case '&': o += "&amp;"; break;
      case '<': o += "&lt;"; break;
      case '>': o += "&gt;"; break;
      case '"': o += "&quot;"; break;
      default: o += c;
    }
  }
  return o;
}

const char* color(int i) {
  static const char* c[] = {"#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f"};
  return c[((i % 8) + 8) % 8];
}

double text_width(const std::string& s, double size) { return 0.58 * size * static_cast<double>(s.size()); }

Panel make_panel(double px, double py, double pw, double ph, double xlo, double xhi, double ylo, double yhi, bool equal,
                 int max_ticks_x, int max_ticks_y) {
  Panel p;
  p.px = px, p.py = py, p.pw = pw, p.ph = ph;
  if (equal) {
    // One scale: pixels per unit set by the axis that needs more room; the other range widened.
    if (!(xhi > xlo)) xlo -= 0.5, xhi += 0.5;
    if (!(yhi > ylo)) ylo -= 0.5, yhi += 0.5;
    const double s = std::min(pw / (xhi - xlo), ph / (yhi - ylo));
    const double cx = (xlo + xhi) / 2, cy = (ylo + yhi) / 2;
    xlo = cx - pw / s / 2, xhi = cx + pw / s / 2;
    ylo = cy - ph / s / 2, yhi = cy + ph / s / 2;
    const double step = nice_step(std::max(xhi - xlo, yhi - ylo), std::max(max_ticks_x, max_ticks_y));
    p.xstep = p.ystep = step;
    p.x0 = xlo, p.x1 = xhi, p.y0 = ylo, p.y1 = yhi;
    return p;
  }
  p.xstep = nice_range(xlo, xhi, max_ticks_x);
  p.ystep = nice_range(ylo, yhi, max_ticks_y);
  p.x0 = xlo, p.x1 = xhi, p.y0 = ylo, p.y1 = yhi;
  return p;
}

Doc::Doc(double width, double height) : w_(width), h_(height) {}

std::string Doc::clip_id(const Panel& p) {
  char b[200];
  const std::string id = "clip" + std::to_string(++clips_);
  std::snprintf(b, sizeof b, "<clipPath id=\"%s\"><rect x=\"%.1f\" y=\"%.1f\" width=\"%.1f\" height=\"%.1f\"/></clipPath>\n",
                id.c_str(), p.px, p.py, p.pw, p.ph);
  defs_ += b;
  return id;
}

void Doc::text(double x, double y, const std::string& s, const char* anchor, double size, const char* fill,
               const char* extra) {
  char b[160];
  std::snprintf(b, sizeof b, "<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"%s\" font-size=\"%g\" fill=\"%s\"%s%s>", x, y,
                anchor, size, fill, *extra ? " " : "", extra);
  body_ += b + escape(s) + "</text>\n";
}

void Doc::axes(const Panel& p, const std::string& xtitle, const std::string& ytitle) {
  char b[240];
  std::snprintf(b, sizeof b, "<rect x=\"%.1f\" y=\"%.1f\" width=\"%.1f\" height=\"%.1f\" fill=\"white\" stroke=\"#666\"/>\n",
                p.px, p.py, p.pw, p.ph);
  body_ += b;
  double widest = 0;
  for (double v : ticks(p.y0, p.y1, p.ystep)) {
    const double y = p.Y(v);
    std::snprintf(b, sizeof b, "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"%s\"/>\n", p.px, y, p.px + p.pw,
                  y, std::abs(v) < p.ystep * 1e-6 ? "#999" : "#e6e6e6");
    body_ += b;
    const std::string t = tick_text(v, p.ystep);
    widest = std::max(widest, text_width(t, 11));
    text(p.px - 5, y + 4, t, "end", 11, "#333");
  }
  for (double v : ticks(p.x0, p.x1, p.xstep)) {
    const double x = p.X(v);
    std::snprintf(b, sizeof b, "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"%s\"/>\n", x, p.py, x,
                  p.py + p.ph, std::abs(v) < p.xstep * 1e-6 ? "#999" : "#e6e6e6");
    body_ += b;
    text(x, p.py + p.ph + 15, tick_text(v, p.xstep), "middle", 11, "#333");
  }
  if (!xtitle.empty()) text(p.px + p.pw / 2, p.py + p.ph + 32, xtitle, "middle", 12);
  if (!ytitle.empty()) {
    const double x = p.px - widest - 14, y = p.py + p.ph / 2;
    std::snprintf(b, sizeof b, "transform=\"rotate(-90 %.1f %.1f)\"", x, y);
    text(x, y, ytitle, "middle", 12, "#000", b);
  }
}

void Doc::polyline(const Panel& p, const std::vector<double>& x, const std::vector<double>& y, const char* stroke,
                   double width, const char* dash) {
  if (x.empty()) return;
  const std::string id = clip_id(p);
  char b[200];
  std::snprintf(b, sizeof b, "<polyline clip-path=\"url(#%s)\" fill=\"none\" stroke=\"%s\" stroke-width=\"%g\"%s%s%s points=\"",
                id.c_str(), stroke, width, dash ? " stroke-dasharray=\"" : "", dash ? dash : "", dash ? "\"" : "");
  body_ += b;
  const std::size_t n = std::min(x.size(), y.size());
  const std::size_t stride = std::max<std::size_t>(1, n / 1500);  // keep files small
  for (std::size_t k = 0; k < n; k += stride) {
    std::snprintf(b, sizeof b, "%.2f,%.2f ", p.X(x[k]), p.Y(y[k]));
    body_ += b;
  }
  std::snprintf(b, sizeof b, "%.2f,%.2f\"/>\n", p.X(x[n - 1]), p.Y(y[n - 1]));
  body_ += b;
}

void Doc::legend(double x, double y, const std::vector<Entry>& entries, double size) {
  double w = 0;
  for (const Entry& e : entries) w = std::max(w, text_width(e.label, size));
  const double row = size + 6, bw = w + 44, bh = row * static_cast<double>(entries.size()) + 8;
  char b[260];
  std::snprintf(b, sizeof b, "<rect x=\"%.1f\" y=\"%.1f\" width=\"%.1f\" height=\"%.1f\" fill=\"white\" fill-opacity=\"0.9\" stroke=\"#999\"/>\n",
                x, y, bw, bh);
  body_ += b;
  for (std::size_t i = 0; i < entries.size(); ++i) {
    const Entry& e = entries[i];
    const double cy = y + 4 + row * (static_cast<double>(i) + 0.5);
    const std::string k = e.kind;
    if (k == "fill")
      std::snprintf(b, sizeof b, "<rect x=\"%.1f\" y=\"%.1f\" width=\"22\" height=\"%.1f\" fill=\"%s\" stroke=\"none\"/>\n",
                    x + 8, cy - size / 2 + 1, size - 2, e.color);
    else if (k == "dot")
      std::snprintf(b, sizeof b, "<circle cx=\"%.1f\" cy=\"%.1f\" r=\"4\" fill=\"%s\"/>\n", x + 19, cy, e.color);
    else
      std::snprintf(b, sizeof b, "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"%s\" stroke-width=\"2.5\"%s/>\n",
                    x + 8, cy, x + 30, cy, e.color, k == "dash" ? " stroke-dasharray=\"5,3\"" : "");
    body_ += b;
    text(x + 36, cy + size / 3, e.label, "start", size);
  }
}

std::string Doc::str() const {
  char b[300];
  std::snprintf(b, sizeof b,
                "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"%.0f\" height=\"%.0f\" viewBox=\"0 0 %.0f %.0f\" "
                "font-family=\"DejaVu Sans, sans-serif\" font-size=\"12\">\n",
                w_, h_, w_, h_);
  std::string s = b;
  if (!defs_.empty()) s += "<defs>\n" + defs_ + "</defs>\n";
  s += "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
  return s + body_ + "</svg>\n";
}

bool Doc::write(const std::string& path) const {
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (!f) return false;
  const std::string s = str();
  const bool ok = std::fwrite(s.data(), 1, s.size(), f) == s.size();
  return std::fclose(f) == 0 && ok;
}

}  // namespace servoarm::fw::svg
