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
