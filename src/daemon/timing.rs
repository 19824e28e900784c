//! Cycle statistics without allocation: a fixed-bucket histogram of durations and the
//! numbers `status` reports about the control loop's timing.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Histogram of durations in microseconds (fixed buckets, no allocation per sample).
#[derive(Debug, Clone)]
pub struct Histogram {
    buckets: [u64; 1000],
    overflow: u64,
    max_us: f64,
    n: u64,
}

impl Default for Histogram {
    fn default() -> Self {
        Self {
            buckets: [0; 1000],
            overflow: 0,
            max_us: 0.0,
            n: 0,
        }
    }
}

impl Histogram {
    /// Buckets of 10 µs up to 10 ms.
    const W: f64 = 10.0;
    /// Records `us` microseconds.
    pub fn record(&mut self, us: f64) {
        let i = (us.max(0.0) / Self::W) as usize;
        match self.buckets.get_mut(i) {
            Some(b) => *b += 1,
            None => self.overflow += 1,
        }
        self.max_us = self.max_us.max(us);
        self.n += 1;
    }
    /// p50, p99 and max, µs (what `status` reports).
    pub fn summary(&self) -> [f64; 3] {
        [self.quantile(0.5), self.quantile(0.99), self.max_us]
    }
    /// The `p` quantile (0…1), µs, to the bucket's upper edge.
    pub fn quantile(&self, p: f64) -> f64 {
        let k = (p * self.n as f64).ceil() as u64;
        let mut c = 0;
        for (i, b) in self.buckets.iter().enumerate() {
            c += b;
            if c >= k.max(1) {
                return (i as f64 + 1.0) * Self::W;
            }
        }
        self.max_us
    }
}

/// Cycle statistics for `status`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema, Default)]
pub struct CycleStats {
    /// Cycles run.
    pub cycles: u64,
    /// Cycles that started later than one period after their deadline.
    pub overruns: u64,
    /// Wake-up lateness, p50 / p99 / max, µs.
    pub jitter_us: [f64; 3],
    /// Compute time of a cycle (receive → commands sent), p50 / p99 / max, µs.
    pub compute_us: [f64; 3],
    /// The configured cycle rate, Hz.
    #[serde(default)]
    pub rate_hz: f64,
    /// The cyclic frames' format: `classic` (six COMMAND and six FEEDBACK frames a cycle) or
    /// `fd` (one COMMAND_FD and one FEEDBACK_FD).
    #[serde(default)]
    pub framing: crate::can::Framing,
    /// Worst-case bus load of the configured rate, %.
    pub bus_load_pct: f64,
    /// Times the control thread found the core's lock held by a client and waited.
    pub lock_waits: u64,
    /// How long those waits took, p50 / p99 / max, µs (zeros when it never waited).
    pub lock_wait_us: [f64; 3],
}
