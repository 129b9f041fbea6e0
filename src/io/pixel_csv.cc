#include "io/pixel_csv.h"

#include "util/csv.h"
#include "util/plausible.h"

namespace carmba {

namespace {

// Which optional columns the file has; the covariance's all three or none.
struct PixelCsvLayout {
  bool key = false, covariance = false, sigma = false;
};

StatusOr<PixelCsvLayout> PixelColumnsOf(const CsvTable& t, const PixelCsvColumns& c) {
  PixelCsvLayout l;
  for (const char* name : {"view", "u_px", "v_px"}) {
    auto col = t.Column(name);
    if (!col.ok()) return col.status();
  }
  l.key = t.Column(c.key).ok();
  if (!l.key && c.key_required) return t.Column(c.key).status();
  l.covariance = t.Column("cov_uu").ok() || t.Column("cov_uv").ok() || t.Column("cov_vv").ok();
  if (l.covariance) {
    for (const char* name : {"cov_uu", "cov_uv", "cov_vv"}) {
      auto col = t.Column(name);
      if (!col.ok()) return col.status();
    }
  }
  l.sigma = !l.covariance && c.sigma_column && t.Column("sigma_px").ok();
  return l;
}

Status ReadRowCovariance(const CsvTable& t, int r, const PixelCsvLayout& l, PixelCsvRow* row) {
  if (l.sigma) {
    auto s = t.NumberIn(r, "sigma_px", plausible::kPixelSigmaPx);
    if (!s.ok()) return s.status();
    row->covariance_px2 = Eigen::Matrix2d::Identity() * *s * *s;
    return Status::Ok();
  }
  if (!l.covariance) return Status::Ok();
  double c[3];
  const char* names[3] = {"cov_uu", "cov_uv", "cov_vv"};
  for (int k = 0; k < 3; ++k) {
    auto x = t.Number(r, names[k]);
    if (!x.ok()) return x.status();
    c[k] = *x;
  }
  if (!(c[0] > 0) || !(c[2] > 0) || !(c[0] * c[2] - c[1] * c[1] > 0)) {
    return Status::Error(row->where +
                         ": columns cov_uu, cov_uv, cov_vv: expected a positive definite pixel "
                         "covariance (px^2), got " +
                         t.rows[r][*t.Column("cov_uu")] + ", " + t.rows[r][*t.Column("cov_uv")] +
                         ", " + t.rows[r][*t.Column("cov_vv")]);
  }
  row->covariance_px2 << c[0], c[1], c[1], c[2];
  return Status::Ok();
}

StatusOr<PixelCsvRow> ReadPixelRow(const CsvTable& t,
                                   int r,
                                   const PixelCsvColumns& c,
                                   const PixelCsvLayout& l) {
  PixelCsvRow row;
  row.where = t.path + ":" + std::to_string(t.line_numbers[r]);
  row.view = t.rows[r][*t.Column("view")];
  if (row.view.empty()) {
    return Status::Error(row.where + ": column 'view': expected a view id, got an empty field");
  }
  row.key = c.absent_key;
  if (l.key) {
    row.key = t.rows[r][*t.Column(c.key)];
    if (c.integer_key) {
      auto id = t.Integer(r, c.key);
      if (!id.ok()) return id.status();
      row.id = *id;
    }
  }
  auto u = t.NumberIn(r, "u_px", plausible::kPixelCoordinatePx);
  if (!u.ok()) return u.status();
  auto v = t.NumberIn(r, "v_px", plausible::kPixelCoordinatePx);
  if (!v.ok()) return v.status();
  row.uv_px = Eigen::Vector2d(*u, *v);
  CARMBA_RETURN_IF_ERROR(ReadRowCovariance(t, r, l, &row));
  return row;
}

}  // namespace

StatusOr<std::vector<PixelCsvRow>> ReadPixelCsv(const std::string& path,
                                                const PixelCsvColumns& columns) {
  auto t = ReadCsv(path);
  if (!t.ok()) return t.status();
  auto layout = PixelColumnsOf(*t, columns);
  if (!layout.ok()) return layout.status();
  std::vector<PixelCsvRow> rows;
  for (size_t r = 0; r < t->rows.size(); ++r) {
    auto row = ReadPixelRow(*t, static_cast<int>(r), columns, *layout);
    if (!row.ok()) return row.status();
    rows.push_back(std::move(*row));
  }
  return rows;
}

}  // namespace carmba
