#!/usr/bin/env bash
# Installs carmba's build and run dependencies from Debian 12 packages.
# Idempotent: packages already installed are skipped; nothing is downloaded if all are present.
# Run as root (or with sudo available) on a bare Debian 12 machine.
set -euo pipefail

PKGS=(
  build-essential cmake ninja-build pkg-config
  libceres-dev libeigen3-dev libgoogle-glog-dev libgflags-dev
  libopencv-dev
  libmrcal-dev mrcal python3-mrcal
  libgdcm-dev libgdcm-tools
  libyaml-cpp-dev nlohmann-json3-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  python3-numpy python3-matplotlib python3-opencv python3-pydicom
  # the Python module (src/python/, pybind11) and its pytest tests (tests/python/)
  pybind11-dev python3-dev python3-pytest
  libgdcm3.0 zlib1g-dev
  # the real consumer of the exported geometry: the DRR end-to-end test renders with
  # `plastimatch drr` (tests/cli/drr_export_e2e_test.cc; skipped, saying so, without it)
  plastimatch
)
if [[ "${CARMBA_WITH_DOCS_DATA:-1}" == 1 ]]; then
  PKGS+=(opencv-doc)
fi
# The real skull CT the CT-fiducial tests embed beads into (GPL; tests skip without it).
if [[ "${CARMBA_WITH_SKULL_CT:-1}" == 1 ]]; then
  PKGS+=(invesalius-examples)
fi
# clang with its runtimes (libFuzzer, ASan, UBSan) and lld for the fuzz harnesses (tests/fuzz/),
# which scripts/test.sh builds and runs (CARMBA_WITH_FUZZ=0 leaves them out, with CARMBA_FUZZ=0).
# scripts/build.sh also compiles carmba with clang and links it with lld when they are installed
# (faster than GCC and ld.bfd, the same results; GCC and ld.bfd otherwise).
if [[ "${CARMBA_WITH_FUZZ:-1}" == 1 ]]; then
  PKGS+=(clang libclang-rt-14-dev lld)
fi
# Headless Chromium for the tests that render every report.html in a browser
# (tests/cli/report_browser.h); they skip without it. CARMBA_WITH_BROWSER=0 leaves it out.
if [[ "${CARMBA_WITH_BROWSER:-1}" == 1 ]]; then
  PKGS+=(chromium)
fi
# A single-node Slurm cluster (slurmctld, slurmd, munge; daemons started by the test itself, not
# by systemd) for the test of scripts/slurm_study.sh on real Slurm
# (tests/cli/study_slurm_cluster_test.sh); it skips without them. CARMBA_WITH_SLURM=0 leaves it out.
if [[ "${CARMBA_WITH_SLURM:-1}" == 1 ]]; then
  PKGS+=(slurmctld slurmd slurm-client munge)
fi

missing=()
for p in "${PKGS[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [[ ${#missing[@]} -eq 0 ]]; then
  echo "setup: all ${#PKGS[@]} packages already installed"
  exit 0
fi

SUDO=""
if [[ $(id -u) -ne 0 ]]; then SUDO="sudo"; fi
echo "setup: installing ${#missing[@]} packages: ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
echo "setup: done"
