//! Dense Cholesky factorisation in place, for the reduced camera system.
//!
//! The matrix is a row-major `n x n` slice; only the lower triangle is read
//! and the factor `L` overwrites it. A pivot that falls below `rel_tol` times
//! its original diagonal element (or is not finite) means the system is
//! singular: a datum defect, points on a line, or a camera seeing nothing.

/// The factorisation found a non-positive or vanishing pivot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NotPositiveDefinite {
    /// Row of the failing pivot.
    pub row: usize,
}

/// Default relative pivot tolerance.
pub const PIVOT_REL_TOL: f64 = 1e-12;

/// Factors `a = L L^T` in place (lower triangle; the strict upper triangle is zeroed).
pub fn factor(a: &mut [f64], n: usize, rel_tol: f64) -> Result<(), NotPositiveDefinite> {
    if a.len() < n * n {
        return Err(NotPositiveDefinite { row: 0 });
    }
    for j in 0..n {
        let orig = a[j * n + j];
        let mut d = orig;
        for k in 0..j {
            d -= a[j * n + k] * a[j * n + k];
        }
        if !(d > rel_tol * orig.abs()) || !(d > 0.0) || !d.is_finite() {
            return Err(NotPositiveDefinite { row: j });
        }
        let l = libm::sqrt(d);
        a[j * n + j] = l;
        for i in j + 1..n {
            let mut s = a[i * n + j];
            for k in 0..j {
                s -= a[i * n + k] * a[j * n + k];
            }
            a[i * n + j] = s / l;
        }
        for i in j + 1..n {
            a[j * n + i] = 0.0;
        }
    }
    Ok(())
}

/// Solves `L L^T x = b` in place in `b`, with `l` from [`factor`].
pub fn solve(l: &[f64], n: usize, b: &mut [f64]) {
    for i in 0..n {
        let mut s = b[i];
        for k in 0..i {
            s -= l[i * n + k] * b[k];
        }
        b[i] = s / l[i * n + i];
    }
    for i in (0..n).rev() {
        let mut s = b[i];
        for k in i + 1..n {
            s -= l[k * n + i] * b[k];
        }
        b[i] = s / l[i * n + i];
    }
}

/// Replaces the factor `L` (from [`factor`]) by the full symmetric inverse
/// `(L L^T)^-1`, in place: first `L^-1` in the lower triangle, then
/// `L^-T L^-1` lower triangle, mirrored.
pub fn invert_in_place(a: &mut [f64], n: usize) {
    // L^-1, lower triangular, computed column by column in place.
    for j in 0..n {
        a[j * n + j] = 1.0 / a[j * n + j];
        for i in j + 1..n {
            let mut s = 0.0;
            for k in j..i {
                s -= a[i * n + k] * a[k * n + j];
            }
            a[i * n + j] = s / a[i * n + i];
        }
    }
    // (L^-1)^T L^-1: entry (i, j), i >= j, = sum_{k >= i} Linv[k][i] Linv[k][j].
    for i in 0..n {
        for j in 0..=i {
            let mut s = 0.0;
            for k in i..n {
                s += a[k * n + i] * a[k * n + j];
            }
            // Row i, column j with j <= i: Linv entries (k, i) for k >= i are not
            // yet overwritten because we write only into row i, column j <= i,
            // and later rows read (k >= i+1, *) only.
            a[i * n + j] = s;
        }
    }
    for i in 0..n {
        for j in i + 1..n {
            a[i * n + j] = a[j * n + i];
        }
    }
}
