//! Pixel coordinates with a fixed number of decimals, written through integers:
//! `{:.4}` formats each float exactly, about 2 000 instructions a coordinate, and the
//! exports write two per image measurement. On the hand-held walk's 100 000
//! observations that was 1 % of a run's instructions for COLMAP's `images.txt` and
//! 0.15 % for E-FOTO's `measurements.txt` (three decimals, shorter to format).

/// `self.0` with `DIGITS` decimals: the same digits as `{:.DIGITS$}` wherever the product
/// by `10^DIGITS` is exact, as it is for every coordinate measured in single precision
/// (24 bits of mantissa and at most 14 of the power of ten fit in a double): exact ties
/// round to even in both.
pub struct Fixed<const DIGITS: u32>(pub f64);

impl<const DIGITS: u32> std::fmt::Display for Fixed<DIGITS> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let x = self.0;
        let digits = DIGITS as usize;
        // Far beyond any image, or not a number: the exact formatting.
        if x.is_nan() || x.abs() >= 1e9 {
            return write!(f, "{x:.digits$}");
        }
        let scale = 10u64.pow(DIGITS);
        let units = (x * scale as f64).round_ties_even() as i64;
        // The sign of the float, not of the rounded units: `{:.4}` writes -0.0000 for
        // a negative coordinate that rounds to zero.
        let sign = if x.is_sign_negative() { "-" } else { "" };
        let u = units.unsigned_abs();
        write!(f, "{sign}{}.{:0digits$}", u / scale, u % scale)
    }
}

#[cfg(test)]
mod tests {
    use super::super::colmap::PIXEL_ORIGIN;
    use super::*;

    proptest::proptest! {
        #[test]
        fn pixel_coordinates_have_the_digits_of_exact_formatting(x in -1e5f32..1e5, k in 0u32..32) {
            // Single-precision measurements, plus COLMAP's half-pixel origin, and the
            // 32nd-pixel fractions where ties of the fourth and fifth decimal are exact.
            for x in [f64::from(x), f64::from(x) + PIXEL_ORIGIN, f64::from(x.trunc()) + f64::from(k) / 32.0] {
                proptest::prop_assert_eq!(Fixed::<4>(x).to_string(), format!("{x:.4}"));
                proptest::prop_assert_eq!(Fixed::<3>(x).to_string(), format!("{x:.3}"));
            }
        }
    }

    #[test]
    fn pixel_coordinates_beyond_the_integers_are_formatted_exactly() {
        for x in [1e12, -3.5e15, f64::INFINITY, f64::NAN, -0.00001, -0.0] {
            assert_eq!(Fixed::<4>(x).to_string(), format!("{x:.4}"));
            assert_eq!(Fixed::<3>(x).to_string(), format!("{x:.3}"));
        }
        assert_eq!(Fixed::<4>(640.25).to_string(), "640.2500");
        assert_eq!(Fixed::<4>(0.000049).to_string(), "0.0000");
        assert_eq!(Fixed::<3>(0.0625).to_string(), "0.062");
        assert_eq!(Fixed::<3>(-1.0625).to_string(), "-1.062");
    }
}
