#include <cmath>
#include <cstdio>
#include <iostream>

#include "commands.hpp"
#include "data_options.hpp"
#include "fit_runner.hpp"
#include "valvediag/data_checks.hpp"
#include "valvediag/diagnosis_report.hpp"
#include "valvediag/loop_assessment.hpp"
#include "valvediag/sweep_report.hpp"
#include "valvediag/verdict.hpp"

namespace valvediag::cli {

void add_diagnose(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand("diagnose",
                                 "Find which physical effect the loop model is missing, ranked");
  cmd->footer(
      "Each effect not in the model is added in a trial fit and scored on held-out data, together "
      "with\n"
      "residual tests that point to it. --auto adds the best supported effect while the error "
      "falls.\n"
      "Examples:\n"
      "  valvediag diagnose loop.csv                        (start from the linear model)\n"
      "  valvediag diagnose loop.csv --model stiction --json diag.json\n"
      "  valvediag diagnose loop.csv --auto                 (climb the ladder; see valvediag "
      "ladder loop.csv)\n"
      "  valvediag diagnose --db site.sqlite --loop FIC101 --auto   (a recorded loop)");
  struct Args {
    DataOptions data;
    std::string model = "linear";
    double validate = 0.3;
    bool autoclimb = false, no_history = false, keep_lead_in = false, split_check = false;
    double min_gain = 2.0;
    std::vector<std::string> candidates;
    std::string json, op_range;
  };
  auto a = std::make_shared<Args>();
  add_data_options(cmd, a->data);
  add_op_range_option(cmd, a->op_range);
  cmd->add_option("--model", a->model,
                  "the model to diagnose, e.g. linear, stiction, stiction+saturation")
      ->capture_default_str();
  cmd->add_option("--validate", a->validate, "fraction of the record held out for scoring")
      ->capture_default_str();
  cmd->add_flag("--auto", a->autoclimb,
                "add the best supported effect while validation error falls");
  cmd->add_option("--min-gain", a->min_gain,
                  "--auto: smallest fitness gain (points) worth an effect")
      ->capture_default_str();
  cmd->add_option("--candidates", a->candidates, "only try these effects (comma separated)")
      ->delimiter(',');
  cmd->add_option("--json", a->json, "write model, fitness, findings, verdict as JSON");
  cmd->add_flag("--keep-lead-in", a->keep_lead_in,
                "diagnose the whole record even when OP holds still for most of it before the "
                "loop moves (by default that lead-in is left out, as in a sweep)");
  cmd->add_flag("--split-check", a->split_check,
                "diagnose again with 0.05 less and 0.05 more held out and say whether the verdict "
                "holds (about 3x the time)");
  cmd->add_flag("--no-history", a->no_history,
                "do not add the fits to the model history next to the data");
  cmd->callback([a, &exit_code] {
    const std::vector<double> shares = split_check_shares(a->validate, a->split_check);
    const ModelSpec spec = parse_model_spec(a->model);
    const OpRange range = parse_op_range(a->op_range);
    std::vector<std::string> notes;
    const LoopData whole = load_data(a->data, notes);
    check_identifiable_data(whole, 200, "a diagnosis");
    // The same part of the record a sweep diagnoses (quiet_lead_in.hpp).
    const AnalysedPart part = analysed_part(whole, a->keep_lead_in, range, notes);
    const std::string& unusable = part.unusable;
    const LoopData& d = part.data;
    if (auto n = op_range_note(d, range, !a->op_range.empty()); !n.empty()) notes.push_back(n);
    for (const auto& n : notes) std::cout << "note: " << n << "\n";
    DiagnoseOptions o;
    o.valve_travel.op_range = range;
    o.time_origin_s = d.t.front();  // the conclusion's times on the data's axis, as the tables'
    o.validation_fraction = a->validate;
    o.min_gain_percent = a->min_gain;
    o.candidates = a->candidates;
    for (const auto& c : o.candidates) (void)parse_effect(c);  // unknown names are user errors
    const double Ts = d.sample_period();
    Diagnosis r = a->autoclimb ? diagnose_auto(d.op, d.pv, d.mv, Ts, spec, o)
                               : diagnose(d.op, d.pv, d.mv, Ts, spec, o);
    std::cout << format_diagnosis(r, d.t, unusable);
    // Not for a record a sweep would not judge: its verdict is not-enough-data at any split.
    const std::vector<SplitVerdict> splits = unusable.empty()
                                                 ? split_verdicts(d, o, shares, a->autoclimb, spec)
                                                 : std::vector<SplitVerdict>{};
    if (!splits.empty()) {
      const std::string v = verdict(r, unusable);
      std::cout << "splits:   ";
      for (const auto& s : splits)
        std::printf(" %s with %.2f held out;", s.verdict.c_str(), s.validate);
      const auto [agree, of] = split_agreement(v, splits);
      std::printf(" %d of %d shares give %s\n", agree, of, v.c_str());
    }
    // The stiction size the sweep reports, for one loop without a site config (none when the
    // record cannot be judged).
    const FrictionSize fr = unusable.empty() ? friction_size(r, d.op, d.pv, range, o.fit.threads,
                                                             FitSetting{Ts, fit_options(o)})
                                             : FrictionSize{};
    if (std::isfinite(fr.band_percent) && std::isfinite(fr.jump_percent)) {
      std::printf("stiction:  %.2f %% of valve travel (He's fs), slip jump %.2f %%",
                  fr.band_percent, fr.jump_percent);
      if (std::isfinite(fr.band_lo_percent) && fr.band_hi_open)
        std::printf(
            "; the data fit fs %.2f %% or more as well (95 %%): they do not bound it "
            "from above, it fits up to the record's OP span, %.2f %%",
            fr.band_lo_percent, fr.band_hi_percent);
      else if (std::isfinite(fr.band_lo_percent))
        std::printf("; the data fit fs %.2f-%.2f %% as well (95 %%)", fr.band_lo_percent,
                    fr.band_hi_percent);
      std::printf("\n");
    } else if (std::isfinite(fr.band_percent))
      std::printf("stiction:  %.2f %% of valve travel (apparent, from the limit cycle)\n",
                  fr.band_percent);
    if (!a->json.empty()) {
      nlohmann::json j = diagnosis_json(r, d.t, unusable);
      auto number = [](double v) {
        return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json();
      };
      j["stiction_percent"] = number(fr.band_percent);
      j["slip_jump_percent"] = number(fr.jump_percent);
      j["stiction_lo_percent"] = number(fr.band_lo_percent);
      j["stiction_hi_percent"] = number(fr.band_hi_percent);
      j["stiction_hi_open"] = fr.band_hi_open;
      j["analysed_from_s"] = part.from_s;
      j["split_check"] = split_check_json(splits);
      write_text(a->json, j.dump(2) + "\n");
      std::cout << "wrote " << a->json << "\n";
    }
    if (!a->no_history) {
      std::vector<HistoryEntry> entries;
      for (const auto& s : r.steps)
        entries.push_back(history_entry(s.fit, a->autoclimb ? "diagnose --auto" : "diagnose"));
      const std::string path = history_path_for(data_name(a->data));
      std::string why;
      if (try_append_history(path, entries, why))
        std::cout << "model history: " << path << " (valvediag ladder " << data_name(a->data)
                  << ")\n";
      else
        std::cerr << "warning: " << why
                  << "; the diagnosis above stands (--no-history skips this)\n";
    }
    exit_code = kOk;
  });
}

void add_ladder(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand(
      "ladder", "Print the model ladder of a data file: each fit, its fitness, the change");
  cmd->footer(
      "Examples:\n  valvediag diagnose loop.csv --auto && valvediag ladder loop.csv\n"
      "  valvediag ladder --db site.sqlite --loop FIC101");
  struct Args {
    std::string data, db, loop;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("data", a->data, "the data file whose history to show");
  cmd->add_option("--db", a->db, "a recording: show the history of --loop in it");
  cmd->add_option("--loop", a->loop, "the recorded loop (with --db), or the loop in a .mat file");
  cmd->callback([a, &exit_code] {
    if (a->data.empty() == a->db.empty())
      throw UsageError("give a data file or --db site.sqlite --loop NAME (one of them)");
    if (!a->db.empty() && a->loop.empty()) throw UsageError("--db needs --loop NAME");
    // The names data_name() gives: the file, FILE.mat.PATH, or site.sqlite.LOOP.
    const std::string name = a->db.empty() ? (a->loop.empty() ? a->data : a->data + "." + a->loop)
                                           : a->db + "." + a->loop;
    const std::string path = history_path_for(name);
    const auto entries = load_history(path);
    const std::string source = a->db.empty()
                                   ? a->data + (a->loop.empty() ? "" : " --loop " + a->loop)
                                   : "--db " + a->db + " --loop " + a->loop;
    if (entries.empty())
      throw UsageError("no model history for " + name + " (" + path +
                       "): run 'valvediag diagnose " + source + " --auto' or 'valvediag fit " +
                       source + " --model SPEC' first");
    std::cout << format_ladder(entries);
    exit_code = kOk;
  });
}

}  // namespace valvediag::cli
