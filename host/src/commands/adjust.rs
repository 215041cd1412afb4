//! `phototraverse adjust BLOCK --out DIR`: bundle adjustment of a block
//! described in files (docs/block-format.md), with the core's window.
use crate::block::{adjust, camera_code, Adjusted, Block};
use anyhow::{Context, Result};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Block directory (block.txt, images.txt, observations.txt, optional control.txt, gnss.txt, odometer.txt).
    pub block: PathBuf,
    /// Output directory (orientations.csv, points.csv, flagged.csv, report.json).
    #[arg(long)]
    pub out: PathBuf,
}

pub fn run(args: Args) -> Result<()> {
    let block = Block::read(&args.block)?;
    let result = adjust(&block)?;
    write_outputs(&args.out, &result)?;
    let r = &result.report;
    println!(
        "adjusted {} epochs, {} points, {} observations: sigma0 {:.4}, redundancy {}, chi-square {:.1} in [{:.1}, {:.1}] {}, {} flagged, {} iterations{}",
        block.images.len(),
        result.points.len(),
        r.observations,
        r.sigma0,
        r.redundancy,
        r.chi2.statistic,
        r.chi2.lower,
        r.chi2.upper,
        if r.chi2.passed { "passed" } else { "FAILED" },
        r.flagged,
        r.iterations,
        if r.converged { "" } else { " (not converged)" }
    );
    println!("wrote {}", args.out.display());
    Ok(())
}

/// Writes orientations.csv, points.csv, flagged.csv and report.json.
pub fn write_outputs(out: &Path, a: &Adjusted) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create", out.display()))?;
    let mut o = String::from(
        "epoch,camera,omega_deg,phi_deg,kappa_deg,X_m,Y_m,Z_m,sd_omega_deg,sd_phi_deg,sd_kappa_deg,sd_X_m,sd_Y_m,sd_Z_m\n",
    );
    for im in &a.images {
        let p = &im.pose;
        let s = &im.std;
        writeln!(
            o,
            "{},{},{:.6},{:.6},{:.6},{:.5},{:.5},{:.5},{:.6},{:.6},{:.6},{:.5},{:.5},{:.5}",
            im.epoch,
            im.camera.name(),
            p.omega.to_degrees(),
            p.phi.to_degrees(),
            p.kappa.to_degrees(),
            p.centre[0],
            p.centre[1],
            p.centre[2],
            s[0].to_degrees(),
            s[1].to_degrees(),
            s[2].to_degrees(),
            s[3],
            s[4],
            s[5]
        )?;
    }
    std::fs::write(out.join("orientations.csv"), o)?;
    let mut p = String::from("point,X_m,Y_m,Z_m,sd_X_m,sd_Y_m,sd_Z_m,observations\n");
    for pt in &a.points {
        writeln!(
            p,
            "{},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{}",
            pt.point,
            pt.xyz[0],
            pt.xyz[1],
            pt.xyz[2],
            pt.std[0],
            pt.std[1],
            pt.std[2],
            pt.observations
        )?;
    }
    std::fs::write(out.join("points.csv"), p)?;
    let mut f =
        String::from("line,point,epoch,camera,column,row,residual_column_px,residual_row_px\n");
    for fl in &a.flagged {
        let ob = &fl.obs;
        writeln!(
            f,
            "{},{},{},{},{:.3},{:.3},{:.3},{:.3}",
            ob.line,
            ob.point,
            ob.epoch,
            camera_code(ob.camera),
            ob.px[0],
            ob.px[1],
            fl.residual_px[0],
            fl.residual_px[1]
        )?;
    }
    std::fs::write(out.join("flagged.csv"), f)?;
    let r = &a.report;
    let rig = a.rig.to_array();
    let report = serde_json::json!({
        "sigma0": r.sigma0,
        "redundancy": r.redundancy,
        "observations": r.observations,
        "constraints": r.constraints,
        "unknowns": r.unknowns,
        "chi_square": {
            "statistic": r.chi2.statistic,
            "dof": r.chi2.dof,
            "lower_2.5%": r.chi2.lower,
            "upper_97.5%": r.chi2.upper,
            "passed": r.chi2.passed,
        },
        "iterations": r.iterations,
        "converged": r.converged,
        "robust_rounds": r.robust_rounds,
        "flagged": r.flagged,
        "excluded_points": r.excluded_points,
        "skipped_points": a.skipped_points,
        "rig": {
            "relative_deg": [rig[0].to_degrees(), rig[1].to_degrees(), rig[2].to_degrees()],
            "base_m": [rig[3], rig[4], rig[5]],
            "std_relative_deg": [a.rig_std[0].to_degrees(), a.rig_std[1].to_degrees(), a.rig_std[2].to_degrees()],
            "std_base_m": [a.rig_std[3], a.rig_std[4], a.rig_std[5]],
        },
        "memory_budget_bytes": a.budget_bytes,
    });
    std::fs::write(
        out.join("report.json"),
        serde_json::to_string_pretty(&report)?,
    )?;
    Ok(())
}
