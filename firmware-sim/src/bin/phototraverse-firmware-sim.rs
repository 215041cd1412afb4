//! Host binary of the firmware: the no_std loop with its link on stdin/stdout
//! (default), a TCP socket or a serial device; see `hosted`.
fn main() {
    let args = std::env::args().skip(1).collect();
    std::process::exit(phototraverse_firmware_sim::hosted::main_with_args(args));
}
