#include <cmath>
#include <cstdio>
#include <iostream>

#include "commands.hpp"
#include "data_options.hpp"
#include "fit_runner.hpp"
#include "history_options.hpp"
#include "valvediag/io/atomic_file.hpp"
#include "valvediag/io/data_checks.hpp"
#include "valvediag/report/diagnosis_report.hpp"
#include "valvediag/report/sweep_report.hpp"
#include "valvediag/sweep/loop_verdict.hpp"
#include "verdict_output.hpp"

namespace valvediag::cli {

void add_diagnose(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand("diagnose",
                                 "Find which physical effect the loop model is missing, ranked");
  cmd->footer(
      "Each effect not in the model is added in a trial fit and scored on held-out data, together "
      "with\n"
      "residual tests that point to it. --auto adds the best supported effect while the error "
      "falls.\n"
      "The verdict is the loop's one verdict, as sweep, report and demo give it: diagnose --auto "
      "from\n"
      "linear on the part of the record a sweep analyses. --model, --auto and --candidates choose "
      "the\n"
      "diagnosis shown, not the verdict; --validate, --min-gain, --op-range and --keep-lead-in "
      "apply to both.\n"
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
    bool autoclimb = false, keep_lead_in = false, split_check = false;
    double min_gain = 2.0;
    std::vector<std::string> candidates;
    std::string json, op_range;
    HistoryOptions hist;
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
  add_history_options(cmd, a->hist, "History");
  cmd->callback([a, &exit_code] {
    const std::vector<double> shares = split_check_shares(a->validate, a->split_check);
    const ModelSpec spec = parse_model_spec(a->model);
    const OpRange range = parse_op_range(a->op_range);
    std::vector<std::string> notes;
    const LoopData whole = load_data(a->data, notes);
    check_identifiable_data(whole, 200, "a diagnosis");
    const HistoryPlace history = history_place(a->hist, a->data, whole);
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
    // The loop's verdict, the same for every command: diagnose --auto from linear on the part a
    // sweep analyses. --model, --auto and --candidates choose the diagnosis shown, not the verdict.
    VerdictOptions vo =
        verdict_options(range, a->validate, a->keep_lead_in, whole.t.front(), a->min_gain);
    vo.check_splits = shares;
    const LoopVerdict lv = loop_verdict(whole, vo);
    // That very analysis asked for: shown as it is, not run twice.
    const bool same = lv.judged() && a->autoclimb && spec.effects.empty() && o.candidates.empty();
    const double Ts = d.sample_period();
    Diagnosis own;
    if (!same)
      own = a->autoclimb ? diagnose_auto(d.op, d.pv, d.mv, Ts, spec, o)
                         : diagnose(d.op, d.pv, d.mv, Ts, spec, o);
    const Diagnosis& r = same ? lv.diagnosis : own;
    const VerdictText vt{lv.verdict, unusable, same ? "" : verdict_basis(lv)};
    std::cout << format_diagnosis(r, d.t, vt);
    if (!lv.split_verdicts.empty()) {
      std::cout << "splits:   ";
      for (const auto& s : lv.split_verdicts)
        std::printf(" %s with %.2f held out;", s.verdict.c_str(), s.validate);
      const auto [agree, of] = split_agreement(lv.verdict, lv.split_verdicts);
      std::printf(" %d of %d shares give %s\n", agree, of, lv.verdict.c_str());
    }
    // The stiction size the sweep reports, for one loop without a site config (none when the
    // record cannot be judged).
    std::cout << stiction_text(lv.stiction);
    if (!a->json.empty()) {
      nlohmann::json j = diagnosis_json(r, d.t, vt);
      add_verdict_json(j, lv);
      j["analysed_from_s"] = part.from_s;
      write_file_atomically(a->json, j.dump(2) + "\n");
      std::cout << "wrote " << a->json << "\n";
    }
    if (!a->hist.off) {
      std::vector<HistoryEntry> entries;
      for (const auto& s : r.steps)
        entries.push_back(history_entry(s.fit, a->autoclimb ? "diagnose --auto" : "diagnose"));
      record_history(history, entries, "the diagnosis above");
    }
    exit_code = kOk;
  });
}

void add_ladder(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand(
      "ladder", "Print the model ladder of a data file: each fit, its fitness, the change");
  cmd->footer(
      "The history is found by the data's content and the options that read it: give the same\n"
      "input options as to fit and diagnose, or the same --history FILE.\n"
      "Examples:\n  valvediag diagnose loop.csv --auto && valvediag ladder loop.csv\n"
      "  valvediag ladder --db site.sqlite --loop FIC101");
  struct Args {
    DataOptions data;
    HistoryOptions hist{"", true};  // only read: no "going on without" warning
  };
  auto a = std::make_shared<Args>();
  add_data_options(cmd, a->data);
  add_history_options(cmd, a->hist, "History", false);
  cmd->callback([a, &exit_code] {
    if (!a->data.db.empty() && a->data.loop.empty()) throw UsageError("--db needs --loop NAME");
    std::vector<std::string> notes;
    const LoopData d = load_data(a->data, notes);
    const std::string name = data_name(a->data);
    const HistoryPlace place = history_place(a->hist, a->data, d);
    if (place.empty()) {
      std::string why;
      (void)history_state_dir(why);
      throw UsageError(why);
    }
    const auto entries = load_history_at(place);
    const std::string source =
        a->data.db.empty() ? a->data.data + (a->data.loop.empty() ? "" : " --loop " + a->data.loop)
                           : "--db " + a->data.db + " --loop " + a->data.loop;
    if (entries.empty())
      throw UsageError("no model history for " + name + " (" + place.where() +
                       "): run 'valvediag diagnose " + source + " --auto' or 'valvediag fit " +
                       source + " --model SPEC' first");
    std::cout << format_ladder(entries);
    exit_code = kOk;
  });
}

}  // namespace valvediag::cli
