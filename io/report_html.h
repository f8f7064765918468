// report.html: the error report as one self-contained page (no server, no network: images are PNG data
// URIs, plots are inline SVG). Per level: its figures, and for a few views the original, the level
// (thick edges orange, points red) and a heat map of silhouette mismatch; on top, plots of silhouette p95
// and Hausdorff mean against triangle count, one series per run, so runs given together sit side by side.
// A small inline script checks that every image decoded and writes "ok N/N" into #report-status (the
// headless-browser test reads it).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "lodstream/lodstream.h"

namespace lodstream::io {

struct HtmlView {
  unsigned view = 0;
  unsigned resolution = 0;
  std::vector<uint8_t> original_rgb, lod_rgb, heat_rgb;  // resolution² RGB pixels each
};

// views[r][l]: the rendered views of level l of run r.
void write_report_html(const std::string& path, const Report& report, const ReportOptions& options,
                       const std::vector<std::vector<std::vector<HtmlView>>>& views);

}  // namespace lodstream::io
