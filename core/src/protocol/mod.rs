//! Serial framing protocol: COBS packets, header, CRC, messages (issue 6).
