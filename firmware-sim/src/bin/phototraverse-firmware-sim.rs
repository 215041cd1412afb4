//! Host binary of the firmware: its link is stdin/stdout by default.
fn main() {
    eprintln!("phototraverse-firmware-sim: the framing protocol is not wired yet");
    std::process::exit(2);
}
