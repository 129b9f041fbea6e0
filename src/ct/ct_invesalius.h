// Reading the volume of an InVesalius 3 project file (.inv3), for real anatomical backgrounds in
// tests (Debian's invesalius-examples ships a real head CT, Cranium.inv3, GPL).
//
// Format (InVesalius 3, format_version 1): a gzip'ed tar holding one directory with main.plist
// (an XML property list) whose "matrix" dict names the volume file (filename, dtype "int16",
// shape [slices, rows, columns]) and whose "spacing" is [x, y, z] in mm. The volume file is raw
// little-endian int16 HU in (z, y, x) order, x fastest; its rows are stored bottom-up (row 0 of
// the file is the last image row).
//
// The volume returned is in carmba's convention (ct_volume.h) with identity axes, row j of the
// image = row rows-1-j of the file, slice thickness = the z spacing, centred at `centre_mm`. The
// project carries no patient position, so the patient frame is arbitrary.
#pragma once

#include <Eigen/Core>
#include <string>

#include "ct/ct_volume.h"
#include "util/status.h"

namespace carmba {

// Errors name the file: not a gzip'ed tar, no main.plist or no volume file in it, a dtype other
// than int16, a shape or spacing missing or not positive, a volume file of the wrong size.
StatusOr<CtVolume> ReadInvesaliusVolume(const std::string& path,
                                        const Eigen::Vector3d& centre_mm = Eigen::Vector3d::Zero());

// The debian path of the real skull CT (package invesalius-examples).
inline const char* kInvesaliusCraniumPath =
    "/usr/share/doc/invesalius-examples/examples/Cranium.inv3";

}  // namespace carmba
