//! Deterministic procedural noise: lattice value noise and band-limited fBm.
//!
//! Every texture is filtered by the pixel footprint: an octave whose
//! wavelength is under two footprints fades out (and is skipped under one),
//! so distant surfaces neither alias nor cost the finest octaves.

/// A 32-bit hash of a lattice point and a seed (integer avalanche mix).
#[inline]
pub fn hash3(x: i32, y: i32, seed: u32) -> u32 {
    // Two multiplies and xor-shifts: enough mixing for textures, cheap in the inner loop.
    let mut h = (x as u32).wrapping_mul(0x27d4_eb2d)
        ^ (y as u32).wrapping_add(seed).wrapping_mul(0x1656_67b1);
    h ^= h >> 15;
    h = h.wrapping_mul(0x85eb_ca77);
    h ^= h >> 13;
    h
}

/// Hash to `[0, 1)`.
#[inline]
pub fn unit(x: i32, y: i32, seed: u32) -> f64 {
    (hash3(x, y, seed) >> 8) as f64 * (1.0 / 16_777_216.0)
}

/// Hash to `[-1, 1)`.
#[inline]
fn signed(x: i32, y: i32, seed: u32) -> f64 {
    unit(x, y, seed) * 2.0 - 1.0
}

/// `floor` without the libm call (inputs are well inside the i32 range).
#[inline]
pub fn fast_floor(x: f64) -> i32 {
    let i = x as i32;
    if x < i as f64 {
        i - 1
    } else {
        i
    }
}

#[inline]
fn fade(t: f64) -> f64 {
    // Quintic: continuous second derivative, no lattice creases.
    t * t * t * (t * (t * 6.0 - 15.0) + 10.0)
}

/// Value noise in `[-1, 1]` with unit lattice spacing.
#[inline]
pub fn value2(x: f64, y: f64, seed: u32) -> f64 {
    let (ix, iy) = (fast_floor(x), fast_floor(y));
    let (fx, fy) = (ix as f64, iy as f64);
    let (tx, ty) = (fade(x - fx), fade(y - fy));
    let a = signed(ix, iy, seed);
    let b = signed(ix + 1, iy, seed);
    let c = signed(ix, iy + 1, seed);
    let d = signed(ix + 1, iy + 1, seed);
    let top = a + (b - a) * tx;
    let bottom = c + (d - c) * tx;
    top + (bottom - top) * ty
}

/// Weight of a feature of wavelength `lambda` seen with footprint `footprint`:
/// 1 above two footprints, 0 below one, linear between.
#[inline]
pub fn band_weight(lambda: f64, footprint: f64) -> f64 {
    (lambda / footprint.max(1e-9) - 1.0).clamp(0.0, 1.0)
}

/// Band-limited fractional Brownian motion, roughly in `[-1, 1]`: `octaves`
/// octaves from wavelength `lambda0` down, amplitude `gain` per octave.
pub fn fbm(
    x: f64,
    y: f64,
    seed: u32,
    lambda0: f64,
    octaves: u32,
    gain: f64,
    footprint: f64,
) -> f64 {
    // Multiplications by running inverses keep divisions out of the loop.
    let inv_fp = 1.0 / footprint.max(1e-9);
    let (mut sum, mut norm, mut amp, mut lambda, mut freq) =
        (0.0, 0.0, 1.0, lambda0, 1.0 / lambda0);
    for i in 0..octaves {
        norm += amp;
        let w = (lambda * inv_fp - 1.0).clamp(0.0, 1.0);
        if w <= 0.0 {
            // Finer octaves are under the footprint too: their mean (0) stands for them.
            for _ in i + 1..octaves {
                amp *= gain;
                norm += amp;
            }
            break;
        }
        // Offsets per octave keep lattices of different octaves from aligning.
        let o = i as f64 * 17.13;
        sum += w * amp * value2(x * freq + o, y * freq - o, seed.wrapping_add(i * 7919));
        amp *= gain;
        lambda *= 0.5;
        freq *= 2.0;
    }
    sum / norm.max(1e-12)
}

/// Box-filtered coverage of the stripe `|x| <= half` by a footprint `w`
/// centred at `x` (exact for a box filter).
#[inline]
pub fn stripe(x: f64, half: f64, w: f64) -> f64 {
    let w = w.max(1e-9);
    let a = (x - 0.5 * w).max(-half);
    let b = (x + 0.5 * w).min(half);
    ((b - a) / w).clamp(0.0, 1.0)
}

/// Box-filtered coverage of a periodic pattern "on" over `[0, on)` of each
/// `period`, at `x` with footprint `w`; blends to the duty cycle when the
/// footprint exceeds the period.
pub fn periodic(x: f64, on: f64, period: f64, w: f64) -> f64 {
    let duty = on / period;
    if w >= period {
        return duty;
    }
    // Integral of the indicator over [x - w/2, x + w/2] / w.
    let integral = |t: f64| {
        let k = fast_floor(t / period) as f64;
        k * on + (t - k * period).min(on)
    };
    let w = w.max(1e-9);
    ((integral(x + 0.5 * w) - integral(x - 0.5 * w)) / w).clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn value_noise_is_continuous_and_bounded() {
        let mut prev = value2(0.0, 0.3, 1);
        for i in 1..10_000 {
            let x = i as f64 * 0.001;
            let v = value2(x, 0.3, 1);
            assert!(v.abs() <= 1.0);
            assert!((v - prev).abs() < 0.01, "jump at {x}");
            prev = v;
        }
        assert_ne!(value2(0.5, 0.5, 1), value2(0.5, 0.5, 2));
    }

    #[test]
    fn filters_are_exact() {
        assert_eq!(stripe(0.0, 0.5, 0.1), 1.0);
        assert!((stripe(0.5, 0.5, 0.2) - 0.5).abs() < 1e-12);
        assert_eq!(stripe(2.0, 0.5, 0.2), 0.0);
        assert!((periodic(0.1, 0.5, 1.0, 3.0) - 0.5).abs() < 1e-12);
        assert!((periodic(0.5, 0.5, 1.0, 0.2) - 0.5).abs() < 1e-12);
        assert!((periodic(0.25, 0.5, 1.0, 0.1) - 1.0).abs() < 1e-12);
        // Footprint covering one full period and a bit: close to the duty cycle.
        assert!((periodic(0.3, 0.25, 1.0, 0.999) - 0.25).abs() < 0.01);
    }

    #[test]
    fn fbm_fades_with_footprint() {
        // At a huge footprint only the mean remains.
        assert_eq!(fbm(3.3, 4.4, 9, 1.0, 6, 0.5, 100.0), 0.0);
        let near = fbm(3.3, 4.4, 9, 1.0, 6, 0.5, 1e-4);
        assert!(near != 0.0 && near.abs() <= 1.0);
    }
}
