//! Fixed-point separable Gaussian smoothing over rows: Q14 symmetric kernels,
//! levels stored as i16 grey levels times 64 (6 fractional bits).
//!
//! The pipeline is streaming: each level keeps only a ring of rows. Level 0 of an
//! octave reads its source (the input image or the decimated octave base) at random,
//! levels >= 1 receive each new row of the level below, blur it horizontally into
//! their own ring of `2 r + 1` rows and blur that ring vertically. Borders replicate
//! the edge pixel, which keeps the vertical pass causal at the top of the image.

use super::config::{FRAC_BITS, KERNEL_BITS, KERNEL_STRIDE, MAX_RADIUS};

/// Fills `taps[0..=radius]` (centre first, then one side) with a Q14 Gaussian whose
/// full symmetric sum is exactly `1 << KERNEL_BITS`.
pub fn make_kernel(sigma: f32, radius: usize, taps: &mut [i32]) {
    let taps = &mut taps[..KERNEL_STRIDE];
    taps.fill(0);
    let radius = radius.min(KERNEL_STRIDE - 1);
    if radius == 0 || sigma <= 0.0 {
        taps[0] = 1 << KERNEL_BITS;
        return;
    }
    let mut w = [0f32; KERNEL_STRIDE];
    let mut sum = 0.0;
    for (i, wi) in w.iter_mut().enumerate().take(radius + 1) {
        let x = i as f32;
        *wi = libm::expf(-x * x / (2.0 * sigma * sigma));
        sum += if i == 0 { *wi } else { 2.0 * *wi };
    }
    let one = (1i32 << KERNEL_BITS) as f32;
    let mut total = 0;
    for i in 0..=radius {
        taps[i] = libm::roundf(w[i] / sum * one) as i32;
        total += if i == 0 { taps[i] } else { 2 * taps[i] };
    }
    // Put the rounding remainder in the centre so flat regions stay exactly flat.
    taps[0] += (1 << KERNEL_BITS) - total;
}

/// `acc / 2^shift`, rounded, saturated to i16 (as the vector paths' `packs`).
#[inline]
fn round_shift(acc: i32, shift: u32) -> i16 {
    let v = (acc + (1 << (shift - 1))) >> shift;
    v.clamp(i16::MIN as i32, i16::MAX as i32) as i16
}

/// Horizontal pass of one row: `out[c] = sum_j k_j * in[clamp(c + j)]`.
/// `pad` needs `w + 2 * radius` values and `acc` `w`.
pub fn blur_row(
    input: &[i16],
    taps: &[i32],
    radius: usize,
    pad: &mut [i16],
    acc: &mut [i32],
    out: &mut [i16],
) {
    let w = input.len().min(out.len()).min(acc.len());
    if w == 0 {
        return;
    }
    if radius == 0 {
        out[..w].copy_from_slice(&input[..w]);
        return;
    }
    let pad = &mut pad[..w + 2 * radius];
    let (left, rest) = pad.split_at_mut(radius);
    let (mid, right) = rest.split_at_mut(w);
    left.fill(input[0]);
    mid.copy_from_slice(&input[..w]);
    right.fill(input[w - 1]);
    let pad = &*pad;
    let mut rows: [&[i16]; 2 * MAX_RADIUS + 1] = [&[]; 2 * MAX_RADIUS + 1];
    for (j, row) in rows.iter_mut().enumerate().take(2 * radius + 1) {
        *row = &pad[j..j + w];
    }
    convolve(&rows[..2 * radius + 1], taps, radius, acc, &mut out[..w]);
}

/// `out[c] = round(sum_j k_|j - radius| * rows[j][c])`: the symmetric kernel applied across
/// `2 radius + 1` rows (shifted copies of one row for the horizontal pass, ring rows for
/// the vertical pass). SSE2 on x86_64 (16-bit pairs multiplied into 32-bit sums, which is
/// exact: taps <= 2^14 and samples <= 255 * 64), the same arithmetic in scalar elsewhere.
pub fn convolve(rows: &[&[i16]], taps: &[i32], radius: usize, acc: &mut [i32], out: &mut [i16]) {
    let w = out.len();
    if rows.len() != 2 * radius + 1 || taps.len() <= radius || rows.iter().any(|r| r.len() < w) {
        return;
    }
    #[cfg(target_arch = "x86_64")]
    let done = {
        // SAFETY (all three): the CPU has the feature (checked at run time; SSE2 is
        // the x86_64 baseline); the rows' count and lengths are checked above.
        let mut start = 0;
        if simd::has_avx512() {
            start = unsafe { simd::convolve_avx512(rows, taps, radius, out, start) };
        }
        if simd::has_avx2() {
            start = unsafe { simd::convolve_avx2(rows, taps, radius, out, start) };
        }
        simd::last_block(w, start, |start| unsafe {
            simd::convolve_sse2(rows, taps, radius, out, start)
        })
    };
    #[cfg(not(target_arch = "x86_64"))]
    let done = 0;
    let n = w.min(acc.len());
    if done < n {
        columns_scalar(
            rows,
            taps,
            radius,
            KERNEL_BITS,
            &mut acc[done..n],
            done,
            &mut out[done..n],
        );
    }
}

/// Columns `first..first + out.len()` of the symmetric kernel over `rows`, one at a
/// time (the tail the vector paths leave, and other targets): the exact integer sums,
/// rounded and shifted by `shift`.
fn columns_scalar<T: Copy + Into<i32>>(
    rows: &[&[T]],
    taps: &[i32],
    radius: usize,
    shift: u32,
    acc: &mut [i32],
    first: usize,
    out: &mut [i16],
) {
    let k0 = taps[0] as i16 as i32;
    for (a, &p) in acc.iter_mut().zip(&rows[radius][first..]) {
        *a = k0 * p.into();
    }
    for (j, &t) in taps.iter().enumerate().take(radius + 1).skip(1) {
        let kj = t as i16 as i32;
        let lo = &rows[radius - j][first..];
        let hi = &rows[radius + j][first..];
        for ((a, &l), &h) in acc.iter_mut().zip(lo).zip(hi) {
            *a += kj * (l.into() + h.into());
        }
    }
    for (o, &a) in out.iter_mut().zip(acc.iter()) {
        *o = round_shift(a, shift);
    }
}

#[cfg(target_arch = "x86_64")]
mod simd {
    use super::{FRAC_BITS, KERNEL_BITS, MAX_RADIUS};
    use core::arch::x86_64::*;

    /// The centre row and the rows `radius -+ j` (j = 1..=radius) as pointers.
    struct TapRows<T> {
        centre: *const T,
        lo: [*const T; MAX_RADIUS + 1],
        hi: [*const T; MAX_RADIUS + 1],
    }

    #[inline(always)]
    fn tap_rows<T>(rows: &[&[T]], radius: usize) -> TapRows<T> {
        let centre = rows[radius].as_ptr();
        let mut t = TapRows {
            centre,
            lo: [centre; MAX_RADIUS + 1],
            hi: [centre; MAX_RADIUS + 1],
        };
        for j in 1..=radius {
            t.lo[j] = rows[radius - j].as_ptr();
            t.hi[j] = rows[radius + j].as_ptr();
        }
        t
    }

    /// Taps in `madd` pairs (k_2m, k_2m+1) as packed i16 halves, the last odd one with a
    /// zero: pair 0 multiplies (centre, s_1), pair m (s_2m, s_2m+1).
    #[inline(always)]
    fn tap_pairs(taps: &[i32], radius: usize) -> [i32; MAX_RADIUS / 2 + 1] {
        let tap = |j: usize| if j <= radius { taps[j] & 0xffff } else { 0 };
        core::array::from_fn(|m| tap(2 * m) | (tap(2 * m + 1) << 16))
    }

    /// Columns `0..w - w % 8` of [`super::convolve`]; returns how many were written.
    ///
    /// # Safety
    /// `rows` must hold `2 radius + 1` rows (`radius` at most [`MAX_RADIUS`]), each of
    /// at least `out.len()` values: the loads are unchecked.
    pub unsafe fn convolve_sse2(
        rows: &[&[i16]],
        taps: &[i32],
        radius: usize,
        out: &mut [i16],
        start: usize,
    ) -> usize {
        let radius = radius.min(MAX_RADIUS);
        let t = tap_rows(rows, radius);
        // SAFETY (both loaders): every row holds at least `out.len()` values (this
        // function's contract) and `columns` loads columns `c..c + 8` with
        // `c + 8 <= out.len()`.
        let load = |c: usize| unsafe { _mm_loadu_si128(t.centre.add(c) as *const __m128i) };
        let sym = |j: usize, c: usize| unsafe {
            _mm_add_epi16(
                _mm_loadu_si128(t.lo[j].add(c) as *const __m128i),
                _mm_loadu_si128(t.hi[j].add(c) as *const __m128i),
            )
        };
        columns(taps, radius, KERNEL_BITS, out, start, load, sym)
    }

    /// Columns `start..w - w % 8` of [`super::blur_column_u8`]: u8 rows, widened to
    /// i16 on load (`l + h` fits: at most 510), then [`columns`] shifted by 14 - 6.
    ///
    /// # Safety
    /// As [`convolve_sse2`]: `2 radius + 1` rows of at least `out.len()` values.
    pub unsafe fn column_u8_sse2(
        rows: &[&[u8]],
        taps: &[i32],
        radius: usize,
        out: &mut [i16],
        start: usize,
    ) -> usize {
        let radius = radius.min(MAX_RADIUS);
        let t = tap_rows(rows, radius);
        // SAFETY: as in `convolve_sse2`; each load reads the 8 bytes `c..c + 8`.
        let widen = |p: *const u8, c: usize| unsafe {
            _mm_unpacklo_epi8(
                _mm_loadl_epi64(p.add(c) as *const __m128i),
                _mm_setzero_si128(),
            )
        };
        let load = |c: usize| widen(t.centre, c);
        let sym =
            |j: usize, c: usize| unsafe { _mm_add_epi16(widen(t.lo[j], c), widen(t.hi[j], c)) };
        columns(taps, radius, KERNEL_BITS - FRAC_BITS, out, start, load, sym)
    }

    /// The symmetric kernel eight columns at a time from `start` (rounded up to 8):
    /// `centre(c)` loads the centre row at columns `c..c + 8` as i16, `sym(j, c)` the sum
    /// of the rows `radius -+ j`. Two taps go into each `madd`: (s_0, s_1), (s_2, s_3),
    /// ... with the centre row as s_0 and a zero row after an odd last tap, so the sums
    /// are the scalar path's exactly; the result is rounded and shifted by `shift`.
    #[inline(always)]
    fn columns(
        taps: &[i32],
        radius: usize,
        shift: u32,
        out: &mut [i16],
        start: usize,
        centre: impl Fn(usize) -> __m128i,
        sym: impl Fn(usize, usize) -> __m128i,
    ) -> usize {
        let blocks = out.len() / 8;
        // SAFETY: SSE2 is part of the x86_64 baseline; the store writes columns
        // `c..c + 8` with `c + 8 <= blocks * 8 <= out.len()`.
        unsafe {
            let round = _mm_set1_epi32(1 << (shift - 1));
            let count = _mm_cvtsi32_si128(shift as i32);
            let kv = tap_pairs(taps, radius).map(|k| _mm_set1_epi32(k));
            let zero = _mm_setzero_si128();
            // Pair 0 is (centre, s_1); full pairs (s_2m, s_2m+1) follow; an even radius
            // leaves s_radius alone with a zero.
            let full = radius.div_ceil(2);
            let odd_tail = radius >= 2 && radius.is_multiple_of(2);
            for b in start.div_ceil(8)..blocks {
                let c = b * 8;
                let x = centre(c);
                let s1 = if radius >= 1 { sym(1, c) } else { zero };
                let mut a0 = _mm_add_epi32(round, _mm_madd_epi16(_mm_unpacklo_epi16(x, s1), kv[0]));
                let mut a1 = _mm_add_epi32(round, _mm_madd_epi16(_mm_unpackhi_epi16(x, s1), kv[0]));
                for (m, &k) in kv.iter().enumerate().take(full).skip(1) {
                    let s0 = sym(2 * m, c);
                    let s1 = sym(2 * m + 1, c);
                    a0 = _mm_add_epi32(a0, _mm_madd_epi16(_mm_unpacklo_epi16(s0, s1), k));
                    a1 = _mm_add_epi32(a1, _mm_madd_epi16(_mm_unpackhi_epi16(s0, s1), k));
                }
                if odd_tail {
                    let s0 = sym(radius, c);
                    let k = kv[radius / 2];
                    a0 = _mm_add_epi32(a0, _mm_madd_epi16(_mm_unpacklo_epi16(s0, zero), k));
                    a1 = _mm_add_epi32(a1, _mm_madd_epi16(_mm_unpackhi_epi16(s0, zero), k));
                }
                a0 = _mm_sra_epi32(a0, count);
                a1 = _mm_sra_epi32(a1, count);
                _mm_storeu_si128(
                    out.as_mut_ptr().add(c) as *mut __m128i,
                    _mm_packs_epi32(a0, a1),
                );
            }
        }
        blocks * 8
    }

    cpufeatures::new!(avx2_cpuid, "avx2");
    cpufeatures::new!(avx512_cpuid, "avx512bw");

    /// Whether this CPU runs [`convolve_avx2`] (detected once).
    pub fn has_avx2() -> bool {
        avx2_cpuid::get()
    }

    /// Whether this CPU runs [`convolve_avx512`] (detected once).
    pub fn has_avx512() -> bool {
        avx512_cpuid::get()
    }

    /// Runs `sse2` (an eight-column kernel) from `start` when the wide kernels left a
    /// block of eight of the `w` columns, and returns the end of the columns written.
    /// Only then: its setup alone costs about 340 instructions per row, and the wide
    /// kernels usually leave none (widths of 640, 320, ..).
    #[inline(always)]
    pub fn last_block(w: usize, start: usize, sse2: impl FnOnce(usize) -> usize) -> usize {
        if start + 8 <= w {
            sse2(start)
        } else {
            start
        }
    }

    /// One wide version of [`convolve_sse2`]'s arithmetic: `$lanes` columns per block
    /// on the named register type and intrinsics, rows of `$elem` widened to i16 by
    /// `$load`, sums shifted by `$shift`. Unpacking works within 128-bit lanes:
    /// the low accumulator holds columns 0-3, 8-11, .. and the high one 4-7, 12-15, ..,
    /// and packing restores the order.
    macro_rules! wide_convolve {
        ($(#[$doc:meta])* $name:ident, $feature:literal, $lanes:expr, $vec:ty, $elem:ty,
         $shift:expr, |$p:ident| $load:expr,
         $set1:ident, $setzero:ident, $storeu:ident, $add16:ident,
         $add32:ident, $madd:ident, $lo:ident, $hi:ident, $srai:ident, $imm:ty, $packs:ident) => {
            $(#[$doc])*
            /// Returns the end of the columns written (from `start`, a multiple of the
            /// block, up to `w - w % $lanes`).
            ///
            /// # Safety
            /// The CPU must support the feature, and every row must hold at least
            /// `out.len()` values.
            #[target_feature(enable = $feature)]
            pub unsafe fn $name(
                rows: &[&[$elem]],
                taps: &[i32],
                radius: usize,
                out: &mut [i16],
                start: usize,
            ) -> usize {
                let w = out.len();
                let blocks = w / $lanes;
                let radius = radius.min(MAX_RADIUS);
                // SAFETY: loads and stores touch columns `c..c + $lanes` with
                // `c + $lanes <= w`.
                unsafe {
                    let round = $set1(1 << ($shift - 1));
                    // Built in place, not by `tap_pairs` / `tap_rows`: returning their
                    // arrays costs about 200 instructions per row here (callgrind), and
                    // this runs once per row of every level.
                    let centre = rows[radius].as_ptr();
                    let tap = |j: usize| if j <= radius { taps[j] & 0xffff } else { 0 };
                    let mut kv = [$setzero(); MAX_RADIUS / 2 + 1];
                    let mut m = 0;
                    while m <= radius / 2 {
                        kv[m] = $set1(tap(2 * m) | (tap(2 * m + 1) << 16));
                        m += 1;
                    }
                    let mut lp = [centre; MAX_RADIUS + 1];
                    let mut hp = [centre; MAX_RADIUS + 1];
                    for j in 1..=radius {
                        lp[j] = rows[radius - j].as_ptr();
                        hp[j] = rows[radius + j].as_ptr();
                    }
                    let zero = $setzero();
                    // A macro, not a closure: closures do not inherit `target_feature`,
                    // and the intrinsics would become calls.
                    macro_rules! load {
                        ($ptr:expr) => {{
                            let $p: *const $elem = $ptr;
                            $load
                        }};
                    }
                    macro_rules! sym {
                        ($j:expr, $c:expr) => {
                            $add16(load!(lp[$j].add($c)), load!(hp[$j].add($c)))
                        };
                    }
                    let full = radius.div_ceil(2);
                    let odd_tail = radius >= 2 && radius.is_multiple_of(2);
                    let mut b = start.div_ceil($lanes);
                    while b < blocks {
                        let c = b * $lanes;
                        b += 1;
                        let x = load!(centre.add(c));
                        let s1 = if radius >= 1 { sym!(1, c) } else { zero };
                        let k = kv[0];
                        let mut a0 = $add32(round, $madd($lo(x, s1), k));
                        let mut a1 = $add32(round, $madd($hi(x, s1), k));
                        // Plain index loop: iterator adapters are not inlined into a
                        // `target_feature` function and would cost a call per pair.
                        let mut m = 1;
                        while m < full {
                            let k = kv[m];
                            let s0 = sym!(2 * m, c);
                            let s1 = sym!(2 * m + 1, c);
                            a0 = $add32(a0, $madd($lo(s0, s1), k));
                            a1 = $add32(a1, $madd($hi(s0, s1), k));
                            m += 1;
                        }
                        if odd_tail {
                            let s0 = sym!(radius, c);
                            let k = kv[radius / 2];
                            a0 = $add32(a0, $madd($lo(s0, zero), k));
                            a1 = $add32(a1, $madd($hi(s0, zero), k));
                        }
                        a0 = $srai::<{ $shift as $imm }>(a0);
                        a1 = $srai::<{ $shift as $imm }>(a1);
                        $storeu(out.as_mut_ptr().add(c) as *mut $vec, $packs(a0, a1));
                    }
                }
                blocks * $lanes
            }
        };
    }

    wide_convolve!(
        /// Sixteen columns at a time on 256-bit registers.
        convolve_avx2, "avx2", 16, __m256i, i16, KERNEL_BITS,
        |p| _mm256_loadu_si256(p as *const __m256i),
        _mm256_set1_epi32, _mm256_setzero_si256, _mm256_storeu_si256, _mm256_add_epi16, _mm256_add_epi32,
        _mm256_madd_epi16, _mm256_unpacklo_epi16, _mm256_unpackhi_epi16,
        _mm256_srai_epi32, i32, _mm256_packs_epi32
    );

    wide_convolve!(
        /// [`column_u8_sse2`] sixteen columns at a time: u8 rows widened to i16 on load.
        column_u8_avx2, "avx2", 16, __m256i, u8, KERNEL_BITS - FRAC_BITS,
        |p| _mm256_cvtepu8_epi16(_mm_loadu_si128(p as *const __m128i)),
        _mm256_set1_epi32, _mm256_setzero_si256, _mm256_storeu_si256, _mm256_add_epi16, _mm256_add_epi32,
        _mm256_madd_epi16, _mm256_unpacklo_epi16, _mm256_unpackhi_epi16,
        _mm256_srai_epi32, i32, _mm256_packs_epi32
    );

    wide_convolve!(
        /// Thirty-two columns at a time on 512-bit registers.
        convolve_avx512, "avx512bw", 32, __m512i, i16, KERNEL_BITS,
        |p| _mm512_loadu_si512(p as *const __m512i),
        _mm512_set1_epi32, _mm512_setzero_si512, _mm512_storeu_si512, _mm512_add_epi16, _mm512_add_epi32,
        _mm512_madd_epi16, _mm512_unpacklo_epi16, _mm512_unpackhi_epi16,
        _mm512_srai_epi32, u32, _mm512_packs_epi32
    );
}

/// Vertical pass: `rows(j)` is the row at offset `j - radius` (already clamped by the caller).
pub fn blur_column<'r>(
    rows: impl Fn(usize) -> &'r [i16],
    taps: &[i32],
    radius: usize,
    acc: &mut [i32],
    out: &mut [i16],
) {
    let radius = radius.min(MAX_RADIUS);
    let mut list: [&[i16]; 2 * MAX_RADIUS + 1] = [&[]; 2 * MAX_RADIUS + 1];
    for (j, row) in list.iter_mut().enumerate().take(2 * radius + 1) {
        *row = rows(j);
    }
    convolve(&list[..2 * radius + 1], taps, radius, acc, out);
}

/// Vertical pass over u8 rows, scaling to the 6-fractional-bit level format.
pub fn blur_column_u8<'r>(
    rows: impl Fn(usize) -> &'r [u8],
    taps: &[i32],
    radius: usize,
    acc: &mut [i32],
    out: &mut [i16],
) {
    let radius = radius.min(MAX_RADIUS);
    let w = out.len().min(acc.len());
    let mut list: [&[u8]; 2 * MAX_RADIUS + 1] = [&[]; 2 * MAX_RADIUS + 1];
    for (j, row) in list.iter_mut().enumerate().take(2 * radius + 1) {
        *row = rows(j);
    }
    let list = &list[..2 * radius + 1];
    if taps.len() <= radius || list.iter().any(|r| r.len() < w) {
        return;
    }
    #[cfg(target_arch = "x86_64")]
    let done = {
        // SAFETY (both): the CPU has the feature (checked at run time; SSE2 is the
        // x86_64 baseline); `2 radius + 1` rows, each of at least `w` values (checked
        // above).
        let out = &mut out[..w];
        let mut start = 0;
        if simd::has_avx2() {
            start = unsafe { simd::column_u8_avx2(list, taps, radius, out, start) };
        }
        simd::last_block(w, start, |start| unsafe {
            simd::column_u8_sse2(list, taps, radius, out, start)
        })
    };
    #[cfg(not(target_arch = "x86_64"))]
    let done = 0;
    // Q14 taps times 2^6 fractional bits: shift by 14 - 6.
    let shift = KERNEL_BITS - FRAC_BITS;
    columns_scalar(
        list,
        taps,
        radius,
        shift,
        &mut acc[done..w],
        done,
        &mut out[done..w],
    );
}

/// Row `r + j - radius` clamped into `0..h`.
#[inline]
pub fn clamp_row(r: usize, j: usize, radius: usize, h: usize) -> usize {
    (r + j).saturating_sub(radius).min(h - 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kernel_sums_to_one_and_keeps_flat_rows_flat() {
        let mut taps = [0i32; KERNEL_STRIDE];
        for &(s, r) in &[(0.8f32, 3usize), (1.6, 5), (3.1, 10)] {
            make_kernel(s, r, &mut taps);
            let sum: i32 = taps[0] + 2 * taps[1..=r].iter().sum::<i32>();
            assert_eq!(sum, 1 << KERNEL_BITS);
            assert!(taps[..=r].windows(2).all(|p| p[0] >= p[1]));
            let input = [1234i16; 17];
            let mut pad = [0i16; 17 + 2 * KERNEL_STRIDE];
            let mut acc = [0i32; 17];
            let mut out = [0i16; 17];
            blur_row(&input, &taps, r, &mut pad, &mut acc, &mut out);
            assert_eq!(out, input);
        }
    }

    /// Widths of the exactness tests: odd and even, below and above the vector lanes.
    const WIDTHS: [usize; 5] = [1, 7, 8, 29, 64];
    type Rows = [[i32; 64]; 2 * MAX_RADIUS + 1];

    /// Pseudo-random rows of samples in `0..=max`, about half of them `max` (the
    /// largest sums).
    fn sample_rows(seed: &mut u32, max: u32) -> Rows {
        core::array::from_fn(|_| {
            core::array::from_fn(|_| {
                *seed = seed.wrapping_mul(1_103_515_245).wrapping_add(12345);
                if *seed >> 31 == 1 {
                    max as i32
                } else {
                    ((*seed >> 16) % (max + 1)) as i32
                }
            })
        })
    }

    /// The scalar definition: the symmetric kernel's exact sum at column `c`.
    fn exact_sum(taps: &[i32], radius: usize, rows: &Rows, c: usize) -> i32 {
        let mut sum = taps[0] * rows[radius][c];
        for j in 1..=radius {
            sum += taps[j] * (rows[radius - j][c] + rows[radius + j][c]);
        }
        sum
    }

    /// The vectorised path (x86_64) gives the integer sums of the scalar definition exactly,
    /// for every radius, odd and even widths and samples up to the largest level value.
    #[test]
    fn convolve_is_exact_for_every_radius() {
        let mut taps = [0i32; KERNEL_STRIDE];
        let mut seed = 12345u32;
        for radius in 0..=MAX_RADIUS {
            make_kernel(0.3 + radius as f32 / 3.0, radius, &mut taps);
            for w in WIDTHS {
                let data = sample_rows(&mut seed, 255 * 64);
                let data16 = data.map(|r| r.map(|v| v as i16));
                let rows: [&[i16]; 2 * MAX_RADIUS + 1] = core::array::from_fn(|j| &data16[j][..]);
                let rows = &rows[..2 * radius + 1];
                let mut acc = [0i32; 64];
                let mut out = [0i16; 64];
                convolve(rows, &taps, radius, &mut acc, &mut out[..w]);
                for (c, &o) in out[..w].iter().enumerate() {
                    let sum = exact_sum(&taps, radius, &data, c);
                    assert_eq!(
                        o,
                        round_shift(sum, KERNEL_BITS),
                        "radius {radius} width {w} column {c}"
                    );
                }
            }
        }
    }

    /// The u8 vertical pass (vectorised on x86_64) gives the scalar definition's
    /// rounded sums exactly, for every radius and odd and even widths.
    #[test]
    fn blur_column_u8_is_exact_for_every_radius() {
        let mut taps = [0i32; KERNEL_STRIDE];
        let mut seed = 777u32;
        for radius in 0..=MAX_RADIUS {
            make_kernel(0.3 + radius as f32 / 3.0, radius, &mut taps);
            for w in WIDTHS {
                let data = sample_rows(&mut seed, 255);
                let data8 = data.map(|r| r.map(|v| v as u8));
                let mut acc = [0i32; 64];
                let mut out = [0i16; 64];
                blur_column_u8(|j| &data8[j][..], &taps, radius, &mut acc, &mut out[..w]);
                for (c, &o) in out[..w].iter().enumerate() {
                    let sum = exact_sum(&taps, radius, &data, c);
                    let expected = ((sum + (1 << 7)) >> 8) as i16;
                    assert_eq!(o, expected, "radius {radius} width {w} column {c}");
                }
            }
        }
    }

    #[test]
    fn blur_matches_float_convolution() {
        let mut taps = [0i32; KERNEL_STRIDE];
        make_kernel(1.5, 5, &mut taps);
        let input: [i16; 37] = core::array::from_fn(|i| ((i * 37) % 101) as i16 * 64);
        let mut pad = [0i16; 37 + 2 * KERNEL_STRIDE];
        let mut acc = [0i32; 37];
        let mut out = [0i16; 37];
        blur_row(&input, &taps, 5, &mut pad, &mut acc, &mut out);
        for (c, &o) in out.iter().enumerate() {
            let mut f = 0.0f64;
            for j in -5i32..=5 {
                let k = taps[j.unsigned_abs() as usize] as f64 / 16384.0;
                let cc = (c as i32 + j).clamp(0, 36) as usize;
                f += k * input[cc] as f64;
            }
            assert!((f - o as f64).abs() <= 0.5 + 1e-9, "c {c}: {f} vs {o}");
        }
    }
}
