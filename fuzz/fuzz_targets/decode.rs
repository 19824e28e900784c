//! Fuzz the CAN decoder: any identifier and payload must decode or return a typed error,
//! never panic, and whatever decodes must encode back to the same frame.
//!
//! `cargo +nightly fuzz run decode` (from the repository root).
#![no_main]

use libfuzzer_sys::fuzz_target;
use pa10::can::protocol::{Frame, decode, encode};

fuzz_target!(|data: &[u8]| {
    if data.len() < 2 {
        return;
    }
    let id = u16::from_le_bytes([data[0], data[1]]) & 0x7FF;
    let payload = &data[2..data.len().min(10)];
    if let Some(frame) = Frame::new(id, payload)
        && let Ok(msg) = decode(&frame)
    {
        assert_eq!(encode(&msg).ok(), Some(frame));
    }
});
