use super::*;

/// Pushes one-byte packets numbered by their first byte.
fn fill(w: &mut TxWindow<&mut [u8]>, n: usize) -> heapless::Vec<u16, 64> {
    let mut seqs = heapless::Vec::new();
    for _ in 0..n {
        let seq = w.next_seq();
        seqs.push(w.push(&[seq as u8, 0xAA]).unwrap()).unwrap();
    }
    seqs
}

/// A window of 16 four-byte slots over `storage` with `n` packets sent at time 0.
fn sent(storage: &mut [u8; 64], n: usize) -> TxWindow<&mut [u8]> {
    let mut w = TxWindow::new(&mut storage[..], 4);
    fill(&mut w, n);
    assert_eq!(send_all(&mut w, 0).len(), n);
    w
}

/// Transmits everything due at `now`; returns the first bytes of what went out.
fn send_all(w: &mut TxWindow<&mut [u8]>, now: u64) -> heapless::Vec<u8, 64> {
    let mut out = heapless::Vec::new();
    while let Some((_, seq)) = w.next_transmission(now) {
        out.push(w.packet(seq).unwrap()[0]).unwrap();
    }
    out
}

#[test]
fn window_holds_acks_and_replays_across_the_wrap() {
    let mut storage = [0u8; 4 * 8];
    let mut w = TxWindow::new(&mut storage[..], 8);
    w.reset(65534);
    assert_eq!(&fill(&mut w, 4)[..], &[65534, 65535, 0, 1]);
    assert!(w.is_full());
    assert_eq!(w.push(&[9]), Err(WindowError::Full));
    assert_eq!(&send_all(&mut w, 0)[..], &[254, 255, 0, 1]);
    assert_eq!(w.ack(10, 65533, 0).released, 0, "stale ack");
    assert_eq!(w.ack(10, 5, 0).released, 0, "ack beyond what was sent");
    let out = w.ack(10, 0, 0);
    assert_eq!(out.released, 2, "ack across the wrap");
    assert_eq!(out.rtt_us, Some(10));
    assert_eq!(w.base(), 0);
    assert_eq!(w.packet(1).map(|p| p[0]), Some(1));
    assert_eq!(w.packet(65535), None, "released");
    // The timer restarted with the progress at 10: it expires at 110, once.
    assert!(!w.timer_expired(109, 100));
    assert!(w.timer_expired(110, 100));
    assert!(!w.timer_expired(111, 100), "one expiry is one event");
    assert!(
        send_all(&mut w, 110).is_empty(),
        "a time-out resends nothing by itself"
    );
    assert_eq!(w.resend_oldest(110), Some(0), "its probe takes the oldest");
}

#[test]
fn a_probe_answered_declares_lost_what_was_sent_before_it() {
    let mut storage = [0u8; 16 * 4];
    let mut w = sent(&mut storage, 6);
    assert_eq!(w.next_timeout(100), Some(100));
    assert!(w.timer_expired(100, 100));
    let probe = w.transmissions();
    fill(&mut w, 1);
    assert_eq!(&send_all(&mut w, 101)[..], &[6], "sent after the probe");
    // The answer: 0 and 1 arrived, 2..5 did not; 6 may still be on its way.
    let out = w.ack(150, 2, 0);
    assert_eq!(out.lost, 0, "too few later deliveries to call a loss");
    assert_eq!(w.lost_before(probe), 4);
    assert_eq!(&send_all(&mut w, 151)[..], &[2, 3, 4, 5]);
    assert_eq!(w.lost_before(probe), 0, "resent after the probe");
}

#[test]
fn any_slot_count_keeps_every_packet_across_the_wrap() {
    // Five slots: with `seq % slots`, 65535 and 0 would share a slot.
    for slots in [3usize, 5, 7] {
        let mut storage = [0u8; 7 * 4];
        let mut w = TxWindow::new(&mut storage[..slots * 4], 4);
        w.reset(65530);
        let mut acked = 65530u16;
        for round in 0..20u16 {
            let free = slots - w.len();
            fill(&mut w, free);
            // Everything held is its own packet, in order.
            for k in 0..slots as u16 {
                let seq = acked.wrapping_add(k);
                assert_eq!(
                    w.packet(seq).unwrap()[0],
                    seq as u8,
                    "{slots} slots, round {round}"
                );
            }
            send_all(&mut w, round as u64);
            // Acknowledge one or two, as a receiver would.
            acked = acked.wrapping_add(1 + round % 2);
            w.ack(round as u64, acked, 0);
        }
    }
}

#[test]
fn a_gap_costs_the_missing_packet_only() {
    let mut storage = [0u8; 16 * 4];
    let mut w = sent(&mut storage, 8);
    // Packet 2 lost: the receiver holds 3, 4, 5 (bits 0..2 after next_expected 2).
    let out = w.ack(5, 2, 0b111);
    assert_eq!((out.released, out.sacked, out.lost), (2, 3, 1));
    assert_eq!(&send_all(&mut w, 6)[..], &[2], "only the hole goes again");
    // The resend arrives with 6 and 7: everything is released.
    assert_eq!(w.ack(8, 8, 0).released, 6);
    assert!(w.is_empty());
}

#[test]
fn a_neighbour_swap_is_not_a_loss() {
    let mut storage = [0u8; 16 * 4];
    let mut w = sent(&mut storage, 8);
    // 1 arrives after 2: the acknowledgement after 2 holds it, nothing is lost yet.
    assert_eq!(w.ack(1, 1, 0b1).lost, 0);
    assert!(send_all(&mut w, 2).is_empty());
}

#[test]
fn a_nack_resends_everything_in_flight_from_its_sequence() {
    let mut storage = [0u8; 16 * 4];
    let mut w = sent(&mut storage, 5);
    w.resend_from(3);
    assert_eq!(&send_all(&mut w, 1)[..], &[3, 4]);
}

#[test]
fn the_reorder_ring_holds_after_a_gap_and_delivers_in_order() {
    let mut storage = [0u8; 3 * 8];
    let mut r = RxReorder::new(&mut storage[..], 8);
    r.reset(65534);
    assert_eq!(r.accept(65535, &[1]), Accept::Held);
    assert_eq!(r.accept(0, &[2]), Accept::Held);
    assert_eq!(r.accept(0, &[2]), Accept::Duplicate);
    assert_eq!(
        r.accept(2, &[9]),
        Accept::Beyond,
        "three slots: 65535, 0, 1"
    );
    assert_eq!(r.accept(1, &[0; 9]), Accept::Beyond, "larger than a slot");
    assert_eq!(r.held(), 0b011);
    assert_eq!(r.accept(65534, &[0]), Accept::Deliver);
    let next = r.advance().expect("65535 is held");
    assert_eq!(r.bytes(next), &[1]);
    let next = r.advance().expect("0 is held");
    assert_eq!(r.bytes(next), &[2]);
    assert_eq!(r.advance(), None, "1 never came");
    assert_eq!(r.expected(), 1);
    assert_eq!(r.accept(0, &[2]), Accept::Duplicate);
    assert_eq!(r.accept(1, &[3]), Accept::Deliver);
}

#[test]
fn the_acknowledgement_of_a_resent_packet_declares_nothing_lost() {
    // A receiver too busy to answer: the time-out resends the oldest packet with the
    // probe. Then it catches up and acknowledges the first two, the original of the
    // resent one among them: which copy arrived is not known, and the packets sent
    // before the probe are not lost, only not reached yet.
    let mut storage = [0u8; 16 * 4];
    let mut w = sent(&mut storage, 8);
    assert!(w.timer_expired(100, 100));
    assert_eq!(w.resend_oldest(100), Some(0));
    let out = w.ack(150, 2, 0);
    assert_eq!(out.released, 2);
    assert_eq!(
        out.lost, 0,
        "nothing declared lost from the resent packet's order"
    );
    assert_eq!(
        out.rtt_us,
        Some(150),
        "packet 1, sent once, times the round trip"
    );
    assert!(send_all(&mut w, 151).is_empty(), "nothing resent");
    // A later delivery of packets sent once still tells a loss.
    let out = w.ack(160, 2, 0b11111);
    assert_eq!(out.lost, 1, "packet 2 is missing while 3 to 7 arrived");
    assert_eq!(&send_all(&mut w, 161)[..], &[2]);
}

/// The tally recounted from the slots, as the scans over the window gave it.
fn recount(w: &TxWindow<&mut [u8]>) -> Tally {
    let mut t = Tally::default();
    for k in 0..w.count {
        let s = w.state[w.slot_at(k)];
        t.unsent += usize::from(s.sent_at.is_none());
        t.sacked += usize::from(s.sacked);
        t.lost += usize::from(s.lost);
    }
    t
}

/// The next transmission as the full scan picked it: the first lost packet, else
/// the first never sent.
fn scanned_pick(w: &TxWindow<&mut [u8]>) -> Option<(Transmission, u16)> {
    let slots = (0..w.count).map(|k| (k, w.state[w.slot_at(k)]));
    let lost = slots
        .clone()
        .find(|(_, s)| !s.sacked && s.sent_at.is_some() && s.lost);
    let new = slots
        .clone()
        .find(|(_, s)| !s.sacked && s.sent_at.is_none());
    match (lost, new) {
        (Some((k, _)), _) => Some((Transmission::Lost, w.base.wrapping_add(k as u16))),
        (None, Some((k, _))) => Some((Transmission::New, w.base.wrapping_add(k as u16))),
        _ => None,
    }
}

proptest::proptest! {
    /// Whatever acknowledgements, probes and time-outs arrive, bogus ones included,
    /// the counted states are the slots' and the next transmission is the scan's.
    #[test]
    fn the_tally_follows_the_slots_under_any_sequence_of_events(
        slots in 1usize..=16,
        start in proptest::prelude::any::<u16>(),
        events in proptest::collection::vec(
            (0u8..7, proptest::prelude::any::<u16>(), proptest::prelude::any::<u64>()),
            0..200,
        ),
    ) {
        let mut storage = [0u8; 16 * 4];
        let mut w = TxWindow::new(&mut storage[..slots * 4], 4);
        w.reset(start);
        for (i, (op, a, b)) in events.into_iter().enumerate() {
            let now = i as u64 * 10;
            match op {
                0 => {
                    let _ = w.push(&[a as u8]);
                }
                1 => {
                    let expected = scanned_pick(&w);
                    proptest::prop_assert_eq!(w.next_transmission(now), expected);
                }
                // An acknowledgement near the window, or anywhere.
                2 => {
                    w.ack(now, w.base.wrapping_add(a % 20), b);
                }
                3 => {
                    w.ack(now, a, b);
                }
                4 => {
                    w.lost_before(a as u32);
                }
                5 => w.resend_from(w.base.wrapping_add(a % 20)),
                _ => {
                    w.resend_oldest(now);
                }
            }
            let t = recount(&w);
            proptest::prop_assert_eq!(w.tally, t);
            proptest::prop_assert_eq!(w.has_due(), t.unsent + t.lost > 0);
        }
    }
}
