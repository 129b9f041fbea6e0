// Numbers in result.json and report.md: one way to write them for every front end.
//   JsonNum: a finite double, or null (JSON has no NaN / inf);
//   JsonVec / JsonRows: vectors and matrices (row by row) of JsonNum;
//   Fmt: one double through a printf format ("%.3f").
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <string>

namespace carmba {

inline nlohmann::json JsonNum(double x) {
  return std::isfinite(x) ? nlohmann::json(x) : nlohmann::json();
}

inline nlohmann::json JsonVec(const Eigen::VectorXd& v) {
  nlohmann::json j = nlohmann::json::array();
  for (Eigen::Index i = 0; i < v.size(); ++i) j.push_back(JsonNum(v[i]));
  return j;
}

inline nlohmann::json JsonRows(const Eigen::MatrixXd& m) {
  nlohmann::json j = nlohmann::json::array();
  for (Eigen::Index r = 0; r < m.rows(); ++r) j.push_back(JsonVec(m.row(r).transpose()));
  return j;
}

inline std::string Fmt(const char* format, double x) {
  char b[64];
  std::snprintf(b, sizeof b, format, x);
  return b;
}

}  // namespace carmba
