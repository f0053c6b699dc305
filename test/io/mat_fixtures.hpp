// MAT-files written by the tests themselves through libmatio: loop structs, struct arrays, cells
// and matrices in v5, v7 (compressed) and v7.3, with any numeric class. Shared by test_io and
// test_cli.
#pragma once

#include <matio.h>

#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace valvediag::test {

// A numeric rows x cols variable (column-major values) of class `cls`.
inline matvar_t* mat_numeric(const std::vector<double>& v, std::size_t rows, std::size_t cols,
                             matio_classes cls = MAT_C_DOUBLE, const char* name = nullptr) {
  std::size_t dims[2] = {rows, cols};
  auto make = [&](auto tag, matio_types type) {
    using T = decltype(tag);
    std::vector<T> buf(v.size());
    for (std::size_t i = 0; i < v.size(); ++i) buf[i] = static_cast<T>(v[i]);
    return Mat_VarCreate(name, cls, type, 2, dims, buf.data(), 0);  // copies the data
  };
  switch (cls) {
    case MAT_C_SINGLE:
      return make(float{}, MAT_T_SINGLE);
    case MAT_C_INT16:
      return make(std::int16_t{}, MAT_T_INT16);
    case MAT_C_UINT8:
      return make(std::uint8_t{}, MAT_T_UINT8);
    case MAT_C_INT32:
      return make(std::int32_t{}, MAT_T_INT32);
    default:
      return make(double{}, MAT_T_DOUBLE);
  }
}

inline matvar_t* mat_column(const std::vector<double>& v, matio_classes cls = MAT_C_DOUBLE) {
  return mat_numeric(v, v.size(), 1, cls);
}
inline matvar_t* mat_row(const std::vector<double>& v, matio_classes cls = MAT_C_DOUBLE) {
  return mat_numeric(v, 1, v.size(), cls);
}
inline matvar_t* mat_scalar(double x) {
  return mat_numeric({x}, 1, 1);
}

using MatFields = std::vector<std::pair<std::string, matvar_t*>>;

// A 1 x n struct array; every element has the fields of the first one (a null value or a missing
// field stays empty).
inline matvar_t* mat_struct(const char* name, const std::vector<MatFields>& elements) {
  std::vector<const char*> names;
  for (const auto& f : elements.at(0)) names.push_back(f.first.c_str());
  names.push_back(nullptr);
  const std::size_t dims[2] = {1, elements.size()};
  matvar_t* s = Mat_VarCreateStruct2(name, 2, dims, names.data());
  for (std::size_t k = 0; k < elements.size(); ++k)
    for (const auto& [field, value] : elements[k])
      if (value != nullptr) Mat_VarSetStructFieldByName(s, field.c_str(), k, value);
  return s;
}

inline matvar_t* mat_cell(const char* name, const std::vector<matvar_t*>& cells) {
  std::size_t dims[2] = {1, cells.size()};
  matvar_t* c = Mat_VarCreate(name, MAT_C_CELL, MAT_T_CELL, 2, dims, nullptr, 0);
  for (std::size_t k = 0; k < cells.size(); ++k) Mat_VarSetCell(c, static_cast<int>(k), cells[k]);
  return c;
}

// Writes the top-level variables (each needs a name) and frees them.
inline void mat_write(const std::string& path, const std::vector<matvar_t*>& vars,
                      mat_ft version = MAT_FT_MAT5,
                      matio_compression compression = MAT_COMPRESSION_NONE) {
  mat_t* m = Mat_CreateVer(path.c_str(), nullptr, version);
  if (m == nullptr) throw std::runtime_error("cannot create " + path);
  bool ok = true;
  for (matvar_t* v : vars) {
    ok = ok && Mat_VarWrite(m, v, compression) == 0;
    Mat_VarFree(v);
  }
  Mat_Close(m);
  if (!ok) throw std::runtime_error("cannot write " + path);
}

// A small loop with a valve that sticks 2 %: OP a slow sine plus a faster one, PV a first-order
// response of the valve position (the same signal as test_cli's loop_csv).
struct LoopSignals {
  std::vector<double> op, pv, sp;
};
inline LoopSignals sticky_loop(std::size_t n, double offset = 0.0) {
  LoopSignals s;
  double x = 50, y = 0;
  for (std::size_t k = 0; k < n; ++k) {
    const double u = 50 + offset + 10 * std::sin(0.02 * static_cast<double>(k)) +
                     3 * std::sin(0.13 * static_cast<double>(k));
    if (std::abs(u - x) > 2.0) x = u;
    y = 0.9 * y + 0.1 * (x - 50);
    s.op.push_back(u);
    s.pv.push_back(y);
    s.sp.push_back(k < n / 2 ? 1.0 : 2.0);
  }
  return s;
}

// `runs`: a 1 x 2 struct array of loops with OP (column), PV (row), SP and Ts = 0.5 s; run 2 is
// offset by 1 % in OP.
inline void write_runs_file(const std::string& path, mat_ft version = MAT_FT_MAT5,
                            matio_compression compression = MAT_COMPRESSION_NONE,
                            std::size_t n = 400) {
  std::vector<MatFields> runs;
  for (int k = 0; k < 2; ++k) {
    const LoopSignals s = sticky_loop(n, k);
    runs.push_back({{"OP", mat_column(s.op)},
                    {"PV", mat_row(s.pv)},
                    {"SP", mat_column(s.sp)},
                    {"Ts", mat_scalar(0.5)}});
  }
  mat_write(path, {mat_struct("runs", runs)}, version, compression);
}

}  // namespace valvediag::test
