//! The parts of `report.html` read at a glance: the run's summary, the epochs that
//! need a look, and the per-epoch series of attitude, height, precision and the
//! global test's bounds.
use super::html::Series;
use super::records::{EpochStatus, RunReport};
use std::fmt::Write as _;

/// The median of `v` (sorted in place); `None` when empty.
fn median(v: &mut [f64]) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    Some(v[v.len() / 2])
}

fn count(report: &RunReport, status: EpochStatus) -> usize {
    report.epochs.iter().filter(|e| e.status == status).count()
}

fn kib(bytes: usize) -> String {
    format!("{:.1} KiB", bytes as f64 / 1024.0)
}

/// The summary table: epochs by outcome, accuracy against the truth, quality, time,
/// link and memory, rounded for people.
pub(crate) fn summary_table(report: &RunReport) -> String {
    let mut rows: Vec<(&str, String)> = vec![(
        "epochs",
        format!(
            "{} ({} adjusted without remark, {} flagged, {} predicted, {} lost on the link)",
            report.epochs.len(),
            count(report, EpochStatus::Ok),
            count(report, EpochStatus::Flagged),
            count(report, EpochStatus::Predicted),
            count(report, EpochStatus::Lost)
        ),
    )];
    if let Some(ev) = &report.evaluation {
        let num = |k: &str| ev.get(k).and_then(serde_json::Value::as_f64);
        if let (Some(t), Some(r)) = (
            num("translation_drift_pct"),
            num("rotation_drift_deg_per_m"),
        ) {
            rows.push(("drift (KITTI)", format!("{t:.3} %, {r:.4} deg/m")));
        }
        if let Some(a) = num("ate_rmse_m") {
            rows.push(("ATE RMSE", format!("{:.1} cm", a * 100.0)));
        }
        if let (Some(e), Some(p)) = (
            num("final_position_error_m"),
            num("final_position_error_pct"),
        ) {
            rows.push((
                "final position error",
                format!("{:.1} cm ({p:.3} % of the path)", e * 100.0),
            ));
        }
    }
    if let Some(q) = &report.quality {
        rows.push((
            "quality",
            format!("sigma0 median {:.2}; {}", q.sigma0_median, q.test_reading()),
        ));
    }
    if let Some(g) = &report.rig {
        let length = |b: &[f64; 3]| b.iter().map(|v| v * v).sum::<f64>().sqrt();
        let [w, p, k] = g.relative_angles_deg;
        let [cw, cp, ck] = g.calibration_angles_deg;
        rows.push((
            "rig",
            format!(
                "as adjusted: base {:.4} m, angles {w:.4}, {p:.4}, {k:.4} deg; \
                 as calibrated: {:.4} m, {cw:.4}, {cp:.4}, {ck:.4} deg",
                length(&g.base_m),
                length(&g.calibration_base_m)
            ),
        ));
    }
    let mut firmware: Vec<f64> = report
        .epochs
        .iter()
        .filter_map(|e| e.stage_ms.get("total").copied())
        .collect();
    let end_to_end = report.wall_ms_per_epoch.map_or(String::new(), |w| {
        format!("; {w:.1} ms end to end (images read, sent over the link, processed, answered)")
    });
    if let Some(m) = median(&mut firmware) {
        rows.push((
            "time per epoch",
            format!("{m:.1} ms median in the firmware{end_to_end}"),
        ));
    }
    if let Some(link) = &report.link {
        let n = |k: &str| link.get(k).and_then(serde_json::Value::as_u64).unwrap_or(0);
        rows.push((
            "link",
            format!(
                "{} sent, {} received; {} packets retransmitted, {} CRC and {} framing errors",
                kib(n("bytes_sent") as usize),
                kib(n("bytes_received") as usize),
                n("retransmitted_packets"),
                n("crc_errors"),
                n("framing_errors")
            ),
        ));
    }
    if let Some(total) = report.memory.iter().find(|m| m.name.starts_with("total")) {
        let carved = total.measured_bytes.map_or("not measured".to_string(), kib);
        rows.push((
            "memory",
            format!(
                "{} predicted, {carved} carved from the firmware's arena",
                kib(total.predicted_bytes)
            ),
        ));
    }
    let mut t = String::from("<table class=\"summary\">");
    for (k, v) in rows {
        let _ = write!(
            t,
            "<tr><th>{k}</th><td>{}</td></tr>",
            super::html::html_escape(&v)
        );
    }
    t.push_str("</table>");
    t
}

/// The epochs that are not plainly adjusted, with their reasons; `None` when there
/// are none.
pub(crate) fn flagged_table(report: &RunReport) -> Option<String> {
    let flagged: Vec<_> = report
        .epochs
        .iter()
        .filter(|e| e.status.is_flagged())
        .collect();
    if flagged.is_empty() {
        return None;
    }
    let mut t = String::from(
        "<table><tr><th>epoch</th><th>status</th><th>tie points</th><th>why</th></tr>",
    );
    for e in flagged {
        let status = match e.status {
            EpochStatus::Ok => "ok",
            EpochStatus::Flagged => "flagged",
            EpochStatus::Predicted => "predicted",
            EpochStatus::Lost => "lost",
        };
        let _ = write!(
            t,
            "<tr><td>{}</td><td>{status}</td><td>{}</td><td style=\"text-align:left\">{}</td></tr>",
            e.epoch,
            e.tie_points,
            super::html::html_escape(e.note.as_deref().unwrap_or("-"))
        );
    }
    t.push_str("</table>");
    Some(t)
}

/// Omega, phi and kappa as they changed since the first epoch, degrees: their
/// absolute values (omega near 90) would flatten the changes on one scale.
pub(crate) fn attitude_series(report: &RunReport) -> Vec<Series> {
    let Some(first) = report.epochs.first() else {
        return Vec::new();
    };
    let angle = |name: &str, f: fn(&super::records::CameraEop) -> f64| Series {
        name: name.into(),
        points: report
            .epochs
            .iter()
            .map(|e| {
                // Wrapped into (-180, 180]: kappa crossing +-180 deg is no jump of 360.
                let d = f(&e.left) - f(&first.left);
                (e.epoch as f64, d - 360.0 * (d / 360.0).round())
            })
            .collect(),
    };
    vec![
        angle("omega", |c| c.omega_deg),
        angle("phi", |c| c.phi_deg),
        angle("kappa", |c| c.kappa_deg),
    ]
}

/// The left centre's height, estimated and true.
pub(crate) fn height_series(report: &RunReport) -> Vec<Series> {
    let mut out = Vec::new();
    if let Some(gt) = &report.ground_truth {
        out.push(Series {
            name: "ground truth".into(),
            points: gt
                .iter()
                .enumerate()
                .map(|(k, p)| (k as f64, p[2]))
                .collect(),
        });
    }
    out.push(Series {
        name: "estimate".into(),
        points: report
            .epochs
            .iter()
            .map(|e| (e.epoch as f64, e.left.z))
            .collect(),
    });
    out
}

/// The left centre's error per coordinate, cm: what the top view is too coarse to
/// show.
pub(crate) fn position_error_series(report: &RunReport) -> Vec<Series> {
    let Some(gt) = &report.ground_truth else {
        return Vec::new();
    };
    ["X", "Y", "Z"]
        .iter()
        .enumerate()
        .map(|(k, name)| Series {
            name: format!("error in {name}"),
            points: report
                .epochs
                .iter()
                .zip(gt)
                .map(|(e, t)| {
                    let est = [e.left.x, e.left.y, e.left.z];
                    (e.epoch as f64, (est[k] - t[k]) * 100.0)
                })
                .collect(),
        })
        .collect()
}

/// Standard deviations of the left centre, cm, with respect to the datum.
pub(crate) fn position_sd_series(report: &RunReport) -> Vec<Series> {
    ["sX", "sY", "sZ"]
        .iter()
        .enumerate()
        .map(|(k, name)| Series {
            name: (*name).into(),
            points: report
                .epochs
                .iter()
                .filter_map(|e| Some((e.epoch as f64, e.left.sigma?[3 + k] * 100.0)))
                .collect(),
        })
        .filter(|s| !s.points.is_empty())
        .collect()
}

/// sigma0 per epoch with the global test's bounds expressed on it: the statistic is
/// `dof sigma0^2`, so its bounds are `sqrt(bound / dof)`.
pub(crate) fn sigma0_series(report: &RunReport) -> Vec<Series> {
    let epochs = || report.epochs.iter();
    let bound = |name: &str, pick: fn(&super::records::EpochChi2) -> f64| Series {
        name: name.into(),
        points: epochs()
            .filter_map(|e| {
                let c = e.chi2.as_ref()?;
                (c.dof > 0).then(|| (e.epoch as f64, (pick(c) / c.dof as f64).sqrt()))
            })
            .collect(),
    };
    let mut out = vec![Series {
        name: "sigma0".into(),
        points: epochs()
            .filter_map(|e| Some((e.epoch as f64, e.sigma0?)))
            .collect(),
    }];
    out.push(bound("lower bound of the global test", |c| c.lower));
    out.push(bound("upper bound", |c| c.upper));
    out.retain(|s| !s.points.is_empty());
    out
}
