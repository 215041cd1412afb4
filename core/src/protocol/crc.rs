//! CRC-32 (ISO-HDLC, the Ethernet/zlib polynomial) of packets and whole frames.
//! The slice-by-16 table (16 KiB of flash) keeps the link far from CPU-bound.
use crc::{Crc, Table, CRC_32_ISO_HDLC};

static CRC32: Crc<u32, Table<16>> = Crc::<u32, Table<16>>::new(&CRC_32_ISO_HDLC);

/// CRC-32 of one byte slice.
pub fn crc32(data: &[u8]) -> u32 {
    CRC32.checksum(data)
}

/// Incremental CRC-32 for data that arrives in pieces (a frame in chunks).
#[derive(Clone)]
pub struct Crc32 {
    digest: crc::Digest<'static, u32, Table<16>>,
}

impl core::fmt::Debug for Crc32 {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str("Crc32")
    }
}

impl Default for Crc32 {
    fn default() -> Self {
        Self::new()
    }
}

impl Crc32 {
    pub fn new() -> Self {
        Crc32 {
            digest: CRC32.digest(),
        }
    }

    pub fn update(&mut self, data: &[u8]) {
        self.digest.update(data);
    }

    pub fn finish(self) -> u32 {
        self.digest.finalize()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn check_value_and_incremental() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        let mut c = Crc32::new();
        c.update(b"1234");
        c.update(b"56789");
        assert_eq!(c.finish(), 0xCBF4_3926);
    }
}
