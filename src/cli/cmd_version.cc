// `carmba version`: prints the version and the versions of the libraries carmba was built with.
#include <ceres/version.h>
#include <opencv2/core/version.hpp>

#include <Eigen/Core>
#include <iostream>

#include "cli/command.h"
#include "util/version.h"

namespace {
int RunVersion() {
  std::cout << "carmba " << carmba::kCarmbaVersion << " (Ceres " << CERES_VERSION_STRING
            << ", Eigen " << EIGEN_WORLD_VERSION << "." << EIGEN_MAJOR_VERSION << "."
            << EIGEN_MINOR_VERSION << ", OpenCV " << CV_VERSION << ")\n";
  return 0;
}
}  // namespace

CARMBA_REGISTER_COMMAND(version, "Print carmba's version and its libraries' versions.", RunVersion);
