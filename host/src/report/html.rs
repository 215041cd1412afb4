//! `report.html`: a self-contained page with SVG plots (plotters) and tables.
use super::glance;
use super::records::{CapacityLine, MemoryLine, RunReport};
use anyhow::{anyhow, Context, Result};
use plotters::prelude::*;
use std::fmt::Write as _;
use std::path::Path;

const SIZE: (u32, u32) = (720, 400);
/// Ten distinct colours (Tableau 10), so that the stages' lines never share one.
const PALETTE: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

/// One named polyline of a chart.
pub(crate) struct Series {
    pub(crate) name: String,
    pub(crate) points: Vec<(f64, f64)>,
}

fn bounds(series: &[Series], equal_aspect: bool) -> (std::ops::Range<f64>, std::ops::Range<f64>) {
    let pts = series
        .iter()
        .flat_map(|s| s.points.iter())
        .filter(|p| p.0.is_finite() && p.1.is_finite());
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in pts {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    if x0 > x1 {
        return (0.0..1.0, 0.0..1.0);
    }
    let pad = |a: f64, b: f64| {
        let m = ((b - a) * 0.05).max(1e-9);
        (a - m, b + m)
    };
    let (mut xa, mut xb) = pad(x0, x1);
    let (mut ya, mut yb) = pad(y0, y1);
    if equal_aspect {
        // Same metres per pixel on both axes, so a top view keeps its shape.
        let scale = ((xb - xa) / SIZE.0 as f64).max((yb - ya) / SIZE.1 as f64);
        let (cx, cy) = ((xa + xb) / 2.0, (ya + yb) / 2.0);
        xa = cx - scale * SIZE.0 as f64 / 2.0;
        xb = cx + scale * SIZE.0 as f64 / 2.0;
        ya = cy - scale * SIZE.1 as f64 / 2.0;
        yb = cy + scale * SIZE.1 as f64 / 2.0;
    }
    (xa..xb, ya..yb)
}

/// How a chart draws its series.
#[derive(Clone, Copy, PartialEq)]
enum Mark {
    Lines,
    /// Markers: series that break off and resume (epochs with and without a GNSS fix)
    /// keep one colour and one legend entry each.
    Dots,
}

/// An SVG chart of `series` as lines (`equal`: one scale on both axes).
pub(crate) fn line_chart(
    title: &str,
    xl: &str,
    yl: &str,
    series: &[Series],
    equal: bool,
) -> Result<String> {
    chart(title, (xl, yl), series, equal, Mark::Lines)
}

fn scatter_chart(
    title: &str,
    xl: &str,
    yl: &str,
    series: &[Series],
    equal: bool,
) -> Result<String> {
    chart(title, (xl, yl), series, equal, Mark::Dots)
}

fn chart(
    title: &str,
    (xl, yl): (&str, &str),
    series: &[Series],
    equal: bool,
    mark: Mark,
) -> Result<String> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(|e| anyhow!("{e:?}"))?;
        let (xr, yr) = bounds(series, equal);
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 18))
            .margin(10)
            .x_label_area_size(36)
            .y_label_area_size(60)
            .build_cartesian_2d(xr, yr)
            .map_err(|e| anyhow!("{e:?}"))?;
        chart
            .configure_mesh()
            .x_desc(xl)
            .y_desc(yl)
            .draw()
            .map_err(|e| anyhow!("{e:?}"))?;
        for (i, s) in series.iter().enumerate() {
            let color = PALETTE[i % PALETTE.len()];
            let points = s.points.iter().copied();
            match mark {
                Mark::Lines => chart
                    .draw_series(LineSeries::new(points, color.stroke_width(2)))
                    .map_err(|e| anyhow!("{e:?}"))?,
                Mark::Dots => chart
                    .draw_series(points.map(|p| Circle::new(p, 2, color.filled())))
                    .map_err(|e| anyhow!("{e:?}"))?,
            };
        }
        root.present().map_err(|e| anyhow!("{e:?}"))?;
    }
    if series.len() > 1 {
        svg.push_str(&legend(series));
    }
    Ok(svg)
}

/// The key of a chart's series, under it in the page: drawn inside the plot it
/// covered the data.
fn legend(series: &[Series]) -> String {
    let mut html = String::from("<p class=\"legend\">");
    for (i, s) in series.iter().enumerate() {
        let RGBColor(r, g, b) = PALETTE[i % PALETTE.len()];
        let _ = write!(
            html,
            "<span style=\"color:rgb({r},{g},{b})\">&#9644;</span> {} &nbsp; ",
            html_escape(&s.name)
        );
    }
    html.push_str("</p>");
    html
}

/// The GNSS sections, when the run had fixes: the trajectory by fix availability,
/// the position error against its predicted 3 sd (with ground truth) and the
/// adjusted positions' residuals to the fixes.
fn gnss_sections(report: &RunReport) -> Result<Vec<(&'static str, String)>> {
    if report.epochs.iter().all(|e| e.gnss.is_none()) {
        return Ok(Vec::new());
    }
    let mut out = Vec::new();
    let top = |fix: bool| -> Vec<(f64, f64)> {
        report
            .epochs
            .iter()
            .filter(|e| e.gnss.is_some() == fix)
            .map(|e| (e.left.x, e.left.y))
            .collect()
    };
    let trajectory = [
        Series {
            name: "with a GNSS fix".into(),
            points: top(true),
        },
        Series {
            name: "without (outage)".into(),
            points: top(false),
        },
    ];
    out.push((
        "GNSS availability",
        scatter_chart(
            "Trajectory by GNSS availability (top view)",
            "X (m)",
            "Y (m)",
            &trajectory,
            true,
        )?,
    ));
    let time = |e: &super::EpochRecord| e.time.unwrap_or(e.epoch as f64);
    if let Some(gt) = &report.ground_truth {
        let distance = |c: [f64; 3], g: &[f64; 3]| {
            ((c[0] - g[0]).powi(2) + (c[1] - g[1]).powi(2) + (c[2] - g[2]).powi(2)).sqrt()
        };
        let error: Vec<(f64, f64)> = report
            .epochs
            .iter()
            .zip(gt)
            .map(|(e, g)| (time(e), distance([e.left.x, e.left.y, e.left.z], g)))
            .collect();
        // The firmware's own positions, before the smoothing over all the fixes.
        let realtime: Vec<(f64, f64)> = report
            .epochs
            .iter()
            .zip(gt)
            .filter_map(|(e, g)| Some((time(e), distance(e.realtime_centre_m?, g))))
            .collect();
        let sd3: Vec<(f64, f64)> = report
            .epochs
            .iter()
            .filter_map(|e| {
                let s = e.left.sigma?;
                Some((
                    time(e),
                    3.0 * (s[3] * s[3] + s[4] * s[4] + s[5] * s[5]).sqrt(),
                ))
            })
            .collect();
        let mut s = vec![
            Series {
                name: "position error".into(),
                points: error,
            },
            Series {
                name: "3 x predicted sd".into(),
                points: sd3,
            },
        ];
        if !realtime.is_empty() {
            s.push(Series {
                name: "error on board (before smoothing)".into(),
                points: realtime,
            });
        }
        out.push((
            "Position error and its predicted precision",
            line_chart(
                "Position error against the truth",
                "time (s)",
                "m",
                &s,
                false,
            )?,
        ));
    }
    let residual = |a: usize| Series {
        name: ["X", "Y", "Z"][a].into(),
        points: report
            .epochs
            .iter()
            .filter_map(|e| Some((time(e), e.gnss?.residual_m[a])))
            .collect(),
    };
    out.push((
        "GNSS residuals",
        scatter_chart(
            "Adjusted position minus GNSS fix",
            "time (s)",
            "m",
            &[residual(0), residual(1), residual(2)],
            false,
        )?,
    ));
    Ok(out)
}

/// Speed per epoch with its standard deviation band.
fn speed_section(report: &RunReport) -> Result<Option<String>> {
    let pts = |k: f64| -> Vec<(f64, f64)> {
        report
            .epochs
            .iter()
            .filter_map(|e| {
                let v = e.velocity?;
                let sd = v.sd_speed_m_s.unwrap_or(0.0);
                Some((
                    e.time.unwrap_or(e.epoch as f64),
                    3.6 * (v.speed_m_s + k * sd),
                ))
            })
            .collect()
    };
    let speed = pts(0.0);
    if speed.is_empty() {
        return Ok(None);
    }
    let s = [
        Series {
            name: "speed".into(),
            points: speed,
        },
        Series {
            name: "+ 1 sd".into(),
            points: pts(1.0),
        },
        Series {
            name: "- 1 sd".into(),
            points: pts(-1.0),
        },
    ];
    line_chart("Speed of the left camera", "time (s)", "km/h", &s, false).map(Some)
}

fn histogram(title: &str, xl: &str, values: &[f32], bins: usize, max: f64) -> Result<String> {
    let mut counts = vec![0u32; bins];
    for &v in values {
        let b = ((v.abs() as f64 / max) * bins as f64) as usize;
        if b < bins {
            counts[b] += 1;
        }
    }
    let top = counts.iter().copied().max().unwrap_or(0).max(1) as f64;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(|e| anyhow!("{e:?}"))?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 18))
            .margin(10)
            .x_label_area_size(36)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..max, 0.0..top * 1.05)
            .map_err(|e| anyhow!("{e:?}"))?;
        chart
            .configure_mesh()
            .x_desc(xl)
            .y_desc("count")
            .draw()
            .map_err(|e| anyhow!("{e:?}"))?;
        let w = max / bins as f64;
        chart
            .draw_series(counts.iter().enumerate().map(|(i, &c)| {
                let x = i as f64 * w;
                Rectangle::new([(x, 0.0), (x + w, c as f64)], PALETTE[0].filled())
            }))
            .map_err(|e| anyhow!("{e:?}"))?;
        root.present().map_err(|e| anyhow!("{e:?}"))?;
    }
    Ok(svg)
}

/// Histogram range of the residuals: the 99th percentile rounded up to a
/// tenth of a pixel (at least 0.5 px), and how many lie beyond it.
fn residual_range(values: &[f32]) -> (f64, usize) {
    let mut v: Vec<f32> = values.iter().map(|x| x.abs()).collect();
    v.sort_by(|a, b| a.total_cmp(b));
    let p99 = v
        .get((v.len() * 99 / 100).min(v.len().saturating_sub(1)))
        .map_or(1.0, |x| *x as f64);
    let max = ((p99 * 10.0).ceil() / 10.0).max(0.5);
    let beyond = v.iter().filter(|x| **x as f64 >= max).count();
    (max, beyond)
}

fn per_epoch(
    report: &RunReport,
    f: impl Fn(&super::EpochRecord) -> Option<f64>,
) -> Vec<(f64, f64)> {
    report
        .epochs
        .iter()
        .filter_map(|e| f(e).map(|v| (e.epoch as f64, v)))
        .collect()
}

/// Distance travelled along the ground truth at each epoch, and the estimate's
/// position error as a percentage of it.
/// The KITTI drift against segment length (`crate::eval::Evaluation::per_length` as
/// JSON): translation (%) and rotation (deg/m) charts, as the devkit plots them.
pub(crate) fn drift_per_length_charts(per_length: &[serde_json::Value]) -> Result<[String; 2]> {
    let series = |key: &str, name: &str| {
        [Series {
            name: name.into(),
            points: per_length
                .iter()
                .filter(|l| l.get("segments").and_then(|v| v.as_u64()).unwrap_or(0) > 0)
                .filter_map(|l| Some((l.get("length_m")?.as_f64()?, l.get(key)?.as_f64()?)))
                .collect(),
        }]
    };
    Ok([
        line_chart(
            "Translation drift against segment length",
            "segment length (m)",
            "translation error (%)",
            &series("translation_pct", "translation drift"),
            false,
        )?,
        line_chart(
            "Rotation drift against segment length",
            "segment length (m)",
            "rotation error (deg/m)",
            &series("rotation_deg_per_m", "rotation drift"),
            false,
        )?,
    ])
}

fn drift_series(report: &RunReport) -> Option<Vec<(f64, f64)>> {
    let gt = report.ground_truth.as_ref()?;
    let mut dist = 0.0;
    let mut out = Vec::new();
    for (i, e) in report.epochs.iter().enumerate().take(gt.len()) {
        if i > 0 {
            let d: f64 = (0..3).map(|k| (gt[i][k] - gt[i - 1][k]).powi(2)).sum();
            dist += d.sqrt();
        }
        if dist > 0.0 {
            let err: f64 = [
                e.left.x - gt[i][0],
                e.left.y - gt[i][1],
                e.left.z - gt[i][2],
            ]
            .iter()
            .map(|v| v * v)
            .sum::<f64>()
            .sqrt();
            out.push((dist, 100.0 * err / dist));
        }
    }
    Some(out)
}

fn stage_series(report: &RunReport) -> Vec<Series> {
    let mut names: Vec<&String> = report
        .epochs
        .iter()
        .flat_map(|e| e.stage_ms.keys())
        .collect();
    names.sort();
    names.dedup();
    names
        .into_iter()
        .map(|n| Series {
            name: n.clone(),
            points: per_epoch(report, |e| e.stage_ms.get(n).copied()),
        })
        .collect()
}

fn memory_table(lines: &[MemoryLine]) -> String {
    let mut t = String::from(
        "<table><tr><th>component</th><th>kind</th><th>predicted (bytes)</th><th>carved (bytes)</th></tr>",
    );
    for l in lines {
        let measured = l.measured_bytes.map_or("-".to_string(), |m| m.to_string());
        // A stage's total (and the whole's) carries the measurement: set it apart.
        let style = if l.measured_bytes.is_some() {
            " style=\"font-weight:bold\""
        } else {
            ""
        };
        let _ = write!(
            t,
            "<tr{style}><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            html_escape(&l.name),
            html_escape(&l.kind),
            l.predicted_bytes,
            measured
        );
    }
    t.push_str("</table>");
    t
}

fn capacity_table(lines: &[CapacityLine]) -> String {
    let mut t =
        String::from("<table><tr><th>capacity</th><th>reserved (items)</th><th>peak use</th></tr>");
    for c in lines {
        let _ = write!(
            t,
            "<tr><td>{}</td><td>{}</td><td>{}</td></tr>",
            html_escape(&c.name),
            c.reserved,
            c.peak
        );
    }
    t.push_str("</table>");
    t
}

/// The run on the emulated microcontroller: its image's sections, its stack, and the
/// instructions per stage with the labelled time estimate.
fn target_section(t: &crate::mcu::TargetReport) -> String {
    let mut s = format!(
        "<h2>On the microcontroller ({})</h2><p>{}</p>\
         <table><tr><th>section</th><th>address</th><th>bytes</th></tr>",
        html_escape(&t.part),
        html_escape(&t.description)
    );
    for sec in &t.sections {
        let _ = write!(
            s,
            "<tr><td>{}</td><td>0x{:08x}</td><td>{}</td></tr>",
            html_escape(&sec.name),
            sec.address,
            sec.bytes
        );
    }
    if let Some(st) = &t.stack {
        let _ = write!(
            s,
            "<tr><td>stack (high-water mark of {} reserved)</td><td></td><td>{}</td></tr>",
            st.reserved_bytes, st.used_bytes
        );
    }
    s.push_str("</table><table><tr><th>stage</th><th>instructions per epoch (median)</th><th>share</th></tr>");
    for st in &t.time.stages {
        let _ = write!(
            s,
            "<tr><td>{}</td><td>{:.2} M</td><td>{:.1} %</td></tr>",
            html_escape(&st.stage),
            st.instructions_median / 1e6,
            100.0 * st.share
        );
    }
    let e = &t.time.estimate;
    let _ = write!(
        s,
        "</table><p>{:.1} M instructions per epoch (median; largest {:.1} M), counted by {}. \
         <b>Estimate, not a measurement:</b> {:.0} ms per epoch on an {} at {:.0} MHz and {} \
         cycles per instruction.</p>",
        t.time.instructions_per_epoch_median / 1e6,
        t.time.instructions_per_epoch_max / 1e6,
        html_escape(&t.time.method),
        e.ms_per_epoch_median,
        html_escape(&e.part),
        e.clock_hz / 1e6,
        e.cycles_per_instruction
    );
    s
}

/// The evaluation (`crate::eval::Evaluation` as JSON) as two tables, rounded for reading.
fn evaluation_table(ev: &serde_json::Value) -> String {
    let num = |k: &str| ev.get(k).and_then(serde_json::Value::as_f64);
    let fmt = |v: Option<f64>, digits: usize, unit: &str| {
        v.map_or("n/a".to_string(), |v| format!("{v:.digits$} {unit}"))
    };
    let rows = [
        (
            "translation drift (KITTI segments)",
            fmt(num("translation_drift_pct"), 3, "%"),
        ),
        (
            "rotation drift",
            fmt(num("rotation_drift_deg_per_m"), 4, "deg/m"),
        ),
        ("ATE, no alignment", fmt(num("ate_rmse_m"), 3, "m")),
        (
            "ATE, rigid alignment (SE(3))",
            fmt(num("ate_se3_rmse_m"), 3, "m"),
        ),
        (
            "ATE, similarity alignment (Sim(3))",
            format!(
                "{} (scale {})",
                fmt(num("ate_sim3_rmse_m"), 3, "m"),
                fmt(num("sim3_scale"), 5, "").trim()
            ),
        ),
        (
            "relative pose error, one frame",
            format!(
                "{}, {}",
                fmt(num("rpe_translation_rmse_m"), 4, "m"),
                fmt(num("rpe_rotation_rmse_deg"), 4, "deg")
            ),
        ),
        (
            "final position error",
            format!(
                "{} ({} of the path)",
                fmt(num("final_position_error_m"), 3, "m"),
                fmt(num("final_position_error_pct"), 3, "%")
            ),
        ),
        ("path length", fmt(num("path_length_m"), 1, "m")),
    ];
    let mut t = String::from("<table>");
    for (name, value) in rows {
        let _ = write!(
            t,
            "<tr><th style=\"text-align:left\">{name}</th><td>{}</td></tr>",
            value.trim()
        );
    }
    t.push_str("</table><p>Drift per segment length:</p><table><tr><th>length (m)</th><th>segments</th><th>translation (%)</th><th>rotation (deg/m)</th></tr>");
    for l in ev
        .get("per_length")
        .and_then(|v| v.as_array())
        .into_iter()
        .flatten()
    {
        let f = |k: &str| {
            l.get(k)
                .and_then(serde_json::Value::as_f64)
                .unwrap_or(f64::NAN)
        };
        let _ = write!(
            t,
            "<tr><td>{:.1}</td><td>{}</td><td>{:.3}</td><td>{:.4}</td></tr>",
            f("length_m"),
            f("segments"),
            f("translation_pct"),
            f("rotation_deg_per_m")
        );
    }
    t.push_str("</table>");
    t
}

pub(crate) fn html_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// Writes `report.html` for `report` at `path`.
pub fn write_html(path: &Path, report: &RunReport) -> Result<()> {
    // The truth first, under the estimate: where the two meet the estimate stays visible.
    let mut trajectory: Vec<Series> = report
        .ground_truth
        .iter()
        .map(|gt| Series {
            name: "ground truth".into(),
            points: gt.iter().map(|p| (p[0], p[1])).collect(),
        })
        .collect();
    trajectory.push(Series {
        name: "estimate (left camera)".into(),
        points: report.epochs.iter().map(|e| (e.left.x, e.left.y)).collect(),
    });
    let mut sections = vec![(
        "Trajectory seen from above",
        line_chart("Trajectory (top view)", "X (m)", "Y (m)", &trajectory, true)?,
    )];
    let error = glance::position_error_series(report);
    if !error.is_empty() {
        sections.push((
            "Position error",
            line_chart(
                "Error of the left camera's position (estimate - truth)",
                "epoch",
                "cm",
                &error,
                false,
            )?,
        ));
    }
    let per_length = report
        .evaluation
        .as_ref()
        .and_then(|e| e.get("per_length"))
        .and_then(|v| v.as_array());
    if let Some(per_length) = per_length {
        let [translation, rotation] = drift_per_length_charts(per_length)?;
        sections.push((
            "KITTI drift against segment length: translation",
            translation,
        ));
        sections.push(("KITTI drift against segment length: rotation", rotation));
    }
    if let Some(drift) = drift_series(report) {
        let s = [Series {
            name: "position error / distance travelled".into(),
            points: drift,
        }];
        sections.push((
            "Position error over the distance travelled",
            line_chart(
                "Position error as a share of the distance",
                "distance (m)",
                "error (%)",
                &s,
                false,
            )?,
        ));
    }
    sections.push((
        "Attitude",
        line_chart(
            "Attitude of the left camera, change since the first epoch",
            "epoch",
            "deg",
            &glance::attitude_series(report),
            false,
        )?,
    ));
    sections.push((
        "Height",
        line_chart(
            "Height of the left camera",
            "epoch",
            "Z (m)",
            &glance::height_series(report),
            false,
        )?,
    ));
    let sd = glance::position_sd_series(report);
    if !sd.is_empty() {
        sections.push((
            "Precision",
            line_chart(
                "Standard deviations of the left camera's position (datum: the first epoch)",
                "epoch",
                "cm",
                &sd,
                false,
            )?,
        ));
    }
    sections.push((
        "sigma0 a posteriori and the global test",
        line_chart(
            "sigma0 per epoch, within the global test's bounds when the test passes",
            "epoch",
            "sigma0",
            &glance::sigma0_series(report),
            false,
        )?,
    ));
    let ties = [Series {
        name: "tie points".into(),
        points: per_epoch(report, |e| Some(e.tie_points as f64)),
    }];
    sections.push((
        "Tie points",
        line_chart("Tie points per epoch", "epoch", "count", &ties, false)?,
    ));
    if !report.residuals_px.is_empty() {
        let (max, beyond) = residual_range(&report.residuals_px);
        sections.push((
            "Residuals",
            histogram(
                &format!(
                    "Final image residuals, {} observations ({beyond} beyond {max:.1} px)",
                    report.residuals_px.len()
                ),
                "|residual| (px)",
                &report.residuals_px,
                40,
                max,
            )?,
        ));
    }
    sections.extend(gnss_sections(report)?);
    if let Some(svg) = speed_section(report)? {
        sections.push(("Speed", svg));
    }
    let stages = stage_series(report);
    if !stages.is_empty() {
        sections.push((
            "Time per stage",
            line_chart("Time per stage", "epoch", "ms", &stages, false)?,
        ));
    }

    let mut page = String::new();
    let _ = write!(
        page,
        "<!doctype html><html><head><meta charset=\"utf-8\"><title>phototraverse report</title>\
         <style>body{{font-family:sans-serif;max-width:780px;margin:auto}}\
         table{{border-collapse:collapse}}td,th{{border:1px solid #ccc;padding:2px 6px;text-align:right}}\
         table.summary td{{text-align:left}}p.legend{{margin-top:0;font-size:90%}}</style>\
         </head><body><h1>phototraverse: {}</h1><p>mode {}, {} epochs of {}x{} px.</p>",
        html_escape(&report.dataset),
        html_escape(&report.mode),
        report.epochs.len(),
        report.image_width,
        report.image_height,
    );
    let _ = write!(page, "<h2>Summary</h2>{}", glance::summary_table(report));
    if let Some(t) = glance::flagged_table(report) {
        let _ = write!(page, "<h2>Epochs flagged, predicted or lost</h2>{t}");
    }
    if report.interrupted {
        let _ = write!(
            page,
            "<p><strong>Interrupted</strong> (Ctrl-C or SIGTERM): the run stopped after {} \
             epochs; everything here is of those.</p>",
            report.epochs.len()
        );
    }
    if let Some(ev) = &report.evaluation {
        let _ = write!(
            page,
            "<h2>Evaluation against the ground truth</h2>{}",
            evaluation_table(ev)
        );
    }
    if let Some(m) = &report.smoothing {
        let _ = write!(
            page,
            "<p>GNSS: the positions are smoothed over {} fixes after the run (the images' \
             step estimated at {:.1} mm); they moved {:.3} m RMS, {:.3} m at most from those \
             output on board.</p>",
            m.fixes,
            m.step_sd_m * 1e3,
            m.rms_shift_m,
            m.largest_shift_m
        );
    }
    for (title, svg) in sections {
        let _ = write!(page, "<h2>{title}</h2>{svg}");
    }
    let _ = write!(
        page,
        "<h2>Memory, predicted and carved; capacities, reserved and used at most</h2>{}{}",
        memory_table(&report.memory),
        capacity_table(&report.capacities)
    );
    if let Some(t) = &report.target {
        let _ = write!(page, "{}", target_section(t));
    }
    page.push_str("</body></html>");
    std::fs::write(path, page).with_context(|| format!("cannot write {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::super::records::*;
    use super::*;

    #[test]
    fn residual_range_covers_the_99th_percentile() {
        // 0.01 .. 1.00 px and one blunder: the range ends at 1.0, two lie at or beyond it.
        let mut v: Vec<f32> = (1..=100).map(|k| k as f32 / 100.0).collect();
        v.push(25.0);
        assert_eq!(residual_range(&v), (1.0, 2));
        // Tiny residuals keep a readable half-pixel range.
        assert_eq!(residual_range(&[0.01, 0.02]), (0.5, 0));
    }

    #[test]
    fn report_has_every_plot_and_the_memory_table() {
        let mut report = RunReport {
            dataset: "straight <synthetic>".into(),
            mode: "window".into(),
            ..Default::default()
        };
        for k in 0..5 {
            let eop = CameraEop::from_pose(
                &phototraverse_core::camera::Pose::from_degrees(
                    90.0,
                    0.0,
                    0.0,
                    [0.0, k as f64 * 1.01, 0.0],
                ),
                Some([1e-4, 1e-4, 1e-4, 0.01, 0.02, 0.01]),
            );
            report.epochs.push(EpochRecord {
                sigma0: Some(1.0),
                chi2_passed: Some(true),
                chi2: Some(EpochChi2 {
                    statistic: 100.0,
                    dof: 100,
                    lower: 74.2,
                    upper: 129.6,
                    result: "passed".into(),
                }),
                observations: 100,
                tie_points: 25,
                keypoints: [1000, 990],
                stereo_matches: 500,
                stage_ms: [
                    ("features".to_string(), 10.0),
                    ("adjust".to_string(), 2.0),
                    ("total".to_string(), 12.0),
                ]
                .into(),
                ..EpochRecord::posed(k, None, EpochStatus::Ok, (eop, eop))
            });
        }
        report.wall_ms_per_epoch = Some(80.0);
        report.epochs[3].status = EpochStatus::Flagged;
        report.epochs[3].note = Some("chi-square test failed".into());
        report.ground_truth = Some((0..5).map(|k| [0.0, k as f64, 0.0]).collect());
        report.residuals_px = vec![0.1, 0.2, 0.5, 1.5];
        report.memory = vec![MemoryLine {
            name: "sift.rings".into(),
            kind: "working".into(),
            predicted_bytes: 10,
            measured_bytes: Some(9),
        }];
        report.capacities = vec![CapacityLine {
            name: "window_points".into(),
            peak: 177,
            reserved: 252,
        }];
        report.evaluation = Some(serde_json::json!({
            "translation_drift_pct": 0.25,
            "ate_rmse_m": 0.0123456,
            "per_length": [
                {"length_m": 1.0, "segments": 2, "translation_pct": 0.5, "rotation_deg_per_m": 0.01},
                {"length_m": 2.0, "segments": 1, "translation_pct": 0.25, "rotation_deg_per_m": 0.005},
            ],
        }));
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("report.html");
        write_html(&path, &report).unwrap();
        let page = std::fs::read_to_string(&path).unwrap();
        assert_eq!(page.matches("<svg").count(), 12);
        // The evaluation as tables rounded for reading, not as JSON.
        assert!(page.contains("<td>0.250 %</td>") && page.contains("<td>0.012 m</td>"));
        assert!(!page.contains("0.0123456"));
        for title in [
            "Trajectory",
            "KITTI drift against segment length: translation",
            "KITTI drift against segment length: rotation",
            "Position error over the distance travelled",
            "(estimate - truth)",
            "Attitude",
            "Height",
            "Standard deviations of the left camera",
            "sigma0",
            "lower bound of the global test",
            "Tie points",
            "Residuals",
            "Time per stage",
            "sift.rings",
        ] {
            assert!(page.contains(title), "{title} missing");
        }
        assert!(page.contains("straight &lt;synthetic&gt;"));
        // The summary and the epochs that need a look come first, in words.
        let summary =
            &page[page.find("<h2>Summary</h2>").unwrap()..page.find("<h2>Trajectory").unwrap()];
        assert!(summary
            .contains("5 (4 adjusted without remark, 1 flagged, 0 predicted, 0 lost on the link)"));
        assert!(summary.contains("<td>3</td><td>flagged</td><td>25</td>"));
        assert!(summary.contains("chi-square test failed"));
        assert!(summary.contains("12.0 ms median in the firmware; 80.0 ms end to end"));
        // The trajectory draws the truth (first colour) first, under the estimate
        // (second colour); the key is under the plot, where it covers nothing.
        let top_view = &page[page.find("Trajectory (top view)").unwrap()..];
        let (svg, after) = top_view.split_at(top_view.find("</svg>").unwrap());
        let (truth, estimate) = (
            svg.find("stroke=\"#1F77B4\"").unwrap(),
            svg.find("stroke=\"#D62728\"").unwrap(),
        );
        assert!(truth < estimate, "the estimate is drawn under the truth");
        assert!(!svg.contains("ground truth"));
        let key = &after[..after.find("<h2>").unwrap()];
        assert!(key.contains("ground truth") && key.contains("estimate (left camera)"));
        assert!(page.contains("<td>window_points</td><td>252</td><td>177</td>"));
        assert!(!page.contains("On the microcontroller"));

        // A run on the emulated microcontroller: its sections, stack and instructions.
        let mut t = [0u32; phototraverse_core::protocol::messages::stage::COUNT];
        t[1] = 170_000;
        t[6] = 9_000;
        report.target = Some(crate::mcu::TargetReport {
            part: "mps2-an500".into(),
            description: "Cortex-M7".into(),
            qemu_machine: Some("mps2-an500".into()),
            image: "image".into(),
            sections: vec![crate::mcu::Section {
                name: ".text".into(),
                address: 0x400,
                bytes: 339_020,
            }],
            predicted: crate::mcu::StorageSizes {
                arena_bytes: 504_573,
                frame_bytes: 76_800,
            },
            stack: Some(crate::mcu::StackReport {
                used_bytes: 31_516,
                reserved_bytes: 4_174_752,
            }),
            time: crate::mcu::target_time(&[t]),
        });
        write_html(&path, &report).unwrap();
        let page = std::fs::read_to_string(&path).unwrap();
        assert!(page.contains("<td>.text</td><td>0x00000400</td><td>339020</td>"));
        assert!(page.contains("<td>31516</td>"));
        assert!(page.contains("<td>sift_left</td><td>170.00 M</td><td>95.0 %</td>"));
        assert!(page.contains("Estimate, not a measurement:"));

        // With fixes at some epochs and times: the GNSS plots and the speed.
        for (k, e) in report.epochs.iter_mut().enumerate() {
            e.time = Some(0.1 * k as f64);
            e.left.sigma = Some([1e-4, 1e-4, 1e-4, 0.01, 0.01, 0.01]);
            e.gnss = (k != 2).then_some(GnssRecord {
                position: [0.0, k as f64, 0.0],
                sigma_m: 0.02,
                residual_m: [0.0, 0.01 * k as f64, 0.0],
            });
        }
        let v = crate::report::velocities(&report.epochs);
        for (e, v) in report.epochs.iter_mut().zip(v) {
            e.velocity = v;
        }
        write_html(&path, &report).unwrap();
        let page = std::fs::read_to_string(&path).unwrap();
        // The 12 plots above and 4 more: GNSS availability, position error, residuals, speed.
        assert_eq!(page.matches("<svg").count(), 16);
        for title in [
            "GNSS availability",
            "Position error",
            "GNSS residuals",
            "Speed",
        ] {
            assert!(page.contains(title), "{title} missing");
        }
    }
}
