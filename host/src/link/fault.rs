//! Fault injection with a seed: bit errors at a bit error rate, dropped bytes,
//! and whole packets dropped, truncated, duplicated or reordered. Both
//! directions of a transport pass through their own injector.
use super::transport::Transport;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::io;
use std::time::Duration;

/// What to inject; probabilities per bit (BER), per byte or per packet.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FaultConfig {
    pub ber: f64,
    pub drop_byte: f64,
    pub drop_packet: f64,
    pub truncate: f64,
    pub duplicate: f64,
    pub reorder: f64,
    pub seed: u64,
}

impl FaultConfig {
    pub fn is_clean(&self) -> bool {
        self.ber == 0.0
            && self.drop_byte == 0.0
            && self.drop_packet == 0.0
            && self.truncate == 0.0
            && self.duplicate == 0.0
            && self.reorder == 0.0
    }
}

/// What an injector did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct FaultCounters {
    pub bits_flipped: u64,
    pub bytes_dropped: u64,
    pub packets_dropped: u64,
    pub packets_truncated: u64,
    pub packets_duplicated: u64,
    pub packets_reordered: u64,
}

/// One direction: cuts the byte stream at delimiters and damages packets.
pub struct Injector {
    cfg: FaultConfig,
    rng: ChaCha8Rng,
    partial: Vec<u8>,
    held: Option<Vec<u8>>,
    /// Bits until the next bit error.
    next_flip: u64,
    pub counters: FaultCounters,
}

impl Injector {
    pub fn new(cfg: FaultConfig, stream: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
        rng.set_stream(stream);
        let mut i = Injector {
            cfg,
            rng,
            partial: Vec::new(),
            held: None,
            next_flip: 0,
            counters: FaultCounters::default(),
        };
        i.next_flip = i.draw_gap();
        i
    }

    /// Geometric gap between bit errors, so the cost does not grow with clean bytes.
    fn draw_gap(&mut self) -> u64 {
        if self.cfg.ber <= 0.0 {
            return u64::MAX;
        }
        let u: f64 = self.rng.gen_range(f64::MIN_POSITIVE..1.0);
        (u.ln() / (1.0 - self.cfg.ber).ln()).floor() as u64
    }

    /// Takes bytes going one way, returns the bytes that come out of the wire.
    pub fn apply(&mut self, input: &[u8]) -> Vec<u8> {
        let mut out = Vec::with_capacity(input.len());
        let mut start = 0;
        for (i, &b) in input.iter().enumerate() {
            if b == 0 {
                self.partial.extend_from_slice(&input[start..=i]);
                start = i + 1;
                let packet = std::mem::take(&mut self.partial);
                self.packet(packet, &mut out);
            }
        }
        self.partial.extend_from_slice(&input[start..]);
        out
    }

    fn packet(&mut self, mut p: Vec<u8>, out: &mut Vec<u8>) {
        let c = self.cfg;
        if self.rng.gen_bool(c.drop_packet.clamp(0.0, 1.0)) {
            self.counters.packets_dropped += 1;
            return;
        }
        if p.len() > 2 && self.rng.gen_bool(c.truncate.clamp(0.0, 1.0)) {
            // Cut the body but keep the delimiter: the next packet stays intact.
            let keep = self.rng.gen_range(1..p.len() - 1);
            p.drain(keep..p.len() - 1);
            self.counters.packets_truncated += 1;
        }
        self.damage(&mut p);
        let dup = self.rng.gen_bool(c.duplicate.clamp(0.0, 1.0));
        if self.rng.gen_bool(c.reorder.clamp(0.0, 1.0)) && self.held.is_none() {
            self.counters.packets_reordered += 1;
            self.held = Some(p.clone());
        } else {
            out.extend_from_slice(&p);
            if let Some(h) = self.held.take() {
                out.extend_from_slice(&h);
            }
        }
        if dup {
            self.counters.packets_duplicated += 1;
            out.extend_from_slice(&p);
        }
    }

    /// Bit flips and dropped bytes.
    fn damage(&mut self, p: &mut Vec<u8>) {
        let bits = p.len() as u64 * 8;
        let mut at = 0u64;
        while self.next_flip < bits - at {
            at += self.next_flip;
            p[(at / 8) as usize] ^= 1 << (at % 8);
            self.counters.bits_flipped += 1;
            at += 1;
            self.next_flip = self.draw_gap();
            if at >= bits {
                break;
            }
        }
        self.next_flip -= (bits - at).min(self.next_flip);
        if self.cfg.drop_byte > 0.0 {
            let before = p.len();
            let pr = self.cfg.drop_byte.clamp(0.0, 1.0);
            let rng = &mut self.rng;
            p.retain(|_| !rng.gen_bool(pr));
            self.counters.bytes_dropped += (before - p.len()) as u64;
        }
    }
}

/// A transport whose two directions pass through injectors.
pub struct Faulty<T> {
    inner: T,
    pub outgoing: Injector,
    pub incoming: Injector,
}

impl<T: Transport> Faulty<T> {
    pub fn new(inner: T, cfg: FaultConfig) -> Self {
        Faulty {
            inner,
            outgoing: Injector::new(cfg, 1),
            incoming: Injector::new(cfg, 2),
        }
    }

    pub fn counters(&self) -> [FaultCounters; 2] {
        [self.outgoing.counters, self.incoming.counters]
    }
}

impl<T: Transport> Transport for Faulty<T> {
    fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
        let out = self.outgoing.apply(bytes);
        self.inner.send(&out)
    }
    fn flush(&mut self) -> io::Result<()> {
        self.inner.flush()
    }
    fn recv(&mut self, timeout: Duration) -> io::Result<Option<Vec<u8>>> {
        Ok(self.inner.recv(timeout)?.map(|b| self.incoming.apply(&b)))
    }
    fn bytes_per_sec(&self) -> Option<f64> {
        self.inner.bytes_per_sec()
    }
    fn set_write_deadline(&mut self, deadline: Duration) {
        self.inner.set_write_deadline(deadline)
    }
    fn describe(&self) -> String {
        format!("{} with faults", self.inner.describe())
    }
    fn fault_counters(&self) -> Option<[FaultCounters; 2]> {
        Some(self.counters())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ber_matches_its_rate_and_seed_repeats() {
        let cfg = FaultConfig {
            ber: 1e-3,
            seed: 7,
            ..Default::default()
        };
        let data: Vec<u8> = (0..200_000)
            .map(|i| (i % 251 + 1) as u8)
            .chain([0])
            .collect();
        let mut a = Injector::new(cfg, 1);
        let out = a.apply(&data);
        let flips: u32 = out
            .iter()
            .zip(&data)
            .map(|(x, y)| (x ^ y).count_ones())
            .sum();
        assert_eq!(flips as u64, a.counters.bits_flipped);
        let expected = data.len() as f64 * 8.0 * 1e-3;
        assert!(
            (flips as f64 - expected).abs() < 5.0 * expected.sqrt(),
            "{flips} flips, expected {expected}"
        );
        let mut b = Injector::new(cfg, 1);
        assert_eq!(b.apply(&data), out, "same seed, same faults");
    }

    #[test]
    fn packet_faults_keep_delimiters() {
        let cfg = FaultConfig {
            drop_packet: 0.2,
            truncate: 0.2,
            duplicate: 0.2,
            reorder: 0.2,
            seed: 3,
            ..Default::default()
        };
        let mut inj = Injector::new(cfg, 1);
        let mut data = Vec::new();
        for k in 0..1000u32 {
            data.extend_from_slice(&[1 + (k % 200) as u8, 5, 6, 7, 0]);
        }
        let out = inj.apply(&data);
        let c = inj.counters;
        assert!(c.packets_dropped > 100 && c.packets_truncated > 100 && c.packets_duplicated > 100);
        let delimiters = out.iter().filter(|&&b| b == 0).count() as u64;
        let held = inj.held.is_some() as u64;
        assert_eq!(
            delimiters,
            1000 - c.packets_dropped + c.packets_duplicated - held
        );
    }
}
