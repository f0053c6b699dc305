#include "valvediag/report/model_history.hpp"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <stdexcept>

#include "valvediag/io/atomic_file.hpp"
#include "valvediag/report/json_number.hpp"

namespace valvediag {

std::string history_path_for(const std::string& data_path) {
  return data_path + ".history.json";
}

std::string history_state_dir(std::string& why) {
  namespace fs = std::filesystem;
  const char* xdg = std::getenv("XDG_STATE_HOME");
  if (xdg && *xdg && fs::path(xdg).is_absolute()) return (fs::path(xdg) / "valvediag").string();
  const char* home = std::getenv("HOME");
  if (home && *home && fs::path(home).is_absolute())
    return (fs::path(home) / ".local" / "state" / "valvediag").string();
  why =
      "no state directory for the model history: neither XDG_STATE_HOME nor HOME is set to an "
      "absolute path; set one, or give --history FILE";
  return "";
}

std::uint64_t history_key(const LoopData& d, const std::string& reading) {
  std::uint64_t h = 14695981039346656037ull;  // FNV-1a, 64 bit
  auto bytes = [&h](const void* p, std::size_t n) {
    const auto* c = static_cast<const unsigned char*>(p);
    for (std::size_t i = 0; i < n; ++i) h = (h ^ c[i]) * 1099511628211ull;
  };
  for (const auto* v : {&d.t, &d.op, &d.pv, &d.sp, &d.mv}) {
    const std::uint64_t n = v->size();  // lengths too: columns cannot trade values
    bytes(&n, sizeof n);
    bytes(v->data(), v->size() * sizeof(double));
  }
  bytes(reading.data(), reading.size());
  return h;
}

std::string history_file_in(const std::string& state_dir, std::uint64_t key) {
  char name[24];
  std::snprintf(name, sizeof name, "%016llx.json", static_cast<unsigned long long>(key));
  return (std::filesystem::path(state_dir) / "history" / name).string();
}

namespace {

double num_of(const nlohmann::json& j) {
  return j.is_number() ? j.get<double>() : std::nan("");
}

HistoryEntry entry_of(const nlohmann::json& e) {
  HistoryEntry h;
  h.model = e.at("model").get<std::string>();
  h.fitness_percent = num_of(e.value("fitness_percent", nlohmann::json()));
  h.validation_fitness_percent = num_of(e.value("validation_fitness_percent", nlohmann::json()));
  for (const auto& p : e.value("parameters", nlohmann::json::array()))
    h.parameters.push_back(
        {p.at("name").get<std::string>(), p.at("value").get<double>(), p.value("unit", "")});
  h.na = e.value("na", 0);
  h.nb = e.value("nb", 0);
  h.nk = e.value("nk", 0);
  h.command = e.value("command", "");
  h.time = e.value("time", "");
  return h;
}

nlohmann::json json_of(const HistoryEntry& h) {
  nlohmann::json p = nlohmann::json::array();
  for (const auto& v : h.parameters)
    p.push_back({{"name", v.name}, {"value", v.value}, {"unit", v.unit}});
  return {{"model", h.model},
          {"fitness_percent", json_number(h.fitness_percent)},
          {"validation_fitness_percent", json_number(h.validation_fitness_percent)},
          {"parameters", p},
          {"na", h.na},
          {"nb", h.nb},
          {"nk", h.nk},
          {"command", h.command},
          {"time", h.time}};
}

}  // namespace

std::string history_entry_to_json(const HistoryEntry& h) {
  return json_of(h).dump();
}

HistoryEntry history_entry_from_json(const std::string& text, const std::string& where) {
  try {
    return entry_of(nlohmann::json::parse(text));
  } catch (const nlohmann::json::exception& e) {
    throw std::runtime_error(where + ": not a valvediag model history entry (" +
                             std::string(e.what()) + ")");
  }
}

std::vector<HistoryEntry> load_history(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec))
    throw std::runtime_error("cannot write the model history " + path +
                             ": a folder has its name; move it away");
  std::ifstream f(path);
  if (!f) return {};
  std::vector<HistoryEntry> out;
  try {
    const auto j = nlohmann::json::parse(f);
    for (const auto& e : j.at("entries")) out.push_back(entry_of(e));
  } catch (const nlohmann::json::exception& e) {
    throw std::runtime_error(path + ": not a valvediag model history (" + std::string(e.what()) +
                             "); move it away to start a new history");
  }
  return out;
}

std::size_t append_history(const std::string& path, const std::vector<HistoryEntry>& entries) {
  auto all = load_history(path);
  all.insert(all.end(), entries.begin(), entries.end());
  nlohmann::json j;
  j["format"] = "valvediag model history 1";
  j["entries"] = nlohmann::json::array();
  for (const auto& h : all) j["entries"].push_back(json_of(h));
  const auto dir = std::filesystem::path(path).parent_path();
  if (!dir.empty() && !std::filesystem::is_directory(dir)) {
    std::error_code ec;
    std::filesystem::create_directories(dir, ec);
    if (ec)
      throw std::runtime_error("cannot write the model history " + path + ": cannot create " +
                               dir.string() + " (" + ec.message() + ")");
    // The history says which data the user looked at: theirs alone.
    std::filesystem::permissions(dir, std::filesystem::perms::owner_all, ec);
  }
  write_file_atomically(path, j.dump(2) + "\n");
  return all.size();
}

bool try_append_history(const std::string& path, const std::vector<HistoryEntry>& entries,
                        std::string& why, std::size_t* total) {
  try {
    const std::size_t n = append_history(path, entries);
    if (total) *total = n;
    return true;
  } catch (const std::exception& e) {
    why = e.what();
    return false;
  }
}

HistoryEntry history_entry(const ModelFit& fit, const std::string& command) {
  HistoryEntry h;
  h.model = to_string(fit.spec);
  h.fitness_percent = fit.fitness_percent;
  h.validation_fitness_percent = fit.validation_fitness_percent;
  for (const auto& e : fit.effects)
    for (const auto& p : e.parameters)
      h.parameters.push_back({e.name + "." + p.name, p.value, p.unit});
  h.na = fit.structure.na;
  h.nb = fit.structure.nb;
  h.nk = fit.structure.nk;
  h.command = command;
  h.time = utc_timestamp();
  return h;
}

}  // namespace valvediag
