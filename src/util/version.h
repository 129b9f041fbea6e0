// carmba's version: `carmba version` prints it and study fingerprints (study/study_inputs.h)
// include it. Keep it equal to project(carmba VERSION ...) in CMakeLists.txt.
#pragma once

namespace carmba {

inline constexpr char kCarmbaVersion[] = "0.1.0";

}  // namespace carmba
