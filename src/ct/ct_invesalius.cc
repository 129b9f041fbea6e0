#include "ct/ct_invesalius.h"

#include <zlib.h>

#include <cstdint>
#include <cstring>
#include <map>
#include <regex>
#include <sstream>
#include <vector>

namespace carmba {

namespace {

// All members of a (gzip'ed) ustar archive whose names end with one of `wanted` (basename match).
Status ReadTarMembers(const std::string& path, std::map<std::string, std::string>* members) {
  gzFile f = gzopen(path.c_str(), "rb");
  if (!f) return Status::Error(path + ": cannot open");
  char header[512];
  Status status = Status::Ok();
  while (true) {
    const int got = gzread(f, header, sizeof(header));
    if (got == 0) break;
    if (got != static_cast<int>(sizeof(header))) {
      status = Status::Error(path + ": truncated tar header (not a gzip'ed tar?)");
      break;
    }
    if (header[0] == '\0') break;  // end-of-archive block
    if (std::memcmp(header + 257, "ustar", 5) != 0) {
      status = Status::Error(path + ": not a tar archive (no ustar header)");
      break;
    }
    const std::string name(header, strnlen(header, 100));
    const std::string size_octal(header + 124, strnlen(header + 124, 12));
    char* end = nullptr;
    const unsigned long long size = std::strtoull(size_octal.c_str(), &end, 8);
    const char type = header[156];
    const size_t padded = (size + 511) / 512 * 512;
    std::string data(padded, '\0');
    if (padded > 0 && gzread(f, data.data(), static_cast<unsigned>(padded)) !=
                          static_cast<int>(padded)) {
      status = Status::Error(path + ": truncated member " + name);
      break;
    }
    if (type == '0' || type == '\0') {
      data.resize(size);
      const auto slash = name.find_last_of('/');
      (*members)[slash == std::string::npos ? name : name.substr(slash + 1)] = std::move(data);
    }
  }
  gzclose(f);
  return status;
}

// The text of <key>KEY</key> followed by one element (a <string>, <array> or <dict>) in `xml`.
std::string PlistValue(const std::string& xml, const std::string& key) {
  const std::string tag = "<key>" + key + "</key>";
  const auto at = xml.find(tag);
  if (at == std::string::npos) return "";
  const auto open = xml.find('<', at + tag.size());
  if (open == std::string::npos) return "";
  const auto name_end = xml.find_first_of(" >/", open + 1);
  const std::string name = xml.substr(open + 1, name_end - open - 1);
  const std::string close = "</" + name + ">";
  const auto stop = xml.find(close, open);
  if (stop == std::string::npos) return "";
  const auto body = xml.find('>', open) + 1;
  return xml.substr(body, stop - body);
}

std::vector<double> PlistNumbers(const std::string& array) {
  std::vector<double> out;
  static const std::regex number("<(integer|real)>\\s*([-+0-9.eE]+)\\s*</(integer|real)>");
  for (std::sregex_iterator it(array.begin(), array.end(), number), e; it != e; ++it) {
    out.push_back(std::stod((*it)[2]));
  }
  return out;
}

}  // namespace

StatusOr<CtVolume> ReadInvesaliusVolume(const std::string& path, const Eigen::Vector3d& centre_mm) {
  std::map<std::string, std::string> members;
  CARMBA_RETURN_IF_ERROR(ReadTarMembers(path, &members));
  auto plist = members.find("main.plist");
  if (plist == members.end()) return Status::Error(path + ": no main.plist in the archive");
  const std::string& xml = plist->second;
  const std::string matrix = PlistValue(xml, "matrix");
  const std::string dtype = PlistValue(matrix, "dtype");
  const std::string filename = PlistValue(matrix, "filename");
  const std::vector<double> shape = PlistNumbers(PlistValue(matrix, "shape"));
  const std::vector<double> spacing = PlistNumbers(PlistValue(xml, "spacing"));
  if (dtype != "int16") {
    return Status::Error(path + ": main.plist: matrix dtype '" + dtype + "', expected int16");
  }
  if (shape.size() != 3 || shape[0] < 1 || shape[1] < 1 || shape[2] < 1) {
    return Status::Error(path + ": main.plist: matrix shape must be 3 positive integers");
  }
  if (spacing.size() != 3 || !(spacing[0] > 0 && spacing[1] > 0 && spacing[2] > 0)) {
    return Status::Error(path + ": main.plist: spacing must be 3 positive numbers");
  }
  auto raw = members.find(filename);
  if (filename.empty() || raw == members.end()) {
    return Status::Error(path + ": volume file '" + filename + "' not in the archive");
  }
  const int slices = static_cast<int>(shape[0]), rows = static_cast<int>(shape[1]),
            columns = static_cast<int>(shape[2]);
  const size_t n = static_cast<size_t>(slices) * rows * columns;
  if (raw->second.size() != 2 * n) {
    return Status::Error(path + ": " + filename + " has " + std::to_string(raw->second.size()) +
                         " bytes, expected " + std::to_string(2 * n) + " (int16, shape " +
                         std::to_string(slices) + " x " + std::to_string(rows) + " x " +
                         std::to_string(columns) + ")");
  }
  CtVolume v;
  v.columns = columns;
  v.rows = rows;
  v.slices = slices;
  v.spacing_mm = Eigen::Vector3d(spacing[0], spacing[1], spacing[2]);
  v.slice_thickness_mm = spacing[2];
  const Eigen::Vector3d half_index(0.5 * (columns - 1), 0.5 * (rows - 1), 0.5 * (slices - 1));
  v.origin_mm = centre_mm - v.PatientFromIndexLinear() * half_index;
  v.hu.resize(n);
  const auto* bytes = reinterpret_cast<const unsigned char*>(raw->second.data());
  for (int k = 0; k < slices; ++k) {
    for (int j = 0; j < rows; ++j) {
      const size_t file_row = (static_cast<size_t>(k) * rows + (rows - 1 - j)) * columns;
      float* out = v.hu.data() + v.Index(0, j, k);
      for (int i = 0; i < columns; ++i) {
        const size_t b = 2 * (file_row + i);
        out[i] = static_cast<float>(static_cast<int16_t>(bytes[b] | (bytes[b + 1] << 8)));
      }
    }
  }
  return v;
}

}  // namespace carmba
