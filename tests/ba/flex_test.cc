// C-arm flex in the engine (issue 14): the smooth intrinsics model's residual against its
// autodiff twin, its solve and covariance, the models' per-view intrinsics and object poses
// against the truth of a flexing synthetic C-arm, model selection, and bad problems.
#include <gtest/gtest.h>

#include <ceres/ceres.h>
#include <ceres/gradient_checker.h>

#include <cmath>
#include <cstdio>
#include <random>

#include "ba/bundle_adjuster.h"
#include "ba/flex_models.h"
#include "ba/quantities.h"
#include "ba/smooth_intrinsics.h"
#include "ba/synthetic_flex.h"
#include "ba/view_intrinsics.h"
#include "camera/camera.h"
#include "geometry/rotation.h"

namespace carmba {
namespace ba {
namespace {

TEST(FlexExplore, Print) {
  for (int rigid = 0; rigid < 2; ++rigid) {
    SyntheticFlexSpec spec;
    if (rigid) spec.flex = CarmFlex();
    const SyntheticFlex sf = MakeSyntheticFlex(spec, 3);
    BaOptions o;
    for (auto m : {IntrinsicsModel::kShared, IntrinsicsModel::kPerGroup, IntrinsicsModel::kSmooth}) {
      BaProblem p = sf.problem;
      ASSERT_TRUE(ApplyIntrinsicsModel(m, SmoothBasis(), &p).ok());
      auto r = SolveBundleAdjustment(p, o);
      ASSERT_TRUE(r.ok()) << r.status().message();
      printf("rigid %d model %s chi2 %.1f dof %d\n", rigid, IntrinsicsModelName(m), r->chi2, r->dof);
      for (size_t v = 0; v < p.views.size(); ++v) {
        if (p.views[v].kind != ViewKind::kObject && v % 6) continue;
        const auto vi = IntrinsicsOfView(p, *r, static_cast<int>(v));
        printf("  %-16s", p.views[v].id.c_str());
        for (int i = 0; i < 4; ++i) {
          const double s = std::sqrt(vi.covariance(i, i));
          printf(" %s %+.2f/%.2f", kIntrinsicNames[i], vi.value[i] - sf.true_intrinsics[v][i], s);
        }
        if (p.views[v].kind == ViewKind::kObject) {
          const auto C = r->Covariance({r->layout->view_block(static_cast<int>(v))});
          const double* x = r->block(r->layout->view_block(static_cast<int>(v)));
          printf(" | pose");
          for (int i = 0; i < 6; ++i) printf(" %+.2f", (x[i] - sf.true_poses[v][i]) / std::sqrt(C(i, i)));
        }
        printf("\n");
      }
    }
    auto sel = SelectIntrinsicsModel(sf.problem, SmoothBasis(), o,
                                     {IntrinsicsModel::kShared, IntrinsicsModel::kPerGroup, IntrinsicsModel::kSmooth});
    ASSERT_TRUE(sel.ok()) << sel.status().message();
    for (const auto& sc : sel->scores) {
      printf("%s ok %d %s k %d chi2 %.1f aic %.1f bic %.1f rms %.4f d2 %.2f\n", IntrinsicsModelName(sc.model), sc.ok,
             sc.error.c_str(), sc.num_free, sc.chi2, sc.aic, sc.bic, sc.held_out_rms_px, sc.held_out_d2_mean);
    }
    printf("-> %s: %s\n", IntrinsicsModelName(sel->recommended), sel->why.c_str());
  }
}

}  // namespace
}  // namespace ba
}  // namespace carmba
