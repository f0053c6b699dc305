#include "valvediag/report/diagnosis_report.hpp"

#include <cmath>
#include <cstdio>
#include <sstream>

#include "number_format.hpp"
#include "valvediag/report/json_number.hpp"
#include "valvediag/util/text_stats.hpp"

namespace valvediag {

namespace {

std::string num(double v, int prec = 2) {
  return report_format::fixed(v, prec);
}
std::string signed_num(double v) {
  return report_format::signed_fixed(v);
}

double t_at(const std::vector<double>& t, std::size_t k) {
  return k < t.size() ? t[k] : static_cast<double>(k);
}

}  // namespace

std::string format_diagnosis(const Diagnosis& d, const std::vector<double>& t,
                             const VerdictText& v) {
  std::ostringstream o;
  if (d.steps.size() > 1) {
    o << "ladder (climbed with --auto):\n";
    for (std::size_t i = 0; i < d.steps.size(); ++i) {
      const auto& f = d.steps[i].fit;
      o << "  " << i + 1 << ". " << to_string(f.spec) << ": " << num(f.fitness_percent)
        << " % estimation, " << num(f.validation_fitness_percent) << " % validation";
      if (i > 0)
        o << " ("
          << signed_num(f.validation_fitness_percent -
                        d.steps[i - 1].fit.validation_fitness_percent)
          << ")";
      o << "\n";
    }
  }
  const auto& s = d.last();
  o << "model:     " << to_string(s.fit.spec) << " (na " << s.fit.structure.na << ", nb "
    << s.fit.structure.nb << ", nk " << s.fit.structure.nk << "): " << num(s.fit.fitness_percent)
    << " % estimation, " << num(s.fit.validation_fitness_percent) << " % validation\n";
  for (const auto& e : s.fit.effects)
    if (!e.parameters.empty())
      o << "           " << e.name << ": " << report_format::parameters(e.parameters) << "\n";
  if (s.fit.status == ModelFitStatus::NoStableModel)
    o << "residual:  none (no stable model, so no simulated PV)\n";
  else
    o << "residual:  RMS " << num(s.residual.rms, 3) << ", white-noise level "
      << num(s.residual.noise_level, 3) << "\n";
  if (const std::string jn = judge_note(s); !jn.empty()) o << "judge:     " << jn << "\n";
  // The order is rank_by_wins' then order_path_by_prediction's (diagnosis.cpp), not the
  // score's: say what it is.
  o << "findings (most likely missing first: among valve, dead-time and process-lag effects, "
       "the lower PE BIC (the one-step prediction of PV), valves with memory by their nested "
       "test, a process lag above an actuator lag that commutes with it; where a load or an "
       "integrator stands among them: one that prediction shows evidence for (an integrator: "
       "its restriction holds) above a load whose output BIC refutes it and, of two "
       "unsupported, above one it shows none for, else a clearly "
       "larger gain on both parts, else fewer parameters, else the higher score):\n";
  o << "  rank  effect          score  gain (val / est)    PE BIC    evidence\n";
  int rank = 0;
  for (const auto& f : s.findings) {
    char line[256];
    const std::string gains =
        std::isfinite(f.trial_fitness_percent)
            ? strprintf("%+7.2f / %+7.2f", f.validation_gain_percent, f.estimation_gain_percent)
            : std::string("   no stable fit");
    std::snprintf(line, sizeof line, "  %-4d  %-14s  %5.2f  %-17s  %8s    %s %s\n", ++rank,
                  f.effect.c_str(), f.score, gains.c_str(),
                  std::isfinite(f.prediction_bic_change)
                      ? strprintf("%+.0f", f.prediction_bic_change).c_str()
                      : "-",
                  f.evidence_test.empty() ? "-" : f.evidence_test.c_str(),
                  f.evidence_test.empty() ? "" : num(f.evidence).c_str());
    o << line;
  }
  for (const auto& f : s.findings)
    if (const std::string note = held_valve_note(f); !note.empty())
      o << "held valve: " << note << "\n";
  if (!s.findings.empty() && !s.findings.front().supported) {
    o << "first:     no effect is clearly missing: the best candidate, `"
      << s.findings.front().effect << "`, gains too little to be worth its parameters\n";
  } else if (!s.findings.empty()) {
    const auto& f = s.findings.front();
    o << "first:     " << f.explanation << "\n";
    if (!f.prediction_parameters.empty()) {
      // What ranked it may be the refit (prediction_refit.hpp), not the fit the line above reads.
      std::string p;
      for (const auto& v : f.prediction_parameters)
        p += (p.empty() ? "" : ", ") + v.name + " " + num(v.value, 3) +
             (v.unit.empty() ? "" : " " + v.unit);
      o << "           refitted to predict PV one step ahead: " << p << " (PE BIC "
        << strprintf("%+.0f", f.prediction_bic_change) << ")\n";
    }
    if (!f.indistinguishable_from.empty())
      o << "           `" << f.effect << "` and `" << f.indistinguishable_from
        << "` explain this data equally well: the data cannot tell them apart\n";
    for (const auto& iv : f.intervals)
      o << "           fails at t " << num(t_at(t, iv.begin), 1) << " .. "
        << num(t_at(t, iv.end - 1), 1) << " s (" << num(100 * iv.share, 0) << " % of the error)\n";
    for (const auto& g : f.regions)
      o << "           " << g.label << " carries " << num(100 * g.share, 0) << " % of the error\n";
  }
  if (d.limit_cycle.oscillating) o << "limit cycle: " << d.limit_cycle.summary << "\n";
  if (d.whole_record.tested) o << "whole record: " << d.whole_record.summary << "\n";
  if (!d.valve_travel.summary.empty()) o << "valve travel: " << d.valve_travel.summary << "\n";
  o << "verdict:   " << v.verdict;
  if (!v.unusable.empty())
    o << ": " << v.unusable
      << " (the fits above are shown, not judged; a sweep does not fit such a record)";
  o << "\n";
  if (!v.basis.empty()) o << "           " << v.basis << "\n";
  o << d.conclusion << "\n";
  return o.str();
}

nlohmann::json limit_cycle_json(const LimitCycle& c) {
  return {{"oscillating", c.oscillating},
          {"period_s", json_number(c.oscillating ? c.period_s : LimitCycle::kNaN)},
          {"phase_deg", json_number(c.phase_deg)},
          {"model_share", json_number(c.model_share)},
          {"integrating", c.integrating},
          {"stick_slip", c.stick_slip},
          {"apparent_band", json_number(c.apparent_band)},
          {"summary", c.summary}};
}

LimitCycle limit_cycle_from_json(const nlohmann::json& j) {
  LimitCycle c;
  if (!j.is_object()) return c;
  auto num = [&j](const char* k) {
    return j.contains(k) && j[k].is_number() ? j[k].get<double>() : LimitCycle::kNaN;
  };
  c.oscillating = j.value("oscillating", false);
  c.period_s = c.oscillating ? num("period_s") : 0.0;
  c.phase_deg = num("phase_deg");
  c.model_share = num("model_share");
  c.integrating = j.value("integrating", false);
  c.stick_slip = j.value("stick_slip", false);
  c.apparent_band = num("apparent_band");
  c.summary = j.value("summary", std::string());
  return c;
}

nlohmann::json whole_record_json(const WholeRecordTest& w) {
  return {{"tested", w.tested},
          {"confirmed", w.confirmed},
          {"memory_model", w.memory_model},
          {"start_fitness_percent", json_number(w.start_fitness)},
          {"memory_fitness_percent", json_number(w.memory_fitness)},
          {"relative_gain", json_number(w.relative_gain)},
          {"load_fitness_percent", json_number(w.load_fitness)},
          {"load_bic_margin", json_number(w.load_bic_margin)},
          {"rival", w.rival},
          {"rival_fitness_percent", json_number(w.rival_fitness)},
          {"rival_bic_margin", json_number(w.rival_bic_margin)},
          {"preferred", w.preferred},
          {"summary", w.summary}};
}

WholeRecordTest whole_record_from_json(const nlohmann::json& j) {
  WholeRecordTest w;
  if (!j.is_object()) return w;
  auto num = [&j](const char* k) {
    return j.contains(k) && j[k].is_number() ? j[k].get<double>() : WholeRecordTest::kNaN;
  };
  w.tested = j.value("tested", false);
  w.confirmed = j.value("confirmed", false);
  w.memory_model = j.value("memory_model", std::string());
  w.start_fitness = num("start_fitness_percent");
  w.memory_fitness = num("memory_fitness_percent");
  w.relative_gain = num("relative_gain");
  w.load_fitness = num("load_fitness_percent");
  w.load_bic_margin = num("load_bic_margin");
  w.rival = j.value("rival", std::string());
  w.rival_fitness = num("rival_fitness_percent");
  w.rival_bic_margin = num("rival_bic_margin");
  w.preferred = j.value("preferred", std::string());
  w.summary = j.value("summary", std::string());
  return w;
}

nlohmann::json valve_travel_json(const ValveTravel& v) {
  return {
      {"tested", v.tested},
      {"decided", v.decided},
      {"verdict", v.verdict},
      {"fs_percent", json_number(v.fs_percent)},
      {"fd_percent", json_number(v.fd_percent)},
      {"slip_jump_percent", json_number(v.jump_percent)},
      {"lag_s", json_number(v.lag_s)},
      {"gain", json_number(v.gain)},
      {"mv_noise", json_number(v.mv_noise)},
      {"follow_fitness_percent", json_number(v.follow_fitness_percent)},
      {"follow_validation_fitness_percent", json_number(v.follow_validation_fitness_percent)},
      {"friction_fitness_percent", json_number(v.friction_fitness_percent)},
      {"friction_validation_fitness_percent", json_number(v.friction_validation_fitness_percent)},
      {"error_share", json_number(v.error_share)},
      {"validation_error_share", json_number(v.validation_error_share)},
      {"summary", v.summary}};
}

ValveTravel valve_travel_from_json(const nlohmann::json& j) {
  ValveTravel v;
  if (!j.is_object()) return v;
  auto num = [&j](const char* k) {
    return j.contains(k) && j[k].is_number() ? j[k].get<double>() : ValveTravel::kNaN;
  };
  v.tested = j.value("tested", false);
  v.decided = j.value("decided", false);
  v.verdict = j.value("verdict", std::string());
  v.fs_percent = num("fs_percent");
  v.fd_percent = num("fd_percent");
  v.jump_percent = num("slip_jump_percent");
  v.lag_s = num("lag_s");
  v.gain = num("gain");
  v.mv_noise = num("mv_noise");
  v.follow_fitness_percent = num("follow_fitness_percent");
  v.follow_validation_fitness_percent = num("follow_validation_fitness_percent");
  v.friction_fitness_percent = num("friction_fitness_percent");
  v.friction_validation_fitness_percent = num("friction_validation_fitness_percent");
  v.error_share = num("error_share");
  v.validation_error_share = num("validation_error_share");
  v.summary = j.value("summary", std::string());
  return v;
}

nlohmann::json diagnosis_json(const Diagnosis& d, const std::vector<double>& t,
                              const VerdictText& v) {
  using nlohmann::json;
  const auto& s = d.last();
  json j;
  j["model"] = to_string(s.fit.spec);
  j["fitness_percent"] = json_number(s.fit.fitness_percent);
  j["validation_fitness_percent"] = json_number(s.fit.validation_fitness_percent);
  j["structure"] = {
      {"na", s.fit.structure.na}, {"nb", s.fit.structure.nb}, {"nk", s.fit.structure.nk}};
  json eff = json::array();
  for (const auto& e : s.fit.effects) {
    json p = json::object();
    for (const auto& v : e.parameters) p[v.name] = v.value;
    eff.push_back({{"effect", e.name}, {"variant", e.variant}, {"parameters", p}});
  }
  j["effects"] = eff;
  j["verdict"] = v.verdict;
  j["unusable_reason"] = v.unusable;
  j["limit_cycle"] = limit_cycle_json(d.limit_cycle);
  j["whole_record"] = whole_record_json(d.whole_record);
  j["valve_travel"] = valve_travel_json(d.valve_travel);
  for (const auto& e : s.fit.effects)
    if (e.name == "stiction") {
      json st = json::object();
      for (const auto& v : e.parameters) st[v.name + "_percent"] = v.value;
      j["stiction"] = st;
    }
  json findings = json::array();
  for (const auto& f : s.findings) {
    json where;
    where["intervals"] = json::array();
    for (const auto& iv : f.intervals)
      where["intervals"].push_back({{"t_begin_s", t_at(t, iv.begin)},
                                    {"t_end_s", t_at(t, iv.end - 1)},
                                    {"begin_sample", iv.begin},
                                    {"end_sample", iv.end},
                                    {"share", iv.share}});
    where["regions"] = json::array();
    for (const auto& g : f.regions)
      where["regions"].push_back(
          {{"kind", g.kind}, {"label", g.label}, {"share", g.share}, {"excess", g.excess}});
    json p = json::object();
    for (const auto& v : f.parameters) p[v.name] = v.value;
    json pp = json::object();
    for (const auto& v : f.prediction_parameters) pp[v.name] = json_number(v.value);
    findings.push_back(
        {{"effect", f.effect},
         {"score", f.score},
         {"validation_gain_percent", json_number(f.validation_gain_percent)},
         {"estimation_gain_percent", json_number(f.estimation_gain_percent)},
         {"gain_percent", json_number(f.gain_percent)},
         {"prediction_estimation_gain_percent", json_number(f.prediction_estimation_gain_percent)},
         {"prediction_validation_gain_percent", json_number(f.prediction_validation_gain_percent)},
         {"prediction_bic_change", json_number(f.prediction_bic_change)},
         {"prediction_validation_deviance_change",
          json_number(f.prediction_validation_deviance_change)},
         {"prediction_drift_bic_change", json_number(f.prediction_drift_bic_change)},
         {"prediction_parameters", pp},
         {"parameter_count", json_number(f.parameter_count)},
         {"output_bic_change", json_number(f.output_bic_change)},
         {"validation_deviance_change", json_number(f.validation_deviance_change)},
         {"held_valve_validation_fitness_percent",
          json_number(f.held_valve_validation_fitness_percent)},
         {"evidence", f.evidence},
         {"evidence_test", f.evidence_test},
         {"parameters", p},
         {"where", where},
         {"explanation", f.explanation},
         {"supported", f.supported},
         {"indistinguishable_from", f.indistinguishable_from},
         {"trial_model", to_string(f.trial_spec)}});
  }
  j["findings"] = findings;
  j["judge"] = {
      {"kind", s.judge.horizon > 0 ? "k-step" : "simulated-output"},
      {"horizon_samples", s.judge.horizon},
      {"model_fitness_percent", json_number(s.judge.model_fitness_percent)},
      {"model_validation_fitness_percent", json_number(s.judge.model_validation_fitness_percent)}};
  json ladder = json::array();
  for (const auto& st : d.steps)
    ladder.push_back(
        {{"model", to_string(st.fit.spec)},
         {"fitness_percent", json_number(st.fit.fitness_percent)},
         {"validation_fitness_percent", json_number(st.fit.validation_fitness_percent)}});
  j["ladder"] = ladder;
  j["residual"] = {{"rms", s.residual.rms}, {"noise_level", s.residual.noise_level}};
  j["conclusion"] = d.conclusion;
  return j;
}

std::string format_ladder(const std::vector<HistoryEntry>& entries) {
  // One row per distinct model, its latest fit, in the order of those fits: a climb run twice
  // (or a refit of the start model) would otherwise repeat rows and their changes.
  std::vector<std::size_t> rows;
  for (std::size_t i = 0; i < entries.size(); ++i) {
    bool later = false;
    for (std::size_t k = i + 1; k < entries.size() && !later; ++k)
      later = entries[k].model == entries[i].model;
    if (!later) rows.push_back(i);
  }
  const auto pct = [](double v) { return std::isfinite(v) ? num(v) + " %" : std::string("-"); };
  const auto change = [](double now, double before) {
    return std::isfinite(now) && std::isfinite(before) ? signed_num(now - before)
                                                       : std::string("-");
  };
  std::ostringstream o;
  char line[512];
  std::snprintf(line, sizeof line, "%-4s  %-28s  %10s  %8s  %10s  %8s  %s\n", "step", "model",
                "estimation", "change", "validation", "change", "parameters that matter");
  o << line;
  for (std::size_t r = 0; r < rows.size(); ++r) {
    const auto& e = entries[rows[r]];
    const HistoryEntry* p = r > 0 ? &entries[rows[r - 1]] : nullptr;
    std::snprintf(
        line, sizeof line, "%-4zu  %-28s  %10s  %8s  %10s  %8s  %s\n", r + 1, e.model.c_str(),
        pct(e.fitness_percent).c_str(),
        p ? change(e.fitness_percent, p->fitness_percent).c_str() : "",
        pct(e.validation_fitness_percent).c_str(),
        p ? change(e.validation_fitness_percent, p->validation_fitness_percent).c_str() : "",
        report_format::parameters(e.parameters).c_str());
    o << line;
  }
  if (rows.size() < entries.size())
    o << "(" << entries.size() - rows.size() << " earlier fit"
      << (entries.size() - rows.size() == 1 ? " of a model above is" : "s of models above are")
      << " left out; the history file keeps every fit)\n";
  return o.str();
}

std::string format_model_fit(const ModelFit& f, const ResidualAnalysis& where,
                             const std::vector<double>& t) {
  std::ostringstream o;
  o << "model:     " << to_string(f.spec) << " (na " << f.structure.na << ", nb " << f.structure.nb
    << ", nk " << f.structure.nk << (f.integrating ? ", integrating" : "") << ")\n";
  for (const auto& e : f.effects)
    if (!e.parameters.empty())
      o << "           " << e.name << (e.variant.empty() ? "" : " (" + e.variant + ")") << ": "
        << report_format::parameters(e.parameters) << "\n";
  o << "fitness:   " << num(f.fitness_percent) << " % on estimation data";
  if (std::isfinite(f.validation_fitness_percent))
    o << ", " << num(f.validation_fitness_percent) << " % on validation data";
  o << " (simulated output: the model driven by OP alone)\n";
  if (f.status == ModelFitStatus::NoStableModel)
    o << "where it fails: nowhere to say (no stable model, so no simulated PV)\n";
  else
    o << "where it fails: residual RMS " << num(where.rms, 3) << ", white-noise level "
      << num(where.noise_level, 3) << "\n";
  std::size_t shown = 0;
  for (const auto& iv : where.intervals) {
    if (shown++ == 3) break;
    o << "           t " << num(t_at(t, iv.begin), 1) << " .. " << num(t_at(t, iv.end - 1), 1)
      << " s: " << num(100 * iv.share, 0) << " % of the squared error\n";
  }
  for (const auto& test : where.tests)
    if (test.score >= 0.3) {
      o << "           " << test.name << " " << num(test.score);
      // A test that points to no effect (whiteness) says what it measured instead.
      if (test.effects.empty()) o << ": " << test.detail;
      for (std::size_t i = 0; i < test.effects.size(); ++i)
        o << (i ? ", " : " -> ") << test.effects[i];
      o << "\n";
    }
  o << "solver:    " << to_string(f.status) << " (" << f.stop_reason << "), " << f.evaluations
    << " evaluations, " << num(f.elapsed_s, 2) << " s\n";
  return o.str();
}

nlohmann::json model_fit_json(const ModelFit& f, const ResidualAnalysis& where,
                              const std::vector<double>& t) {
  using nlohmann::json;
  json j;
  j["model"] = to_string(f.spec);
  j["structure"] = {{"na", f.structure.na}, {"nb", f.structure.nb}, {"nk", f.structure.nk}};
  j["integrating"] = f.integrating;
  j["fitness_percent"] = json_number(f.fitness_percent);
  j["validation_fitness_percent"] = json_number(f.validation_fitness_percent);
  j["a"] = f.a;
  j["b"] = f.b;
  j["c"] = f.c;
  json eff = json::array();
  for (const auto& e : f.effects) {
    json p = json::object();
    for (const auto& v : e.parameters) p[v.name] = v.value;
    eff.push_back({{"effect", e.name}, {"variant", e.variant}, {"parameters", p}});
  }
  j["effects"] = eff;
  json iv = json::array();
  for (const auto& i : where.intervals)
    iv.push_back({{"t_begin_s", t_at(t, i.begin)},
                  {"t_end_s", t_at(t, i.end - 1)},
                  {"share", i.share},
                  {"rms", i.rms}});
  json ts = json::array();
  for (const auto& x : where.tests)
    ts.push_back(
        {{"name", x.name}, {"effects", x.effects}, {"score", x.score}, {"detail", x.detail}});
  j["where"] = {{"residual_rms", where.rms},
                {"noise_level", where.noise_level},
                {"intervals", iv},
                {"tests", ts}};
  j["solver"] = {{"status", to_string(f.status)},
                 {"stop_reason", f.stop_reason},
                 {"evaluations", f.evaluations}};
  j["elapsed_s"] = f.elapsed_s;
  return j;
}

}  // namespace valvediag
