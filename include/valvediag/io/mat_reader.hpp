// Reads control loops from MATLAB MAT-files (v5, v7 compressed, v7.3 HDF5) through libmatio.
//
// Two layouts hold loops:
// - a loop struct: a struct with an OP field (any case) and usually Ts (sample period, s), PV,
//   SP, MV; found anywhere in the file by walking structs, struct arrays and cell arrays, as in
//   the International Stiction Database (`benchmark.chemicals.loop23`);
// - a plain matrix (samples in rows, signals in columns), e.g. the Tennessee Eastman runs: its
//   columns are named by 1-based numbers (op "51", pv "21") and the sample period is given.
//
// Loops are named by the path a MATLAB user would type: `benchmark.chemicals.loop23`,
// `runs(2)` for an element of a struct array, `data{3}` for a cell, `m1d14` for a matrix. A
// path may leave out leading parts when the rest is unique (`chemicals.loop23`, `loop23` if only
// one group has it). Variables saved at the top level (OP, PV, Ts in the file itself) form the
// loop `.`.
//
// Every problem throws DataError naming the file, the loop path and what is wrong (a missing
// field lists the fields present; a malformed or truncated file says so). Nothing is printed:
// libmatio's own messages are caught and put into the error.
#pragma once

#include <cstddef>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "valvediag/io/csv_reader.hpp"  // kDefaultMaxRows
#include "valvediag/io/loop_data.hpp"

namespace valvediag {

// One loop (or matrix) found in a MAT-file.
struct MatLoopInfo {
  std::string path;          // what to pass as `loop` to read_mat_loop
  bool matrix = false;       // a plain numeric matrix: columns must be named
  std::size_t samples = 0;   // length of OP (rows of a matrix)
  std::size_t columns = 0;   // matrix only
  std::optional<double> ts;  // the Ts field when it is a positive finite scalar
  bool has_op = false, has_pv = false, has_sp = false, has_mv = false;
  std::vector<std::string> fields;  // loop struct: all its field names, in file order
  // Loop struct: its numeric scalar fields other than Ts (which is `ts`): a database's labels
  // such as `oscillation`.
  std::vector<std::pair<std::string, double>> scalars;
};

struct MatFileInfo {
  std::string format;  // "MATLAB v5", "MATLAB v7.3 (HDF5)"
  std::vector<MatLoopInfo> loops;
};

// Lists the loops and matrices of `path` in file order.
MatFileInfo list_mat_loops(const std::string& path);

struct MatOptions {
  // Field of a loop struct (case-insensitive name) or column of a matrix (1-based number). sp and
  // mv: empty means "the field named sp / mv if there is one" (none for a matrix); "none" never
  // reads it.
  std::string op = "op";
  std::string pv = "pv";
  std::string sp;
  std::string mv;
  // Matrix only: 1-based time column (s); empty, "t" or "none": rows are sample_period apart.
  std::string t;
  // Sample period, s: required for a matrix without a time column and for a loop without Ts;
  // otherwise it must agree with Ts (within 1 %).
  std::optional<double> sample_period;
  // When false a loop without PV is read with pv empty (for import of OP-only records).
  bool require_pv = true;
  // More samples than this are refused (DataError), as CsvOptions::max_rows.
  std::size_t max_rows = kDefaultMaxRows;
};

// Reads loop `loop` (a path as listed; empty: the file's only loop) of `path`. t starts at 0.
// LoopData::source is "FILE:PATH". Notes (fields used, Ts) go to `notes` when given.
LoopData read_mat_loop(const std::string& path, const std::string& loop,
                       const MatOptions& options = {}, std::vector<std::string>* notes = nullptr);

// True when `path` ends in ".mat" (any case): the data options read such files with this reader.
bool is_mat_file(const std::string& path);

}  // namespace valvediag
