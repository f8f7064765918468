// report.html; see report_html.h.
#include "io/report_html.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "io/base64.h"
#include "io/file_writer.h"
#include "io/png_writer.h"

namespace lodstream::io {
namespace {

std::string escape(const std::string& s) {
  std::string out;
  for (char c : s) {
    switch (c) {
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '&': out += "&amp;"; break;
      case '"': out += "&quot;"; break;
      default: out += c;
    }
  }
  return out;
}

std::string img(const std::vector<uint8_t>& rgb, unsigned h, const std::string& alt) {
  const std::vector<uint8_t> png = encode_png(rgb, int(h), int(h), 3);
  return fmt::format("<img width=\"{}\" height=\"{}\" alt=\"{}\" src=\"data:image/png;base64,{}\">",
                     std::min(h, 320u), std::min(h, 320u), escape(alt), base64_encode(png));
}

const char* kColors[] = {"#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf", "#8c564b", "#e377c2"};

// A log–log plot of y(level) against the level's triangle count, one polyline per run. Values <= 0 sit on
// the bottom edge.
template <class Y>
std::string plot(const Report& report, const std::string& title, const std::string& unit, Y&& y) {
  double x0 = 1e300, x1 = 0, y0 = 1e300, y1 = 0;
  for (const ReportRun& r : report.runs)
    for (const ReportLevel& l : r.levels) {
      const double x = std::max<double>(1, double(l.triangles)), v = y(l);
      x0 = std::min(x0, x), x1 = std::max(x1, x);
      if (v > 0 && std::isfinite(v)) y0 = std::min(y0, v), y1 = std::max(y1, v);
    }
  if (x1 == 0) return "";
  if (y1 == 0) y0 = 0.1, y1 = 1;
  const double lx0 = std::floor(std::log10(x0)), lx1 = std::max(lx0 + 1, std::ceil(std::log10(x1)));
  const double ly0 = std::floor(std::log10(y0)), ly1 = std::max(ly0 + 1, std::ceil(std::log10(y1)));
  const int W = 520, H = 300, L = 60, R = 20, T = 30, B = 45;
  auto px = [&](double x) { return L + (std::log10(std::max(x, 1.0)) - lx0) / (lx1 - lx0) * (W - L - R); };
  auto py = [&](double v) {
    const double lv = v > 0 && std::isfinite(v) ? std::log10(v) : v > 0 ? ly1 : ly0;
    return T + (1 - (std::clamp(lv, ly0, ly1) - ly0) / (ly1 - ly0)) * (H - T - B);
  };
  std::string s = fmt::format("<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{}\" height=\"{}\" class=\"plot\">", W, H);
  s += fmt::format("<text x=\"{}\" y=\"18\" font-size=\"14\">{}</text>", L, escape(title));
  s += fmt::format("<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"#999\"/>", L, T, W - L - R, H - T - B);
  for (double e = lx0; e <= lx1; ++e)
    s += fmt::format("<text x=\"{:.1f}\" y=\"{}\" font-size=\"11\" text-anchor=\"middle\">1e{}</text>", px(std::pow(10, e)), H - B + 15, int(e));
  for (double e = ly0; e <= ly1; ++e)
    s += fmt::format("<text x=\"{}\" y=\"{:.1f}\" font-size=\"11\" text-anchor=\"end\">1e{}</text>", L - 5, py(std::pow(10, e)) + 4, int(e));
  s += fmt::format("<text x=\"{}\" y=\"{}\" font-size=\"12\">triangles</text>", (W + L) / 2 - 25, H - 8);
  s += fmt::format("<text x=\"12\" y=\"{}\" font-size=\"12\" transform=\"rotate(-90 12 {})\">{}</text>", (H + T) / 2, (H + T) / 2, escape(unit));
  for (size_t r = 0; r < report.runs.size(); ++r) {
    const char* color = kColors[r % std::size(kColors)];
    std::string pts;
    for (const ReportLevel& l : report.runs[r].levels) {
      const double x = px(std::max<double>(1, double(l.triangles))), v = py(y(l));
      pts += fmt::format("{:.1f},{:.1f} ", x, v);
      s += fmt::format("<circle cx=\"{:.1f}\" cy=\"{:.1f}\" r=\"3\" fill=\"{}\"/>", x, v, color);
    }
    s += fmt::format("<polyline points=\"{}\" fill=\"none\" stroke=\"{}\" stroke-width=\"1.5\"/>", pts, color);
    s += fmt::format("<text x=\"{}\" y=\"{}\" font-size=\"11\" fill=\"{}\">{}</text>", W - R - 200, T + 14 + 13 * int(r), color,
                     escape(report.runs[r].name));
  }
  return s + "</svg>";
}

std::string num(double v) { return fmt::format("{:.4g}", v); }

}  // namespace

void write_report_html(const std::string& path, const Report& report, const ReportOptions& options,
                       const std::vector<std::vector<std::vector<HtmlView>>>& views) {
  std::string h;
  h += "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>lodstream error report</title>\n";
  h += "<style>body{font-family:sans-serif;margin:20px;color:#222}table{border-collapse:collapse;margin:8px 0}"
       "td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}th{background:#f3f3f3}"
       "td:first-child,th:first-child{text-align:left}.views img{margin:2px;border:1px solid #ddd}"
       ".caption{font-size:12px;color:#555}.plots svg{margin-right:16px}</style></head><body>\n";
  h += "<h1>lodstream error report</h1>\n";
  h += fmt::format("<p>{} views per level, {}×{} pixels, seed {}, {} Hausdorff samples of each kind per direction. "
                   "Pixel figures are pixels of these images, with the camera at the level's switching distance. "
                   "A pixel is covered when its centre ray or any of {}×{} rays over it hits, for original and level "
                   "alike.</p>\n",
                   options.views, options.resolution, options.resolution, options.seed, options.samples,
                   options.supersample, options.supersample);
  h += "<div class=\"plots\">";
  h += plot(report, "silhouette error p95 vs triangles", "pixels", [](const ReportLevel& l) { return l.silhouette.p95; });
  h += plot(report, "Hausdorff mean vs triangles", "% of bbox diagonal", [](const ReportLevel& l) { return l.hausdorff_mean_percent; });
  h += "</div>\n";
  for (size_t r = 0; r < report.runs.size(); ++r) {
    const ReportRun& run = report.runs[r];
    h += fmt::format("<h2>{}</h2>\n<p>original {}: {} triangles, bbox diagonal {}</p>\n", escape(run.name),
                     escape(run.original), run.original_triangles, num(run.bbox_diagonal));
    h += "<table><tr><th>level</th><th>triangles</th><th>edges</th><th>points</th><th>switch distance</th>"
         "<th>silhouette max / p95 / mean (px)</th><th>mismatch</th><th>thin kept</th><th>depth p95 (px)</th><th>normal p95 (°)</th>"
         "<th>Hausdorff max / mean (% diag)</th><th>Hausdorff max / mean (px)</th></tr>\n";
    for (size_t l = 0; l < run.levels.size(); ++l) {
      const ReportLevel& v = run.levels[l];
      h += fmt::format("<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{} / {} / {}</td><td>{:.3f}%</td>"
                       "<td>{:.1f}%</td><td>{}</td><td>{}</td><td>{} / {}</td><td>{} / {}</td></tr>\n",
                       l, v.triangles, v.edges, v.points, num(v.switch_distance), num(v.silhouette.max),
                       num(v.silhouette.p95), num(v.silhouette.mean), 100 * v.mismatch_fraction,
                       100 * v.thin_kept_fraction, num(v.depth.p95),
                       num(v.normal.p95), num(v.hausdorff_max_percent), num(v.hausdorff_mean_percent),
                       num(v.hausdorff_max_pixels), num(v.hausdorff_mean_pixels));
    }
    h += "</table>\n";
    for (size_t l = 0; l < run.levels.size() && r < views.size() && l < views[r].size(); ++l) {
      if (views[r][l].empty()) continue;
      h += fmt::format("<h3>{} — level {} ({} triangles)</h3>\n<div class=\"views\">\n", escape(run.name), l,
                       run.levels[l].triangles);
      for (const HtmlView& v : views[r][l]) {
        const std::string tag = fmt::format("level {} view {}", l, v.view);
        h += "<div>" + img(v.original_rgb, v.resolution, "original, " + tag) + img(v.lod_rgb, v.resolution, tag) +
             img(v.heat_rgb, v.resolution, "mismatch, " + tag) +
             fmt::format("<div class=\"caption\">view {}: original, level {}, silhouette mismatch (yellow 1 px → red ≥ 8 px)</div></div>\n",
                         v.view, l);
      }
      h += "</div>\n";
    }
  }
  h += "<p id=\"report-status\">not checked</p>\n";
  h += "<script>window.addEventListener('load',function(){var im=document.images,ok=0;for(var i=0;i<im.length;i++)"
       "if(im[i].complete&&im[i].naturalWidth>0)ok++;"
       "document.getElementById('report-status').textContent=(ok==im.length?'ok ':'broken ')+ok+'/'+im.length;});"
       "</script>\n";
  h += "</body></html>\n";
  write_file_atomic(path, h, Sync::durable);
}

}  // namespace lodstream::io
