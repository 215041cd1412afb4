//! Little-endian field readers and writers over a payload, and the parse error.
use super::EncodeError;

/// Why a payload could not be parsed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ParseError {
    /// The payload ends before a field.
    Truncated,
    /// A field holds a value outside its domain (named).
    Invalid(&'static str),
    /// A type byte no message has.
    UnknownType(u8),
}

/// Little-endian field reader over a payload.
pub struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    pub fn new(buf: &'a [u8]) -> Self {
        Reader { buf, pos: 0 }
    }
    pub fn bytes(&mut self, n: usize) -> Result<&'a [u8], ParseError> {
        let end = self.pos.checked_add(n).ok_or(ParseError::Truncated)?;
        let s = self.buf.get(self.pos..end).ok_or(ParseError::Truncated)?;
        self.pos = end;
        Ok(s)
    }
    fn array<const N: usize>(&mut self) -> Result<[u8; N], ParseError> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.bytes(N)?);
        Ok(a)
    }
    pub fn u8(&mut self) -> Result<u8, ParseError> {
        Ok(self.array::<1>()?[0])
    }
    pub fn u16(&mut self) -> Result<u16, ParseError> {
        Ok(u16::from_le_bytes(self.array()?))
    }
    pub fn u32(&mut self) -> Result<u32, ParseError> {
        Ok(u32::from_le_bytes(self.array()?))
    }
    pub fn u64(&mut self) -> Result<u64, ParseError> {
        Ok(u64::from_le_bytes(self.array()?))
    }
    pub fn f32(&mut self) -> Result<f32, ParseError> {
        Ok(f32::from_le_bytes(self.array()?))
    }
    pub fn f64(&mut self) -> Result<f64, ParseError> {
        Ok(f64::from_le_bytes(self.array()?))
    }
    pub fn f64s<const N: usize>(&mut self) -> Result<[f64; N], ParseError> {
        let mut a = [0.0; N];
        for v in a.iter_mut() {
            *v = self.f64()?;
        }
        Ok(a)
    }
    pub fn f32s<const N: usize>(&mut self) -> Result<[f32; N], ParseError> {
        let mut a = [0.0; N];
        for v in a.iter_mut() {
            *v = self.f32()?;
        }
        Ok(a)
    }
    pub fn u32s<const N: usize>(&mut self) -> Result<[u32; N], ParseError> {
        let mut a = [0; N];
        for v in a.iter_mut() {
            *v = self.u32()?;
        }
        Ok(a)
    }
    pub fn rest(&mut self) -> &'a [u8] {
        let s = &self.buf[self.pos..];
        self.pos = self.buf.len();
        s
    }
    pub fn remaining(&self) -> usize {
        self.buf.len() - self.pos
    }
}

/// Little-endian field writer into a payload buffer.
pub struct Writer<'a> {
    buf: &'a mut [u8],
    pos: usize,
}

impl<'a> Writer<'a> {
    pub fn new(buf: &'a mut [u8]) -> Self {
        Writer { buf, pos: 0 }
    }
    pub fn bytes(&mut self, b: &[u8]) -> Result<(), EncodeError> {
        let end = self.pos + b.len();
        let dst = self
            .buf
            .get_mut(self.pos..end)
            .ok_or(EncodeError::PayloadTooLarge)?;
        dst.copy_from_slice(b);
        self.pos = end;
        Ok(())
    }
    pub fn u8(&mut self, v: u8) -> Result<(), EncodeError> {
        self.bytes(&[v])
    }
    pub fn u16(&mut self, v: u16) -> Result<(), EncodeError> {
        self.bytes(&v.to_le_bytes())
    }
    pub fn u32(&mut self, v: u32) -> Result<(), EncodeError> {
        self.bytes(&v.to_le_bytes())
    }
    pub fn u64(&mut self, v: u64) -> Result<(), EncodeError> {
        self.bytes(&v.to_le_bytes())
    }
    pub fn f32(&mut self, v: f32) -> Result<(), EncodeError> {
        self.bytes(&v.to_le_bytes())
    }
    pub fn f64(&mut self, v: f64) -> Result<(), EncodeError> {
        self.bytes(&v.to_le_bytes())
    }
    pub fn f64s(&mut self, v: &[f64]) -> Result<(), EncodeError> {
        v.iter().try_for_each(|x| self.f64(*x))
    }
    pub fn f32s(&mut self, v: &[f32]) -> Result<(), EncodeError> {
        v.iter().try_for_each(|x| self.f32(*x))
    }
    pub fn u32s(&mut self, v: &[u32]) -> Result<(), EncodeError> {
        v.iter().try_for_each(|x| self.u32(*x))
    }
    pub fn len(&self) -> usize {
        self.pos
    }
    pub fn is_empty(&self) -> bool {
        self.pos == 0
    }
}
