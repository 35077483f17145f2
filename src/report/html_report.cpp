#include "report/html_report.h"

#include <openssl/evp.h>

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>
#include <set>

#include "io/bsdf_file.h"
#include "io/bsdf_lookup.h"
#include "io/file_summary.h"
#include "io/slice_export.h"
#include "job/effects_plan.h"
#include "job/effects_planner.h"
#include "render/preview.h"

namespace mbsdf {

namespace {

std::string escapeHtml(const std::string& s) {
  std::string out;
  for (char c : s) switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      case '\'':
        out += "&#39;";
        break;
      default:
        out += c;
    }
  return out;
}

std::string pngDataUri(const RgbImage& img) {
  const std::vector<uint8_t> png = encodePng(img);
  std::string b64(4 * ((png.size() + 2) / 3) + 1, '\0');
  const int n = EVP_EncodeBlock(reinterpret_cast<unsigned char*>(b64.data()), png.data(), int(png.size()));
  b64.resize(size_t(n));
  return "data:image/png;base64," + b64;
}

// JSON for a <script type="application/json"> block: "</" cannot end the block early.
std::string scriptJson(const nlohmann::json& j) {
  std::string s = j.dump();
  for (size_t p = 0; (p = s.find("</", p)) != std::string::npos; p += 3) s.replace(p, 2, "<\\/");
  return s;
}

std::string row(const std::string& key, const std::string& value) {
  return "<tr><th>" + escapeHtml(key) + "</th><td>" + escapeHtml(value) + "</td></tr>\n";
}

std::string provenance(const BsdfFileReader& f, const nlohmann::json& summary) {
  std::string h = "<table class=\"kv\">\n";
  h += row("file", summary["file"].get<std::string>());
  for (const char* a : {"title", "program_version", "job_file", "geometry_kind", "geometry_hash", "material", "seed",
                        "paths_per_slice", "path_allocation", "max_depth", "incidence_sampling", "storage_profile",
                        "reciprocity", "symmetry", "input_files"})
    if (f.hasAttribute(a)) h += row(a, f.attribute(a));
  h += row("grid", summary["grid"].get<std::string>() + ", " + summary["bins"].dump() + " bins over the sphere");
  h += row("wavelengths (nm)", summary["wavelengths_nm"].dump());
  h += row("components", summary["components"].dump());
  h += row("slices", summary["done_count"].dump() + " of " + summary["incidence_count"].dump() + " finished" +
                         (summary["complete"].get<bool>() ? "" : " (a run that has not finished)"));
  return h + "</table>\n";
}

std::string plannerSection(const nlohmann::json& summary) {
  if (!summary.contains("effects_plan"))
    return "<p>The job listed its components itself (no <code>components = \"auto\"</code>): no planner "
           "decisions.</p>\n";
  return "<pre>" + escapeHtml(formatEffects(EffectsPlan::fromJson(summary["effects_plan"]))) + "</pre>\n";
}

std::string number(double v, const char* format) {
  if (std::isnan(v)) return "&mdash;";
  char buf[64];
  std::snprintf(buf, sizeof buf, format, v);
  return buf;
}

std::string infoTable(const nlohmann::json& summary) {
  std::string h =
      "<table class=\"info\"><thead><tr><th>slice</th><th>&theta;</th><th>&phi;</th><th>samples</th>"
      "<th>seconds</th><th>albedo</th><th>&plusmn; s.e.</th><th>reflected</th><th>transmitted</th>"
      "<th>truncated</th><th>rel. error</th><th>balance</th><th>lost</th><th>not physical</th></tr></thead>"
      "<tbody>\n";
  for (const auto& s : summary["slices"]) {
    if (!s["done"].get<bool>()) continue;
    const SliceSummary r = summariseSlice(s);
    h += "<tr><td>" + s["index"].dump() + "</td><td>" + number(s["theta_deg"].get<double>(), "%.2f") + "</td><td>" +
         number(s["phi_deg"].get<double>(), "%.2f") + "</td><td>" + s["samples"].dump() + "</td><td>" +
         number(s["seconds"].get<double>(), "%.3f") + "</td><td>" + number(r.reflected + r.transmitted, "%.6f") +
         "</td><td>" + number(r.albedoStdError, "%.2e") + "</td><td>" + number(r.reflected, "%.6f") + "</td><td>" +
         number(r.transmitted, "%.6f") + "</td><td>" + number(r.truncated, "%.2e") + "</td><td>" +
         number(r.relError, "%.2e") + "</td><td>" + number(r.balance, "%+.4f") + "</td><td>" + number(r.lost, "%+.4f") +
         "</td><td" + (r.nonphysical ? " class=\"flagged\">" + describeSliceFlags(r.nonphysical) : ">") +
         "</td></tr>\n";
  }
  return h + "</tbody></table>\n";
}

// Whether a finished slice of fileSummary's sends energy through the surface (lost left out).
bool transmits(const nlohmann::json& summary) {
  for (const auto& sl : summary["slices"]) {
    if (!sl["done"].get<bool>()) continue;
    for (const auto& [c, v] : sl["energy"]["transmitted"].items())
      for (const auto& e : v)
        if (c != "lost" && e.get<double>() > 0) return true;
  }
  return false;
}

// f in the plane of incidence, signed θo from −89° to 89° (positive: the specular side), the mean over
// the table's rows, on the side of reflection (reflected) or the other side.
std::vector<double> lobe(const BsdfLookup& lookup, const BsdfFileReader& f, int incidence, bool reflected) {
  const double phi = radians(f.incidencePhi(incidence));
  const double side = f.incidenceTheta(incidence) <= 90 ? 1.0 : -1.0;
  std::vector<double> out;
  for (int t = -89; t <= 89; ++t) {
    const double th = radians(std::abs(t)), ph = t > 0 ? phi + kPi : phi;
    const Vec3 wo{std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph), (reflected ? side : -side) * std::cos(th)};
    double v = 0;
    for (int l = 0; l < lookup.wavelengthCount(); ++l) v += lookup.eval(incidence, wo, l) / lookup.wavelengthCount();
    out.push_back(v);
  }
  return out;
}

nlohmann::json slicesData(const BsdfFileReader& f, const nlohmann::json& summary, const std::vector<int>& incidences,
                          const ReportRequest& req, const std::vector<std::string>& models) {
  nlohmann::json d;
  bool trueColour = true;
  try {
    f.toColour();
  } catch (const std::invalid_argument&) {
    trueColour = false;
  }
  const bool both = transmits(summary);
  d["both"] = both;
  d["true_colour"] = trueColour;
  for (int i : incidences)
    d["incidences"].push_back({{"index", i}, {"theta", f.incidenceTheta(i)}, {"phi", f.incidencePhi(i)}});
  for (const std::string& m : models) {
    const BsdfLookup lookup(f, m);
    nlohmann::json md;
    for (int i : incidences) {
      SliceRequest s;
      s.model = m;
      s.size = req.sliceSize;
      s.both = both;
      s.style = "false";
      md["false"].push_back(pngDataUri(renderSliceImage(f, s, i)));
      if (trueColour) {
        s.style = "true";
        md["true"].push_back(pngDataUri(renderSliceImage(f, s, i)));
      }
      md["lobe_reflected"].push_back(lobe(lookup, f, i, true));
      if (both) md["lobe_transmitted"].push_back(lobe(lookup, f, i, false));
    }
    d["models"][m] = md;
    d["model_order"].push_back(m);
  }
  return d;
}

// Per component, (θi, albedo as the mean over λ of reflected + transmitted) of each finished slice.
nlohmann::json albedoData(const nlohmann::json& summary) {
  nlohmann::json d = nlohmann::json::object();
  for (const auto& sl : summary["slices"]) {
    if (!sl["done"].get<bool>()) continue;
    const auto& reflected = sl["energy"]["reflected"];
    const auto& transmitted = sl["energy"]["transmitted"];
    for (const auto& [c, v] : reflected.items()) {
      double e = 0;
      for (size_t l = 0; l < v.size(); ++l)
        e += (v[l].get<double>() + transmitted.at(c)[l].get<double>()) / double(v.size());
      d[c].push_back({sl["theta_deg"].get<double>(), e});
    }
  }
  return d;
}

// Per model a figure with its slice in true colour (when a wavelength is visible) and in false colour;
// the script sets the pictures of the slider's incidence.
std::string viewer(const std::vector<std::string>& models, bool trueColour) {
  std::string h;
  for (const std::string& m : models) {
    const std::string id = escapeHtml(m);
    h += "<figure><figcaption>" + id + "</figcaption><div class=\"pair\">";
    if (trueColour) h += "<img id=\"true-" + id + "\" alt=\"" + id + " true colour\">";
    h += "<img id=\"false-" + id + "\" alt=\"" + id + " false colour\"></div></figure>\n";
  }
  return h.empty() ? "<p>The file holds no complete model.</p>" : h;
}

std::string previewSection(const BsdfFileReader& f, const ReportRequest& req) {
  if (req.renderSize <= 0) return "<p>No preview (<code>--render-size 0</code>).</p>\n";
  RenderRequest r;
  r.size = req.renderSize;
  r.shape = req.shape;
  r.settings.samplesPerPixel = req.renderSpp;
  const std::vector<PreviewPanel> panels = renderPreview(f, r);
  return "<p>Path traced in the built-in studio environment, " + std::to_string(req.renderSpp) +
         " samples per pixel, filmic tone curve (<code>microbsdf render</code>; docs/pictures.md).</p>\n<img "
         "alt=\"preview\" "
         "src=\"" +
         pngDataUri(composePanels(panels, 0, ToneCurve::Filmic)) + "\">\n";
}

// The page's style sheet, and its script: the slider, the lobes of the slider's incidence and the
// albedo plot, drawn as SVG from the inline JSON; #incidence=K in the address moves the slider to
// position K (through the slider's own input event).
constexpr const char* kStyle = R"(
body { font: 14px/1.45 sans-serif; margin: 1.5em auto; max-width: 1200px; color: #222; padding: 0 1em; }
h1 { font-size: 1.5em; } h2 { font-size: 1.2em; margin-top: 2em; border-bottom: 1px solid #ccc; }
table { border-collapse: collapse; } td, th { padding: 2px 8px; text-align: left; vertical-align: top; }
table.info td { text-align: right; font-variant-numeric: tabular-nums; }
table.info tbody tr:nth-child(odd) { background: #f4f4f4; } .scroll { max-height: 420px; overflow: auto; }
table.info td.flagged { color: #b00020; text-align: left; font-weight: bold; }
pre { background: #f6f6f6; padding: 0.6em; overflow: auto; max-height: 420px; }
.models { display: flex; flex-wrap: wrap; gap: 14px; } figure { margin: 0; }
figcaption { font-weight: bold; } .pair img { margin-right: 6px; image-rendering: pixelated; }
#incidence { width: 420px; vertical-align: middle; } svg text { font: 11px sans-serif; }
#errors:empty { display: none; } #errors { color: #b00; }
)";
constexpr const char* kScript = R"(
(function () {
  'use strict';
  const data = JSON.parse(document.getElementById('report-data').textContent);
  const incs = data.incidences || [];
  const models = data.model_order || [];
  const colours = { GS: '#1f77b4', GM: '#ff7f0e', WS: '#2ca02c', WM: '#d62728', coherent: '#1f77b4',
                    incoherent: '#2ca02c', multiple: '#ff7f0e', lost: '#7f7f7f', geo_masked: '#9467bd' };
  const NS = 'http://www.w3.org/2000/svg';
  function el(tag, attrs, text) {
    const e = document.createElementNS(NS, tag);
    for (const k in attrs) e.setAttribute(k, attrs[k]);
    if (text !== undefined) e.textContent = text;
    return e;
  }
  // series: [{name, colour, points: [[x, y], ...], dots}]; axes from opts.
  function plot(svg, series, o) {
    while (svg.firstChild) svg.removeChild(svg.firstChild);
    const W = 520, H = 300, L = 60, R = 110, T = 12, B = 40;
    svg.setAttribute('viewBox', '0 0 ' + W + ' ' + H);
    svg.setAttribute('width', W); svg.setAttribute('height', H);
    const sx = x => L + (x - o.xMin) / (o.xMax - o.xMin) * (W - L - R);
    const sy = y => H - B - (y - o.yMin) / (o.yMax - o.yMin) * (H - T - B);
    svg.appendChild(el('rect', { x: L, y: T, width: W - L - R, height: H - T - B, fill: 'none', stroke: '#999' }));
    for (const x of o.xTicks) {
      svg.appendChild(el('line', { x1: sx(x), x2: sx(x), y1: H - B, y2: H - B + 4, stroke: '#999' }));
      svg.appendChild(el('text', { x: sx(x), y: H - B + 16, 'text-anchor': 'middle' }, String(x)));
    }
    for (const t of o.yTicks) {
      svg.appendChild(el('line', { x1: L - 4, x2: W - R, y1: sy(t.y), y2: sy(t.y), stroke: '#eee' }));
      svg.appendChild(el('text', { x: L - 6, y: sy(t.y) + 4, 'text-anchor': 'end' }, t.label));
    }
    svg.appendChild(el('text', { x: (L + W - R) / 2, y: H - 6, 'text-anchor': 'middle' }, o.xLabel));
    svg.appendChild(el('text', { x: 12, y: T + (H - T - B) / 2, transform: 'rotate(-90 12 ' + (T + (H - T - B) / 2) + ')',
                                 'text-anchor': 'middle' }, o.yLabel));
    series.forEach((s, k) => {
      const pts = s.points.filter(p => isFinite(p[1])).map(p => sx(p[0]).toFixed(1) + ',' + sy(p[1]).toFixed(1));
      if (s.dots) {
        for (const p of pts) { const [x, y] = p.split(','); svg.appendChild(el('circle', { cx: x, cy: y, r: 2.5, fill: s.colour })); }
      } else if (pts.length) {
        svg.appendChild(el('polyline', { points: pts.join(' '), fill: 'none', stroke: s.colour, 'stroke-width': 1.5,
                                         'stroke-dasharray': s.dash || '' }));
      }
      svg.appendChild(el('line', { x1: W - R + 8, x2: W - R + 26, y1: T + 10 + 16 * k, y2: T + 10 + 16 * k, stroke: s.colour,
                                   'stroke-width': 3, 'stroke-dasharray': s.dash || '' }));
      svg.appendChild(el('text', { x: W - R + 30, y: T + 14 + 16 * k }, s.name));
    });
  }
  function drawLobes(k) {
    const series = [];
    let top = 0;
    for (const m of models) {
      for (const side of ['reflected', 'transmitted']) {
        const v = (data.models[m]['lobe_' + side] || [])[k];
        if (!v) continue;
        for (const y of v) top = Math.max(top, y);
        series.push({ name: m + (side === 'transmitted' ? ' (T)' : ''), colour: colours[m] || '#000',
                      dash: side === 'transmitted' ? '4 3' : '', values: v });
      }
    }
    const hi = Math.ceil(Math.log10(top > 0 ? top : 1)), lo = hi - 6;
    const yTicks = [];
    for (let d = lo; d <= hi; ++d) yTicks.push({ y: d, label: '1e' + d });
    for (const s of series)
      s.points = s.values.map((y, i) => [i - 89, y > 0 ? Math.max(lo, Math.log10(y)) : lo]);
    plot(document.getElementById('lobes'), series, { xMin: -90, xMax: 90, yMin: lo, yMax: hi,
      xTicks: [-90, -60, -30, 0, 30, 60, 90], yTicks: yTicks,
      xLabel: 'theta_o in the plane of incidence (deg; > 0: specular side)', yLabel: 'f (1/sr)' });
  }
  function drawAlbedo() {
    const series = [];
    let top = 1, below = false;
    for (const c in data.albedo) {
      const pts = data.albedo[c].slice().sort((a, b) => a[0] - b[0]);
      for (const p of pts) { top = Math.max(top, p[1]); below = below || p[0] > 90; }
      series.push({ name: c, colour: colours[c] || '#000', points: pts, dots: true });
    }
    const yMax = Math.ceil(top * 10) / 10, yTicks = [];
    for (let y = 0; y <= yMax + 1e-9; y += 0.2) yTicks.push({ y: y, label: y.toFixed(1) });
    plot(document.getElementById('albedo'), series, { xMin: 0, xMax: below ? 180 : 90, yMin: 0, yMax: yMax,
      xTicks: below ? [0, 30, 60, 90, 120, 150, 180] : [0, 15, 30, 45, 60, 75, 90], yTicks: yTicks,
      xLabel: 'theta_i (deg; > 90: light from below)', yLabel: 'albedo (mean over wavelengths)' });
  }
  const slider = document.getElementById('incidence');
  function update(k) {
    k = Math.max(0, Math.min(incs.length - 1, k | 0));
    slider.value = k;
    const inc = incs[k];
    document.getElementById('incidence-label').textContent = inc ?
      'theta_i = ' + inc.theta.toFixed(2) + ' deg, phi_i = ' + inc.phi.toFixed(2) + ' deg (slice ' + inc.index + ')' : '';
    for (const m of models) {
      document.getElementById('false-' + m).setAttribute('src', data.models[m]['false'][k]);
      if (data.true_colour) document.getElementById('true-' + m).setAttribute('src', data.models[m]['true'][k]);
    }
    drawLobes(k);
  }
  function fromHash() { const m = /incidence=(\d+)/.exec(location.hash); return m ? +m[1] : 0; }
  // The address moves the slider itself: its own input event redraws, as a hand on it would.
  function moveSlider(k) { slider.value = k; slider.dispatchEvent(new Event('input')); }
  slider.max = Math.max(0, incs.length - 1);
  slider.addEventListener('input', () => update(+slider.value));
  window.addEventListener('hashchange', () => moveSlider(fromHash()));
  drawAlbedo();
  moveSlider(fromHash());
  document.body.dataset.ready = '1';
})();
)";

// The page around the parts: CSS, the slice viewer's markup and the script that draws the figures.
std::string page(const std::string& title, const std::string& provenanceHtml, const std::string& jobHtml,
                 const std::string& plannerHtml, const std::string& infoHtml, const std::string& viewerHtml,
                 const std::string& dataJson, const std::string& previewHtml) {
  return "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>microbsdf report: " + title +
         "</title>\n<style>" + kStyle +
         "</style>\n"
         "<script>window.addEventListener('error', e => { document.getElementById('errors').textContent += "
         "e.message + '\\n'; });</script></head>\n<body>\n<pre id=\"errors\"></pre>\n<h1>microbsdf report: " +
         title + "</h1>\n<h2>Provenance</h2>\n" + provenanceHtml + "<h2>Job</h2>\n" + jobHtml +
         "<h2>Effects planner</h2>\n" + plannerHtml +
         "<h2>Slices: energy and errors</h2>\n<p>As <code>microbsdf info</code> prints them: albedo of the components "
         "the file holds (without the lost diagnostic) &plusmn; its standard error, mean over wavelengths; rel. error "
         "the largest estimated relative per-bin error; balance reflected + transmitted + lost paths &minus; 1 (the "
         "largest over wavelengths, for a material that absorbs only an excess over 1).</p>\n<div class=\"scroll\">" +
         infoHtml +
         "</div>\n<h2>Slices by incidence</h2>\n<p><input type=\"range\" id=\"incidence\" min=\"0\" "
         "max=\"0\" value=\"0\" step=\"1\"> <span id=\"incidence-label\"></span></p>\n<div class=\"models\" "
         "id=\"slices\">" +
         viewerHtml +
         "</div>\n<h3>Plane of incidence</h3>\n<svg id=\"lobes\"></svg>\n<h2>Albedo against "
         "incidence, per component</h2>\n<svg id=\"albedo\"></svg>\n<h2>Material preview</h2>\n" +
         previewHtml + "<script id=\"report-data\" type=\"application/json\">" + dataJson + "</script>\n<script>" +
         kScript + "</script>\n</body></html>\n";
}

}  // namespace

std::vector<int> reportIncidences(const BsdfFileReader& f, int most) {
  std::vector<int> done;
  for (int i = 0; i < f.incidenceCount(); ++i)
    if (f.done(i)) done.push_back(i);
  if (int(done.size()) > most) {
    std::vector<int> ring;
    for (int i : done)
      if (std::abs(f.incidencePhi(i) - f.incidencePhi(done.front())) < 1e-9) ring.push_back(i);
    if (ring.size() >= 2) done = ring;
  }
  std::stable_sort(done.begin(), done.end(), [&](int a, int b) { return f.incidenceTheta(a) < f.incidenceTheta(b); });
  if (int(done.size()) <= most) return done;
  std::vector<int> out;
  for (int k = 0; k < most; ++k) out.push_back(done[size_t(std::lround(double(k) * (done.size() - 1) / (most - 1)))]);
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

std::string htmlReport(const BsdfFileReader& f, const std::string& path, const ReportRequest& req,
                       const std::function<void(const std::string&)>& progress) {
  auto step = [&](const char* what) {
    if (progress) progress(what);
  };
  step("summary");
  const nlohmann::json summary = fileSummary(f, path);
  const std::vector<std::string> models = availableModels(f);
  const std::vector<int> incidences = reportIncidences(f, std::max(2, req.maxIncidences));
  step("slices and lobes");
  nlohmann::json data = slicesData(f, summary, incidences, req, models);
  data["albedo"] = albedoData(summary);
  step("preview");
  const std::string preview =
      models.empty() ? "<p>The file holds no complete model to render.</p>\n" : previewSection(f, req);
  return page(escapeHtml(path), provenance(f, summary),
              f.hasAttribute("job_text") ? "<pre>" + escapeHtml(f.attribute("job_text")) + "</pre>\n" : "",
              plannerSection(summary), infoTable(summary), viewer(models, data["true_colour"].get<bool>()),
              scriptJson(data), preview);
}

}  // namespace mbsdf
