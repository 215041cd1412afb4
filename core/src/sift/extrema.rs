//! 3x3x3 extrema of the integer difference of Gaussians, then sub-pixel and
//! sub-scale refinement (Lowe's quadratic fit, as in OpenCV's adjustLocalExtrema)
//! with contrast and edge rejection.

use super::config::{BORDER, FRAC_BITS, REFINE_ROWS};
use super::fastmath::round_i;
use super::levels::Levels;
use super::pending::Pending;

/// Most refinement steps.
const MAX_STEPS: usize = 5;

/// Constants of the refinement derived from the configuration.
#[derive(Debug, Clone, Copy)]
pub struct RefineParams {
    /// Detection layers per octave (`s`).
    pub levels: usize,
    /// Contrast threshold (grey levels / 255, before division by `levels`).
    pub contrast: f32,
    /// Edge threshold `r` (ratio of principal curvatures).
    pub edge: f32,
}

/// Integer threshold of the extremum search: half the final contrast threshold,
/// in the 6-fractional-bit level format (OpenCV's prelimContrastThr).
pub fn prelim_threshold(contrast: f32, levels: usize) -> i32 {
    let t = 0.5 * contrast / levels as f32 * 255.0 * (1 << FRAC_BITS) as f32;
    libm::floorf(t) as i32
}

/// Candidates of `row[start..start + len]`, `len <= 32` (bit `i` for column
/// `start + i`): beyond `thr` in magnitude and not below (above, for minima) their row
/// neighbours, which must exist (`1 <= start`, `start + len < row.len()`). The
/// 26-neighbour test follows for the few that pass. Most samples fail, so this filter
/// is the detector's inner loop: whole chunks of 32 take the vector path.
#[inline]
pub fn candidate_mask(row: &[i16], start: usize, len: usize, thr: i16) -> u32 {
    #[cfg(target_arch = "x86_64")]
    if len == 32 && start >= 1 && start + 33 <= row.len() {
        return simd::candidate_mask(row, start, thr);
    }
    candidate_mask_scalar(row, start, len, thr)
}

/// [`candidate_mask`] one column at a time (the tail of a row, other targets, and the
/// reference of the vector path).
pub fn candidate_mask_scalar(row: &[i16], start: usize, len: usize, thr: i16) -> u32 {
    let chunk = &row[start..start + len];
    let left = &row[start - 1..start + len - 1];
    let right = &row[start + 1..start + len + 1];
    let mut mask = 0u32;
    for (i, ((&v, &a), &b)) in chunk.iter().zip(left).zip(right).enumerate() {
        let max = (v > thr) & (v >= a) & (v >= b);
        let min = (v < -thr) & (v <= a) & (v <= b);
        mask |= ((max | min) as u32) << i;
    }
    mask
}

#[cfg(target_arch = "x86_64")]
mod simd {
    use core::arch::x86_64::*;

    /// [`super::candidate_mask`] of 32 columns, eight per compare, packed to bits by
    /// `movemask`; needs `1 <= start` and `start + 33 <= row.len()`.
    pub fn candidate_mask(row: &[i16], start: usize, thr: i16) -> u32 {
        assert!(start >= 1 && start + 33 <= row.len());
        // SAFETY: SSE2 is part of the x86_64 baseline; every load reads columns
        // `start - 1 + k .. start + 7 + k + 2` for k < 32, inside `row` (asserted above).
        unsafe {
            let p = row.as_ptr().add(start);
            let hi = _mm_set1_epi16(thr);
            let lo = _mm_set1_epi16(-thr);
            let bits8 = |k: usize| {
                let v = _mm_loadu_si128(p.add(k) as *const __m128i);
                let a = _mm_loadu_si128(p.add(k).sub(1) as *const __m128i);
                let b = _mm_loadu_si128(p.add(k + 1) as *const __m128i);
                // v >= a is !(a > v).
                let below_a = _mm_cmpgt_epi16(a, v);
                let below_b = _mm_cmpgt_epi16(b, v);
                let above_a = _mm_cmpgt_epi16(v, a);
                let above_b = _mm_cmpgt_epi16(v, b);
                let max = _mm_andnot_si128(_mm_or_si128(below_a, below_b), _mm_cmpgt_epi16(v, hi));
                let min = _mm_andnot_si128(_mm_or_si128(above_a, above_b), _mm_cmpgt_epi16(lo, v));
                _mm_or_si128(max, min)
            };
            let m0 = _mm_packs_epi16(bits8(0), bits8(8));
            let m1 = _mm_packs_epi16(bits8(16), bits8(24));
            let b0 = _mm_movemask_epi8(m0) as u32 & 0xffff;
            let b1 = _mm_movemask_epi8(m1) as u32 & 0xffff;
            b0 | (b1 << 16)
        }
    }
}

/// Is `v` (the DoG at `cur[c]`) an extremum over its 26 neighbours?
/// `rows` are the nine rows: layer below (r-1, r, r+1), this layer, layer above.
#[inline]
pub fn is_extremum(rows: &[&[i16]; 9], c: usize, v: i16) -> bool {
    if v > 0 {
        for (i, row) in rows.iter().enumerate() {
            let n = &row[c - 1..c + 2];
            if i == 4 {
                if v < n[0] || v < n[2] {
                    return false;
                }
            } else if v < n[0] || v < n[1] || v < n[2] {
                return false;
            }
        }
    } else {
        for (i, row) in rows.iter().enumerate() {
            let n = &row[c - 1..c + 2];
            if i == 4 {
                if v > n[0] || v > n[2] {
                    return false;
                }
            } else if v > n[0] || v > n[1] || v > n[2] {
                return false;
            }
        }
    }
    true
}

/// What refinement made of a candidate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Refined {
    Kept(Pending),
    /// Did not converge, or moved out of the octave, its layers or the streaming window.
    Unstable,
    LowContrast,
    Edge,
}

/// Refines an extremum found at (`c`, `r`) in DoG layer `layer` of the octave.
/// Rows read stay within `r_det +- REFINE_ROWS`, which the rings hold.
pub fn refine(lv: &Levels, p: &RefineParams, c: usize, r: usize, layer: usize) -> Refined {
    let scale = 1.0 / (255.0 * (1 << FRAC_BITS) as f32);
    let (w, h) = (lv.w as isize, lv.h as isize);
    let r_det = r as isize;
    let (mut c, mut r, mut k) = (c as isize, r as isize, layer as isize);
    let mut x = [0f32; 3];
    let mut grad = [0f32; 3];
    let mut converged = false;
    for _ in 0..MAX_STEPS {
        let ku = k as usize;
        let cube = dog_cube(lv, ku, r, c);
        // d(ds, dr, dc): the DoG at layer ku + ds, row r + dr, column c + dc.
        let d = |ds: usize, dr: usize, dc: usize| cube[ds][dr][dc];
        let v2 = 2.0 * d(1, 1, 1);
        grad = [
            (d(1, 1, 2) - d(1, 1, 0)) * 0.5 * scale,
            (d(1, 2, 1) - d(1, 0, 1)) * 0.5 * scale,
            (d(2, 1, 1) - d(0, 1, 1)) * 0.5 * scale,
        ];
        let dxx = (d(1, 1, 2) + d(1, 1, 0) - v2) * scale;
        let dyy = (d(1, 2, 1) + d(1, 0, 1) - v2) * scale;
        let dss = (d(2, 1, 1) + d(0, 1, 1) - v2) * scale;
        let dxy = (d(1, 2, 2) - d(1, 2, 0) - d(1, 0, 2) + d(1, 0, 0)) * 0.25 * scale;
        let dxs = (d(2, 1, 2) - d(2, 1, 0) - d(0, 1, 2) + d(0, 1, 0)) * 0.25 * scale;
        let dys = (d(2, 2, 1) - d(2, 0, 1) - d(0, 2, 1) + d(0, 0, 1)) * 0.25 * scale;
        let hm = [[dxx, dxy, dxs], [dxy, dyy, dys], [dxs, dys, dss]];
        x = match solve3(&hm, &grad) {
            Some(s) => [-s[0], -s[1], -s[2]],
            None => return Refined::Unstable,
        };
        if x.iter().all(|v| v.abs() < 0.5) {
            converged = true;
            break;
        }
        if x.iter().any(|v| v.is_nan() || v.abs() >= 1.0e6) {
            return Refined::Unstable;
        }
        c += round_i(x[0]) as isize;
        r += round_i(x[1]) as isize;
        k += round_i(x[2]) as isize;
        if k < 1
            || k > p.levels as isize
            || c < BORDER as isize
            || c >= w - BORDER as isize
            || r < BORDER as isize
            || r >= h - BORDER as isize
            || (r - r_det).abs() > REFINE_ROWS as isize - 1
        {
            return Refined::Unstable;
        }
    }
    if !converged {
        return Refined::Unstable;
    }
    let ku = k as usize;
    let v = lv.dog(ku, r, c) as f32 * scale;
    let contrast = v + 0.5 * (grad[0] * x[0] + grad[1] * x[1] + grad[2] * x[2]);
    if contrast.abs() * (p.levels as f32) < p.contrast {
        return Refined::LowContrast;
    }
    // Principal curvature ratio from the 2x2 spatial Hessian at the final sample.
    let d = |rr: isize, cc: isize| lv.dog(ku, rr, cc) as f32;
    let v2 = 2.0 * d(r, c);
    let dxx = d(r, c + 1) + d(r, c - 1) - v2;
    let dyy = d(r + 1, c) + d(r - 1, c) - v2;
    let dxy = (d(r + 1, c + 1) - d(r + 1, c - 1) - d(r - 1, c + 1) + d(r - 1, c - 1)) * 0.25;
    let tr = dxx + dyy;
    let det = dxx * dyy - dxy * dxy;
    let e = p.edge;
    if det <= 0.0 || tr * tr * e >= (e + 1.0) * (e + 1.0) * det {
        return Refined::Edge;
    }
    Refined::Kept(Pending {
        x: c as f32 + x[0],
        y: r as f32 + x[1],
        layer: k as f32 + x[2],
        response: contrast.abs(),
        row: r_det as i32,
        level: ku as u32,
    })
}

/// The 3x3x3 DoG neighbourhood of (`c`, `r`) in layers `k - 1..=k + 1`, as f32: twelve
/// row lookups instead of one per sample (a ring slot costs a division).
fn dog_cube(lv: &Levels, k: usize, r: isize, c: isize) -> [[[f32; 3]; 3]; 3] {
    let mut cube = [[[0f32; 3]; 3]; 3];
    for (dr, rr) in (r - 1..=r + 1).enumerate() {
        // Levels k - 1 ..= k + 2 give layers k - 1 ..= k + 1.
        let rows: [&[i16]; 4] = core::array::from_fn(|i| lv.row((k + i).saturating_sub(1), rr));
        for (dc, cc) in (c - 1..=c + 1).enumerate() {
            let px = |row: &[i16]| -> i32 {
                if row.is_empty() {
                    return 0;
                }
                row[cc.clamp(0, row.len() as isize - 1) as usize] as i32
            };
            let v: [i32; 4] = core::array::from_fn(|i| px(rows[i]));
            for ds in 0..3 {
                cube[ds][dr][dc] = (v[ds + 1] - v[ds]) as f32;
            }
        }
    }
    cube
}

/// Solves the symmetric 3x3 system `H s = b` by Cramer's rule; `None` when singular.
fn solve3(m: &[[f32; 3]; 3], b: &[f32; 3]) -> Option<[f32; 3]> {
    let det3 = |a: &[[f32; 3]; 3]| {
        a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
            - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
            + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
    };
    let det = det3(m);
    if !det.is_finite() || det.abs() <= 1e-30 {
        return None;
    }
    let mut out = [0f32; 3];
    for (i, o) in out.iter_mut().enumerate() {
        let mut a = *m;
        for row in 0..3 {
            a[row][i] = b[row];
        }
        *o = det3(&a) / det;
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn candidate_mask_matches_the_scalar_reference() {
        // A xorshift stream over the whole i16 range, with runs of equal values and
        // values at +-thr so that ties and the threshold's edges occur.
        let mut x = 0x2545_f491_4f6c_dd1du64;
        let mut row = [0i16; 200];
        for round in 0..200 {
            let thr = (round * 37 % 300) as i16;
            for v in row.iter_mut() {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                *v = match x % 5 {
                    0 => thr,
                    1 => -thr,
                    2 => (x >> 8) as i16,
                    _ => ((x >> 8) % 700) as i16 - 350,
                };
            }
            for start in 1..=row.len() - 33 {
                assert_eq!(
                    candidate_mask(&row, start, 32, thr),
                    candidate_mask_scalar(&row, start, 32, thr),
                    "round {round} start {start}"
                );
            }
        }
    }

    #[test]
    fn cramer_solves_and_refuses_singular() {
        let m = [[4.0, 1.0, 0.5], [1.0, 3.0, 0.25], [0.5, 0.25, 2.0]];
        let s = solve3(&m, &[1.0, 2.0, 3.0]).unwrap();
        for i in 0..3 {
            let b: f32 = (0..3).map(|j| m[i][j] * s[j]).sum();
            assert!((b - [1.0, 2.0, 3.0][i]).abs() < 1e-5);
        }
        assert!(solve3(
            &[[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 0.0, 1.0]],
            &[1.0; 3]
        )
        .is_none());
    }

    #[test]
    fn extremum_needs_all_neighbours() {
        let flat = [0i16; 5];
        let mut mid = [0i16; 5];
        mid[2] = 9;
        let rows: [&[i16]; 9] = [&flat, &flat, &flat, &flat, &mid, &flat, &flat, &flat, &flat];
        assert!(is_extremum(&rows, 2, 9));
        let mut above = [0i16; 5];
        above[3] = 10;
        let rows: [&[i16]; 9] = [
            &flat, &flat, &flat, &flat, &mid, &flat, &flat, &above, &flat,
        ];
        assert!(!is_extremum(&rows, 2, 9));
    }
}
