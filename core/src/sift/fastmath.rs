//! Small deterministic f32 helpers (software polynomials: the same bits on every target).

use core::f32::consts::PI;

/// atan2 in `[0, 2 pi)` with an error below 0.01 degree (a 7th-order minimax
/// polynomial as in OpenCV's fastAtan2), about 5x cheaper than `libm::atan2f`.
#[inline]
pub fn atan2_pos(y: f32, x: f32) -> f32 {
    const P1: f32 = 0.999_787_87;
    const P3: f32 = -0.325_808_4;
    const P5: f32 = 0.155_578_65;
    const P7: f32 = -0.044_326_556;
    let ax = if x < 0.0 { -x } else { x };
    let ay = if y < 0.0 { -y } else { y };
    // Selects instead of branches, so loops over samples vectorise; the values are those
    // of the branching form.
    let steep = ax < ay;
    let (num, den) = if steep { (ax, ay) } else { (ay, ax) };
    let c = num / (den + f32::EPSILON);
    let c2 = c * c;
    let p = (((P7 * c2 + P5) * c2 + P3) * c2 + P1) * c;
    let a = if steep { PI / 2.0 - p } else { p };
    let a = if x < 0.0 { PI - a } else { a };
    let a = if y < 0.0 { 2.0 * PI - a } else { a };
    if a >= 2.0 * PI {
        a - 2.0 * PI
    } else {
        a
    }
}

/// Four-lane SSE2 twins of the helpers of this module, with the same IEEE operations in
/// the same order: lane by lane, the bits of the scalar forms.
#[cfg(target_arch = "x86_64")]
pub mod sse {
    // SAFETY (every function): register-only SSE2 operations, part of the x86_64 baseline.
    use core::arch::x86_64::*;
    use core::f32::consts::PI;

    /// floor(x) for x in the i32 range, as [`super::floor_i`].
    #[inline(always)]
    pub fn floor_epi32(x: __m128) -> __m128i {
        unsafe {
            let i = _mm_cvttps_epi32(x);
            let back = _mm_cvtepi32_ps(i);
            // Truncation rounded a negative non-integer up: subtract one (the mask is -1).
            _mm_add_epi32(i, _mm_castps_si128(_mm_cmpgt_ps(back, x)))
        }
    }

    /// Lanes of `x` clamped into `lo..=hi`.
    #[inline(always)]
    pub fn clamp_epi32(x: __m128i, lo: i32, hi: i32) -> __m128i {
        unsafe {
            let (l, h) = (_mm_set1_epi32(lo), _mm_set1_epi32(hi));
            let below = _mm_cmplt_epi32(x, l);
            let x = _mm_or_si128(_mm_and_si128(below, l), _mm_andnot_si128(below, x));
            let above = _mm_cmpgt_epi32(x, h);
            _mm_or_si128(_mm_and_si128(above, h), _mm_andnot_si128(above, x))
        }
    }

    #[inline(always)]
    pub fn select(mask: __m128, a: __m128, b: __m128) -> __m128 {
        unsafe { _mm_or_ps(_mm_and_ps(mask, a), _mm_andnot_ps(mask, b)) }
    }

    /// [`super::atan2_pos`] four lanes at a time.
    #[inline(always)]
    pub fn atan2_pos(y: __m128, x: __m128) -> __m128 {
        unsafe {
            const P1: f32 = 0.999_787_87;
            const P3: f32 = -0.325_808_4;
            const P5: f32 = 0.155_578_65;
            const P7: f32 = -0.044_326_556;
            let zero = _mm_setzero_ps();
            let xneg = _mm_cmplt_ps(x, zero);
            let yneg = _mm_cmplt_ps(y, zero);
            let ax = select(xneg, _mm_sub_ps(zero, x), x);
            let ay = select(yneg, _mm_sub_ps(zero, y), y);
            let steep = _mm_cmplt_ps(ax, ay);
            let num = select(steep, ax, ay);
            let den = select(steep, ay, ax);
            let c = _mm_div_ps(num, _mm_add_ps(den, _mm_set1_ps(f32::EPSILON)));
            let c2 = _mm_mul_ps(c, c);
            let mut p = _mm_add_ps(_mm_mul_ps(_mm_set1_ps(P7), c2), _mm_set1_ps(P5));
            p = _mm_add_ps(_mm_mul_ps(p, c2), _mm_set1_ps(P3));
            p = _mm_add_ps(_mm_mul_ps(p, c2), _mm_set1_ps(P1));
            p = _mm_mul_ps(p, c);
            let a = select(steep, _mm_sub_ps(_mm_set1_ps(PI / 2.0), p), p);
            let a = select(xneg, _mm_sub_ps(_mm_set1_ps(PI), a), a);
            let two_pi = _mm_set1_ps(2.0 * PI);
            let a = select(yneg, _mm_sub_ps(two_pi, a), a);
            select(_mm_cmpge_ps(a, two_pi), _mm_sub_ps(a, two_pi), a)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn atan2_matches_libm() {
        for i in 0..720 {
            let t = i as f32 * PI / 360.0;
            for &r in &[0.3f32, 1.0, 250.0] {
                let (y, x) = (r * libm::sinf(t), r * libm::cosf(t));
                let mut want = libm::atan2f(y, x);
                if want < 0.0 {
                    want += 2.0 * PI;
                }
                let got = atan2_pos(y, x);
                let mut d = (got - want).abs();
                d = d.min(2.0 * PI - d);
                assert!(d < 2e-4, "angle {t}: {got} vs {want}");
                assert!((0.0..2.0 * PI).contains(&got));
            }
        }
        assert_eq!(atan2_pos(0.0, 0.0), 0.0);
    }
}

/// Floor to i32 without a libm call (inputs are far inside the i32 range; NaN gives 0).
#[inline]
pub fn floor_i(x: f32) -> i32 {
    let i = x as i32;
    if (i as f32) > x {
        i - 1
    } else {
        i
    }
}

/// Round half up to i32.
#[inline]
pub fn round_i(x: f32) -> i32 {
    floor_i(x + 0.5)
}

#[cfg(test)]
mod rounding_tests {
    use super::*;

    #[test]
    fn floor_and_round_match_libm() {
        for i in -400..400 {
            let x = i as f32 * 0.173;
            assert_eq!(floor_i(x), libm::floorf(x) as i32);
            assert_eq!(round_i(x), libm::floorf(x + 0.5) as i32);
        }
        assert_eq!(floor_i(-0.5), -1);
        assert_eq!(round_i(-0.5), 0);
        assert_eq!(floor_i(f32::NAN), 0);
    }
}
