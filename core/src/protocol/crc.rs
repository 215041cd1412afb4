//! CRC-32 (ISO-HDLC, the Ethernet/zlib polynomial) of packets and whole frames,
//! through `crc32fast`: carry-less multiplication where the CPU has it
//! (runtime-detected on the host), a table otherwise (microcontrollers).

/// CRC-32 of one byte slice.
pub fn crc32(data: &[u8]) -> u32 {
    crc32fast::hash(data)
}

/// Incremental CRC-32 for data that arrives in pieces (a frame in chunks).
#[derive(Clone, Default)]
pub struct Crc32 {
    hasher: crc32fast::Hasher,
}

impl core::fmt::Debug for Crc32 {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str("Crc32")
    }
}

impl Crc32 {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn update(&mut self, data: &[u8]) {
        self.hasher.update(data);
    }

    pub fn finish(self) -> u32 {
        self.hasher.finalize()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn check_value_and_incremental() {
        // The catalogue check value of CRC-32/ISO-HDLC, also what the `crc` crate gives.
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        let reference = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);
        let data: [u8; 1000] = core::array::from_fn(|i| (i * 7 + 3) as u8);
        assert_eq!(crc32(&data), reference.checksum(&data));
        let mut c = Crc32::new();
        c.update(b"1234");
        c.update(b"56789");
        assert_eq!(c.finish(), 0xCBF4_3926);
    }
}
