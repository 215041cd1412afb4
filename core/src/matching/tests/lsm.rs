//! Least-squares matching: the sub-pixel shift of a template under a change of gain and
//! offset and under a brightness ramp, the same from every start, along a row only when
//! asked, and no guess along an edge.
use super::refine::{sample_template, Correlator, TEMPLATE_LEN};
use crate::image::ImageView;
extern crate std;
use std::vec::Vec;

/// Smooth texture: sines of several directions and a few blobs (grey levels about 128).
fn surface(x: f64, y: f64) -> f64 {
    let mut v = 128.0
        + 35.0 * libm::sin(0.31 * x + 0.17 * y)
        + 30.0 * libm::sin(0.13 * x - 0.29 * y + 1.0)
        + 20.0 * libm::sin(0.43 * x + 0.37 * y + 2.0);
    for (cx, cy, a) in [(58.0, 28.0, 40.0), (64.0, 33.0, -35.0), (61.0, 25.0, 25.0)] {
        let d2 = (x - cx) * (x - cx) + (y - cy) * (y - cy);
        v += a * libm::exp(-d2 / 6.0);
    }
    v
}

/// The surface seen `shift` pixels further on, with a gain and an offset, as u8.
fn image(w: usize, h: usize, shift: [f64; 2], gain: f64, offset: f64) -> Vec<u8> {
    shaded(w, h, shift, gain, |_, _| offset)
}

/// The same with a brightness `light(x, y)` added (vignetting, uneven light).
fn shaded(
    w: usize,
    h: usize,
    shift: [f64; 2],
    gain: f64,
    light: impl Fn(f64, f64) -> f64,
) -> Vec<u8> {
    (0..w * h)
        .map(|i| {
            let (c, r) = ((i % w) as f64, (i / w) as f64);
            let (x, y) = (c - shift[0], r - shift[1]);
            (light(c, r) + gain * surface(x, y))
                .round()
                .clamp(0.0, 255.0) as u8
        })
        .collect()
}

const W: usize = 120;
const H: usize = 60;
const AT: [f32; 2] = [60.0, 30.0];

fn template(img: &[u8]) -> [f32; TEMPLATE_LEN] {
    let mut tpl = [0f32; TEMPLATE_LEN];
    sample_template(&ImageView::new(img, W, H).unwrap(), AT, 4, &mut tpl).unwrap();
    tpl
}

#[test]
fn least_squares_finds_a_subpixel_shift_under_gain_and_offset_from_any_start() {
    let shift = [0.37f32, -0.23];
    let tpl = template(&image(W, H, [0.0; 2], 1.0, 0.0));
    let moved = image(W, H, [shift[0] as f64, shift[1] as f64], 0.8, 15.0);
    let view = ImageView::new(&moved, W, H).unwrap();
    let truth = [AT[0] + shift[0], AT[1] + shift[1]];
    let mut found = Vec::new();
    for (dx, dy) in [
        (-0.4, 0.0),
        (0.4, 0.3),
        (0.0, -0.4),
        (0.25, 0.25),
        (-0.3, -0.35),
    ] {
        let start = [truth[0] + dx, truth[1] + dy];
        let at = Correlator::new()
            .least_squares(&tpl, 4, &view, start, (1, 1))
            .unwrap_or_else(|| panic!("no convergence from {start:?}"));
        found.push(at);
    }
    for at in &found {
        let err = [at[0] - truth[0], at[1] - truth[1]];
        // Bilinear resampling of the u8 image errs by a few hundredths of a pixel here
        // (measured 0.02 / 0.01; the correlation's re-centred parabola 0.07 / 0.01).
        assert!(
            err[0].abs() < 0.04 && err[1].abs() < 0.04,
            "{at:?} against {truth:?}"
        );
        // The same position from every start (to the convergence tolerance).
        let d = [at[0] - found[0][0], at[1] - found[0][1]];
        assert!(
            d[0].abs() < 0.004 && d[1].abs() < 0.004,
            "{at:?} against {:?}",
            found[0]
        );
    }
}

#[test]
fn least_squares_ignores_a_brightness_ramp() {
    // 2 grey levels per pixel across the template: 16 from one side to the other.
    let shift = [0.3f32, 0.2];
    let tpl = template(&image(W, H, [0.0; 2], 1.0, 0.0));
    let ramp = shaded(W, H, [0.3, 0.2], 0.9, |c, r| {
        2.0 * (c - 60.0) - 1.0 * (r - 30.0)
    });
    let view = ImageView::new(&ramp, W, H).unwrap();
    let truth = [AT[0] + shift[0], AT[1] + shift[1]];
    let at = Correlator::new()
        .least_squares(&tpl, 4, &view, [truth[0] - 0.2, truth[1] + 0.2], (1, 1))
        .unwrap();
    let err = [at[0] - truth[0], at[1] - truth[1]];
    assert!(
        err[0].abs() < 0.04 && err[1].abs() < 0.04,
        "{at:?} against {truth:?}"
    );
}

#[test]
fn least_squares_along_a_row_keeps_the_row() {
    let tpl = template(&image(W, H, [0.0; 2], 1.0, 0.0));
    let moved = image(W, H, [-0.41, 0.0], 1.0, 0.0);
    let view = ImageView::new(&moved, W, H).unwrap();
    let start = [AT[0] - 0.1, AT[1]];
    let at = Correlator::new()
        .least_squares(&tpl, 4, &view, start, (1, 0))
        .unwrap();
    assert_eq!(at[1], AT[1]);
    // Measured 0.043 px off (bilinear resampling; see the test above).
    assert!((at[0] - (AT[0] - 0.41)).abs() < 0.06, "{at:?}");
}

#[test]
fn least_squares_refuses_an_edge_and_a_flat_patch() {
    // A vertical edge: the shift along it is not determined.
    let edge: Vec<u8> = (0..W * H)
        .map(|i| if i % W < 60 { 60 } else { 190 })
        .collect();
    let tpl = template(&edge);
    let view = ImageView::new(&edge, W, H).unwrap();
    assert_eq!(
        Correlator::new().least_squares(&tpl, 4, &view, [60.2, 30.0], (1, 1)),
        None
    );
    // Along the row the edge does determine it.
    let at = Correlator::new().least_squares(&tpl, 4, &view, [60.2, 30.0], (1, 0));
    assert!(at.is_some_and(|a| (a[0] - 60.0).abs() < 0.05), "{at:?}");
    let flat = [100u8; W * H];
    let view = ImageView::new(&flat, W, H).unwrap();
    assert_eq!(
        Correlator::new().least_squares(&tpl, 4, &view, AT, (1, 1)),
        None
    );
}

/// Pseudo-random values in -100..100 from `seed` (a linear congruential sequence).
fn values(seed: u32) -> impl FnMut() -> f32 {
    let mut state = seed;
    move || {
        state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (state >> 8) as f32 / (1u32 << 24) as f32 * 200.0 - 100.0
    }
}

/// The SSE kernel of the normal equations' sums gives the scalar definition's sums to
/// the bit (the same products, summed lane by lane in the same order), so a target
/// without SSE matches as the host does.
#[test]
fn least_squares_sums_on_sse_are_the_scalar_sums() {
    use super::super::lsm::{sum_row, sum_row_scalar, LANES, ROW, SUMS};
    let mut next = values(12345);
    for _ in 0..50 {
        let cols: [[f32; ROW]; 5] = core::array::from_fn(|_| core::array::from_fn(|_| next()));
        let start: [[f32; LANES]; SUMS] =
            core::array::from_fn(|_| core::array::from_fn(|_| next()));
        for n in (LANES..=ROW).step_by(LANES) {
            let (mut acc, mut line) = (start, [[1.5f32; LANES]; 4]);
            let (mut acc_s, mut line_s) = (start, [[1.5f32; LANES]; 4]);
            sum_row(&cols, n, &mut acc, &mut line);
            sum_row_scalar(&cols, n, &mut acc_s, &mut line_s);
            assert_eq!(
                acc.map(|a| a.map(f32::to_bits)),
                acc_s.map(|a| a.map(f32::to_bits))
            );
            assert_eq!(
                line.map(|a| a.map(f32::to_bits)),
                line_s.map(|a| a.map(f32::to_bits))
            );
        }
    }
}

/// Summing only the groups a template reaches gives the sums of the whole row to the
/// bit when the samples past it are zero: the zeros change no sum.
#[test]
fn least_squares_sums_skip_the_zeros_past_the_template() {
    use super::super::lsm::{sum_row, LANES, ROW, SUMS};
    let mut next = values(777);
    for n in 1..=ROW {
        let mut cols = [[0f32; ROW]; 5];
        for col in cols.iter_mut() {
            for x in col[..n].iter_mut() {
                *x = next();
            }
        }
        // Zeros of both signs inside the template, as the columns can hold.
        cols[0][0] = -0.0;
        cols[3][n - 1] = 0.0;
        let (mut part, mut part_line) = ([[0f32; LANES]; SUMS], [[0f32; LANES]; 4]);
        let (mut whole, mut whole_line) = ([[0f32; LANES]; SUMS], [[0f32; LANES]; 4]);
        sum_row(&cols, n, &mut part, &mut part_line);
        sum_row(&cols, ROW, &mut whole, &mut whole_line);
        assert_eq!(
            part.map(|a| a.map(f32::to_bits)),
            whole.map(|a| a.map(f32::to_bits)),
            "n {n}"
        );
        assert_eq!(
            part_line.map(|a| a.map(f32::to_bits)),
            whole_line.map(|a| a.map(f32::to_bits)),
            "n {n}"
        );
    }
}

/// A Gauss-Newton step `k` times too long swings about the optimum, reversed and
/// `k - 1` times as long each time; the step length measured from the first reversal
/// ends the swing.
#[test]
fn step_length_ends_a_swing_about_the_optimum() {
    use super::super::lsm::{StepLength, ITERATIONS, SETTLED_PX};
    for k in [1.5f32, 1.9, 2.5, 4.0] {
        let (mut x, target) = (0.0f32, [0.4f32, -0.3]);
        let mut y = 0.0f32;
        let mut length = StepLength::default();
        let mut settled = false;
        for _ in 0..ITERATIONS {
            let d = length.take([k * (target[0] - x), k * (target[1] - y)]);
            x += d[0];
            y += d[1];
            if d[0].abs() < SETTLED_PX && d[1].abs() < SETTLED_PX {
                settled = true;
                break;
            }
        }
        assert!(settled, "k = {k}: at {x}, {y}");
        assert!((x - target[0]).abs() < 0.01 && (y - target[1]).abs() < 0.01);
    }
}

/// Fine texture: central differences are flatter than the image between samples, and
/// the plain Gauss-Newton steps overshoot (without the step length they did not settle
/// here).
fn fine(w: usize, h: usize, shift: [f64; 2]) -> Vec<u8> {
    (0..w * h)
        .map(|i| {
            let (x, y) = ((i % w) as f64 - shift[0], (i / w) as f64 - shift[1]);
            (128.0
                + 40.0 * libm::sin(1.4 * x + 0.3 * y)
                + 35.0 * libm::sin(0.4 * x - 1.3 * y + 1.0)
                + 25.0 * libm::sin(0.9 * x + 0.8 * y + 2.0))
            .round()
            .clamp(0.0, 255.0) as u8
        })
        .collect()
}

#[test]
fn least_squares_settles_on_fine_texture() {
    let shift = [0.3f32, -0.2];
    let tpl = template(&fine(W, H, [0.0; 2]));
    let moved = fine(W, H, [shift[0] as f64, shift[1] as f64]);
    let view = ImageView::new(&moved, W, H).unwrap();
    let truth = [AT[0] + shift[0], AT[1] + shift[1]];
    for (dx, dy) in [(-0.35, 0.0), (0.3, 0.25), (0.0, -0.35), (-0.25, 0.3)] {
        let start = [truth[0] + dx, truth[1] + dy];
        let at = Correlator::new()
            .least_squares(&tpl, 4, &view, start, (1, 1))
            .unwrap_or_else(|| panic!("no convergence from {start:?}"));
        let err = [at[0] - truth[0], at[1] - truth[1]];
        assert!(
            err[0].abs() < 0.05 && err[1].abs() < 0.05,
            "{at:?} against {truth:?}"
        );
    }
}
