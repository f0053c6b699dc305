#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <optional>

#include "commands.hpp"
#include "data_options.hpp"
#include "fit_runner.hpp"
#include "history_options.hpp"
#include "valvediag/diagnose/residual_analysis.hpp"
#include "valvediag/io/atomic_file.hpp"
#include "valvediag/io/csv_reader.hpp"
#include "valvediag/io/csv_writer.hpp"
#include "valvediag/io/data_checks.hpp"
#include "valvediag/model/model_fit.hpp"
#include "valvediag/report/diagnosis_report.hpp"
#include "valvediag/report/fit_report.hpp"
#include "valvediag/report/model_history.hpp"
#include "verdict_output.hpp"

namespace valvediag::cli {

namespace {

struct FitArgs {
  DataOptions in;  // the CSV file and its layout (shared with diagnose)
  FitOptions fit;
  std::string method = "joint", stop = "cost", normalization = "nonnegative", memory = "estimate";
  std::string output = "pv";
  std::string validate;
  std::string select_on = "estimation";
  std::string json, series;
  std::string op_range;  // --op-range: stiction figures in % of this OP span
  bool no_merge = false;
  std::string model;  // a composable model instead of the Preisach identification
  std::vector<std::string> add, remove;
  HistoryOptions hist;   // --history, --no-history
  bool verdict = false;  // --verdict: the loop's one verdict too (loop_verdict.hpp)
  // Given on the command line: the ARX orders and Preisach levels bound a --model fit too; the
  // options of the Preisach identification alone are refused with --model.
  std::vector<CLI::Option*> bounds, identification_only;
};

// "0.3": the last 30 % held out; "t=600" or "600s": samples from t >= 600 s held out;
// "600:900": samples with 600 <= t < 900 s held out and the data after 900 s left out.
// Returns the first held-out sample (0 for a fraction, which goes into fo).
std::size_t validation_start(LoopData& d, const std::string& spec, FitOptions& fo) {
  auto number = [&](std::string s) {
    if (s.rfind("t=", 0) == 0) s = s.substr(2);
    if (!s.empty() && s.back() == 's') s.pop_back();
    try {
      std::size_t pos = 0;
      const double v = std::stod(s, &pos);
      if (pos == s.size() && std::isfinite(v)) return v;
    } catch (const std::exception&) {
    }
    throw UsageError(
        "--validate '" + spec +
        "': give a fraction (0.3), a start time (t=600 or 600s) or a time range (600:900)");
  };
  auto index_at = [&](double seconds) {
    const auto it = std::lower_bound(d.t.begin(), d.t.end(), d.t.front() + seconds);
    return static_cast<std::size_t>(it - d.t.begin());
  };
  const auto colon = spec.find(':');
  if (colon != std::string::npos) {
    const double a = number(spec.substr(0, colon)), b = number(spec.substr(colon + 1));
    const std::size_t ia = index_at(a), ib = index_at(b);
    if (!(b > a) || ia == 0 || ia >= d.size() || ib <= ia)
      throw UsageError("--validate " + spec +
                       ": the range must lie inside the data's time range (0 .. " +
                       std::to_string(d.t.back() - d.t.front()) + " s) and end after it starts");
    auto cut = [&](std::vector<double>& v) {
      if (!v.empty()) v.resize(ib);
    };
    for (auto* v : {&d.t, &d.op, &d.pv, &d.sp, &d.mv}) cut(*v);
    return ia;
  }
  const bool time = spec.rfind("t=", 0) == 0 || (!spec.empty() && spec.back() == 's');
  const double v = number(spec);
  if (!time) {
    if (!(v > 0 && v < 0.9))
      throw UsageError("--validate fraction must lie in (0, 0.9), got " + spec);
    fo.validation_fraction = v;
    return 0;
  }
  const std::size_t idx = index_at(v);
  if (idx == 0 || idx >= d.size())
    throw UsageError("--validate " + spec + " lies outside the data's time range");
  return idx;
}

}  // namespace

// The orders, levels and threads given on the command line steer the model's search as they do the
// Preisach identification; the model's own (smaller) defaults stay where none was given.
void apply_given_options(const FitArgs& a, const FitOptions& fo, ModelFitOptions& mo) {
  for (const CLI::Option* o : a.identification_only)
    if (o->count() > 0)
      throw UsageError(o->get_name() +
                       " goes with the Preisach identification (fit without --model, --add or "
                       "--remove): leave it out");
  const auto given = [&a](const std::string& name) {
    return std::any_of(a.bounds.begin(), a.bounds.end(), [&name](const CLI::Option* o) {
      return o->check_name(name) && o->count() > 0;
    });
  };
  StructureRange& r = mo.structure;
  if (given("--na-min")) r.na_min = fo.na_min;
  if (given("--na-max")) r.na_max = fo.na_max;
  if (given("--nb-min")) r.nb_min = fo.nb_min;
  if (given("--nb-max")) r.nb_max = fo.nb_max;
  if (given("--nk-min")) r.nk_min = fo.nk_min;
  if (given("--nk-max")) r.nk_max = fo.nk_max;
  if (given("--L-min")) mo.preisach_L_min = fo.L_min;
  if (given("--L-max")) mo.preisach_L_max = fo.L_max;
  mo.threads = fo.threads;
  if (r.na_min < 1 || r.nb_min < 1 || r.nk_min < 0 || r.na_min > r.na_max || r.nb_min > r.nb_max ||
      r.nk_min > r.nk_max)
    throw UsageError(
        "the ARX orders must satisfy 1 <= na-min <= na-max, 1 <= nb-min <= nb-max "
        "and 0 <= nk-min <= nk-max (with --model the defaults are na, nb 1..2 and "
        "nk 0..10): got na " +
        std::to_string(r.na_min) + ".." + std::to_string(r.na_max) + ", nb " +
        std::to_string(r.nb_min) + ".." + std::to_string(r.nb_max) + ", nk " +
        std::to_string(r.nk_min) + ".." + std::to_string(r.nk_max));
  if (mo.preisach_L_min < 1 || mo.preisach_L_min > mo.preisach_L_max)
    throw UsageError("the Preisach levels must satisfy 1 <= L-min <= L-max: got " +
                     std::to_string(mo.preisach_L_min) + ".." + std::to_string(mo.preisach_L_max));
  // `order` searches na, nb up to order_max: never below the base range.
  mo.order_max = std::max({mo.order_max, r.na_max, r.nb_max});
}

// fit --model/--add/--remove: a composable model, relative to the data's model history.
int fit_spec(const LoopData& d, const FitArgs& a, const FitOptions& fo, const HistoryPlace& history,
             const LoopVerdict* lv) {
  ModelSpec spec = parse_model_spec("linear");
  std::optional<ModelSpec> last;  // the history's last model, which --add extends
  if (!a.model.empty()) {
    spec = parse_model_spec(a.model);
  } else {
    const auto h = load_history_at(history);
    if (!h.empty()) last = spec = parse_model_spec(h.back().model);
    std::cout << "note: starting from the last model of this data: " << to_string(spec)
              << (h.empty() ? " (no history yet)" : "") << "\n";
  }
  for (const auto& e : a.add) {
    const EffectSpec added = parse_effect(e);
    // Already there as given (the default model is `preisach`): the fit is what was asked for.
    if (const EffectSpec* have = spec.find(added.name); have && *have == added) {
      std::cout << "note: " << to_string(added) << " is already in the model: fitting it again\n";
      continue;
    }
    std::vector<EffectSpec> replaced;
    spec = add_effect(spec, e, &replaced);
    if (replaced.empty()) continue;
    std::string names;  // "stiction", "stiction and deadband"
    for (std::size_t i = 0; i < replaced.size(); ++i)
      names += (i ? " and " : "") + to_string(replaced[i]);
    const bool narrower = replaced.front().name == "preisach";
    std::cout << "note: " << to_string(added) << " replaces " << names
              << (narrower               ? " (the Preisach weights combine with no other valve "
                                           "effect; the ladder keeps both to compare)"
                  : replaced.size() == 1 ? " (it generalizes it)"
                                         : " (it generalizes them)")
              << "\n";
  }
  for (const auto& e : a.remove) spec = remove_effect(spec, e);
  if (a.output == "mv")
    throw UsageError("--output mv goes with the Preisach identification, not with --model");
  check_identifiable_data(d, 200, "model " + to_string(spec));
  ModelFitOptions mo;
  mo.validation_fraction = fo.validation_fraction;
  mo.validation_start = fo.validation_start;
  apply_given_options(a, fo, mo);
  // Effects only added to the last model: that model, fitted again as it was, starts the new
  // one's search and bounds it (ModelFitOptions::extends), so adding an effect never fits the
  // estimation part worse than the model it was added to. Not the Preisach weights: their
  // identification takes no start, so fitting them again would be time lost.
  std::optional<ModelFit> extended;
  if (last && *last != spec && !last->has("preisach") &&
      std::all_of(last->effects.begin(), last->effects.end(), [&spec](const EffectSpec& e) {
        const EffectSpec* in = spec.find(e.name);
        return in && *in == e;
      })) {
    extended = fit_model(d.op, d.pv, d.sample_period(), *last, mo);
    mo.extends = &*extended;
  }
  const ModelFit f = fit_model(d.op, d.pv, d.sample_period(), spec, mo);
  ResidualAnalysis where;
  if (f.status != ModelFitStatus::NoStableModel) {
    ResidualAnalysisOptions ro;
    ro.model_delay = static_cast<std::size_t>(std::max(0, f.structure.nk + 1));
    where = analyse_residual(d.op, d.pv, f.y_sim, f.first_sample, f.estimation_end, ro);
  }
  std::cout << format_model_fit(f, where, d.t);
  // How well the data fix a friction band: its 95 % profile-likelihood range (band_interval).
  nlohmann::json bands = nlohmann::json::array();
  for (const char* effect : {"stiction", "deadband"}) {
    if (!spec.has(effect)) continue;
    const BandInterval iv = band_interval(d.op, d.pv, d.sample_period(), f, effect, mo);
    if (!iv.valid) continue;
    if (iv.open_above)
      std::printf(
          "band:      %s %.3f OP or more within 95 %% (profile likelihood, N_eff %.0f); "
          "the data do not bound it from above: it fits up to the record's OP span, "
          "%.3f\n",
          effect, iv.lo, iv.effective_samples, iv.hi);
    else
      std::printf("band:      %s %.3f-%.3f OP within 95 %% (profile likelihood, N_eff %.0f)%s\n",
                  effect, iv.lo, iv.hi, iv.effective_samples,
                  iv.capped ? "; wider still: the walk reached its step budget" : "");
    bands.push_back({{"effect", effect},
                     {"lo", iv.lo},
                     {"hi", iv.hi},
                     {"level", 0.95},
                     {"effective_samples", iv.effective_samples},
                     {"capped", iv.capped},
                     {"open_above", iv.open_above}});
  }
  if (lv) std::cout << verdict_text(*lv, true);
  if (!a.json.empty()) {
    nlohmann::json j = model_fit_json(f, where, d.t);
    j["band_intervals"] = bands;
    if (lv) add_verdict_json(j, *lv);
    write_file_atomically(a.json, j.dump(2) + "\n");
    std::cout << "wrote " << a.json << "\n";
  }
  if (!a.series.empty() && f.status != ModelFitStatus::NoStableModel) {
    std::vector<double> res(d.size());
    for (std::size_t k = 0; k < d.size(); ++k) res[k] = d.pv[k] - f.y_sim[k];
    write_columns_csv(a.series, {"t", "op", "pv", "x_hat", "pv_sim", "residual"},
                      {d.t, d.op, d.pv, f.x_hat, f.y_sim, res});
    std::cout << "wrote " << a.series << "\n";
  }
  if (!a.hist.off && f.status != ModelFitStatus::NoStableModel)
    record_history(history, {history_entry(f, "fit")}, "the fit above");
  return f.status == ModelFitStatus::NoStableModel ? kNoModel : kOk;
}

void add_fit(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand("fit", "Identify a Preisach-Hammerstein model from OP/PV data");
  cmd->footer(
      "Examples:\n"
      "  valvediag fit loop.csv --json model.json --series-out series.csv\n"
      "  valvediag fit --db site.sqlite --loop FIC101 --from 600   (a recorded loop)\n"
      "  valvediag fit loop.csv --validate 0.3 --select-on validation\n"
      "  valvediag fit loop.csv --model stiction --verdict   (and the loop's verdict, as "
      "diagnose gives it)\n"
      "  valvediag fit export.txt   (historian export: the layout is found and shown as options)\n"
      "  valvediag fit valve.csv --output mv           (valve position measured: identity linear "
      "block)\n"
      "  valvediag fit loop.csv --method alternation --stop parameter --normalization paper-sign   "
      "(the paper)");
  auto a = std::make_shared<FitArgs>();
  add_data_options(cmd, a->in);
  add_op_range_option(cmd, a->op_range);

  auto* g_m = "Model";
  a->bounds = {cmd->add_option("--na-max", a->fit.na_max, "largest A order (--model: default 2)")
                   ->group(g_m)
                   ->capture_default_str(),
               cmd->add_option("--nb-max", a->fit.nb_max, "largest B order (--model: default 2)")
                   ->group(g_m)
                   ->capture_default_str(),
               cmd->add_option("--nk-max", a->fit.nk_max, "largest delay in samples")
                   ->group(g_m)
                   ->capture_default_str(),
               cmd->add_option("--na-min", a->fit.na_min, "smallest A order")->group(g_m),
               cmd->add_option("--nb-min", a->fit.nb_min, "smallest B order")->group(g_m),
               cmd->add_option("--nk-min", a->fit.nk_min, "smallest delay")->group(g_m),
               cmd->add_option("--L-max", a->fit.L_max,
                               "largest Preisach discretization level (--model: default 16)")
                   ->group(g_m)
                   ->capture_default_str(),
               cmd->add_option("--L-min", a->fit.L_min, "smallest Preisach level")
                   ->group(g_m)
                   ->capture_default_str()};
  cmd->add_option("--output", a->output,
                  "fit pv (process) or mv (measured valve position, identity block)")
      ->check(CLI::IsMember({"pv", "mv"}))
      ->group(g_m)
      ->capture_default_str();
  cmd->add_option("--method", a->method,
                  "joint (exact in a, c, mu) or alternation (the paper's eqs 17-19)")
      ->check(CLI::IsMember({"joint", "alternation"}))
      ->group(g_m)
      ->capture_default_str();
  cmd->add_option("--stop", a->stop,
                  "alternation stop: cost (relative decrease) or parameter (paper's 1 % rule)")
      ->check(CLI::IsMember({"cost", "parameter"}))
      ->group(g_m)
      ->capture_default_str();
  cmd->add_option("--normalization", a->normalization,
                  "nonnegative (gain sign in b) or paper-sign (the paper's: the sign of b's first "
                  "nonzero tap goes into the weights)")
      ->check(CLI::IsMember({"nonnegative", "paper-sign"}))
      ->group(g_m)
      ->capture_default_str();
  cmd->add_option("--initial-memory", a->memory,
                  "estimate, or rising (OP came up from its minimum)")
      ->check(CLI::IsMember({"estimate", "rising"}))
      ->group(g_m)
      ->capture_default_str();
  cmd->add_flag(
         "--bic-simulated", a->fit.bic_on_simulated_output,
         "BIC from the simulated output (paper, O(N) per kappa) instead of the equation error")
      ->group(g_m);
  cmd->add_flag("--no-merge", a->no_merge, "do not merge relays with identical histories")
      ->group(g_m);
  cmd->add_option("--max-iterations", a->fit.max_iterations, "inner iteration cap")
      ->group(g_m)
      ->capture_default_str();
  cmd->add_option("--parsimony", a->fit.parsimony_percent,
                  "prefer the smallest model within this many fitness points")
      ->group(g_m)
      ->capture_default_str();
  cmd->add_option("--threads", a->fit.threads, "worker threads (0: all cores)")->group(g_m);
  for (const char* name : {"--method", "--stop", "--normalization", "--initial-memory",
                           "--bic-simulated", "--no-merge", "--max-iterations", "--parsimony"})
    a->identification_only.push_back(cmd->get_option(name));

  auto* g_v = "Validation and output";
  cmd->add_option(
         "--validate", a->validate,
         "hold out the last fraction (0.3), from a time on (t=600) or a time range (600:900, s)")
      ->group(g_v);
  cmd->add_option("--select-on", a->select_on,
                  "choose the configuration on estimation or validation fitness")
      ->check(CLI::IsMember({"estimation", "validation"}))
      ->group(g_v)
      ->capture_default_str();
  a->identification_only.push_back(cmd->get_option("--select-on"));
  cmd->add_option("--json", a->json, "write the result as JSON")->group(g_v);
  const char* g_e = "Composable models (effects.md)";
  cmd->add_option("--model", a->model,
                  "fit this chain of effects, e.g. stiction+saturation, linear")
      ->group(g_e);
  cmd->add_option("--add", a->add,
                  "add an effect to the last model of this data (see valvediag ladder); "
                  "preisach replaces stiction or deadband, which it generalizes")
      ->group(g_e);
  cmd->add_option("--remove", a->remove, "remove an effect from the last model of this data")
      ->group(g_e);
  add_history_options(cmd, a->hist, g_e);
  cmd->add_flag("--verdict", a->verdict,
                "also give the loop's verdict and stiction size, the same as diagnose, report and "
                "sweep give (diagnose --auto from linear: seconds more; JSON key verdict)")
      ->group(g_v);
  cmd->add_option("--series-out", a->series, "write t, op, pv, x_hat, pv_sim, residual as CSV")
      ->group(g_v);

  cmd->callback([a, &exit_code] {
    std::vector<std::string> notes;
    const OpRange range = parse_op_range(a->op_range);
    if (a->output == "mv" && a->in.csv.mv_column.empty()) a->in.csv.mv_column = "mv";
    LoopData d = load_data(a->in, notes);
    // Keyed by the data as read, before --validate A:B cuts it.
    const HistoryPlace history = history_place(a->hist, a->in, d);
    if (auto n = op_range_note(d, range, !a->op_range.empty()); !n.empty()) notes.push_back(n);
    const LoopData whole = a->verdict ? d : LoopData{};  // --validate A:B may cut d below
    FitOptions& fo = a->fit;
    fo.method = a->method == "joint" ? FitMethod::Joint : FitMethod::Alternation;
    fo.stop_rule = a->stop == "cost" ? StopRule::CostDecrease : StopRule::ParameterChange;
    fo.normalization = a->normalization == "nonnegative" ? Normalization::KeepMuNonnegative
                                                         : Normalization::PaperSign;
    fo.initial_memory =
        a->memory == "estimate" ? InitialMemory::Estimate : InitialMemory::RisingFromMin;
    fo.merge_identical_relays = !a->no_merge;
    fo.block = a->output == "mv" ? LinearBlock::Identity : LinearBlock::Arx;
    if (!a->validate.empty()) fo.validation_start = validation_start(d, a->validate, fo);
    fo.select_on_validation = a->select_on == "validation";
    if (fo.select_on_validation && a->validate.empty())
      throw UsageError("--select-on validation needs --validate (a fraction or a start time)");
    if (fo.block == LinearBlock::Identity && !d.has_mv())
      throw UsageError(data_name(a->in) +
                       ": --output mv needs a valve position column (name it with --mv COLUMN)");
    if (auto msg = validate(fo); !msg.empty()) throw UsageError(msg);
    // The loop's verdict is judged on the whole record with a held-out share, as diagnose and
    // sweep judge it: --validate's fraction, else their default.
    std::optional<LoopVerdict> lv;
    if (a->verdict) {
      check_identifiable_data(whole, 200, "a verdict");
      if (fo.validation_fraction <= 0)
        notes.push_back(
            "the verdict holds out the last 30 % of the record, as diagnose and sweep do" +
            std::string(a->validate.empty() ? "" : " (--validate with times is the fit's own)"));
      const double share = fo.validation_fraction > 0 ? fo.validation_fraction : 0.3;
      (void)split_check_shares(share, false);  // a share diagnose takes, or a user error
      lv = loop_verdict(whole, verdict_options(range, share, false, whole.t.front()));
    }
    for (const auto& n : notes) std::cout << "note: " << n << "\n";
    if (!a->model.empty() || !a->add.empty() || !a->remove.empty()) {
      exit_code = fit_spec(d, *a, fo, history, lv ? &*lv : nullptr);
      return;
    }
    FitRun run = run_fit(d, fo, a->output, range);
    std::cout << run.summary;
    if (lv) {
      std::cout << verdict_text(*lv, true);
      add_verdict_json(run.json, *lv);
    }
    if (!a->json.empty()) {
      write_file_atomically(a->json, run.json.dump(2) + "\n");
      std::cout << "wrote " << a->json << "\n";
    }
    if (!a->series.empty() && run.result.status == IdentificationStatus::Ok) {
      write_series(a->series, d, run);
      std::cout << "wrote " << a->series << "\n";
    }
    // Last: the answer above is never lost for the side file.
    if (!a->hist.off && run.result.status == IdentificationStatus::Ok) {
      HistoryEntry h;
      h.model = "preisach:general";  // the core method alone (the paper's)
      h.fitness_percent = run.result.fitness_percent;
      h.validation_fitness_percent = run.result.validation_fitness_percent;
      const auto& st = run.result.best.structure;
      h.na = st.na;
      h.nb = st.nb;
      h.nk = st.nk;
      h.parameters.push_back({"preisach.L", static_cast<double>(st.L), ""});
      h.parameters.push_back(
          {"preisach.nonzero_weights", static_cast<double>(run.result.best.nonzero_weights), ""});
      h.command = "fit";
      h.time = utc_timestamp();
      record_history(history, {h}, "the fit above");
    }
    exit_code = run.result.status == IdentificationStatus::Ok ? kOk : kNoModel;
  });
}

}  // namespace valvediag::cli
