//! Observation weights: seed 000's schemes and the robust estimation.
//!
//! Weights are `p = sigma0^2 / sigma^2` (seed 000 eq. 51) per coordinate.
//! - [`Scheme::Sigma`] (default): `1/sigma^2` from the measuring precision, so
//!   sigma0 a posteriori is 1 when the precision is right.
//! - [`Scheme::Parallax`] (seed 000 default): `p_x = pa_x^2`, `p_y = 1/pa_y^2`
//!   with `pa_x, pa_y` the stereo parallaxes (left minus right) of the point at
//!   that epoch; `pa_y` is bounded below by [`MIN_Y_PARALLAX_MM`] (the seed
//!   divides by it and leaves zero undefined).
//! - [`Scheme::Radial`] (seed 000 eq. 50): both coordinates weigh the radial
//!   distance from the principal point, `sqrt(xc^2 + yc^2)`.
//! - [`Scheme::Equal`] (seed 000 §7.3.4): every coordinate weighs 0.0001.
//!
//! The robust default ([`super::Robust::Snooping`]) first iterates with Cauchy
//! weights on a robust (median) scale, then tests every observation with
//! `T = v^T Q_vv^-1 v` (2 degrees of freedom) and excludes the outliers, repeating
//! until the set is stable: see `super::window`.

/// Smallest y-parallax the parallax scheme divides by, mm.
pub const MIN_Y_PARALLAX_MM: f64 = 1e-3;
/// Seed 000 equal weight.
pub const SEED_EQUAL_WEIGHT: f64 = 1e-4;
/// Seed 000 weight given to an observation whose residual exceeds the pixel size.
pub const SEED_REWEIGHT: f64 = 1e-5;

/// How the caller derives observation weights.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Scheme {
    /// `1/sigma^2` with the given photo-coordinate precision, mm.
    Sigma(f64),
    Parallax,
    Radial,
    Equal,
}

/// Weights `[p_x, p_y]` of one observation. `partner` is the same point's
/// corrected coordinates in the other image of the stereo pair (for parallax).
pub fn weights(scheme: Scheme, xy: [f64; 2], partner: Option<[f64; 2]>) -> [f64; 2] {
    match scheme {
        Scheme::Sigma(s) => {
            let p = 1.0 / (s * s);
            [p, p]
        }
        Scheme::Equal => [SEED_EQUAL_WEIGHT, SEED_EQUAL_WEIGHT],
        Scheme::Radial => {
            let r = libm::sqrt(xy[0] * xy[0] + xy[1] * xy[1]);
            [r, r]
        }
        Scheme::Parallax => match partner {
            Some(q) => {
                let pax = xy[0] - q[0];
                let pay = (xy[1] - q[1]).abs().max(MIN_Y_PARALLAX_MM);
                [pax * pax, 1.0 / (pay * pay)]
            }
            None => [SEED_EQUAL_WEIGHT, SEED_EQUAL_WEIGHT],
        },
    }
}

/// Cauchy weight factor for a standardised residual `t` (tuning constant `c`).
pub fn cauchy_factor(t: f64, c: f64) -> f64 {
    let u = t / c;
    1.0 / (1.0 + u * u)
}

/// Median of the chi-square law with 2 degrees of freedom (`2 ln 2`): the
/// robust scale of `T` statistics is `median(T) / CHI2_2_MEDIAN`.
pub const CHI2_2_MEDIAN: f64 = core::f64::consts::LN_2 * 2.0;

/// Smallest variance factor data snooping tests on (`T` over the a-priori variance):
/// 0.02 is a noise of 0.07 px at the default 0.5 px. Least-squares matching puts the
/// bulk of the tie points within a few hundredths of a pixel; on that scale an
/// observation merely held by others (a 2 cm GNSS fix, the motion model) tests as a
/// blunder, and the robust rounds once left a new epoch 34 of its 134 observations and
/// too few to solve it (a rendered drive with fixes, epochs 183 and 184).
pub const MIN_SNOOPING_SCALE: f64 = 0.02;

/// Median of `values` (reordered in place); 0 for an empty slice.
pub fn median(values: &mut [f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    let mid = values.len() / 2;
    let (_, m, _) = values.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
    *m
}

/// The same median as [`median`] (the element of rank `len / 2` in `f64::total_cmp`
/// order) of the values `value(i)` for `i < n` that are `Some`, without a copy: a radix
/// selection over the totally ordered keys of the bit patterns, one byte per pass (nine
/// passes over the values). Spares the adjustment a scratch buffer as long as its
/// observations.
pub fn median_by_rank(n: usize, value: impl Fn(usize) -> Option<f64>) -> f64 {
    // Monotone map of total_cmp order onto u64 order.
    let key = |x: f64| {
        let b = x.to_bits();
        if b >> 63 == 1 {
            !b
        } else {
            b | 1 << 63
        }
    };
    let count = (0..n).filter(|&i| value(i).is_some()).count();
    if count == 0 {
        return 0.0;
    }
    let mut rank = count / 2;
    let mut prefix = 0u64;
    for pass in 0..8u32 {
        let shift = 56 - 8 * pass;
        // Bits above this byte, already chosen.
        let high = if pass == 0 { 0 } else { !0u64 << (shift + 8) };
        let mut hist = [0usize; 256];
        for k in (0..n).filter_map(&value).map(key) {
            if k & high == prefix {
                hist[((k >> shift) & 0xff) as usize] += 1;
            }
        }
        let mut digit = 0;
        while digit < 255 && rank >= hist[digit] {
            rank -= hist[digit];
            digit += 1;
        }
        prefix |= (digit as u64) << shift;
    }
    let bits = if prefix >> 63 == 1 {
        prefix & !(1 << 63)
    } else {
        !prefix
    };
    f64::from_bits(bits)
}

#[cfg(test)]
mod tests {
    use super::{median, median_by_rank};

    /// The bisection picks exactly the element `select_nth` picks, for ties, signs,
    /// infinities and every length, with and without a filter.
    #[test]
    fn median_by_rank_equals_the_sorting_median() {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        for len in 0..200usize {
            let mut values = [0.0f64; 200];
            for v in values[..len].iter_mut() {
                *v = match next() % 10 {
                    0 => f64::INFINITY,
                    1 => 0.0,
                    2 => -((next() % 100) as f64) * 0.25,
                    3 => 1.5,
                    _ => (next() % 1_000_000) as f64 * 1e-3 + 1e-9,
                };
            }
            let mut copy = values;
            assert_eq!(
                median_by_rank(len, |i| Some(values[i])).to_bits(),
                median(&mut copy[..len]).to_bits(),
                "len {len}"
            );
            let keep = |i: usize| values[i].is_finite() && !i.is_multiple_of(3);
            let mut kept = [0.0f64; 200];
            let mut m = 0;
            for i in (0..len).filter(|&i| keep(i)) {
                kept[m] = values[i];
                m += 1;
            }
            assert_eq!(
                median_by_rank(len, |i| keep(i).then_some(values[i])).to_bits(),
                median(&mut kept[..m]).to_bits(),
                "filtered, len {len}"
            );
        }
    }
}
