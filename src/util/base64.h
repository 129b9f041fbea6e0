// Base64 (RFC 4648, with padding) of bytes: PNGs embedded in report.html as data: URLs.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace carmba {

std::string Base64(const std::vector<uint8_t>& bytes);

}  // namespace carmba
