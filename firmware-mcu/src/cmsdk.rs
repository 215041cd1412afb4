//! The two peripherals the firmware needs, as the Arm CMSDK provides them on the MPS2
//! boards: the APB UART (the link, polled) and an APB timer (the clock).
use core::cell::Cell;
use core::ptr::{read_volatile, write_volatile};

/// A memory-mapped 32-bit register.
#[derive(Clone, Copy)]
struct Reg(usize);

impl Reg {
    fn read(self) -> u32 {
        // SAFETY: the address is a register of a peripheral this module owns.
        unsafe { read_volatile(self.0 as *const u32) }
    }
    fn write(self, v: u32) {
        // SAFETY: as in `read`.
        unsafe { write_volatile(self.0 as *mut u32, v) }
    }
}

/// CMSDK APB UART, polled: one byte in each direction at a time.
pub struct Uart {
    base: usize,
}

const UART_DATA: usize = 0x00;
const UART_STATE: usize = 0x04;
const UART_CTRL: usize = 0x08;
const UART_BAUDDIV: usize = 0x10;
const STATE_TX_FULL: u32 = 1 << 0;
const STATE_RX_FULL: u32 = 1 << 1;
const CTRL_TX_EN: u32 = 1 << 0;
const CTRL_RX_EN: u32 = 1 << 1;

impl Uart {
    /// UART0 of the MPS2 FPGA images (AN385, AN386, AN500).
    pub const UART0: usize = 0x4000_4000;

    /// Enables transmit and receive. The divider is the smallest the block accepts;
    /// on the emulated board the bytes move as fast as the host feeds them.
    pub fn new(base: usize) -> Self {
        let uart = Uart { base };
        uart.reg(UART_BAUDDIV).write(16);
        uart.reg(UART_CTRL).write(CTRL_TX_EN | CTRL_RX_EN);
        uart
    }

    fn reg(&self, offset: usize) -> Reg {
        Reg(self.base + offset)
    }

    fn rx_ready(&self) -> bool {
        self.reg(UART_STATE).read() & STATE_RX_FULL != 0
    }
}

impl embedded_io::ErrorType for Uart {
    type Error = core::convert::Infallible;
}

impl embedded_io::Read for Uart {
    /// Blocks for the first byte, then takes what has already arrived.
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
        if buf.is_empty() {
            return Ok(0);
        }
        while !self.rx_ready() {}
        let mut n = 0;
        while n < buf.len() && self.rx_ready() {
            buf[n] = self.reg(UART_DATA).read() as u8;
            n += 1;
        }
        Ok(n)
    }
}

impl embedded_io::Write for Uart {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        for &b in buf {
            while self.reg(UART_STATE).read() & STATE_TX_FULL != 0 {}
            self.reg(UART_DATA).write(b as u32);
        }
        Ok(buf.len())
    }
    fn flush(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}

/// CMSDK APB timer 0, free-running down from `u32::MAX` at the peripheral clock, extended
/// to 64 bits in software (the clock is read at least once per stage, far more often
/// than the 32-bit counter wraps).
pub struct Timer {
    base: usize,
    last: Cell<u32>,
    ticks: Cell<u64>,
}

const TIMER_CTRL: usize = 0x00;
const TIMER_VALUE: usize = 0x04;
const TIMER_RELOAD: usize = 0x08;

impl Timer {
    pub const TIMER0: usize = 0x4000_0000;
    /// The MPS2 peripheral clock.
    pub const HZ: u64 = 25_000_000;

    pub fn start(base: usize) -> Self {
        let t = Timer {
            base,
            last: Cell::new(u32::MAX),
            ticks: Cell::new(0),
        };
        Reg(base + TIMER_RELOAD).write(u32::MAX);
        Reg(base + TIMER_VALUE).write(u32::MAX);
        Reg(base + TIMER_CTRL).write(1);
        t
    }

    /// Ticks since start.
    pub fn ticks(&self) -> u64 {
        let now = Reg(self.base + TIMER_VALUE).read();
        let elapsed = self.last.get().wrapping_sub(now);
        self.last.set(now);
        self.ticks.set(self.ticks.get() + elapsed as u64);
        self.ticks.get()
    }
}

impl phototraverse_firmware_sim::Clock for Timer {
    fn now_us(&self) -> u64 {
        self.ticks() * 1_000_000 / Self::HZ
    }
}
