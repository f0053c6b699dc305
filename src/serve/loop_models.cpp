#include "valvediag/serve/loop_models.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <thread>

#include "valvediag/io/data_checks.hpp"
#include "valvediag/report/diagnosis_report.hpp"
#include "valvediag/report/html_report.hpp"
#include "valvediag/report/json_number.hpp"
#include "valvediag/serve/workbench_api.hpp"

namespace valvediag::serve {

namespace {

using nlohmann::json;

std::string number_text(double x) {
  char b[32];
  std::snprintf(b, sizeof b, "%g", x);
  return b;
}

double t_at(const LoopData& d, std::size_t i) {
  return d.t.empty() ? NAN : d.t[std::min(i, d.t.size() - 1)];
}

// Where a fitted model fails, on its estimation part: as fit --model and report find it.
ResidualAnalysis where_it_fails(const ModelFit& f, const LoopData& d) {
  ResidualAnalysisOptions ro;
  ro.model_delay = static_cast<std::size_t>(std::max(0, f.structure.nk + 1));
  return analyse_residual(d.op, d.pv, f.y_sim, f.first_sample, f.estimation_end, ro);
}

std::shared_ptr<const ModelStep> make_step(const std::string& action, ModelFit f,
                                           ResidualAnalysis where,
                                           std::shared_ptr<const LoopData> data, double validate) {
  auto s = std::make_shared<ModelStep>();
  s->action = action;
  s->entry = history_entry(f, "workbench " + action);
  s->fit = std::move(f);
  s->where = std::move(where);
  s->data = std::move(data);
  s->validate = validate;
  return s;
}

// Appends the new models' rows to a history file. One writer at a time: two loops served from the
// same data share a file, and each append reads and rewrites it.
json append_to_file(const std::string& file, const std::vector<HistoryEntry>& entries) {
  static std::mutex writing;
  std::lock_guard<std::mutex> lock(writing);
  std::string why;
  std::size_t total = 0;
  if (try_append_history(file, entries, why, &total)) return {{"entries", total}};
  return {{"error", why + "; the models stand without it"}};
}

// What a job fitted: the samples and their time span, the held-out share.
json data_summary(const LoopData& d, double validate) {
  return {{"samples", d.size()},
          {"from_s", json_number(d.t.empty() ? NAN : d.t.front())},
          {"to_s", json_number(d.t.empty() ? NAN : d.t.back())},
          {"validate", validate}};
}

json step_summary(std::size_t n, const ModelStep& s) {
  return {{"step", n},
          {"model", s.entry.model},
          {"action", s.action},
          {"fitness_percent", json_number(s.entry.fitness_percent)},
          {"validation_fitness_percent", json_number(s.entry.validation_fitness_percent)},
          {"data", data_summary(*s.data, s.validate)}};
}

}  // namespace

ModelFitOptions ModelOptions::fit_options() const {
  ModelFitOptions mo;
  mo.validation_fraction = validate;
  mo.threads = threads;
  return mo;
}

std::size_t ModelOptions::estimation_end(std::size_t n) const {
  // fit_model's rule (model_fit.cpp): the last `validate` share held out, rounded to a sample.
  if (!(validate > 0)) return n;
  return static_cast<std::size_t>(std::llround(static_cast<double>(n) * (1.0 - validate)));
}

DiagnoseOptions ModelOptions::diagnose_options(const LoopData& d) const {
  // As diagnose sets them (cmd_diagnose.cpp).
  DiagnoseOptions o;
  o.valve_travel.op_range = range;
  o.time_origin_s = d.t.empty() ? 0.0 : d.t.front();
  o.validation_fraction = validate;
  o.min_gain_percent = min_gain;
  o.fit.threads = threads;
  return o;
}

LoopModels::LoopModels(std::string history_file) {
  if (!history_file.empty())
    writer_ = [file = std::move(history_file)](const std::vector<HistoryEntry>& e) {
      return append_to_file(file, e);
    };
}

json LoopModels::record_history(const std::vector<HistoryEntry>& entries) const {
  if (!writer_ || entries.empty()) return json();
  return writer_(entries);
}

json JobRequest::info() const {
  json j{{"action", action}};
  if (!model.empty()) j["model"] = model;
  if (!effect.empty()) j["effect"] = effect;
  if (action == "diagnose") j["climb"] = climb;
  if (validate) j["validate"] = *validate;
  if (last_s) j["last_s"] = *last_s;
  return j;
}

LoopData latest_part(const LoopData& d, double seconds) {
  if (d.t.empty() || !(d.t.back() - d.t.front() > seconds)) return d;
  // A hair below the start: 1 s of 5 ms samples is 201 of them, whatever the rounding of t.
  const double from = d.t.back() - seconds - 1e-9 * std::max(1.0, std::abs(d.t.back()));
  const auto first =
      static_cast<std::size_t>(std::lower_bound(d.t.begin(), d.t.end(), from) - d.t.begin());
  LoopData p = d;
  const auto cut = [first](std::vector<double>& v) {
    if (v.size() > first) v.erase(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(first));
  };
  for (auto* v : {&p.t, &p.op, &p.pv, &p.sp, &p.mv}) cut(*v);
  return p;
}

JobRequest parse_job_request(const json& body) {
  const std::string usage =
      "send {\"action\":\"fit\",\"model\":\"stiction\"}, {\"action\":\"add\",\"effect\":"
      "\"stiction\"}, {\"action\":\"remove\",\"effect\":\"deadband\"} or {\"action\":"
      "\"diagnose\"} (\"climb\":true climbs the ladder, as diagnose --auto)";
  if (!body.is_object()) throw std::invalid_argument("the body must be a JSON object: " + usage);
  const auto text = [&](const char* key) {
    const auto it = body.find(key);
    if (it == body.end())
      throw std::invalid_argument(std::string("missing \"") + key + "\": " + usage);
    if (!it->is_string() || it->get<std::string>().empty() || it->get<std::string>().size() > 200)
      throw std::invalid_argument(std::string("\"") + key +
                                  "\" must be a non-empty string: " + usage);
    return it->get<std::string>();
  };
  JobRequest r;
  r.action = text("action");
  std::vector<std::string> keys{"action", "validate", "last_s"};
  if (const auto it = body.find("validate"); it != body.end()) {
    const double v = it->is_number() ? it->get<double>() : NAN;
    if (!(v >= kMinJobValidate && v <= kMaxJobValidate))
      throw std::invalid_argument(
          "\"validate\" must be the held-out share, a number from " + number_text(kMinJobValidate) +
          " to " + number_text(kMaxJobValidate) + ", got " + it->dump().substr(0, 40));
    r.validate = v;
  }
  if (const auto it = body.find("last_s"); it != body.end()) {
    const double v = it->is_number() ? it->get<double>() : NAN;
    if (!(v > 0 && std::isfinite(v)))
      throw std::invalid_argument(
          "\"last_s\" must be a positive number of seconds (fit the latest that many), got " +
          it->dump().substr(0, 40));
    r.last_s = v;
  }
  if (r.action == "fit") {
    r.model = text("model");
    (void)parse_model_spec(r.model);  // ModelSpecError (an invalid_argument) names the problem
    keys.push_back("model");
  } else if (r.action == "add" || r.action == "remove") {
    r.effect = text("effect");
    (void)parse_effect(r.effect);
    keys.push_back("effect");
  } else if (r.action == "diagnose") {
    if (const auto it = body.find("climb"); it != body.end()) {
      if (!it->is_boolean()) throw std::invalid_argument("\"climb\" must be true or false");
      r.climb = it->get<bool>();
    }
    keys.push_back("climb");
  } else {
    throw std::invalid_argument("unknown action \"" + r.action.substr(0, 40) + "\": " + usage);
  }
  for (const auto& [k, v] : body.items())
    if (std::find(keys.begin(), keys.end(), k) == keys.end())
      throw std::invalid_argument("unknown key \"" + k.substr(0, 40) + "\" for action " + r.action +
                                  ": " + usage);
  return r;
}

std::vector<std::shared_ptr<const ModelStep>> LoopModels::steps() const {
  std::lock_guard<std::mutex> lock(m_);
  return steps_;
}

std::shared_ptr<const ModelStep> LoopModels::step(std::size_t n) const {
  std::lock_guard<std::mutex> lock(m_);
  return n < steps_.size() ? steps_[n] : nullptr;
}

std::shared_ptr<const ModelStep> LoopModels::last() const {
  std::lock_guard<std::mutex> lock(m_);
  return steps_.empty() ? nullptr : steps_.back();
}

void LoopModels::push(std::shared_ptr<const ModelStep> s) {
  std::lock_guard<std::mutex> lock(m_);
  steps_.push_back(std::move(s));
}

std::optional<LoopModels::Diagnosed> LoopModels::diagnosis() const {
  std::lock_guard<std::mutex> lock(m_);
  return diagnosis_;
}

void LoopModels::set_diagnosis(Diagnosed d) {
  std::lock_guard<std::mutex> lock(m_);
  diagnosis_ = std::move(d);
}

json run_job(const JobRequest& req, const LoopData& d, LoopModels& models, const ModelOptions& opt,
             JobControl& control, std::size_t max_steps) {
  return run_job(req, std::make_shared<const LoopData>(d), models, opt, control, max_steps);
}

json run_job(const JobRequest& req, std::shared_ptr<const LoopData> whole, LoopModels& models,
             const ModelOptions& server, JobControl& control, std::size_t max_steps) {
  if (models.steps().size() >= max_steps)
    throw std::invalid_argument("this loop's ladder holds " + std::to_string(max_steps) +
                                " models, the most the workbench keeps: download the ones to keep "
                                "and restart valvediag serve for a new ladder");
  // The request's own held-out share and part of the record, else the server's and all of it.
  ModelOptions opt = server;
  if (req.validate) opt.validate = *req.validate;
  const std::shared_ptr<const LoopData> data =
      req.last_s ? std::make_shared<const LoopData>(latest_part(*whole, *req.last_s)) : whole;
  const LoopData& d = *data;
  const double Ts = d.sample_period();
  const auto current = models.last();
  // The model the request starts from: the ladder's last, else linear (diagnose's default).
  const ModelSpec base = current ? current->fit.spec : parse_model_spec("linear");
  if (req.action == "diagnose") {
    check_identifiable_data(d, 200, "a diagnosis");
    DiagnoseOptions o = opt.diagnose_options(d);
    o.fit.cancel = control.cancel_flag();
    const std::string what =
        (req.climb ? "climbing the ladder from " : "diagnosing ") + to_string(base) + ": ";
    control.report(0.05, what + "trial fits of the missing effects");
    o.progress = [&control, &what](double fraction, const std::string& phase) {
      control.report(0.05 + 0.9 * fraction, what + phase);
    };
    auto r = std::make_shared<Diagnosis>(req.climb ? diagnose_auto(d.op, d.pv, d.mv, Ts, base, o)
                                                   : diagnose(d.op, d.pv, d.mv, Ts, base, o));
    throw_if_cancelled(control.cancel_flag());
    // The fits the diagnosis made join the ladder when they are new: its start on an empty
    // ladder, the climb's steps after it.
    std::vector<HistoryEntry> entries;
    for (std::size_t k = 0; k < r->steps.size(); ++k) {
      if (k == 0 && current) continue;
      const auto& s = r->steps[k];
      if (s.fit.status == ModelFitStatus::NoStableModel) continue;
      auto step = make_step(req.climb ? "diagnose --auto" : "diagnose", s.fit, s.residual, data,
                            opt.validate);
      entries.push_back(step->entry);
      models.push(std::move(step));
    }
    const json history = models.record_history(entries);
    json j = diagnosis_json(*r, d.t, VerdictText{});
    j.erase("verdict");  // the loop's verdict is /verdict's (loop_verdict), not this analysis'
    j.erase("unusable_reason");
    j["data"] = data_summary(d, opt.validate);
    models.set_diagnosis({r, j, data});
    control.report(1.0, "done");
    return {{"model", j["model"]},
            {"findings", j["findings"]},
            {"conclusion", j["conclusion"]},
            {"steps_added", entries.size()},
            {"ladder_steps", models.steps().size()},
            {"history", history},
            {"data", j["data"]}};
  }
  ModelSpec spec = base;
  std::vector<EffectSpec> replaced;
  if (req.action == "fit") {
    spec = parse_model_spec(req.model);
  } else if (req.action == "add") {
    // As fit --add: an effect already there as given is fitted again.
    const EffectSpec added = parse_effect(req.effect);
    if (const EffectSpec* have = base.find(added.name); !have || !(*have == added))
      spec = add_effect(base, req.effect, &replaced);
  } else {
    spec = remove_effect(base, req.effect);
  }
  check_identifiable_data(d, 200, "model " + to_string(spec));
  ModelFitOptions mo = opt.fit_options();
  mo.cancel = control.cancel_flag();
  // An effect added to the last model, on the same samples and split: that fit starts and bounds
  // the new one's search (ModelFitOptions::extends), as fit --add's does.
  if (req.action == "add" && replaced.empty() && current && spec != base &&
      current->validate == opt.validate && current->data && current->data->op == d.op &&
      current->data->pv == d.pv)
    mo.extends = &current->fit;
  const std::string fitting = "fitting " + to_string(spec);
  control.report(0.05, fitting);
  mo.progress = [&control, &fitting](double share, const std::string& stage) {
    control.report(0.05 + 0.9 * share, fitting + ": " + stage);
  };
  ModelFit f = fit_model(d.op, d.pv, Ts, spec, mo);
  if (f.status == ModelFitStatus::NoStableModel)
    throw std::invalid_argument("no stable model " + to_string(spec) +
                                " fits this loop: try another model");
  ResidualAnalysis where = where_it_fails(f, d);
  throw_if_cancelled(control.cancel_flag());  // a cancelled job leaves the ladder as it was
  const std::string action =
      req.action == "fit" ? "fit " + to_string(spec) : req.action + " " + req.effect;
  auto step = make_step(action, std::move(f), std::move(where), data, opt.validate);
  const HistoryEntry entry = step->entry;
  models.push(std::move(step));
  const auto steps = models.steps();
  json j = step_summary(steps.size() - 1, *steps.back());
  j["history"] = models.record_history({entry});
  j["replaced"] = json::array();
  for (const auto& e : replaced) j["replaced"].push_back(to_string(e));
  control.report(1.0, "done");
  return j;
}

json ladder_json(const LoopModels& models) {
  const auto steps = models.steps();
  json rows = json::array();
  for (std::size_t n = 0; n < steps.size(); ++n) {
    const ModelStep& s = *steps[n];
    json r = step_summary(n, s);
    const auto change = [&](double now, double before) {
      return n > 0 ? json_number(now - before) : json();
    };
    const HistoryEntry* p = n > 0 ? &steps[n - 1]->entry : nullptr;
    r["fitness_change"] = p ? change(s.entry.fitness_percent, p->fitness_percent) : json();
    r["validation_fitness_change"] =
        p ? change(s.entry.validation_fitness_percent, p->validation_fitness_percent) : json();
    json params = json::object();
    for (const auto& v : s.entry.parameters) params[v.name] = json_number(v.value);
    r["parameters"] = params;
    r["estimation_end_s"] = json_number(t_at(*s.data, s.fit.estimation_end));
    r["valve_effect"] = has_valve_effect(s.fit.spec);
    r["time"] = s.entry.time;
    rows.push_back(std::move(r));
  }
  return {{"steps", rows}};
}

json model_json(const ModelStep& s, const LoopData& d) {
  return model_fit_json(s.fit, s.where, d.t);
}

json simulation_json(const ModelStep& s, const LoopData& d, double from, double to, int buckets) {
  std::vector<double> res(d.pv.size(), NAN);
  for (std::size_t k = 0; k < res.size() && k < s.fit.y_sim.size(); ++k)
    res[k] = d.pv[k] - s.fit.y_sim[k];
  json j = decimated_columns(d.t, {{"pv", &d.pv}, {"pv_sim", &s.fit.y_sim}, {"residual", &res}},
                             from, to, buckets);
  j["model"] = s.entry.model;
  j["estimation_end_s"] = json_number(t_at(d, s.fit.estimation_end));
  j["first_sample_s"] = json_number(t_at(d, s.fit.first_sample));
  return j;
}

bool has_valve_effect(const ModelSpec& spec) {
  return std::any_of(spec.effects.begin(), spec.effects.end(),
                     [](const EffectSpec& e) { return is_valve_effect(e.name); });
}

json signature_json(const ModelStep& s, const LoopData& d, double from, double to, int points) {
  json j = decimated_path(d.t, {{"op", &d.op}, {"x", &s.fit.x_hat}}, from, to, points,
                          s.fit.estimation_end);
  j["model"] = s.entry.model;
  // null when nothing is held out (validate 0)
  j["estimation_end_s"] =
      s.fit.estimation_end < d.t.size() ? json(d.t[s.fit.estimation_end]) : json();
  j["x_in_op_units"] = !s.fit.spec.has("preisach");
  return j;
}

std::string report_html(const LoopModels& models, const std::string& name,
                        const std::string& verdict) {
  const auto last = models.last();
  if (!last)
    throw std::invalid_argument(
        "no model yet: fit one first (POST /api/loops/{id}/jobs {\"action\":\"diagnose\"})");
  ReportContent c;
  c.data = last->data.get();
  c.data_name = name;
  c.fit = &last->fit;
  c.where = &last->where;
  const auto dg = models.diagnosis();
  if (dg && dg->data == last->data && dg->diagnosis->last().fit.spec == last->fit.spec) {
    c.diagnosis = dg->diagnosis.get();
    c.diagnosis_command = "valvediag serve: diagnose " + to_string(last->fit.spec);
  }
  c.verdict = verdict;
  for (const auto& s : models.steps()) c.ladder.push_back(s->entry);
  c.generator = "valvediag serve";
  ReportOptions ro;
  ro.require_plots = false;  // without gnuplot the page says so in place of each plot
  return html_report(c, ro).html;
}

}  // namespace valvediag::serve
