//! The phototraverse firmware on a Cortex-M7: the protocol loop and the core traverse of
//! the hosted firmware, its link on the board's UART, its clock the board's timer, its
//! storage statics placed by the part's memory map (build.rs, `parts/`). No allocator.
//!
//! On QEMU's `mps2-an500` (`phototraverse run --link qemu`), a panic or a fault prints
//! through semihosting and ends the emulation with a failure.
#![no_std]
#![no_main]

mod cmsdk;
mod stack;

use core::mem::MaybeUninit;
use core::ptr::addr_of_mut;
use cortex_m_rt::{entry, exception, ExceptionFrame};
use cortex_m_semihosting::{debug, hprintln};
use phototraverse_firmware_sim::{Firmware, Limits, LinkBuffers, TraverseFactory};

/// The part and the storage sizes this image was built for (build.rs).
mod sizes {
    #![allow(dead_code)]
    include!(concat!(env!("OUT_DIR"), "/sizes.rs"));
}

#[link_section = ".arena"]
static mut ARENA: MaybeUninit<[u8; sizes::ARENA_BYTES]> = MaybeUninit::uninit();
#[link_section = ".frames"]
static mut FRAMES: MaybeUninit<[u8; 2 * sizes::FRAME_BYTES]> = MaybeUninit::uninit();
static mut LINK: LinkBuffers = LinkBuffers::new();

/// Takes a NOLOAD static as cleared bytes.
///
/// # Safety
/// Called once per static, before anything else refers to it.
unsafe fn cleared<const N: usize>(s: *mut MaybeUninit<[u8; N]>) -> &'static mut [u8; N] {
    s.cast::<u8>().write_bytes(0, N);
    &mut *s.cast::<[u8; N]>()
}

#[entry]
fn main() -> ! {
    stack::paint();
    // SAFETY: `main` runs once; these are the only references to the statics.
    let (arena, frames, link) = unsafe {
        (
            cleared(addr_of_mut!(ARENA)),
            cleared(addr_of_mut!(FRAMES)),
            &mut *addr_of_mut!(LINK),
        )
    };
    let mut uart = cmsdk::Uart::new(cmsdk::Uart::UART0);
    let clock = cmsdk::Timer::start(cmsdk::Timer::TIMER0);
    let mut firmware = Firmware::new(arena, TraverseFactory, clock, Limits::default())
        .with_frame_storage(frames)
        .with_stack_gauge(stack::usage);
    // The UART never ends: the host stops the board when the session is over.
    let Ok(()) = firmware.run(&mut uart, link);
    halt(debug::EXIT_SUCCESS)
}

/// Ends the emulation with `code` (semihosting); on a board without a debugger, sleeps.
fn halt(code: debug::ExitStatus) -> ! {
    debug::exit(code);
    loop {
        cortex_m::asm::wfi();
    }
}

#[exception]
unsafe fn HardFault(frame: &ExceptionFrame) -> ! {
    hprintln!(
        "phototraverse firmware: hard fault at pc {:#010x}",
        frame.pc()
    );
    halt(debug::EXIT_FAILURE)
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    hprintln!("phototraverse firmware: {}", info);
    halt(debug::EXIT_FAILURE)
}
