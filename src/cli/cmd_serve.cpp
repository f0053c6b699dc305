// valvediag serve: the workbench's HTTP server (issue 36). cpp-httplib in front of the JSON API
// of src/serve (workbench_api.hpp), which holds the routing and the rules; this file only reads
// the data, binds, prints the address and stops on Ctrl-C.
#include <sys/socket.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <optional>
#include <thread>

#include "commands.hpp"
#include "data_options.hpp"
#include "history_options.hpp"
#include "stop_signal.hpp"
#include "valvediag/serve/workbench_api.hpp"
#include "valvediag/sweep/loop_verdict.hpp"
#include "verdict_output.hpp"
#include "workbench_server.hpp"

// Last: it brings <resolv.h>, whose `_res` macro breaks the Eigen headers included after it.
#include <httplib.h>

namespace valvediag::cli {

void check_workbench_bind(const WorkbenchSettings& w) {
  // A server others can reach without a token would hand the plant's data to anyone on the
  // network.
  if (!serve::is_loopback(w.bind) && !w.token)
    throw UsageError("--bind " + w.bind +
                     " lets other machines connect: add --token, so that every request must "
                     "carry the random token printed at start");
}

serve::LoopSnapshot served_snapshot(LoopData d, const WorkbenchSettings& w,
                                    std::vector<std::string>& notes) {
  // The models are fitted to the part diagnose analyses (a quiet lead-in left out).
  std::optional<LoopData> part;
  if (d.size() >= 200) {
    AnalysedPart p = analysed_part(d, w.keep_lead_in, w.range, notes);
    if (p.from_s > 0) part = std::move(p.data);
  }
  return {std::move(d), std::move(part)};
}

serve::ServedLoop served_loop(std::string name, LoopData d, const WorkbenchSettings& w,
                              std::vector<std::string>& notes) {
  serve::LoopSnapshot s = served_snapshot(std::move(d), w, notes);
  return {std::move(name), std::move(s.data), std::move(s.analysed)};
}

void run_workbench(std::vector<serve::ServedLoop> loops, const WorkbenchSettings& w,
                   const WorkbenchExtras& extras) {
  check_workbench_bind(w);
  // The very call diagnose makes for its verdict, with the same options and JSON keys.
  const OpRange range = w.range;
  const double validate = w.validate, min_gain = w.min_gain;
  const bool keep = w.keep_lead_in;
  // Set on Ctrl-C: a verdict being computed stops at its next fit instead of holding the exit.
  std::atomic<bool> closing{false};
  serve::VerdictFunction verdict = [=, &closing](const LoopData& d, const OpRange& span) {
    VerdictOptions vo =
        verdict_options(span, validate, keep, d.t.empty() ? 0.0 : d.t.front(), min_gain);
    vo.diagnose.fit.cancel = &closing;
    const LoopVerdict lv = loop_verdict(d, vo);
    nlohmann::json j;
    add_verdict_json(j, lv);
    j["verdict_basis"] = verdict_basis(lv);
    j["analysed_from_s"] = lv.analysed_from_s;
    return j;
  };
  const std::string token = w.token ? serve::random_token() : "";
  serve::ModelOptions mo;
  mo.validate = validate;
  mo.min_gain = min_gain;
  mo.range = range;
  serve::JobLimits limits;
  const unsigned cores = std::max(1u, std::thread::hardware_concurrency());
  limits.workers = w.jobs == 0 ? cores : std::min(w.jobs, cores);
  // The cores shared out: jobs times threads per fit stay within them.
  mo.threads = static_cast<int>(std::max(1u, cores / limits.workers));
  const serve::WorkbenchApi api(std::move(loops), verdict, token, mo, limits, extras.status);

  httplib::Server srv;
  auto handler = [&api](const httplib::Request& req, httplib::Response& res) {
    serve::ApiRequest r;
    r.method = req.method;
    r.path = req.path;  // URL-decoded by httplib: "%2e%2e" arrives as ".."
    for (const auto& [k, v] : req.params) r.query.emplace(k, v);
    r.authorization = req.get_header_value("Authorization");
    r.cookie = req.get_header_value("Cookie");
    r.host = req.get_header_value("Host");
    r.content_type = req.get_header_value("Content-Type");
    r.body = req.body;
    const serve::ApiResponse out = api.handle(r);
    res.status = out.status;
    if (!out.attachment.empty())
      res.set_header("Content-Disposition", "attachment; filename=\"" + out.attachment + "\"");
    if (!out.set_cookie.empty()) res.set_header("Set-Cookie", out.set_cookie);
    res.set_content(serve::response_text(out), serve::response_type(out));
  };
  // Every path and method goes to the API, which refuses what it does not serve ([\s\S]: a
  // decoded %0a in a path must not fall through to httplib's empty 404).
  const char* any = R"([\s\S]*)";
  srv.Get(any, handler);
  srv.Post(any, handler);
  srv.Put(any, handler);
  srv.Patch(any, handler);
  srv.Delete(any, handler);
  srv.Options(any, handler);
  // What httplib refuses itself (a malformed request line, a too long URI) gets a JSON error
  // too; the API's own errors already have their body.
  srv.set_error_handler([](const httplib::Request&, httplib::Response& res) {
    if (res.body.empty())
      res.set_content(
          serve::response_text(
              {res.status, {{"error", "bad request (HTTP " + std::to_string(res.status) + ")"}}}),
          "application/json");
  });
  srv.set_exception_handler(
      [](const httplib::Request&, httplib::Response& res, std::exception_ptr) {
        res.status = 500;
        res.set_content(R"({"error":"internal error"})", "application/json");
      });
  srv.set_default_headers({{"Cache-Control", "no-store"}, {"X-Content-Type-Options", "nosniff"}});
  // httplib's default sets SO_REUSEPORT, with which a second server binds a port already in
  // use and takes some of its connections: SO_REUSEADDR alone refuses a port in use.
  srv.set_socket_options([](int sock) {
    int yes = 1;
    setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
  });
  srv.set_payload_max_length(serve::kMaxBody + 1);  // larger bodies: 413 before they are read
  srv.set_read_timeout(5, 0);
  srv.set_write_timeout(5, 0);

  int port = w.port;
  if (port == 0)
    port = srv.bind_to_any_port(w.bind);
  else if (!srv.bind_to_port(w.bind, port))
    port = -1;
  if (port <= 0)
    throw std::runtime_error("cannot listen on " + w.bind + " port " + std::to_string(w.port) +
                             ": the port is in use or the address is not this machine's");
  std::atomic<bool>& stop = install_stop_signals();
  std::atomic<bool> ended{false};
  std::thread server([&] {
    srv.listen_after_bind();
    ended = true;
  });
  // stop() only closes a socket listen_after_bind() has started on: a Ctrl-C before that would
  // leave the join below waiting for ever.
  while (!srv.is_running() && !ended) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  if (extras.listening) extras.listening();
  const std::string host = w.bind.find(':') != std::string::npos ? "[" + w.bind + "]" : w.bind;
  const std::string page = "http://" + host + ":" + std::to_string(port) + "/";
  std::cout << "serving " << api.size() << " loop(s) on " << page
            << "api/loops; the workbench: " << page << (token.empty() ? "" : "?token=" + token)
            << " (Ctrl-C stops)\n";
  if (!token.empty())
    std::cout << "token: " << token << "  (send 'Authorization: Bearer " << token << "')\n";
  std::cout << std::flush;
  while (!stop && !ended) std::this_thread::sleep_for(std::chrono::milliseconds(50));
  // Finishes the requests in progress (a verdict being computed stops at its next fit with a
  // 503), then returns; the jobs are cancelled when `api` goes.
  closing = true;
  srv.stop();
  server.join();
  if (!stop)  // the listening loop ended without being asked to: not a clean stop
    throw std::runtime_error("the server stopped listening on " + w.bind + " port " +
                             std::to_string(port) + " unexpectedly");
  std::cout << "stopped" << std::endl;
}

void add_serve(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand(
      "serve", "Serve the loops of data files to the workbench (a web page and its JSON API)");
  cmd->footer(
      "Reads the files as diagnose does (or a recording's loops, or records a site live) and\n"
      "answers, until Ctrl-C:\n"
      "  GET /api/loops                          the loops: id, name, samples, sample period\n"
      "  GET /api/loops/ID/series?from=S&to=S&buckets=N   OP, PV, SP min/max per bucket\n"
      "  GET /api/loops/ID/verdict               the loop's verdict, as diagnose gives it\n"
      "  POST /api/loops/ID/jobs, GET/DELETE /api/jobs/ID   fit, diagnose, add an effect\n"
      "       (\"validate\": the held-out share 0.05..0.6; \"last_s\": fit the latest N s)\n"
      "  GET /api/loops/ID/ladder, /diagnosis, /models/N, /models/N/simulation, /report\n"
      "  GET /api/loops/ID/phase, /models/N/signature   PV and the valve position against OP\n"
      "  GET /api/status                         with --config: the recorder and bus counters\n"
      "  GET /                                   the workbench page (open it in a browser)\n"
      "It binds 127.0.0.1; another --bind needs --token (open the printed address with\n"
      "?token=..., or send 'Authorization: Bearer TOKEN'). It writes no file but each file's\n"
      "model history in the state directory, as fit and diagnose do (a recording's: its table\n"
      "model_history; --no-history: none), and with --config the recording into --db. It never\n"
      "writes to a PLC: --config only reads, as valvediag record. See docs/workbench.md.\n"
      "Exit status 0 after Ctrl-C; 2 for bad options, files or databases; 1 when it cannot\n"
      "listen or the recorder failed.\n"
      "Examples:\n"
      "  valvediag serve loop.csv                 (open http://127.0.0.1:8080/)\n"
      "  valvediag serve loops/*.csv --port 0     (a free port, printed)\n"
      "  valvediag serve --db site.sqlite --loops 'FIC*' --window 2h   (recorded loops)\n"
      "  valvediag serve --config site.toml --db site.sqlite   (record and watch live)\n"
      "  valvediag serve loop.csv --bind 0.0.0.0 --token");
  struct Args {
    std::vector<std::string> files;
    DataOptions layout;
    WorkbenchSettings w;
    std::string op_range;
    HistoryOptions hist;
    std::string db, config, loops, window = "4h";
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("files", a->files, "data files (CSV or .mat), one loop each");
  cmd->add_option("--db", a->db,
                  "a recording (valvediag record): serve its loops' latest --window; with "
                  "--config, record into it and serve the loops live");
  cmd->add_option("--config", a->config,
                  "site TOML: record its loops into --db while serving them (reads only)");
  cmd->add_option("--loops", a->loops,
                  "with --db: comma-separated loop names or patterns (FIC*); default: all");
  CLI::Option* window = cmd->add_option("--window", a->window,
                                        "with --db: the latest recorded window per loop: 30m, 4h")
                            ->capture_default_str();
  add_layout_options(cmd, a->layout);
  add_op_range_option(cmd, a->op_range);
  cmd->add_option("--port", a->w.port, "TCP port; 0 picks a free one (printed)")
      ->check(CLI::Range(0, 65535))
      ->capture_default_str();
  cmd->add_option("--bind", a->w.bind, "address to listen on; other than loopback needs --token")
      ->capture_default_str();
  cmd->add_flag("--token", a->w.token,
                "require a random token (printed at start) on every request");
  cmd->add_option("--jobs", a->w.jobs,
                  "model jobs run at once (0: one per core; at most the cores)")
      ->capture_default_str();
  cmd->add_option("--validate", a->w.validate, "verdict: fraction of the record held out")
      ->capture_default_str();
  cmd->add_option("--min-gain", a->w.min_gain, "verdict: smallest fitness gain worth an effect")
      ->capture_default_str();
  cmd->add_flag("--keep-lead-in", a->w.keep_lead_in,
                "verdict: analyse the whole record, quiet lead-in included");
  cmd->add_flag("--no-history", a->hist.off,
                "do not add the models to each file's model history in the state directory "
                "(the one fit, diagnose and ladder use)");
  cmd->callback([a, window, &exit_code] {
    check_workbench_bind(a->w);                      // before any data is read
    (void)split_check_shares(a->w.validate, false);  // the range check diagnose makes
    // The page's jobs may move the split within the API's bounds: the server's share too.
    if (a->w.validate > serve::kMaxJobValidate) {
      char b[160];
      std::snprintf(b, sizeof b,
                    "--validate %g: the workbench holds out at most %g of a record (its page "
                    "moves the split within that); give less",
                    a->w.validate, serve::kMaxJobValidate);
      throw UsageError(b);
    }
    a->w.range = parse_op_range(a->op_range);
    if (!a->config.empty() && a->db.empty())
      throw UsageError("--config needs --db site.sqlite: the recording the workbench writes");
    if (!a->config.empty() && !a->op_range.empty())
      throw UsageError(
          "--op-range goes with data files or --db alone; a site gives each loop's OP range as "
          "op_range = [min, max] in " +
          a->config);
    if (a->files.empty() == a->db.empty())
      throw UsageError(
          "give data files, or --db site.sqlite (a recording; with --config site.toml: record "
          "it live), one of them");
    if (a->db.empty() && (!a->loops.empty() || window->count() > 0))
      throw UsageError("--loops and --window go with --db");
    if (!a->db.empty()) {
      RecordingSource src;
      src.db = a->db;
      src.wanted = split_names(a->loops);
      src.window_s = duration_option("--window", a->window);
      src.max_rows = a->layout.csv.max_rows;
      if (a->config.empty()) {
        run_workbench(recorded_loops_to_serve(src, a->w, a->hist), a->w);
        exit_code = kOk;
        return;
      }
      LiveRecording live(load_site_config(a->config), src, a->w, a->hist);
      WorkbenchExtras extras;
      extras.status = [&live] { return live.status_json(); };
      extras.listening = [&live, &src] {
        live.start();
        std::cout << "recording into " << src.db << " (reads only; Ctrl-C stops)\n";
      };
      run_workbench(live.take_loops(), a->w, extras);
      live.stop();  // every sample taken is stored, the run ended
      std::cout << live.summary();
      if (!live.error().empty()) throw std::runtime_error("the recorder stopped: " + live.error());
      exit_code = kOk;
      return;
    }
    std::vector<serve::ServedLoop> loops;
    for (const auto& f : a->files) {
      DataOptions in = a->layout;
      in.data = f;
      std::vector<std::string> notes;
      LoopData d = load_data(in, notes);
      std::string name = d.tag.empty() ? std::filesystem::path(f).stem().string() : d.tag;
      // The history fit and diagnose keep for this data read this way: `ladder` lists the
      // workbench's models with theirs.
      const std::string history = a->hist.off ? "" : history_place(a->hist, in, d).file;
      loops.push_back(served_loop(std::move(name), std::move(d), a->w, notes));
      loops.back().history = history;
      for (const auto& n : notes) std::cout << "note: " << f << ": " << n << "\n";
      if (!history.empty()) std::cout << "model history of " << f << ": " << history << "\n";
    }
    run_workbench(std::move(loops), a->w);
    exit_code = kOk;
  });
}

}  // namespace valvediag::cli
