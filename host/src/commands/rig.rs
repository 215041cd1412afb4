//! `phototraverse rig`: rig files from other tools' calibrations.
use crate::dataset::calibration::{
    detect_format, read_kalibr, read_opencv, CalibrationFormat, PixelCamera, PixelStereo,
};
use crate::dataset::rigfile::parse_rig_file;
use crate::dataset::{default_datum, rig_toml_text};
use anyhow::{anyhow, bail, Context, Result};
use phototraverse_core::camera::CameraError;
use std::path::PathBuf;

/// Work with rig files (`rig.toml`).
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(subcommand)]
    pub command: RigCommand,
}

#[derive(clap::Subcommand, Debug)]
pub enum RigCommand {
    /// Write rig.toml from a stereo calibration made by OpenCV's stereoCalibrate
    /// (FileStorage YAML or XML: M1, D1, M2, D2, R, T and the image size) or by
    /// Kalibr (camchain YAML, pinhole cameras with radtan or no distortion). The
    /// lens model is carried over exactly (`distortion_model = "projection"`), so
    /// the rig projects as the calibration tool does; docs/conventions.md,
    /// "Calibrations from OpenCV and Kalibr", gives the mapping.
    Import(ImportArgs),
}

#[derive(clap::Args, Debug)]
pub struct ImportArgs {
    /// The calibration file(s). OpenCV users often save intrinsics and extrinsics
    /// apart: give both.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// Where to write the rig file.
    #[arg(short, long, default_value = "rig.toml")]
    pub output: PathBuf,
    /// The tool that wrote the calibration; by default told from the file (a
    /// camchain has cam0).
    #[arg(long, value_enum)]
    pub format: Option<CalibrationFormat>,
    /// OpenCV only: the unit of T, which is that of the calibration target's
    /// square size (Kalibr's is always metres).
    #[arg(long, value_enum, default_value_t = Unit::Mm)]
    pub translation_unit: Unit,
    /// OpenCV only: the image size WxH when the file does not state it
    /// (image_width and image_height, or imageSize).
    #[arg(long, value_parser = parse_size)]
    pub size: Option<(u32, u32)>,
    /// Kalibr only: the left and right cameras of the camchain.
    #[arg(long, default_value = "0,1", value_parser = parse_pair)]
    pub cameras: (usize, usize),
    /// Pixel size in mm, to state the interior orientation in millimetres; by
    /// default pixels serve as photo units (pixel_size_mm = 1), as for KITTI.
    #[arg(long, default_value_t = 1.0)]
    pub pixel_size_mm: f64,
}

#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum Unit {
    Mm,
    Cm,
    M,
}

impl Unit {
    fn metres(self) -> f64 {
        match self {
            Unit::Mm => 1e-3,
            Unit::Cm => 1e-2,
            Unit::M => 1.0,
        }
    }
}

fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("{s}: expected WxH, e.g. 640x480"))?;
    match (w.parse(), h.parse()) {
        (Ok(w), Ok(h)) if w > 0 && h > 0 => Ok((w, h)),
        _ => Err(format!("{s}: expected two positive integers, WxH")),
    }
}

fn parse_pair(s: &str) -> Result<(usize, usize), String> {
    let (a, b) = s
        .split_once(',')
        .ok_or_else(|| format!("{s}: expected two camera numbers, e.g. 0,1"))?;
    match (a.trim().parse(), b.trim().parse()) {
        (Ok(a), Ok(b)) => Ok((a, b)),
        _ => Err(format!("{s}: expected two camera numbers, e.g. 0,1")),
    }
}

pub fn run(args: Args) -> Result<()> {
    match args.command {
        RigCommand::Import(a) => import(a),
    }
}

fn import(a: ImportArgs) -> Result<()> {
    if !(a.pixel_size_mm > 0.0 && a.pixel_size_mm.is_finite()) {
        bail!("--pixel-size-mm {} must be positive", a.pixel_size_mm);
    }
    let format = match a.format {
        Some(f) => f,
        None => detect_format(&a.files[0])?,
    };
    let stereo = match format {
        CalibrationFormat::Opencv => read_opencv(&a.files, a.translation_unit.metres(), a.size)?,
        CalibrationFormat::Kalibr => {
            if a.files.len() != 1 {
                bail!(
                    "a Kalibr calibration is one camchain file; {} given",
                    a.files.len()
                );
            }
            read_kalibr(&a.files[0], a.cameras.0, a.cameras.1)?
        }
    };
    let rig = stereo.to_rig(a.pixel_size_mm);
    for (side, cam) in [("left", &rig.left), ("right", &rig.right)] {
        cam.validate().map_err(|e| {
            let why = match e {
                CameraError::DistortionDiverged => "its distortion folds the image over itself \
                     (a polynomial extrapolated past its data, or k3 left out): no inverse exists"
                    .to_string(),
                e => e.to_string(),
            };
            anyhow!("{}: the {side} camera: {why}", a.files[0].display())
        })?;
    }
    let text = rig_toml_text(&rig, &default_datum());
    // What is written must read back: the same checks as every run's.
    parse_rig_file(&text, &a.output)?;
    std::fs::write(&a.output, &text).with_context(|| format!("writing {}", a.output.display()))?;
    print_summary(&stereo, format, &a);
    Ok(())
}

fn print_summary(s: &PixelStereo, format: CalibrationFormat, a: &ImportArgs) {
    let source = match format {
        CalibrationFormat::Opencv => "OpenCV",
        CalibrationFormat::Kalibr => "Kalibr",
    };
    println!("{source} calibration read from {}", a.files[0].display());
    for (name, c) in [("left", &s.left), ("right", &s.right)] {
        println!("  {name:5} {}", describe(c));
    }
    let t = s.translation_m * 1e3;
    let angle = s.rotation.trace().clamp(-1.0, 3.0);
    println!(
        "  base {:.2} mm (T = {:.2}, {:.2}, {:.2} mm), relative rotation {:.3} deg",
        t.norm(),
        t[0],
        t[1],
        t[2],
        ((angle - 1.0) / 2.0).clamp(-1.0, 1.0).acos().to_degrees()
    );
    println!(
        "wrote {} (distortion_model = \"projection\", photo units {} mm per pixel; \
         no [precision]: the calibration check assumes the defaults)",
        a.output.display(),
        a.pixel_size_mm
    );
}

fn describe(c: &PixelCamera) -> String {
    format!(
        "{}x{}, fx {:.2} fy {:.2} cx {:.2} cy {:.2} px, k1 {:.4} k2 {:.4} k3 {:.4}, p1 {:.5} p2 {:.5}",
        c.width_px,
        c.height_px,
        c.fx,
        c.fy,
        c.cx,
        c.cy,
        c.radial[0],
        c.radial[1],
        c.radial[2],
        c.tangential[0],
        c.tangential[1]
    )
}
