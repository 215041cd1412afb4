//! Frame assembly on the receiving side: FrameBegin, in-order chunks and
//! FrameEnd fill one preallocated buffer; the length and the whole-frame CRC
//! are checked, and u16 frames are scaled to 8 bits in place.
use super::crc::Crc32;
use super::messages::{frame_bytes, FrameBegin, FrameChunk, FrameEnd, PixelFormat};
use crate::image::ImageView;

/// Why a frame message was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AssemblyError {
    /// The frame is larger than the buffer or the configured size.
    TooLarge { bytes: u64, capacity: u64 },
    /// A chunk or end without a matching FrameBegin.
    NotStarted,
    /// A chunk whose offset is not the next expected byte.
    OutOfOrder { expected: u32, got: u32 },
    /// Chunk data past the frame's size.
    Overrun,
    /// FrameEnd length differs from what arrived.
    Length { expected: u32, got: u32 },
    /// FrameEnd CRC differs from the assembled frame's.
    Crc { expected: u32, got: u32 },
    /// A message of a frame that already failed (reported once, then ignored).
    AlreadyFailed,
}

#[derive(Debug, Clone)]
enum State {
    Idle,
    Receiving {
        begin: FrameBegin,
        next: u32,
        crc: Crc32,
    },
    Complete {
        begin: FrameBegin,
    },
    Failed {
        epoch: u32,
    },
}

/// One camera's frame buffer and assembly state.
pub struct FrameAssembler<'a> {
    buf: &'a mut [u8],
    max_width: u16,
    max_height: u16,
    state: State,
}

impl<'a> FrameAssembler<'a> {
    /// `buf` must hold `max_width * max_height * bytes_per_pixel` bytes.
    pub fn new(buf: &'a mut [u8], max_width: u16, max_height: u16) -> Self {
        FrameAssembler {
            buf,
            max_width,
            max_height,
            state: State::Idle,
        }
    }

    pub fn reset(&mut self) {
        self.state = State::Idle;
    }

    /// Refuses `epoch`'s frame (the receiver found it unusable at its FrameBegin): its
    /// chunks and end are ignored as those of a failed frame.
    pub fn refuse(&mut self, epoch: u32) {
        self.state = State::Failed { epoch };
    }

    /// Epoch being received, complete or failed, if any.
    pub fn epoch(&self) -> Option<u32> {
        match &self.state {
            State::Idle => None,
            State::Receiving { begin, .. } | State::Complete { begin } => Some(begin.epoch),
            State::Failed { epoch } => Some(*epoch),
        }
    }

    pub fn is_complete(&self, epoch: u32) -> bool {
        matches!(&self.state, State::Complete { begin } if begin.epoch == epoch)
    }

    /// Starts a frame. Returns the epoch of an unfinished frame it abandons.
    pub fn begin(&mut self, begin: FrameBegin) -> Result<Option<u32>, AssemblyError> {
        let abandoned = match &self.state {
            State::Receiving { begin: b, .. } if b.epoch != begin.epoch => Some(b.epoch),
            _ => None,
        };
        let bytes = begin.frame_bytes();
        let capacity = self.buf.len() as u64;
        if begin.width > self.max_width
            || begin.height > self.max_height
            || bytes > capacity
            || bytes == 0
        {
            self.state = State::Failed { epoch: begin.epoch };
            let configured = frame_bytes(self.max_width, self.max_height, begin.format);
            return Err(AssemblyError::TooLarge {
                bytes,
                capacity: capacity.min(configured),
            });
        }
        self.state = State::Receiving {
            begin,
            next: 0,
            crc: Crc32::new(),
        };
        Ok(abandoned)
    }

    pub fn chunk(&mut self, chunk: &FrameChunk) -> Result<(), AssemblyError> {
        let (begin, next, crc) = match &mut self.state {
            State::Receiving { begin, next, crc } if begin.epoch == chunk.epoch => {
                (begin, next, crc)
            }
            State::Failed { epoch } if *epoch == chunk.epoch => {
                return Err(AssemblyError::AlreadyFailed)
            }
            _ => return Err(AssemblyError::NotStarted),
        };
        if chunk.offset != *next {
            let e = AssemblyError::OutOfOrder {
                expected: *next,
                got: chunk.offset,
            };
            self.state = State::Failed { epoch: chunk.epoch };
            return Err(e);
        }
        let start = *next as usize;
        let end = start + chunk.data.len();
        if end as u64 > begin.frame_bytes() {
            self.state = State::Failed { epoch: chunk.epoch };
            return Err(AssemblyError::Overrun);
        }
        self.buf[start..end].copy_from_slice(chunk.data);
        crc.update(chunk.data);
        *next = end as u32;
        Ok(())
    }

    pub fn end(&mut self, end: &FrameEnd) -> Result<(), AssemblyError> {
        let state = core::mem::replace(&mut self.state, State::Failed { epoch: end.epoch });
        let (begin, next, crc) = match state {
            State::Receiving { begin, next, crc } if begin.epoch == end.epoch => (begin, next, crc),
            State::Failed { epoch } if epoch == end.epoch => {
                return Err(AssemblyError::AlreadyFailed)
            }
            other => {
                self.state = other;
                return Err(AssemblyError::NotStarted);
            }
        };
        if next != end.total_bytes || next as u64 != begin.frame_bytes() {
            return Err(AssemblyError::Length {
                expected: end.total_bytes,
                got: next,
            });
        }
        let got = crc.finish();
        if got != end.crc32 {
            return Err(AssemblyError::Crc {
                expected: end.crc32,
                got,
            });
        }
        if let PixelFormat::Gray16 { bits } = begin.format {
            scale_in_place(&mut self.buf[..next as usize], bits);
        }
        self.state = State::Complete { begin };
        Ok(())
    }

    /// The complete 8-bit image of `epoch` and its FrameBegin.
    pub fn image(&self, epoch: u32) -> Option<(ImageView<'_>, FrameBegin)> {
        match &self.state {
            State::Complete { begin } if begin.epoch == epoch => {
                let (w, h) = (begin.width as usize, begin.height as usize);
                ImageView::new(&self.buf[..w * h], w, h)
                    .ok()
                    .map(|v| (v, *begin))
            }
            _ => None,
        }
    }
}

/// u16 LE pixels with `bits` significant bits -> u8 at the front of the same
/// buffer (pixel i is read at 2i before it is written at i).
fn scale_in_place(buf: &mut [u8], bits: u8) {
    let shift = bits.saturating_sub(8) as u32;
    for i in 0..buf.len() / 2 {
        let v = u16::from_le_bytes([buf[2 * i], buf[2 * i + 1]]);
        buf[i] = (v >> shift).min(255) as u8;
    }
}
