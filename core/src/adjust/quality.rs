//! Quality figures: the a-posteriori variance factor and the global
//! chi-square test.
//!
//! With weights `p_i = sigma0^2 / sigma_i^2` and the a-priori `sigma0 = 1`,
//! `vTPv` (observations and constraints) follows a chi-square law with
//! `r = n + n_x - u` degrees of freedom (seed 000 eq. 46). The global test
//! is two-sided at 95 % (seed 002, Table 16): it passes when
//! `chi2(0.025, r) <= vTPv <= chi2(0.975, r)`.

/// Regularised lower incomplete gamma function `P(a, x)` (series for
/// `x < a + 1`, continued fraction otherwise).
pub fn gamma_p(a: f64, x: f64) -> f64 {
    if !(x > 0.0) || !(a > 0.0) {
        return 0.0;
    }
    let gln = libm::lgamma(a);
    if x < a + 1.0 {
        let mut ap = a;
        let mut sum = 1.0 / a;
        let mut del = sum;
        for _ in 0..1000 {
            ap += 1.0;
            del *= x / ap;
            sum += del;
            if del.abs() < sum.abs() * 1e-16 {
                break;
            }
        }
        (sum * libm::exp(-x + a * libm::log(x) - gln)).clamp(0.0, 1.0)
    } else {
        // Lentz's continued fraction for Q(a, x).
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..1000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let del = d * c;
            h *= del;
            if (del - 1.0).abs() < 1e-16 {
                break;
            }
        }
        (1.0 - libm::exp(-x + a * libm::log(x) - gln) * h).clamp(0.0, 1.0)
    }
}

/// Cumulative distribution of chi-square with `dof` degrees of freedom.
pub fn chi2_cdf(x: f64, dof: f64) -> f64 {
    gamma_p(0.5 * dof, 0.5 * x)
}

/// Quantile `q` of chi-square with `dof` degrees of freedom (bisection on the cdf).
pub fn chi2_quantile(q: f64, dof: f64) -> f64 {
    if !(dof > 0.0) || !(q > 0.0 && q < 1.0) {
        return f64::NAN;
    }
    let mut lo = 0.0;
    let mut hi = dof + 10.0 * libm::sqrt(2.0 * dof) + 20.0;
    while chi2_cdf(hi, dof) < q {
        hi *= 2.0;
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if chi2_cdf(mid, dof) < q {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo <= 1e-12 * hi {
            break;
        }
    }
    0.5 * (lo + hi)
}

/// The global test of the variance factor.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ChiSquareTest {
    /// `vTPv` with the a-priori variance factor 1.
    pub statistic: f64,
    /// Degrees of freedom (redundancy).
    pub dof: usize,
    /// Lower and upper bounds at 95 % (two-sided).
    pub lower: f64,
    pub upper: f64,
    pub passed: bool,
}

impl ChiSquareTest {
    pub fn new(statistic: f64, dof: usize) -> Self {
        if dof == 0 {
            return ChiSquareTest {
                statistic,
                dof,
                lower: 0.0,
                upper: 0.0,
                passed: false,
            };
        }
        let lower = chi2_quantile(0.025, dof as f64);
        let upper = chi2_quantile(0.975, dof as f64);
        ChiSquareTest {
            statistic,
            dof,
            lower,
            upper,
            passed: statistic >= lower && statistic <= upper,
        }
    }
}
