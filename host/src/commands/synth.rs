//! `phototraverse synth --scene NAME --out DIR`: renders a synthetic street
//! sequence with ground truth (see [`crate::synth`] and docs/datasets.md).
use crate::dataset::aiding;
use crate::synth::aiding::AidingOptions;
use crate::synth::realism::{CalibError, Imperfections};
use crate::synth::{generate, LayoutChoice, SynthOptions, SCENES};
use std::io::IsTerminal;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene: straight, curves, seed2014, seed2006, hard, handheld, drive or traffic.
    #[arg(long)]
    pub scene: String,
    /// Output directory (created).
    #[arg(long)]
    pub out: PathBuf,
    /// Number of epochs (default per scene).
    #[arg(long)]
    pub frames: Option<usize>,
    /// Random seed: same seed, same bytes.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Dataset layout (default: kitti for straight, curves, hard; rig for the seed scenes).
    #[arg(long, value_enum)]
    pub layout: Option<LayoutChoice>,
    /// Write depth maps depth_0/*.pfm, depth_1/*.pfm (distance along the camera's -z, metres).
    #[arg(long)]
    pub depth: bool,
    /// Calibration residuals of the written rig, e.g. `base=0.003,focal=0.003,pp_px=1,rel_deg=0.05`.
    #[arg(long, default_value = "")]
    pub calib_error: String,
    /// Optical blur, Gaussian sigma in pixels.
    #[arg(long, default_value_t = 0.0)]
    pub blur: f64,
    /// Vignetting: fractional darkening at the corners.
    #[arg(long, default_value_t = 0.0)]
    pub vignetting: f64,
    /// Exposure flicker: random gain change per image, +- fraction.
    #[arg(long, default_value_t = 0.0)]
    pub flicker: f64,
    /// Sensor read noise, grey levels (shot noise is added in proportion).
    #[arg(long, default_value_t = 0.0)]
    pub noise: f64,
    /// Write JPEG with this quality (1..100) instead of PNG.
    #[arg(long)]
    pub jpeg: Option<u8>,
    /// Rays per side on silhouette pixels (anti-aliasing).
    #[arg(long, default_value_t = 3)]
    pub edge_ss: u32,
    /// Image size WxH (e.g. 320x240) instead of the scene's: the same sensor and field of
    /// view sampled by fewer (or more) pixels.
    #[arg(long, value_parser = parse_size)]
    pub size: Option<(u32, u32)>,
    /// Render with the cameras of this rig file (yours, e.g. written by `rig import`)
    /// instead of the scene's, to try the traverse on your rig before you drive; the
    /// dataset then has the rig layout.
    #[arg(long, value_name = "RIG_TOML")]
    pub rig: Option<PathBuf>,
    /// Texture the facades with photographs (PNG, JPEG, ...): image files and the image
    /// files of directories, comma-separated; 1 to 3 cm per texel.
    #[arg(long, value_name = "PATH[,PATH...]", value_delimiter = ',')]
    pub photo_textures: Vec<PathBuf>,
    /// Typical sensor: `--realistic` = blur 0.6, vignetting 0.25, flicker 0.05, noise 1.5, JPEG 90, calib base=0.003,focal=0.003,pp_px=1,rel_deg=0.05.
    #[arg(long)]
    pub realistic: bool,
    /// Write gnss.txt: simulated GNSS fixes of the left perspective centre with this
    /// sigma per coordinate, metres (e.g. 0.02).
    #[arg(long, value_name = "SIGMA_M")]
    pub gnss: Option<f64>,
    /// GNSS fixes per second (default: one at every epoch).
    #[arg(long, value_name = "HZ", requires = "gnss")]
    pub gnss_rate: Option<f64>,
    /// No GNSS fixes in this time span, seconds (repeatable).
    #[arg(long, value_name = "START_S..END_S", value_parser = aiding::parse_span, requires = "gnss")]
    pub gnss_outage: Vec<(f64, f64)>,
    /// The GNSS antenna in the left camera's frame (x right, y up, z backwards), metres,
    /// e.g. `0,1.2,0.5`: the fixes are the antenna's, and gnss.toml states the lever arm.
    #[arg(
        long,
        value_name = "X,Y,Z",
        value_parser = numbers::<3>,
        requires = "gnss"
    )]
    pub gnss_lever_arm: Option<[f64; 3]>,
    /// Write the fixes as gnss_geodetic.txt (WGS84), the object frame's origin at
    /// LAT,LON (deg), H (m) with +Y at HEADING (deg from north), stated in gnss.toml.
    #[arg(
        long,
        value_name = "LAT,LON,H,HEADING",
        value_parser = numbers::<4>,
        requires = "gnss"
    )]
    pub gnss_geodetic: Option<[f64; 4]>,
    /// Write odometer.txt: the distance between epochs with this relative sigma
    /// (0.005 = 0.5 %).
    #[arg(long, value_name = "SIGMA")]
    pub odometer: Option<f64>,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    if !SCENES.contains(&a.scene.as_str()) {
        anyhow::bail!("unknown scene `{}` (one of {})", a.scene, SCENES.join(", "));
    }
    let mut opts = SynthOptions::new(&a.scene, a.out.clone());
    opts.frames = a.frames;
    opts.seed = a.seed;
    opts.layout = a.layout;
    opts.depth = a.depth;
    opts.edge_ss = a.edge_ss.clamp(1, 8);
    opts.progress = std::io::stderr().is_terminal();
    opts.imperfections = Imperfections {
        blur_px: a.blur,
        vignetting: a.vignetting,
        flicker: a.flicker,
        noise: a.noise,
    };
    opts.jpeg_quality = a.jpeg;
    opts.size = a.size;
    opts.rig = a
        .rig
        .as_deref()
        .map(crate::dataset::read_rig)
        .transpose()?
        .map(|(rig, _)| rig);
    opts.photo_textures = a.photo_textures.clone();
    opts.calib_error =
        CalibError::parse(&a.calib_error).map_err(|e| anyhow::anyhow!("--calib-error: {e}"))?;
    if a.realistic {
        opts.imperfections = Imperfections {
            blur_px: 0.6,
            vignetting: 0.25,
            flicker: 0.05,
            noise: 1.5,
        };
        opts.jpeg_quality = Some(a.jpeg.unwrap_or(90));
        if a.calib_error.is_empty() {
            opts.calib_error = CalibError {
                base: 0.003,
                focal: 0.003,
                pp_px: 1.0,
                rel_deg: 0.05,
            };
        }
    }
    let positive = |v: Option<f64>, name: &str| match v {
        Some(x) if !(x > 0.0 && x.is_finite()) => {
            Err(anyhow::anyhow!("--{name} {x}: must be a positive number"))
        }
        _ => Ok(v),
    };
    opts.aiding = AidingOptions {
        gnss_sigma_m: positive(a.gnss, "gnss")?,
        gnss_rate_hz: positive(a.gnss_rate, "gnss-rate")?,
        gnss_outages: a.gnss_outage.clone(),
        odometer_sigma: positive(a.odometer, "odometer")?,
        lever_arm_m: a.gnss_lever_arm.unwrap_or_default(),
        geodetic: a.gnss_geodetic,
    };
    let s = generate(&opts)?;
    println!(
        "synth {}: {} epochs ({}x{}, {} layout, {:.1} m) written to {}",
        s.scene,
        s.frames,
        s.width,
        s.height,
        s.layout,
        s.path_length_m,
        a.out.display()
    );
    println!(
        "render time per image: {:.1} ms mean, {:.1} ms max ({} threads, {:.1}% silhouette pixels supersampled)",
        s.render_ms_mean,
        s.render_ms_max,
        s.threads,
        s.edge_fraction * 100.0
    );
    if let Some(cpu) = s.render_cpu_ms_mean {
        println!(
            "render CPU time per image: {:.1} ms (= {:.1} ms wall on {} idle cores)",
            cpu,
            cpu / s.threads.max(1) as f64,
            s.threads
        );
    }
    Ok(())
}

/// `WxH` -> (W, H).
pub(crate) fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("{s:?}: expected WxH, e.g. 320x240"))?;
    let p = |v: &str| {
        v.trim()
            .parse::<u32>()
            .map_err(|_| format!("{s:?}: {v:?} is not a pixel count"))
    };
    Ok((p(w)?, p(h)?))
}

/// `N` comma-separated finite numbers.
fn numbers<const N: usize>(s: &str) -> Result<[f64; N], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>().ok().filter(|v| v.is_finite()))
        .collect::<Option<_>>()
        .ok_or_else(|| format!("`{s}`: expected {N} comma-separated numbers"))?;
    v.try_into()
        .map_err(|_| format!("`{s}`: expected {N} comma-separated numbers"))
}
