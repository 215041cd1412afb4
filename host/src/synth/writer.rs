//! Writing a synthetic dataset: images (PNG or JPEG), calibration in either
//! layout, times, ground truth and depth maps.
use anyhow::Context;
use image::codecs::jpeg::JpegEncoder;
use image::codecs::png::{CompressionType, FilterType, PngEncoder};
use image::{ExtendedColorType, ImageEncoder};
use std::io::Write;
use std::path::Path;

/// Writes an 8-bit gray image as PNG, or JPEG when `jpeg_quality` is given.
pub fn write_gray(
    path: &Path,
    data: &[u8],
    w: u32,
    h: u32,
    jpeg_quality: Option<u8>,
) -> anyhow::Result<()> {
    let file = std::fs::File::create(path)
        .with_context(|| format!("{}: cannot create", path.display()))?;
    let buf = std::io::BufWriter::new(file);
    match jpeg_quality {
        Some(q) => JpegEncoder::new_with_quality(buf, q.clamp(1, 100)).write_image(
            data,
            w,
            h,
            ExtendedColorType::L8,
        ),
        None => PngEncoder::new_with_quality(buf, CompressionType::Fast, FilterType::Adaptive)
            .write_image(data, w, h, ExtendedColorType::L8),
    }
    .with_context(|| format!("{}: cannot encode", path.display()))
}

/// Writes a depth map as PFM (`Pf`, one float channel, little-endian, rows
/// bottom-up as PFM stores them; `inf` where no surface).
pub fn write_pfm(path: &Path, data: &[f32], w: usize, h: usize) -> anyhow::Result<()> {
    let mut bytes = Vec::with_capacity(w * h * 4 + 32);
    bytes.extend_from_slice(format!("Pf\n{w} {h}\n-1.0\n").as_bytes());
    for r in (0..h).rev() {
        for v in &data[r * w..(r + 1) * w] {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    let mut f = std::fs::File::create(path)
        .with_context(|| format!("{}: cannot create", path.display()))?;
    f.write_all(&bytes)
        .with_context(|| format!("{}: cannot write", path.display()))
}

/// Reads a PFM written by [`write_pfm`] (or any one-channel PFM) into
/// top-down rows: `(width, height, data)`.
pub fn read_pfm(path: &Path) -> anyhow::Result<(usize, usize, Vec<f32>)> {
    let bytes = std::fs::read(path).with_context(|| format!("{}: cannot read", path.display()))?;
    let mut fields = Vec::new();
    let mut pos = 0;
    while fields.len() < 4 && pos < bytes.len() {
        while pos < bytes.len() && bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        let start = pos;
        while pos < bytes.len() && !bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        fields.push(String::from_utf8_lossy(&bytes[start..pos]).into_owned());
    }
    pos += 1; // the single whitespace after the scale
    anyhow::ensure!(
        fields.len() == 4 && fields[0] == "Pf",
        "{}: not a one-channel PFM",
        path.display()
    );
    let w: usize = fields[1]
        .parse()
        .with_context(|| format!("{}: bad width", path.display()))?;
    let h: usize = fields[2]
        .parse()
        .with_context(|| format!("{}: bad height", path.display()))?;
    let scale: f32 = fields[3]
        .parse()
        .with_context(|| format!("{}: bad scale", path.display()))?;
    let need = w
        .checked_mul(h)
        .and_then(|n| n.checked_mul(4))
        .context("PFM size overflows")?;
    anyhow::ensure!(
        bytes.len() >= pos + need,
        "{}: truncated PFM",
        path.display()
    );
    let mut data = vec![0.0f32; w * h];
    for r in 0..h {
        for c in 0..w {
            let i = pos + ((h - 1 - r) * w + c) * 4;
            let b = [bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]];
            data[r * w + c] = if scale < 0.0 {
                f32::from_le_bytes(b)
            } else {
                f32::from_be_bytes(b)
            };
        }
    }
    Ok((w, h, data))
}
