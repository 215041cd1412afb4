//! `phototraverse`: the host runner's command line.
use clap::{Parser, Subcommand};
use phototraverse_host::commands;

/// Photogrammetric traverse for a forward-looking stereo rig: orients every
/// image of a stereo sequence from the images alone, on a no_std core that runs
/// behind an emulated serial link exactly as it would on board.
#[derive(Parser)]
#[command(name = "phototraverse", version)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Synthesize the default street, run it through the firmware and summarise.
    Demo(commands::demo::Args),
    /// Orient a stereo sequence (KITTI or rig.toml layout): poses, EOPs with precision, report.
    Run(commands::run::Args),
    /// Render a synthetic street sequence with ground truth.
    Synth(commands::synth::Args),
    /// Compare an estimated trajectory with ground truth (KITTI drift, ATE).
    Eval(commands::eval::Args),
    /// Extract reduced SIFT features of one image (COLMAP text format).
    Features(commands::features::Args),
    /// Stereo tie points between a left and a right image.
    Match(commands::match_pair::Args),
    /// Bundle adjustment of a block described in files.
    Adjust(commands::adjust::Args),
    /// Memory budget of a configuration and image size.
    Budget(commands::budget::Args),
    /// Rig files: `rig import` writes rig.toml from an OpenCV or Kalibr calibration.
    Rig(commands::rig::Args),
    /// Run the firmware on this computer (what `--link child` starts): the no_std loop
    /// with its link on stdin/stdout, `--tcp ADDR` or `--serial DEV`.
    #[command(hide = true)]
    Firmware {
        #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
        args: Vec<String>,
    },
}

fn main() {
    let cli = Cli::parse();
    // Not for the commands that talk to a firmware process: a firmware that dies must
    // be an error the run reports (keeping the poses processed), not the end of it.
    if !matches!(
        cli.command,
        Command::Demo(_) | Command::Run(_) | Command::Firmware { .. }
    ) {
        restore_sigpipe();
    }
    let result = match cli.command {
        Command::Demo(a) => commands::demo::run(a),
        Command::Run(a) => commands::run::run(a),
        Command::Synth(a) => commands::synth::run(a),
        Command::Eval(a) => commands::eval::run(a),
        Command::Features(a) => commands::features::run(a),
        Command::Match(a) => commands::match_pair::run(a),
        Command::Adjust(a) => commands::adjust::run(a),
        Command::Budget(a) => commands::budget::run(a),
        Command::Rig(a) => commands::rig::run(a),
        Command::Firmware { args } => {
            std::process::exit(phototraverse_firmware_sim::hosted::main_with_args(args))
        }
    };
    if let Err(err) = result {
        eprintln!("phototraverse: error: {err:#}");
        std::process::exit(1);
    }
}

/// A closed pipe ends the process quietly, as it does other command-line tools
/// (`phototraverse budget | head`): Rust ignores SIGPIPE, so `println!` would panic
/// on the broken pipe instead. Called before any thread exists.
fn restore_sigpipe() {
    #[cfg(unix)]
    // SAFETY: called first in main, before any thread exists; SIG_DFL is a valid handler.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}
