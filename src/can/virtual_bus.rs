//! An in-process CAN bus for tests and the simulated backend.
//!
//! Any number of endpoints share one bus with broadcast semantics: every frame reaches every
//! other endpoint (and the sender only if it asked to receive its own frames). Faults can be
//! injected — latency, loss, corruption, bus-off — and a bit-accurate counter (real bit
//! stuffing and CRC-15, not an estimate) reports the bus load.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use rand::{RngExt, SeedableRng};
use rand_pcg::Pcg64;
use tokio::sync::mpsc;
use tokio::time::Instant;

use super::bus::{BusError, BusEvent, CanBus, Filter, passes};
use super::protocol::CanFrame;

/// Fault injection and timing of a virtual bus.
#[derive(Debug, Clone, PartialEq)]
pub struct VirtualConfig {
    /// Bit rate, bit/s (for the load figure).
    pub bitrate: f64,
    /// Delivery delay of every frame (resolved to tokio's 1 ms timer).
    pub latency: Duration,
    /// Probability (0…1) that a frame is lost.
    pub loss: f64,
    /// Probability (0…1) that a delivered frame has one data bit flipped.
    pub corrupt: f64,
    /// Seed of the loss and corruption draws.
    pub seed: u64,
}

impl Default for VirtualConfig {
    fn default() -> Self {
        Self {
            bitrate: 1e6,
            latency: Duration::ZERO,
            loss: 0.0,
            corrupt: 0.0,
            seed: 0,
        }
    }
}

/// Traffic counters.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BusStats {
    /// Frames put on the bus (lost ones included: they used the wire).
    pub frames: u64,
    /// Exact bits on the wire, stuffing and interframe space included.
    pub bits: u64,
}

#[derive(Debug, Clone, Copy)]
enum Delivery {
    Frame(CanFrame, Instant),
    BusOff,
}

struct Slot {
    tx: mpsc::UnboundedSender<Delivery>,
    receive_own: bool,
}

struct Shared {
    slots: Vec<Option<Slot>>,
    cfg: VirtualConfig,
    stats: BusStats,
    rng: Pcg64,
    bus_off: bool,
}

/// A virtual CAN bus; clone it freely (all clones are the same bus).
#[derive(Clone)]
pub struct VirtualBus {
    shared: Arc<Mutex<Shared>>,
}

/// One node on a [`VirtualBus`].
pub struct VirtualEndpoint {
    index: usize,
    shared: Arc<Mutex<Shared>>,
    rx: mpsc::UnboundedReceiver<Delivery>,
    filters: Vec<Filter>,
    /// A frame taken from the channel whose delivery time had not come yet: kept, so that a
    /// receive that times out (or is dropped) while it waits does not lose it.
    held: Option<(CanFrame, Instant)>,
}

impl VirtualBus {
    /// A bus with `cfg`.
    pub fn new(cfg: VirtualConfig) -> Self {
        let rng = Pcg64::seed_from_u64(cfg.seed);
        Self {
            shared: Arc::new(Mutex::new(Shared {
                slots: Vec::new(),
                cfg,
                stats: BusStats::default(),
                rng,
                bus_off: false,
            })),
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Shared> {
        self.shared.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// A new endpoint; `receive_own`: it also receives what it sends.
    pub fn endpoint(&self, receive_own: bool) -> VirtualEndpoint {
        let (tx, rx) = mpsc::unbounded_channel();
        let mut s = self.lock();
        s.slots.push(Some(Slot { tx, receive_own }));
        VirtualEndpoint {
            index: s.slots.len() - 1,
            shared: self.shared.clone(),
            rx,
            filters: Vec::new(),
            held: None,
        }
    }

    /// Traffic so far.
    pub fn stats(&self) -> BusStats {
        self.lock().stats
    }

    /// Replaces the fault configuration.
    pub fn set_config(&self, cfg: VirtualConfig) {
        self.lock().cfg = cfg;
    }

    /// Forces the bus off (every endpoint sees [`BusEvent::BusOff`], sends fail) or recovers it.
    pub fn set_bus_off(&self, off: bool) {
        let mut s = self.lock();
        s.bus_off = off;
        if off {
            for slot in s.slots.iter().flatten() {
                let _ = slot.tx.send(Delivery::BusOff);
            }
        }
    }
}

impl Drop for VirtualEndpoint {
    fn drop(&mut self) {
        let mut s = self.shared.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(slot) = s.slots.get_mut(self.index) {
            *slot = None;
        }
    }
}

impl CanBus for VirtualEndpoint {
    async fn send(&mut self, frame: CanFrame) -> Result<(), BusError> {
        let mut s = self.shared.lock().unwrap_or_else(|p| p.into_inner());
        if s.bus_off {
            return Err(BusError::BusOff);
        }
        s.stats.frames += 1;
        s.stats.bits += exact_frame_bits(&frame) as u64;
        let (loss, corrupt, latency) = (s.cfg.loss, s.cfg.corrupt, s.cfg.latency);
        if loss > 0.0 && s.rng.random::<f64>() < loss {
            return Ok(());
        }
        let mut delivered = frame;
        if corrupt > 0.0 && frame.dlc() > 0 && s.rng.random::<f64>() < corrupt {
            let bit = s.rng.random_range(0..frame.dlc() * 8);
            let mut d = [0u8; 8];
            d[..frame.dlc()].copy_from_slice(frame.data());
            d[bit / 8] ^= 1 << (bit % 8);
            delivered = CanFrame::new(frame.id(), &d[..frame.dlc()]).unwrap_or(frame);
        }
        let at = Instant::now() + latency;
        for (i, slot) in s.slots.iter().enumerate() {
            if let Some(slot) = slot
                && (i != self.index || slot.receive_own)
            {
                let _ = slot.tx.send(Delivery::Frame(delivered, at));
            }
        }
        Ok(())
    }

    async fn recv(&mut self, timeout: Duration) -> Result<BusEvent, BusError> {
        let deadline = Instant::now() + timeout;
        loop {
            let (f, at) = match self.held {
                Some(held) => held,
                None => match tokio::time::timeout_at(deadline, self.rx.recv()).await {
                    Err(_) => return Err(BusError::Timeout),
                    Ok(None) => return Err(BusError::Closed),
                    Ok(Some(Delivery::BusOff)) => return Ok(BusEvent::BusOff),
                    Ok(Some(Delivery::Frame(f, at))) => (f, at),
                },
            };
            if at > Instant::now() {
                self.held = Some((f, at));
                if at > deadline {
                    tokio::time::sleep_until(deadline).await;
                    return Err(BusError::Timeout);
                }
                tokio::time::sleep_until(at).await;
            }
            self.held = None;
            if passes(&self.filters, f.id()) {
                return Ok(BusEvent::Frame(f));
            }
        }
    }

    fn set_filters(&mut self, filters: &[Filter]) -> Result<(), BusError> {
        self.filters = filters.to_vec();
        Ok(())
    }
}

/// CRC-15/CAN of a bit sequence.
fn crc15(bits: &[bool]) -> u16 {
    let mut crc: u16 = 0;
    for &b in bits {
        let next = b ^ ((crc >> 14) & 1 == 1);
        crc = (crc << 1) & 0x7FFF;
        if next {
            crc ^= 0x4599;
        }
    }
    crc
}

/// Exact length on the wire of a standard data frame, bits: SOF … CRC with the bit stuffing
/// this very frame needs, then CRC delimiter, ACK slot and delimiter, EOF and the 3-bit
/// interframe space.
pub fn exact_frame_bits(f: &CanFrame) -> u32 {
    let mut bits: Vec<bool> = Vec::with_capacity(128);
    bits.push(false); // SOF
    for i in (0..11).rev() {
        bits.push((f.id() >> i) & 1 == 1);
    }
    bits.extend([false, false, false]); // RTR, IDE, r0
    for i in (0..4).rev() {
        bits.push((f.dlc() >> i) & 1 == 1);
    }
    for byte in f.data() {
        for i in (0..8).rev() {
            bits.push((byte >> i) & 1 == 1);
        }
    }
    let crc = crc15(&bits);
    for i in (0..15).rev() {
        bits.push((crc >> i) & 1 == 1);
    }
    let (mut stuffed, mut run, mut last) = (0u32, 0u32, None);
    for &b in &bits {
        if Some(b) == last {
            run += 1;
        } else {
            run = 1;
            last = Some(b);
        }
        if run == 5 {
            stuffed += 1;
            last = Some(!b);
            run = 1;
        }
    }
    bits.len() as u32 + stuffed + 1 + 2 + 7 + 3
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::can::protocol::{frame_bits_nominal, frame_bits_worst};

    #[test]
    fn exact_bits_lie_between_nominal_and_worst_case() {
        for dlc in 0..=8 {
            for pattern in [0x00u8, 0xFF, 0x55, 0x0F] {
                let f = CanFrame::new(0x7FF & (0x555 + dlc as u16), &vec![pattern; dlc]).unwrap();
                let b = exact_frame_bits(&f);
                assert!(
                    b >= frame_bits_nominal(dlc) && b <= frame_bits_worst(dlc),
                    "dlc {dlc} {pattern:#x}: {b}"
                );
            }
        }
        // all-zero payloads stuff a bit every four: clearly more than nominal
        let zeros = CanFrame::new(0x000, &[0; 8]).unwrap();
        assert!(exact_frame_bits(&zeros) > frame_bits_nominal(8) + 15);
        // CRC-15 of the empty message is 0
        assert_eq!(crc15(&[]), 0);
    }

    #[tokio::test(start_paused = true)]
    async fn broadcast_own_frames_filters_latency_loss_and_bus_off() {
        let bus = VirtualBus::new(VirtualConfig {
            latency: Duration::from_millis(2),
            ..Default::default()
        });
        let mut a = bus.endpoint(false);
        let mut b = bus.endpoint(false);
        let mut c = bus.endpoint(true);
        let f = CanFrame::new(0x181, &[1, 2, 3, 4, 5, 6, 7, 8]).unwrap();
        let t0 = Instant::now();
        a.send(f).await.unwrap();
        assert_eq!(
            b.recv(Duration::from_millis(10)).await,
            Ok(BusEvent::Frame(f))
        );
        assert!(
            Instant::now() - t0 >= Duration::from_millis(2),
            "latency applied"
        );
        assert_eq!(
            c.recv(Duration::from_millis(10)).await,
            Ok(BusEvent::Frame(f))
        );
        assert_eq!(
            a.recv(Duration::from_millis(5)).await,
            Err(BusError::Timeout),
            "no echo without receive_own"
        );
        c.send(f).await.unwrap();
        assert_eq!(
            c.recv(Duration::from_millis(10)).await,
            Ok(BusEvent::Frame(f)),
            "own frame when asked"
        );
        let _ = b.recv(Duration::from_millis(10)).await;
        let _ = a.recv(Duration::from_millis(10)).await;
        // filters
        b.set_filters(&[Filter::exact(0x080)]).unwrap();
        a.send(f).await.unwrap();
        a.send(CanFrame::new(0x080, &[1, 0]).unwrap())
            .await
            .unwrap();
        assert_eq!(
            b.recv(Duration::from_millis(10)).await.unwrap(),
            BusEvent::Frame(CanFrame::new(0x080, &[1, 0]).unwrap())
        );
        // load counter
        let s = bus.stats();
        assert_eq!(s.frames, 4);
        assert!(s.bits >= 3 * 111 + 63);
        // bus-off
        bus.set_bus_off(true);
        assert_eq!(
            b.recv(Duration::from_millis(10)).await,
            Ok(BusEvent::BusOff)
        );
        assert_eq!(a.send(f).await, Err(BusError::BusOff));
        bus.set_bus_off(false);
        // loss = 1 drops everything, corruption flips one bit
        bus.set_config(VirtualConfig {
            loss: 1.0,
            ..Default::default()
        });
        a.send(f).await.unwrap();
        b.set_filters(&[]).unwrap();
        assert_eq!(
            b.recv(Duration::from_millis(5)).await,
            Err(BusError::Timeout)
        );
        bus.set_config(VirtualConfig {
            corrupt: 1.0,
            ..Default::default()
        });
        a.send(f).await.unwrap();
        let Ok(BusEvent::Frame(g)) = b.recv(Duration::from_millis(5)).await else {
            panic!()
        };
        let flipped: u32 = g
            .data()
            .iter()
            .zip(f.data())
            .map(|(x, y)| (x ^ y).count_ones())
            .sum();
        assert_eq!(flipped, 1);
    }
}
