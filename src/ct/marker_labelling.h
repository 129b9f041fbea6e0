// Labelling of detected markers against a model of the object (nominal marker positions), and
// rigid transforms between the CT and the object frame.
//
// Matching. The model's points and the found centres are compared by their pairwise distances,
// which a rigid motion preserves: a depth-first search assigns found marker i to model point j
// only if |d(i, i') - D(j, j')| <= tolerance_mm for every marker i' assigned before. Every
// complete assignment found (at most 10000) is then scored by the RMS residual of the proper
// rigid fit (rotation with det +1, Kabsch/Umeyama without scale) model <- CT; the best one wins.
// A mirror-image assignment has the same pairwise distances but cannot be fitted by a proper
// rotation, so the fit decides handedness. When the second best assignment fits about as well
// (RMS <= max(2 x best, tolerance / 4)), the model is too symmetric and the labelling is refused.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "geometry/pose.h"
#include "util/status.h"

namespace carmba {

struct ModelPoint {
  int id = 0;
  Eigen::Vector3d p_in_object = Eigen::Vector3d::Zero();  // mm
};

// Reads a model CSV: an id column ('id' or 'marker') and three coordinate columns, `columns`
// when given, else the first present of (x_mm,y_mm,z_mm), (x,y,z), (x_o,y_o,z_o),
// (x_ct,y_ct,z_ct). Lines starting with '#' are comments. Errors name file, line and column.
StatusOr<std::vector<ModelPoint>> ReadModelCsv(const std::string& path,
                                               const std::vector<std::string>& columns = {});

// The least-squares proper rigid transform target_from_source (det R = +1). Needs >= 3 points
// not all on a line; false otherwise.
bool FitRigid(const std::vector<Eigen::Vector3d>& source,
              const std::vector<Eigen::Vector3d>& target,
              Rigid3* target_from_source);

struct Labelling {
  std::vector<int> model_index;      // per found marker, its index into the model (-1: not used)
  Rigid3 object_from_ct;     // the rigid fit model <- CT
  std::vector<double> residual_mm;   // per found marker, |object_from_ct * c - model|
  double rms_mm = 0;
  double max_mm = 0;
  double second_best_rms_mm = -1;    // -1 when the assignment is unique
  int assignments = 0;               // complete assignments consistent with the distances
  int selected = 0;                  // > 0: found more candidates than model points, these used
};

// Labels `found` (CT centres, mm) with the model's points. With 3 <= found.size() <=
// model.size(), every found marker is labelled. With more candidates than model points (bone,
// teeth or stray metal among them), the subset that fits is selected (hypothesise and verify:
// the same pairwise-distance search with the roles swapped, every model point matched, each
// complete assignment verified by its rigid fit); the others get model_index -1. Errors: no
// consistent assignment within tolerance_mm (saying how many could be matched; with more
// candidates, listing them), a best fit RMS above tolerance_mm (a mirror image), an ambiguous
// (symmetric) model or selection (listing the two best assignments' candidates).
StatusOr<Labelling> LabelMarkers(const std::vector<Eigen::Vector3d>& found,
                                 const std::vector<ModelPoint>& model,
                                 double tolerance_mm);

}  // namespace carmba
