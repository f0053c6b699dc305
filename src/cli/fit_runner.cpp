#include "fit_runner.hpp"

#include <fstream>
#include <stdexcept>

#include "valvediag/core/stiction_quantification.hpp"
#include "valvediag/io/csv_writer.hpp"
#include "valvediag/io/data_checks.hpp"
#include "valvediag/report/fit_report.hpp"

namespace valvediag::cli {

FitRun run_fit(const LoopData& d, const FitOptions& fo, const std::string& output,
               const OpRange& range) {
  const std::string model =
      "this model (na <= " + std::to_string(fo.na_max) + ", nb <= " + std::to_string(fo.nb_max) +
      ", nk <= " + std::to_string(fo.nk_max) + ", L <= " + std::to_string(fo.L_max) + ")";
  LoopData checked = d;
  if (output == "mv") checked.pv = d.mv;  // the identity block fits the valve position
  check_identifiable_data(checked, minimum_samples(fo), model);
  FitRun run;
  run.result = identify(d.op, checked.pv, fo);
  ResidualAnalysis where;
  FitContext ctx;
  if (run.result.status == IdentificationStatus::Ok) {
    const FitSeries series = fit_series(run.result, d.op, checked.pv);
    where = analyse_fit(run.result, d.op, checked.pv, series);
    ctx.residual = &where;
  }
  ctx.time = &d.t;
  ctx.op = &d.op;        // stiction figures probe the identified valve on the data's own OP
  ctx.pv = &checked.pv;  // ... and are refined on the data
  ctx.data_name = d.source;
  ctx.samples = d.size();
  ctx.sample_period = d.sample_period();
  ctx.output_name = output;
  ctx.method = method_name(fo.method);
  ctx.threads = fo.threads;
  if (run.result.status == IdentificationStatus::Ok) {
    ctx.stiction = fit_stiction(run.result, ctx);  // in OP units: % when OP is 0..100
    if (range != OpRange{}) ctx.stiction = in_percent_of_span(*ctx.stiction, range);
  }
  run.summary = format_summary(run.result, ctx);
  run.json = to_json(run.result, ctx);
  return run;
}

void write_series(const std::string& path, const LoopData& d, const FitRun& run) {
  const auto& y = run.result.model.block == LinearBlock::Identity ? d.mv : d.pv;
  const FitSeries s = fit_series(run.result, d.op, y);
  const std::string yname = run.result.model.block == LinearBlock::Identity ? "mv" : "pv";
  write_columns_csv(path, {"t", "op", yname, "x_hat", yname + "_sim", "residual"},
                    {d.t, d.op, y, s.x_hat, s.y_sim, s.residual});
}

}  // namespace valvediag::cli
