// Small statistics helpers.
#pragma once

namespace carmba {

// Regularised upper incomplete gamma function Q(a, x) = Gamma(a, x) / Gamma(a), a > 0, x >= 0
// (series for x < a + 1, Lentz continued fraction otherwise; relative accuracy ~1e-14).
double RegularizedGammaQ(double a, double x);

// P(X > chi2) for X ~ chi-square with `dof` degrees of freedom (1 when dof <= 0).
double ChiSquareUpperTail(double chi2, int dof);

}  // namespace carmba
