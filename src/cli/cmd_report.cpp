// valvediag report: one self-contained HTML page about a loop and its model (html_report.hpp).
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>

#include "commands.hpp"
#include "data_options.hpp"
#include "history_options.hpp"
#include "valvediag/io/atomic_file.hpp"
#include "valvediag/io/data_checks.hpp"
#include "valvediag/report/html_report.hpp"
#include "valvediag/report/model_history.hpp"
#include "valvediag/sweep/loop_verdict.hpp"
#include "verdict_output.hpp"

namespace valvediag::cli {

void check_report_writable(const std::string& path) {
  if (path.empty())
    throw UsageError("--out FILE: give the HTML file to write, e.g. --out report.html");
  if (std::filesystem::is_directory(path))
    throw UsageError("--out " + path + " is a directory: give a file name, e.g. report.html");
  try {
    AtomicFile probe(path);  // not committed: removed, the path untouched
  } catch (const std::runtime_error& e) {
    throw UsageError("cannot write the report to " + path +
                     ": check that the directory exists and is writable (" + e.what() + ")");
  }
}

ReportFile write_report_file(const std::string& path, const ReportContent& content,
                             const ReportOptions& opt) {
  return write_page_file(path, html_report(content, opt));
}

ReportFile write_page_file(const std::string& path, const HtmlReport& rep) {
  write_file_atomically(path, rep.html);
  return {rep.html.size(), rep.plots.size(), rep.plot_seconds, rep.warnings};
}

std::string report_file_summary(const std::string& path, const ReportFile& r) {
  char buf[256];
  std::snprintf(buf, sizeof buf, "wrote %s (%.0f KB, %zu plots drawn by gnuplot in %.2f s)\n",
                path.c_str(), static_cast<double>(r.bytes) / 1024.0, r.plots, r.plot_seconds);
  std::string s = buf;
  for (const auto& w : r.warnings) s += "warning: " + w + "\n";
  return s;
}

void add_report(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand(
      "report", "Write one self-contained HTML report of a loop and its model, with plots");
  cmd->footer(
      "The page: data, model, fitness and verdict; OP/PV/SP trends; measured vs simulated PV with\n"
      "the failing intervals shaded; residual; valve signature beside the Preisach triangle; Bode\n"
      "and step response of the linear block; where the model fails; the diagnosis; the model\n"
      "ladder. Plots are drawn by gnuplot (Debian package gnuplot-nox; VALVEDIAG_GNUPLOT names\n"
      "another program) and embedded as SVG: the file has no scripts and no external links.\n"
      "The verdict is the loop's one verdict, as diagnose, sweep and demo give it (diagnose "
      "--auto\n"
      "from linear), whatever model is shown. By default the page shows the model the verdict\n"
      "rests on; with --no-diagnose, the last model of the data's ladder, else preisach.\n"
      "Examples:\n"
      "  valvediag report loop.csv --out report.html          (model: the verdict's)\n"
      "  valvediag report loop.csv --model stiction --out report.html\n"
      "  valvediag report --db site.sqlite --loop FIC101 --out fic101.html\n"
      "  valvediag report loop.csv --no-diagnose --no-plots --out quick.html");
  struct Args {
    DataOptions data;
    std::string model, out, gnuplot;
    double validate = 0.3;
    double timeout = 30.0;
    bool no_diagnose = false, no_plots = false, keep_lead_in = false;
    std::string op_range;
    HistoryOptions hist;
  };
  auto a = std::make_shared<Args>();
  add_data_options(cmd, a->data);
  add_op_range_option(cmd, a->op_range);
  const char* g = "Report";
  cmd->add_option("--model", a->model,
                  "the model to fit and show, e.g. preisach, stiction+saturation (default: the "
                  "model the verdict rests on; with --no-diagnose the last model of the data's "
                  "ladder, else preisach)")
      ->group(g);
  // Never a default beside the data: a shared folder of exports is not ours to write in.
  cmd->add_option("--out", a->out, "the HTML file to write (required)")->group(g);
  cmd->add_option("--validate", a->validate, "fraction of the record held out for validation")
      ->group(g)
      ->capture_default_str();
  cmd->add_flag("--no-diagnose", a->no_diagnose,
                "leave out the diagnosis and the verdict (trial fits of every missing effect; "
                "takes seconds)")
      ->group(g);
  cmd->add_flag("--keep-lead-in", a->keep_lead_in,
                "fit and diagnose the whole record even when OP holds still for most of it "
                "before the loop moves (by default that lead-in is left out, as in diagnose)")
      ->group(g);
  add_history_options(cmd, a->hist, g);
  cmd->add_flag("--no-plots", a->no_plots, "write the page without plots (gnuplot not needed)")
      ->group(g);
  cmd->add_option("--gnuplot", a->gnuplot,
                  "the gnuplot program (default: $VALVEDIAG_GNUPLOT, else gnuplot from PATH)")
      ->group(g);
  cmd->add_option("--plot-timeout", a->timeout, "seconds before a hanging gnuplot is stopped")
      ->check(CLI::Range(1.0, 600.0))
      ->group(g)
      ->capture_default_str();
  cmd->callback([a, &exit_code] {
    if (!(a->validate > 0.05 && a->validate < 0.9))
      throw UsageError("--validate must lie in (0.05, 0.9)");
    std::optional<ModelSpec> spec;
    if (!a->model.empty()) spec = parse_model_spec(a->model);  // bad names: exit status 2
    const OpRange range = parse_op_range(a->op_range);
    const std::string name = data_name(a->data);
    const std::string& out = a->out;
    ReportOptions ro;
    ro.gnuplot.program = a->gnuplot;
    ro.gnuplot.timeout_s = a->timeout;
    ro.plots = !a->no_plots;
    // The cheap checks first: where the page goes and whether gnuplot runs, before the fits.
    check_report_writable(out);
    if (ro.plots) {
      try {
        (void)gnuplot_run("", ro.gnuplot);
      } catch (const GnuplotMissing& e) {
        throw GnuplotMissing(std::string(e.what()) + "; or leave the plots out: --no-plots");
      }
    }

    std::vector<std::string> notes;
    const LoopData whole = load_data(a->data, notes);
    check_identifiable_data(whole, 200, "a report");
    // The part of the record diagnose and a sweep analyse (quiet_lead_in.hpp), so that the
    // page agrees with the diagnose command it quotes.
    const AnalysedPart part = analysed_part(whole, a->keep_lead_in, range, notes);
    const std::string& unusable = part.unusable;
    const LoopData& d = part.data;
    if (auto n = op_range_note(d, range, !a->op_range.empty()); !n.empty()) notes.push_back(n);
    for (const auto& n : notes) std::cout << "note: " << n << "\n";
    HistoryPlace history = history_place(a->hist, a->data, whole);
    auto ladder = read_history_or_warn(history);
    // The loop's verdict for the header, the same for every command (loop_verdict.hpp): never
    // from the model history.
    LoopVerdict lv;
    if (!a->no_diagnose)
      lv = loop_verdict(whole,
                        verdict_options(range, a->validate, a->keep_lead_in, whole.t.front()));
    if (!spec) {
      // The page explains its verdict: by default it shows the model the verdict rests on (the
      // end of diagnose --auto's climb); without a verdict, the data's ladder's last model.
      if (lv.judged()) {
        spec = lv.diagnosis.last().fit.spec;
        std::cout << "note: model " << to_string(*spec)
                  << " (the model the verdict rests on; --model shows another)\n";
      } else {
        spec = parse_model_spec(ladder.empty() ? "preisach:general" : ladder.back().model);
        std::cout << "note: model " << to_string(*spec)
                  << (ladder.empty() ? " (no model history for this data yet)"
                                     : " (the last model of this data's ladder)")
                  << "\n";
      }
    }
    const double Ts = d.sample_period();
    std::cout << "fitting " << to_string(*spec)
              << (a->no_diagnose ? ""
                                 : " and diagnosing it (trial fits of the missing effects); "
                                   "the verdict from diagnose --auto")
              << " ..." << std::endl;
    // The model shown is where the verdict's climb ended (a history that diagnose --auto wrote):
    // that climb is the diagnosis, not run again.
    const bool same = lv.judged() && lv.diagnosis.last().fit.spec == *spec;
    Diagnosis diag;
    ModelFit fit;
    ResidualAnalysis where;
    bool diagnosed = false;
    if (same) {
      diag = lv.diagnosis;
      fit = diag.last().fit;
      where = diag.last().residual;
      diagnosed = true;
    } else if (!a->no_diagnose) {
      DiagnoseOptions o;
      o.validation_fraction = a->validate;
      o.valve_travel.op_range = range;
      o.time_origin_s = d.t.front();  // as diagnose: the conclusion's times on the data's axis
      try {
        diag = diagnose(d.op, d.pv, d.mv, Ts, *spec, o);
        fit = diag.steps.front().fit;
        where = diag.steps.front().residual;
        diagnosed = true;
      } catch (const std::invalid_argument& e) {
        // The model itself does not fit (no stable linear part): said below, without a diagnosis.
        notes.push_back(std::string("The diagnosis could not run: ") + e.what());
      }
    }
    if (!diagnosed) {
      ModelFitOptions mo;
      mo.validation_fraction = a->validate;
      fit = fit_model(d.op, d.pv, Ts, *spec, mo);
      if (fit.status != ModelFitStatus::NoStableModel) {
        ResidualAnalysisOptions rao;
        rao.model_delay = static_cast<std::size_t>(std::max(0, fit.structure.nk + 1));
        where = analyse_residual(d.op, d.pv, fit.y_sim, fit.first_sample, fit.estimation_end, rao);
      }
    }
    if (fit.status == ModelFitStatus::NoStableModel) {
      std::cerr << "error: no stable model " << to_string(*spec)
                << " fits this data: no report written (try another --model)\n";
      exit_code = kNoModel;
      return;
    }
    if (!a->hist.off && (ladder.empty() || ladder.back().model != to_string(fit.spec))) {
      const HistoryEntry entry = history_entry(fit, "report");
      record_history(history, {entry}, "the report");
      ladder.push_back(entry);  // on the page, written or not
    }
    ReportContent c;
    c.data = &d;
    c.data_name = name;
    c.fit = &fit;
    c.where = &where;
    if (diagnosed) {
      c.diagnosis = &diag;
      c.diagnosis_command = "valvediag diagnose " + name +
                            (same ? " --auto" : " --model " + to_string(*spec)) +
                            (a->keep_lead_in ? " --keep-lead-in" : "");
    }
    c.unusable = unusable;
    c.verdict = lv.verdict;
    c.verdict_basis = same ? "" : verdict_basis(lv);
    c.ladder = ladder;
    c.notes = notes;
    c.generator = "valvediag report";
    const ReportFile r = write_report_file(out, c, ro);
    if (std::isfinite(fit.fitness_percent))
      std::printf("model:     %s: %.2f %% estimation, %.2f %% validation\n",
                  to_string(fit.spec).c_str(), fit.fitness_percent, fit.validation_fitness_percent);
    else
      std::printf("model:     %s: no stable model on this record\n", to_string(fit.spec).c_str());
    std::fflush(stdout);
    if (!lv.verdict.empty()) std::cout << verdict_text(lv, !same);
    std::cout << report_file_summary(out, r);
    exit_code = kOk;
  });
}

}  // namespace valvediag::cli
