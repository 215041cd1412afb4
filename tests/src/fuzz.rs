//! The protocol fuzz harness: random and mutated inputs for the streaming
//! decoder, the message parsers (CRC-valid mutations, so the parsers see them
//! and not the CRC check) and the reliable endpoint. Any panic is a failure;
//! the parsers must also re-emit what they accept byte for byte.
//!
//! The long run is the `fuzz-protocol` binary:
//! `cargo run --release -p phototraverse-tests --bin fuzz-protocol -- --inputs 10000000`;
//! the tests run a short version.
use phototraverse_core::protocol::crc::crc32;
use phototraverse_core::protocol::messages::*;
use phototraverse_core::protocol::samples::sample_messages;
use phototraverse_core::protocol::{
    cobs, Decoder, Endpoint, EndpointBuffers, EndpointConfig, Event, MAX_ENCODED, MAX_PACKET,
    PROTOCOL_VERSION,
};

/// What a run did.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct FuzzStats {
    pub inputs: u64,
    /// Packets the decoder accepted / runs it dropped.
    pub packets: u64,
    pub dropped: u64,
    /// Mutated payloads the parsers accepted / refused.
    pub parsed: u64,
    pub refused: u64,
    /// Messages an endpoint delivered.
    pub delivered: u64,
}

/// The fuzzed component.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Target {
    Decoder,
    Messages,
    Endpoint,
}

impl Target {
    pub const ALL: [Target; 3] = [Target::Decoder, Target::Messages, Target::Endpoint];

    pub fn name(self) -> &'static str {
        match self {
            Target::Decoder => "decoder",
            Target::Messages => "messages",
            Target::Endpoint => "endpoint",
        }
    }
}

/// xorshift64*: fast, dependency-free, reproducible from a seed.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n.max(1) as u64) as usize
    }
}

/// Payloads of the sample messages with their type bytes.
fn sample_payloads() -> Vec<(u8, Vec<u8>)> {
    let data: Vec<u8> = (0..200u8).collect();
    sample_messages(&data)
        .iter()
        .map(|m| {
            let mut p = vec![0u8; 4096];
            let n = m.emit(&mut p).expect("samples fit");
            p.truncate(n);
            (m.message_type() as u8, p)
        })
        .collect()
}

/// A wire packet around `payload` with a valid CRC, built by hand so the type
/// byte may be one no message has.
fn packet(type_byte: u8, seq: u16, payload: &[u8], out: &mut Vec<u8>) {
    let mut body = vec![PROTOCOL_VERSION, type_byte];
    body.extend_from_slice(&seq.to_le_bytes());
    body.extend_from_slice(&(payload.len() as u16).to_le_bytes());
    body.extend_from_slice(payload);
    let crc = crc32(&body);
    body.extend_from_slice(&crc.to_le_bytes());
    let mut wire = vec![0u8; cobs::max_encoded_len(body.len())];
    let n = cobs::encode(&body, &mut wire).expect("sized for it");
    out.extend_from_slice(&wire[..n]);
    out.push(0);
}

/// Flips, deletes, inserts or truncates a few bytes.
fn mutate(rng: &mut Rng, bytes: &mut Vec<u8>) {
    for _ in 0..1 + rng.below(4) {
        match rng.below(5) {
            0 | 1 if !bytes.is_empty() => {
                let i = rng.below(bytes.len());
                bytes[i] ^= 1 << rng.below(8);
            }
            2 if !bytes.is_empty() => {
                let i = rng.below(bytes.len());
                bytes.remove(i);
            }
            3 => {
                let i = rng.below(bytes.len() + 1);
                bytes.insert(i, rng.next_u64() as u8);
            }
            _ => {
                let n = rng.below(bytes.len() + 1);
                bytes.truncate(n);
            }
        }
    }
}

/// Random bytes or mutated valid packets into a decoder with a random buffer
/// size and random read sizes.
fn fuzz_decoder(rng: &mut Rng, samples: &[(u8, Vec<u8>)], stats: &mut FuzzStats) {
    let mut stream = Vec::new();
    if rng.below(2) == 0 {
        stream.extend((0..rng.below(2048)).map(|_| rng.next_u64() as u8));
    } else {
        for k in 0..1 + rng.below(6) {
            let (t, p) = &samples[rng.below(samples.len())];
            packet(*t, k as u16, p, &mut stream);
        }
        mutate(rng, &mut stream);
    }
    let cap = if rng.below(7) == 0 {
        1 + rng.below(512)
    } else {
        MAX_ENCODED
    };
    let mut decoder = Decoder::new(vec![0u8; cap]);
    let split = 1 + rng.below(300);
    for part in stream.chunks(split) {
        let mut rest = part;
        while !rest.is_empty() {
            let (n, ev) = decoder.feed(rest);
            rest = &rest[n..];
            match ev {
                Some(Ok(p)) => {
                    stats.packets += 1;
                    let _ = Message::parse(p.type_byte(), p.payload());
                }
                Some(Err(_)) => stats.dropped += 1,
                None => {}
            }
        }
    }
}

/// A CRC-valid mutated payload of a random (sometimes unknown) type: parsed, and
/// what parses must re-emit to bytes that parse to the same bytes again.
fn fuzz_messages(rng: &mut Rng, samples: &[(u8, Vec<u8>)], stats: &mut FuzzStats) {
    let (mut t, p) = samples[rng.below(samples.len())].clone();
    let mut payload = p;
    mutate(rng, &mut payload);
    if rng.below(16) == 0 {
        t = rng.next_u64() as u8;
    }
    // Through the decoder, so the parser sees what a receiver would.
    let mut wire = Vec::new();
    packet(t, 0, &payload, &mut wire);
    let mut decoder = Decoder::new(vec![0u8; MAX_ENCODED]);
    let (_, ev) = decoder.feed(&wire);
    let Some(Ok(pk)) = ev else {
        panic!(
            "a CRC-valid packet was refused: type {t}, {} bytes",
            payload.len()
        );
    };
    match Message::parse(pk.type_byte(), pk.payload()) {
        Ok(m) => {
            stats.parsed += 1;
            let mut once = vec![0u8; 4096];
            let n = m.emit(&mut once).expect("a parsed message emits");
            once.truncate(n);
            let again = Message::parse(t, &once).expect("an emitted message parses");
            let mut twice = vec![0u8; 4096];
            let n2 = again.emit(&mut twice).expect("emits");
            assert_eq!(&twice[..n2], &once[..], "type {t}: emit/parse not stable");
        }
        Err(_) => stats.refused += 1,
    }
}

fn endpoint(rng: &mut Rng) -> Endpoint<Vec<u8>> {
    let slots = 1 + rng.below(16);
    Endpoint::new(
        EndpointBuffers {
            decode: vec![0; MAX_ENCODED],
            reorder: vec![0; slots * 300],
            reorder_slot: 300,
            window: vec![0; (1 + rng.below(16)) * 300],
            window_slot: 300,
            raw: vec![0; MAX_PACKET],
        },
        EndpointConfig {
            tx_reserve: rng.below(3),
            min_rto_us: 1 + rng.below(1000) as u64,
            ..EndpointConfig::default()
        },
    )
}

/// Two endpoints exchanging messages over a line that damages, drops, repeats
/// and injects packets (CRC-valid acknowledgements and packets with random
/// sequence numbers among them). Whatever is delivered must come in order.
fn fuzz_endpoint(rng: &mut Rng, samples: &[(u8, Vec<u8>)], stats: &mut FuzzStats) {
    let mut a = endpoint(rng);
    let mut b = endpoint(rng);
    let data = [7u8; 64];
    let chunk = Message::FrameChunk(FrameChunk {
        epoch: 0,
        camera: Camera::Left,
        offset: 0,
        data: &data,
    });
    let mut now = rng.below(1 << 20) as u64;
    let mut last_seq: Option<u16> = None;
    for _ in 0..1 + rng.below(40) {
        now += rng.below(2000) as u64;
        for _ in 0..rng.below(4) {
            let _ = a.tx.send(&chunk);
        }
        let mut line = Vec::new();
        while let Some(p) = a.poll_transmit(now) {
            if rng.below(10) != 0 {
                line.extend_from_slice(p);
            }
            if line.len() > 1 << 16 {
                break;
            }
        }
        if rng.below(3) == 0 {
            // Something the peer never sent: a valid packet with a random sequence.
            let (t, p) = &samples[rng.below(samples.len())];
            packet(*t, rng.next_u64() as u16, p, &mut line);
        }
        if rng.below(3) == 0 {
            mutate(rng, &mut line);
        }
        let mut rest = &line[..];
        loop {
            let (n, ev) = b.receive(now, rest);
            rest = &rest[n..];
            if let Some(Event::Message { seq }) = ev {
                stats.delivered += 1;
                if let Some(prev) = last_seq {
                    // Only a new session (a Hello) may restart the sequence.
                    let is_hello = matches!(b.rx.message(), Some((_, Ok(Message::Hello(_)))));
                    assert!(
                        is_hello || seq == prev.wrapping_add(1),
                        "delivered {seq} after {prev}"
                    );
                }
                last_seq = Some(seq);
                let _ = b.rx.message();
            }
            if ev.is_none() && rest.is_empty() {
                break;
            }
        }
        b.acknowledge();
        let mut back = Vec::new();
        while let Some(p) = b.poll_transmit(now) {
            back.extend_from_slice(p);
        }
        if rng.below(3) == 0 {
            mutate(rng, &mut back);
        }
        let mut rest = &back[..];
        while !rest.is_empty() {
            let (n, _) = a.receive(now, rest);
            rest = &rest[n..];
        }
        assert!(a.tx.in_flight() <= a.tx.capacity());
    }
}

/// Runs `inputs` inputs of `target` from `seed`; `progress` is called every
/// 2^16 inputs with the count so far.
pub fn run(target: Target, inputs: u64, seed: u64, mut progress: impl FnMut(u64)) -> FuzzStats {
    let samples = sample_payloads();
    let mut rng = Rng::new(seed ^ target as u64);
    let mut stats = FuzzStats::default();
    for i in 0..inputs {
        match target {
            Target::Decoder => fuzz_decoder(&mut rng, &samples, &mut stats),
            Target::Messages => fuzz_messages(&mut rng, &samples, &mut stats),
            Target::Endpoint => fuzz_endpoint(&mut rng, &samples, &mut stats),
        }
        stats.inputs += 1;
        if i & 0xFFFF == 0xFFFF {
            progress(i + 1);
        }
    }
    stats
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_short_fuzz_run_of_every_target() {
        for target in Target::ALL {
            let n = match target {
                Target::Endpoint => 2_000,
                _ => 20_000,
            };
            let s = run(target, n, 1, |_| {});
            assert_eq!(s.inputs, n);
            match target {
                Target::Decoder => assert!(s.packets > 0 && s.dropped > 0, "{s:?}"),
                Target::Messages => assert!(s.parsed > 0 && s.refused > 0, "{s:?}"),
                Target::Endpoint => assert!(s.delivered > 0, "{s:?}"),
            }
        }
    }
}
