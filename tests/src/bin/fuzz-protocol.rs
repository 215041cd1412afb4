//! The protocol fuzz run: `fuzz-protocol [--inputs N] [--seed S] [--target decoder|messages|endpoint|all]`.
//! Every target gets N inputs (default 10^7); a panic is a crash and ends the run
//! with its message, target and seed.
use phototraverse_tests::fuzz::{run, Target};
use std::time::Instant;

fn main() {
    let mut inputs: u64 = 10_000_000;
    let mut seed: u64 = 1;
    let mut targets: Vec<Target> = Target::ALL.to_vec();
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let value = || it.clone().next().cloned().unwrap_or_default();
        match a.as_str() {
            "--inputs" => inputs = parse(&value(), "--inputs"),
            "--seed" => seed = parse(&value(), "--seed"),
            "--target" => {
                let v = value();
                targets = match v.as_str() {
                    "all" => Target::ALL.to_vec(),
                    name => match Target::ALL.iter().find(|t| t.name() == name) {
                        Some(t) => vec![*t],
                        None => usage(&format!("unknown target {name:?}")),
                    },
                }
            }
            "-h" | "--help" => usage(""),
            other => usage(&format!("unknown argument {other:?}")),
        }
        if a.starts_with("--") && a != "-h" {
            it.next();
        }
    }
    for target in targets {
        let t0 = Instant::now();
        let stats = run(target, inputs, seed, |done| {
            eprint!("\r{}: {done} of {inputs} inputs", target.name());
        });
        eprintln!();
        println!(
            "{}: {} inputs, 0 crashes in {:.0} s (seed {seed}): {stats:?}",
            target.name(),
            stats.inputs,
            t0.elapsed().as_secs_f64()
        );
    }
}

fn parse(v: &str, flag: &str) -> u64 {
    v.replace('_', "")
        .parse::<f64>()
        .ok()
        .filter(|x| *x >= 0.0)
        .map(|x| x as u64)
        .unwrap_or_else(|| usage(&format!("{flag} needs a number, got {v:?}")))
}

fn usage(problem: &str) -> ! {
    if !problem.is_empty() {
        eprintln!("fuzz-protocol: {problem}");
    }
    eprintln!(
        "usage: fuzz-protocol [--inputs N (default 1e7)] [--seed S] [--target decoder|messages|endpoint|all]"
    );
    std::process::exit(if problem.is_empty() { 0 } else { 2 })
}
