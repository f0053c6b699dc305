// One self-contained HTML page about a fitted loop model, for an engineer to mail to a colleague:
// header (data, model, fitness, verdict), plots drawn by gnuplot's SVG terminal and embedded
// inline (OP/PV/SP trends; measured vs simulated PV with the failing intervals shaded; residual;
// valve signature beside the Preisach weights on the Preisach triangle; Bode and step response of
// the linear block; the model ladder), the "where it fails" tables, the diagnosis findings and the
// ladder table. No scripts, no external files: the SVG ids are made unique per plot, all text is
// escaped. Long records are decimated for plotting (min and max per bucket, so spikes show).
#pragma once

#include <cstddef>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "valvediag/core/identification.hpp"
#include "valvediag/diagnose/diagnosis.hpp"
#include "valvediag/diagnose/residual_analysis.hpp"
#include "valvediag/io/loop_data.hpp"
#include "valvediag/model/model_fit.hpp"
#include "valvediag/report/gnuplot.hpp"
#include "valvediag/report/model_history.hpp"
#include "valvediag/sweep/loop_health.hpp"

namespace valvediag {

struct ReportContent {
  const LoopData* data = nullptr;           // required: t, op, pv (sp, mv when present)
  std::string data_name;                    // where the data came from, as shown
  const ModelFit* fit = nullptr;            // required: the model the report is about
  const ResidualAnalysis* where = nullptr;  // where it fails (nullptr: not shown)
  const Diagnosis* diagnosis = nullptr;     // nullptr: not run (the page says so)
  std::string diagnosis_command;            // how it was run, e.g. "diagnose --auto from linear"
  std::string unusable;  // why a sweep would not judge the record (loop_health.hpp), "" if it
                         // would: the verdict is then not-enough-data, the diagnosis still shown
  // The loop's verdict (loop_verdict.hpp), shown in the header; "": not judged. verdict_basis:
  // what it rests on when that is not `diagnosis` (one sentence), else "".
  std::string verdict, verdict_basis;
  std::vector<HistoryEntry> ladder;     // the data's model history
  std::vector<std::string> notes;       // shown under the header (data notes)
  std::string generated;                // date shown; empty: now (UTC)
  std::string generator = "valvediag";  // program and version in the footer
};

struct ReportOptions {
  GnuplotOptions gnuplot;
  bool plots = true;          // false: a note in place of each plot, gnuplot is not run
  bool require_plots = true;  // gnuplot cannot be started: throw GnuplotMissing (true), or
                              // write the page with a note in place of the plots (false)
  std::size_t buckets = 500;  // time series longer than this keep min and max per bucket
};

struct HtmlReport {
  std::string html;
  std::vector<std::string> plots;     // ids of the figures drawn (plot-trends, plot-fit, ...)
  std::vector<std::string> warnings;  // plots that could not be drawn, and why
  double plot_seconds = 0.0;          // wall time spent in gnuplot
};

// Throws std::invalid_argument when data or fit is missing or their lengths differ, and
// GnuplotMissing (see require_plots).
HtmlReport html_report(const ReportContent& content, const ReportOptions& opt = {});

// A page for a record no model was fitted to (a sweep's not-enough-data loop, or a ladder with no
// stable linear part): why, the
// loop-health figures and the trend of what was recorded (OP alone when PV is missing), so the
// engineer sees what the data lacks without opening the file.
struct DataPageContent {
  const LoopData* data = nullptr;      // required: t, op (pv, sp, mv when present)
  std::string data_name;               // as shown
  std::string verdict;                 // e.g. not-enough-data
  std::string reason;                  // why there is no model
  const LoopHealth* health = nullptr;  // nullptr: not shown
  // Further rows of the summary, shown as given: what the verdict rests on when there is one
  // (limit cycle, whole record).
  std::vector<std::pair<std::string, std::string>> findings;
  std::vector<std::string> notes;       // shown under the header (data notes)
  std::string generated;                // date shown; empty: now (UTC)
  std::string generator = "valvediag";  // program and version in the footer
};
// Throws std::invalid_argument when data is missing or its lengths differ, and GnuplotMissing
// (see require_plots).
HtmlReport html_data_page(const DataPageContent& content, const ReportOptions& opt = {});

// A Preisach identification (identify()) in the shape of a composable model fit, so the report
// takes both: spec `preisach`, the ARX part, x_hat and the simulated output on u, y.
ModelFit model_fit_of(const IdentificationResult& r, const std::vector<double>& u,
                      const std::vector<double>& y, double Ts);

// ---- Pieces, exposed for the tests ----

// &, <, >, " and ' as entities; invalid UTF-8 bytes and control characters (but tab and newline)
// as U+FFFD.
std::string html_escape(std::string_view text);

// Samples [from, to) of y reduced to at most 2 * buckets indices: the minimum and the maximum of
// each bucket, in time order (all indices when the range has no more than 2 * buckets samples).
std::vector<std::size_t> minmax_decimate(const std::vector<double>& y, std::size_t from,
                                         std::size_t to, std::size_t buckets);

// Frequency response of B(q)/A(q) (B = b1 q^-(nk+1) + ..., A = 1 + a1 q^-1 + ..., times
// (1 - q^-1) when integrating) at `points` log-spaced frequencies from Nyquist / 1000 to
// Nyquist; phase unwrapped, in degrees.
struct FrequencyResponse {
  std::vector<double> f_hz, magnitude_db, phase_deg;
};
FrequencyResponse frequency_response(const std::vector<double>& a, const std::vector<double>& b,
                                     int nk, bool integrating, double Ts, std::size_t points = 300);
// Response of the same block to a unit step at sample 0, samples 0 .. n - 1.
std::vector<double> step_response(const std::vector<double>& a, const std::vector<double>& b,
                                  int nk, bool integrating, std::size_t n);
// Samples the step response needs to settle (within 1 % of its final value), for plotting:
// at least 20, at most `cap`.
std::size_t settling_samples(const std::vector<double>& a, const std::vector<double>& b, int nk,
                             bool integrating, std::size_t cap);

// Makes the ids of an SVG document unique in a page (prefix-id, with references rewritten) and
// drops the XML declaration, so several SVGs can be inlined in one HTML page.
std::string inline_svg(const std::string& svg, const std::string& prefix);

}  // namespace valvediag
