//! Fuzz the CAN decoder: any identifier and payload, classic or CAN FD, must decode or return
//! a typed error, never panic, and whatever decodes must encode back to the same frame (but for the bit-rate switch).
//!
//! `cargo +nightly fuzz run decode` (from the repository root).
#![no_main]

use libfuzzer_sys::fuzz_target;
use pa10::can::protocol::{CanFrame, FD_LENGTHS, decode, encode};

fuzz_target!(|data: &[u8]| {
    if data.len() < 3 {
        return;
    }
    let id = u16::from_le_bytes([data[0], data[1]]) & 0x7FF;
    let payload = &data[3..];
    let frame = if data[2] & 1 == 0 {
        CanFrame::new(id, &payload[..payload.len().min(8)])
    } else {
        let len = FD_LENGTHS
            .iter()
            .rev()
            .find(|&&l| l <= payload.len())
            .copied()
            .unwrap_or(0);
        CanFrame::new_fd(id, &payload[..len], data[2] & 2 != 0)
    };
    if let Some(frame) = frame
        && let Ok(msg) = decode(&frame)
    {
        // the bit-rate switch is the sender's choice, not the message's
        let back = encode(&msg).ok().and_then(|f| f.with_data(f.data()));
        let same = |f: &CanFrame| (f.id(), f.data().to_vec(), f.is_fd());
        assert_eq!(back.map(|f| same(&f)), Some(same(&frame)));
    }
});
