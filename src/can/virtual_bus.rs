//! An in-process CAN bus for tests and the simulated backend.
//!
//! Any number of endpoints share one bus with broadcast semantics: every frame reaches every
//! other endpoint (and the sender only if it asked to receive its own frames). Faults can be
//! injected — latency, loss, corruption, bus-off — and a bit-accurate counter (real bit
//! stuffing, not an estimate; for CAN FD frames the arbitration phase at the nominal and the
//! data phase at the data bit rate, `crate::can::timing`) reports the time the wire was busy.
//! A classic bus refuses FD frames, as a classic controller (or a vcan with MTU 16) does.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use rand::{RngExt, SeedableRng};
use rand_pcg::Pcg64;
use tokio::sync::mpsc;
use tokio::time::Instant;

use super::bus::{BusError, BusEvent, CanBus, Filter, passes};
use super::frame::{CanFrame, Framing};
use super::timing::{BusTiming, exact_bits};

/// Fault injection and timing of a virtual bus.
#[derive(Debug, Clone, PartialEq)]
pub struct VirtualConfig {
    /// Framing and bit rates (for the wire time; a classic bus refuses FD frames).
    pub timing: BusTiming,
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
            timing: BusTiming::classic(1e6),
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
    /// Time the wire was busy with them, s (FD data phases at the data bit rate).
    pub wire_s: f64,
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
        if frame.is_fd() && s.cfg.timing.framing != Framing::Fd {
            return Err(BusError::FdUnsupported);
        }
        s.stats.frames += 1;
        s.stats.bits += exact_bits(&frame).total() as u64;
        s.stats.wire_s += s.cfg.timing.frame_time_s(&frame);
        let (loss, corrupt, latency) = (s.cfg.loss, s.cfg.corrupt, s.cfg.latency);
        if loss > 0.0 && s.rng.random::<f64>() < loss {
            return Ok(());
        }
        let mut delivered = frame;
        if corrupt > 0.0 && frame.dlc() > 0 && s.rng.random::<f64>() < corrupt {
            let bit = s.rng.random_range(0..frame.dlc() * 8);
            let mut d = [0u8; 64];
            d[..frame.dlc()].copy_from_slice(frame.data());
            d[bit / 8] ^= 1 << (bit % 8);
            delivered = frame.with_data(&d[..frame.dlc()]).unwrap_or(frame);
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

#[cfg(test)]
mod tests {
    use super::*;

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
        assert!(
            (s.wire_s - s.bits as f64 / 1e6).abs() < 1e-12,
            "all at 1 Mbit/s"
        );
        // a classic bus refuses FD frames
        let fd = CanFrame::new_fd(0x180, &[0; 48], true).unwrap();
        assert_eq!(a.send(fd).await, Err(BusError::FdUnsupported));
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

#[cfg(test)]
mod fd_tests {
    use super::*;

    #[tokio::test(start_paused = true)]
    async fn an_fd_bus_carries_both_formats_and_times_the_data_phase_at_its_rate() {
        let bus = VirtualBus::new(VirtualConfig {
            timing: BusTiming::fd(1e6, 5e6),
            corrupt: 1.0,
            ..Default::default()
        });
        let mut a = bus.endpoint(false);
        let mut b = bus.endpoint(false);
        let fd = CanFrame::new_fd(0x180, &[0x33; 48], true).unwrap();
        a.send(fd).await.unwrap();
        a.send(CanFrame::new(0x080, &[1, 0]).unwrap())
            .await
            .unwrap();
        let Ok(BusEvent::Frame(g)) = b.recv(Duration::from_millis(1)).await else {
            panic!("the FD frame arrives")
        };
        // corrupted in one bit of its 48 bytes, still an FD frame with the switch
        assert!(g.is_fd() && g.brs() && g.dlc() == 48);
        let flipped: u32 = g
            .data()
            .iter()
            .zip(fd.data())
            .map(|(x, y)| (x ^ y).count_ones())
            .sum();
        assert_eq!(flipped, 1);
        assert!(
            matches!(b.recv(Duration::from_millis(1)).await, Ok(BusEvent::Frame(f)) if !f.is_fd())
        );
        let s = bus.stats();
        let (fd_bits, sync_bits) = (
            exact_bits(&fd),
            exact_bits(&CanFrame::new(0x080, &[1, 0]).unwrap()),
        );
        assert_eq!(s.bits, (fd_bits.total() + sync_bits.total()) as u64);
        let want = fd_bits.nominal as f64 / 1e6
            + fd_bits.data as f64 / 5e6
            + sync_bits.total() as f64 / 1e6;
        assert!((s.wire_s - want).abs() < 1e-12, "{} vs {want}", s.wire_s);
    }
}
