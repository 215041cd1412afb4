//! The stack's high-water mark: the free stack is painted with a pattern at start, and
//! the deepest word no longer holding it is how far the stack has grown.
use core::ptr::{addr_of, read_volatile, write_volatile};
use phototraverse_core::protocol::messages::StackUse;

const PAINT: u32 = 0x5AFE_C0DE;
/// Left unpainted below the stack pointer at the time of painting: the painting
/// function's own frame.
const MARGIN: usize = 256;

extern "C" {
    /// End of the statics in RAM (cortex-m-rt): the lowest address the stack may reach.
    static __euninit: u32;
    /// Top of the stack (cortex-m-rt).
    static _stack_start: u32;
}

fn bottom() -> usize {
    (addr_of!(__euninit) as usize + 3) & !3
}

fn top() -> usize {
    addr_of!(_stack_start) as usize
}

/// Paints the free stack below the current stack pointer. Call once, first thing.
pub fn paint() {
    let sp = cortex_m::register::msp::read() as usize;
    let mut p = bottom();
    while p + MARGIN < sp {
        // SAFETY: between the end of the statics and below the live frames: unused stack.
        unsafe { write_volatile(p as *mut u32, PAINT) };
        p += 4;
    }
}

/// Bytes of stack used so far at most, against the bytes reserved for it (from the end
/// of the statics to the top of RAM).
pub fn usage() -> StackUse {
    let mut p = bottom();
    // SAFETY: reads words of the stack region, which is always mapped.
    while p < top() && unsafe { read_volatile(p as *const u32) } == PAINT {
        p += 4;
    }
    StackUse {
        used: (top() - p) as u32,
        reserved: (top() - bottom()) as u32,
    }
}
