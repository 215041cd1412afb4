//! Imperfections of real cameras and calibrations: optical blur, vignetting,
//! exposure changes, sensor noise, quantization (JPEG is the writer's), and
//! the residuals of a real calibration.
use phototraverse_core::camera::Rig;
use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// Image-space imperfections.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Imperfections {
    /// Gaussian optical blur, sigma in pixels (0 = none).
    pub blur_px: f64,
    /// Light fall-off at the image corners, fraction (0.3 = corners 30 % darker).
    pub vignetting: f64,
    /// Random gain change per image, +- fraction (uniform).
    pub flicker: f64,
    /// Read noise, standard deviation in 8-bit grey levels.
    pub noise: f64,
}

impl Default for Imperfections {
    fn default() -> Self {
        Imperfections {
            blur_px: 0.0,
            vignetting: 0.0,
            flicker: 0.0,
            noise: 0.0,
        }
    }
}

/// Full-scale radiance: a radiance of 1.0 maps to this grey level.
pub const WHITE_LEVEL: f64 = 235.0;

/// Separable Gaussian blur in place (clamped borders).
pub fn gaussian_blur(img: &mut [f32], w: usize, h: usize, sigma: f64) {
    if sigma <= 0.0 || w == 0 || h == 0 {
        return;
    }
    let radius = (3.0 * sigma).ceil() as isize;
    let kernel: Vec<f32> = (-radius..=radius)
        .map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp() as f32)
        .collect();
    let sum: f32 = kernel.iter().sum();
    let kernel: Vec<f32> = kernel.iter().map(|k| k / sum).collect();
    let mut tmp = vec![0.0f32; w * h];
    for r in 0..h {
        for c in 0..w {
            let mut acc = 0.0;
            for (k, kv) in kernel.iter().enumerate() {
                let cc = (c as isize + k as isize - radius).clamp(0, w as isize - 1) as usize;
                acc += kv * img[r * w + cc];
            }
            tmp[r * w + c] = acc;
        }
    }
    for r in 0..h {
        for c in 0..w {
            let mut acc = 0.0;
            for (k, kv) in kernel.iter().enumerate() {
                let rr = (r as isize + k as isize - radius).clamp(0, h as isize - 1) as usize;
                acc += kv * tmp[rr * w + c];
            }
            img[r * w + c] = acc;
        }
    }
}

/// Applies vignetting, the gain, noise and 8-bit quantization.
pub fn develop(
    img: &[f32],
    w: usize,
    h: usize,
    gain: f64,
    imp: &Imperfections,
    rng: &mut ChaCha8Rng,
) -> Vec<u8> {
    let (cx, cy) = ((w as f64 - 1.0) * 0.5, (h as f64 - 1.0) * 0.5);
    let r2max = cx * cx + cy * cy;
    let mut out = Vec::with_capacity(w * h);
    for r in 0..h {
        for c in 0..w {
            let (dx, dy) = (c as f64 - cx, r as f64 - cy);
            let vig = 1.0 - imp.vignetting * (dx * dx + dy * dy) / r2max.max(1.0);
            let mut v = img[r * w + c] as f64 * gain * vig * WHITE_LEVEL;
            if imp.noise > 0.0 {
                // Read noise plus shot noise growing with the signal.
                let sigma = (imp.noise * imp.noise + 0.02 * v.max(0.0)).sqrt();
                v += sigma * gaussian(rng);
            }
            out.push(v.round().clamp(0.0, 255.0) as u8);
        }
    }
    out
}

/// A standard normal deviate (Box-Muller).
pub fn gaussian(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = rng.gen_range(f64::EPSILON..1.0);
    let u2: f64 = rng.gen();
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

/// Sizes of the calibration residuals (`--calib-error base=..,focal=..,pp_px=..,rel_deg=..`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CalibError {
    /// Relative base-length error.
    pub base: f64,
    /// Relative focal-length error (each camera).
    pub focal: f64,
    /// Principal-point error, pixels (each camera, random direction).
    pub pp_px: f64,
    /// Relative-rotation error, degrees (random axis).
    pub rel_deg: f64,
}

impl CalibError {
    /// Parses `key=value` pairs separated by commas.
    pub fn parse(text: &str) -> Result<CalibError, String> {
        let mut e = CalibError::default();
        for part in text.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let (k, v) = part
                .split_once('=')
                .ok_or_else(|| format!("`{part}`: expected key=value"))?;
            let v: f64 = v
                .trim()
                .parse()
                .map_err(|_| format!("`{part}`: `{v}` is not a number"))?;
            if !v.is_finite() || v < 0.0 {
                return Err(format!("`{part}`: must be a finite non-negative number"));
            }
            match k.trim() {
                "base" => e.base = v,
                "focal" => e.focal = v,
                "pp_px" => e.pp_px = v,
                "rel_deg" => e.rel_deg = v,
                other => {
                    return Err(format!(
                        "unknown calibration error `{other}` (base, focal, pp_px, rel_deg)"
                    ))
                }
            }
        }
        Ok(e)
    }

    pub fn is_zero(&self) -> bool {
        *self == CalibError::default()
    }

    /// The calibration a user would have for `truth`: every parameter off by
    /// the given size with a random sign or direction.
    pub fn perturb(&self, truth: &Rig, rng: &mut ChaCha8Rng) -> Rig {
        let mut rig = *truth;
        let mut sign = || if rng.gen_bool(0.5) { 1.0 } else { -1.0 };
        let s = 1.0 + self.base * sign();
        rig.base_m = [rig.base_m[0] * s, rig.base_m[1] * s, rig.base_m[2] * s];
        rig.left.focal_mm *= 1.0 + self.focal * sign();
        rig.right.focal_mm *= 1.0 + self.focal * sign();
        for cam in [&mut rig.left, &mut rig.right] {
            let a: f64 = rng.gen_range(0.0..std::f64::consts::TAU);
            cam.principal_point_mm[0] += self.pp_px * cam.pixel_size_mm[0] * a.cos();
            cam.principal_point_mm[1] += self.pp_px * cam.pixel_size_mm[1] * a.sin();
        }
        // A rotation of rel_deg about a random axis, as small angle increments.
        let (th, ph): (f64, f64) = (
            rng.gen_range(0.0..std::f64::consts::TAU),
            rng.gen_range(-1.0f64..1.0).acos(),
        );
        let axis = [ph.sin() * th.cos(), ph.sin() * th.sin(), ph.cos()];
        for (angle, a) in rig.relative_angles.iter_mut().zip(axis) {
            *angle += self.rel_deg.to_radians() * a;
        }
        rig
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use phototraverse_core::camera::Interior;
    use rand::SeedableRng;

    #[test]
    fn calib_error_parse_and_size() {
        let e = CalibError::parse("base=0.003,focal=0.003, pp_px=1,rel_deg=0.05").unwrap();
        assert_eq!(
            e,
            CalibError {
                base: 0.003,
                focal: 0.003,
                pp_px: 1.0,
                rel_deg: 0.05
            }
        );
        assert!(CalibError::parse("bas=1").unwrap_err().contains("unknown"));
        assert!(CalibError::parse("base=x")
            .unwrap_err()
            .contains("not a number"));
        let truth = Rig::rectified(Interior::pinhole_px(640, 480, 500.0), 0.94);
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let r = e.perturb(&truth, &mut rng);
        assert!(((r.base_length() / 0.94 - 1.0).abs() - 0.003).abs() < 1e-12);
        assert!(((r.left.focal_mm / 500.0 - 1.0).abs() - 0.003).abs() < 1e-12);
        let pp = r.left.principal_point_mm;
        assert!(((pp[0] * pp[0] + pp[1] * pp[1]).sqrt() - 1.0).abs() < 1e-12);
        let a = r.relative_angles;
        assert!(
            ((a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt() - 0.05f64.to_radians()).abs() < 1e-12
        );
    }

    #[test]
    fn blur_keeps_mean_and_spreads() {
        let (w, h) = (21, 21);
        let mut img = vec![0.0f32; w * h];
        img[10 * w + 10] = 1.0;
        gaussian_blur(&mut img, w, h, 1.5);
        let sum: f32 = img.iter().sum();
        assert!((sum - 1.0).abs() < 1e-5);
        assert!(img[10 * w + 10] < 0.1 && img[10 * w + 11] > 0.0);
    }
}
