//! Time on the wire, sans IO: how many bits a frame takes (worst case, and exactly for a given
//! frame), how long at a bus's bit rates ([`BusTiming`]: classic CAN, or CAN FD with an
//! arbitration and a data phase), and the worst-case load of one control cycle's traffic, which
//! the daemon reports and enforces ([`BusTiming::check_rate`]).
//!
//! Frame lengths follow ISO 11898-1:2015 as the Linux kernel counts them
//! (`include/linux/can/length.h`): worst-case dynamic stuffing of one bit every four after the
//! first, over SOF … end of data; CAN FD's stuff count, CRC-17 (≤ 16 bytes) or CRC-21 and their
//! fixed stuff bits; the 3-bit interframe space. For CAN FD the arbitration phase (SOF … BRS,
//! its stuff bits, then CRC delimiter, ACK, EOF and interframe space) runs at the nominal bit
//! rate and the rest at the data bit rate.

use super::frame::{CanFrame, Framing};

/// Bits of an FD frame in each phase.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FdBits {
    /// Bits at the nominal (arbitration) bit rate.
    pub nominal: u32,
    /// Bits at the data bit rate (with the bit-rate switch; else also at the nominal rate).
    pub data: u32,
}

impl FdBits {
    /// All bits.
    pub fn total(&self) -> u32 {
        self.nominal + self.data
    }
}

/// Worst-case bits of a classic standard frame with `dlc` data bytes, stuffing and the 3-bit
/// interframe space included: `34 + 8s + 13 + ⌊(34 + 8s − 1)/4⌋` (Davis et al. 2007).
pub fn frame_bits_worst(dlc: usize) -> u32 {
    let g = 34 + 8 * dlc as u32;
    g + 13 + (g - 1) / 4
}

/// Nominal bits of a classic standard frame (no stuffing), interframe space included.
pub fn frame_bits_nominal(dlc: usize) -> u32 {
    47 + 8 * dlc as u32
}

/// SOF, identifier, RRS, IDE, FDF, res, BRS: the FD bits sent before the bit-rate switch.
const FD_ARBITRATION_BITS: u32 = 17;
/// ESI and DLC: the FD header bits after the switch.
const FD_CONTROL_BITS: u32 = 5;
/// CRC delimiter, ACK slot and delimiter, EOF and the interframe space: at the nominal rate.
const FD_TRAILER_BITS: u32 = 1 + 2 + 7 + 3;

/// CAN FD's CRC length for `len` data bytes: 17 up to 16 bytes, else 21.
fn fd_crc_bits(len: usize) -> u32 {
    if len <= 16 { 17 } else { 21 }
}

/// The stuff count (4 bits), the CRC and their fixed stuff bits (one before the stuff count
/// and one after every fourth bit: 6 with CRC-17, 7 with CRC-21).
fn fd_crc_field_bits(len: usize) -> u32 {
    let bits = 4 + fd_crc_bits(len);
    bits + 1 + (bits - 1) / 4
}

/// Worst-case bits of a CAN FD standard frame with `len` data bytes, by phase: the dynamic stuff
/// bits the arbitration phase can hold (4) at the nominal rate, the rest at the data rate.
pub fn fd_frame_bits_worst(len: usize) -> FdBits {
    let dynamic = FD_ARBITRATION_BITS + FD_CONTROL_BITS + 8 * len as u32;
    let stuff = (dynamic - 1) / 4;
    let stuff_arbitration = (FD_ARBITRATION_BITS - 1) / 4;
    FdBits {
        nominal: FD_ARBITRATION_BITS + stuff_arbitration + FD_TRAILER_BITS,
        data: FD_CONTROL_BITS
            + 8 * len as u32
            + (stuff - stuff_arbitration)
            + fd_crc_field_bits(len),
    }
}

/// Nominal bits of a CAN FD standard frame (no dynamic stuffing; fixed stuff bits included).
pub fn fd_frame_bits_nominal(len: usize) -> FdBits {
    FdBits {
        nominal: FD_ARBITRATION_BITS + FD_TRAILER_BITS,
        data: FD_CONTROL_BITS + 8 * len as u32 + fd_crc_field_bits(len),
    }
}

/// The unstuffed bits of one frame up to its CRC, on the stack: counting a frame's bits does
/// not allocate (the virtual bus counts every frame the loop sends).
struct Bits {
    b: [bool; 576],
    len: usize,
}

impl Bits {
    fn new() -> Self {
        Self {
            b: [false; 576],
            len: 0,
        }
    }
    fn push(&mut self, v: bool) {
        if let Some(slot) = self.b.get_mut(self.len) {
            *slot = v;
            self.len += 1;
        }
    }
    fn extend(&mut self, v: impl IntoIterator<Item = bool>) {
        for b in v {
            self.push(b);
        }
    }
    fn as_slice(&self) -> &[bool] {
        &self.b[..self.len]
    }
}

/// Pushes the `n` low bits of `v`, most significant first.
fn push_bits(bits: &mut Bits, v: u32, n: u32) {
    for i in (0..n).rev() {
        bits.push((v >> i) & 1 == 1);
    }
}

/// Dynamic stuff bits of a bit sequence (after five equal bits, one of the other value), and
/// how many of them fall within its first `split` bits.
fn stuff_bits(bits: &[bool], split: usize) -> (u32, u32) {
    let (mut stuffed, mut before, mut run, mut last) = (0u32, 0u32, 0u32, None);
    for (i, &b) in bits.iter().enumerate() {
        if Some(b) == last {
            run += 1;
        } else {
            run = 1;
            last = Some(b);
        }
        if run == 5 {
            stuffed += 1;
            if i < split {
                before += 1;
            }
            last = Some(!b);
            run = 1;
        }
    }
    (stuffed, before)
}

/// CRC-15/CAN of a bit sequence.
pub(crate) fn crc15(bits: &[bool]) -> u16 {
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

/// Exact bits of this very frame on the wire, by phase: its own dynamic stuffing (classic:
/// over SOF … CRC-15; FD: over SOF … data, the CRC field having fixed stuff bits), the trailer
/// and the interframe space. A classic frame is all `nominal`.
pub fn exact_bits(f: &CanFrame) -> FdBits {
    let mut bits = Bits::new();
    bits.push(false); // SOF
    push_bits(&mut bits, u32::from(f.id()), 11);
    if !f.is_fd() {
        bits.extend([false, false, false]); // RTR, IDE, r0
        push_bits(&mut bits, u32::from(f.dlc_code()), 4);
        for &byte in f.data() {
            push_bits(&mut bits, u32::from(byte), 8);
        }
        let crc = crc15(bits.as_slice());
        push_bits(&mut bits, u32::from(crc), 15);
        let (stuffed, _) = stuff_bits(bits.as_slice(), 0);
        return FdBits {
            nominal: bits.len as u32 + stuffed + 1 + 2 + 7 + 3,
            data: 0,
        };
    }
    // RRS, IDE dominant; FDF recessive; res dominant; BRS; ESI dominant (error active)
    bits.extend([false, false, true, false, f.brs(), false]);
    push_bits(&mut bits, u32::from(f.dlc_code()), 4);
    for &byte in f.data() {
        push_bits(&mut bits, u32::from(byte), 8);
    }
    let (stuffed, arbitration) = stuff_bits(bits.as_slice(), FD_ARBITRATION_BITS as usize);
    FdBits {
        nominal: FD_ARBITRATION_BITS + arbitration + FD_TRAILER_BITS,
        data: bits.len as u32 - FD_ARBITRATION_BITS
            + (stuffed - arbitration)
            + fd_crc_field_bits(f.dlc()),
    }
}

/// Ceiling on the data bit rate, bit/s: CAN FD transceivers are specified up to 8 Mbit/s; 10
/// leaves room for the fastest, not for a typing error.
pub const MAX_DATA_BITRATE: f64 = 10e6;

/// A bit rate a bus cannot have.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum RateError {
    /// The arbitration-phase (classic: the only) bit rate.
    #[error("bitrate must be > 0 and ≤ 1000000 bit/s (CAN's arbitration phase), got {0}")]
    Bitrate(f64),
    /// The CAN FD data-phase bit rate.
    #[error("data_bitrate must be within bitrate ({bitrate:.0}) … {max:.0} bit/s, got {got}", max = MAX_DATA_BITRATE)]
    DataBitrate {
        /// The arbitration-phase rate, bit/s.
        bitrate: f64,
        /// The data-phase rate asked for, bit/s.
        got: f64,
    },
}

/// A bus's framing and bit rates, bit/s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BusTiming {
    /// The cyclic traffic's frame format.
    pub framing: Framing,
    /// Nominal (arbitration-phase) bit rate, bit/s; a classic bus's only rate.
    pub bitrate: f64,
    /// Data-phase bit rate of FD frames sent with the bit-rate switch, bit/s (= `bitrate` on a
    /// classic bus, or an FD bus without the switch).
    pub data_bitrate: f64,
}

impl BusTiming {
    /// A classic bus at `bitrate` bit/s.
    pub fn classic(bitrate: f64) -> Self {
        Self {
            framing: Framing::Classic,
            bitrate,
            data_bitrate: bitrate,
        }
    }

    /// A CAN FD bus: arbitration at `bitrate`, data phase at `data_bitrate`, bit/s.
    pub fn fd(bitrate: f64, data_bitrate: f64) -> Self {
        Self {
            framing: Framing::Fd,
            bitrate,
            data_bitrate,
        }
    }

    /// Whether FD frames switch to the data bit rate (it is above the nominal one).
    pub fn brs(&self) -> bool {
        self.framing == Framing::Fd && self.data_bitrate > self.bitrate
    }

    /// The rates checked: each positive and finite, the arbitration rate within CAN's
    /// 1 Mbit/s, the data rate within [`MAX_DATA_BITRATE`] and not below the nominal one.
    pub fn validate(&self) -> Result<(), RateError> {
        if !(self.bitrate.is_finite() && self.bitrate > 0.0 && self.bitrate <= 1e6) {
            return Err(RateError::Bitrate(self.bitrate));
        }
        if self.framing == Framing::Fd
            && !(self.data_bitrate.is_finite()
                && self.data_bitrate >= self.bitrate
                && self.data_bitrate <= MAX_DATA_BITRATE)
        {
            return Err(RateError::DataBitrate {
                bitrate: self.bitrate,
                got: self.data_bitrate,
            });
        }
        Ok(())
    }

    /// Time of `count` times `b` on the wire, s: the nominal bits at the nominal rate, the
    /// data bits at the data rate when the frame switches (`brs`) and the bus has a faster
    /// data phase, else at the nominal rate too. (`count` multiplies each phase before the
    /// division, so that 500 cycles of 1695 bits on 1 Mbit/s are exactly 0.8475 s.)
    fn wire_s(&self, b: FdBits, brs: bool, count: f64) -> f64 {
        let data_rate = if brs && self.brs() {
            self.data_bitrate
        } else {
            self.bitrate
        };
        count * b.nominal as f64 / self.bitrate + count * b.data as f64 / data_rate
    }

    /// Worst-case time of `f` on this bus, s.
    pub fn frame_time_worst_s(&self, f: &CanFrame) -> f64 {
        let b = if f.is_fd() {
            fd_frame_bits_worst(f.dlc())
        } else {
            FdBits {
                nominal: frame_bits_worst(f.dlc()),
                data: 0,
            }
        };
        self.wire_s(b, f.brs(), 1.0)
    }

    /// Exact time of `f` on this bus (its own stuffing), s.
    pub fn frame_time_s(&self, f: &CanFrame) -> f64 {
        self.wire_s(exact_bits(f), f.brs(), 1.0)
    }

    /// Worst-case wire time of one control cycle, s: SYNC (2 bytes) and, classic, six
    /// COMMAND and six FEEDBACK frames of 8 bytes; FD, one COMMAND_FD (32 bytes) and one
    /// FEEDBACK_FD (48 bytes).
    pub fn cycle_time_worst_s(&self) -> f64 {
        self.load(1.0)
    }

    /// Worst-case bits of one control cycle by phase (classic: all `nominal`).
    fn cycle_bits(&self) -> FdBits {
        let sync = frame_bits_worst(2);
        match self.framing {
            Framing::Classic => FdBits {
                nominal: cycle_bits_worst(),
                data: 0,
            },
            Framing::Fd => {
                let (c, f) = (
                    fd_frame_bits_worst(super::protocol::COMMAND_FD_LEN),
                    fd_frame_bits_worst(super::protocol::FEEDBACK_FD_LEN),
                );
                FdBits {
                    nominal: sync + c.nominal + f.nominal,
                    data: c.data + f.data,
                }
            }
        }
    }

    /// Worst-case bus load (0…1+) of the cyclic traffic at `rate_hz`.
    pub fn load(&self, rate_hz: f64) -> f64 {
        self.wire_s(self.cycle_bits(), true, rate_hz)
    }

    /// The highest cycle rate whose worst-case load stays within `limit` (0…1), Hz.
    pub fn max_rate_hz(&self, limit: f64) -> f64 {
        limit / self.cycle_time_worst_s()
    }

    /// A cycle rate is refused when its worst-case load exceeds `limit` (0…1); the load
    /// otherwise.
    pub fn check_rate(&self, rate_hz: f64, limit: f64) -> Result<f64, String> {
        if !(rate_hz.is_finite() && rate_hz > 0.0) {
            return Err(format!("cycle rate must be > 0 Hz, got {rate_hz}"));
        }
        self.validate().map_err(|e| e.to_string())?;
        let load = self.load(rate_hz);
        if load > limit {
            return Err(format!(
                "{rate_hz} Hz needs {:.1} % of {} worst case, above the {:.1} % limit (max {:.0} Hz)",
                load * 100.0,
                self.describe(),
                limit * 100.0,
                self.max_rate_hz(limit).floor()
            ));
        }
        Ok(load)
    }

    /// "a 1000 kbit/s bus" / "a CAN FD bus at 1000/5000 kbit/s".
    pub fn describe(&self) -> String {
        match self.framing {
            Framing::Classic => format!("a {:.0} kbit/s bus", self.bitrate / 1e3),
            Framing::Fd => format!(
                "a CAN FD bus at {:.0}/{:.0} kbit/s",
                self.bitrate / 1e3,
                self.data_bitrate / 1e3
            ),
        }
    }
}

/// Worst-case bits of one classic control cycle: 6 COMMAND + 1 SYNC + 6 FEEDBACK.
pub fn cycle_bits_worst() -> u32 {
    12 * frame_bits_worst(8) + frame_bits_worst(2)
}

/// Worst-case bus load (0…1+) of the classic cyclic traffic at `rate_hz` on a `bitrate` bit/s
/// bus ([`BusTiming::load`] for any bus).
pub fn bus_load(rate_hz: f64, bitrate: f64) -> f64 {
    BusTiming::classic(bitrate).load(rate_hz)
}

/// A classic cycle rate is refused when its worst-case load exceeds `limit` (0…1)
/// ([`BusTiming::check_rate`] for any bus).
pub fn check_rate(rate_hz: f64, bitrate: f64, limit: f64) -> Result<f64, String> {
    BusTiming::classic(bitrate).check_rate(rate_hz, limit)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn classic_load_matches_the_design_numbers() {
        assert_eq!(frame_bits_worst(8), 135);
        assert_eq!(frame_bits_nominal(8), 111);
        assert_eq!(frame_bits_worst(2), 75);
        assert_eq!(cycle_bits_worst(), 1695);
        assert!((bus_load(500.0, 1e6) - 0.8475).abs() < 1e-12);
        assert!(check_rate(500.0, 1e6, 0.9).is_ok());
        let e = check_rate(600.0, 1e6, 0.9).unwrap_err();
        assert!(e.contains("101.7 %") && e.contains("max 530 Hz"), "{e}");
        assert!(check_rate(0.0, 1e6, 0.9).is_err());
        assert!(
            check_rate(500.0, 2e6, 0.9).is_err(),
            "arbitration above 1 Mbit/s"
        );
    }

    /// The kernel's worst case (`can_frame_bits(true, false, true, true, len)`), split by phase.
    #[test]
    fn fd_worst_case_is_the_kernels_and_splits_by_phase() {
        for &len in &super::super::frame::FD_LENGTHS {
            let kernel = {
                let destuffed = 22 + 8 * len as u32;
                let crc_field = if len <= 16 { 28 } else { 33 };
                destuffed + (destuffed - 1) / 4 + crc_field + 9 + 3
            };
            assert_eq!(fd_frame_bits_worst(len).total(), kernel, "{len} bytes");
            assert_eq!(fd_frame_bits_worst(len).nominal, 34);
        }
        // the cycle's two frames: FEEDBACK_FD 48 bytes, COMMAND_FD 32
        assert_eq!(
            fd_frame_bits_worst(48),
            FdBits {
                nominal: 34,
                data: 518
            }
        );
        assert_eq!(
            fd_frame_bits_worst(32),
            FdBits {
                nominal: 34,
                data: 358
            }
        );
        // 1 Mbit/s arbitration, 5 Mbit/s data: 75 + 137.6 + 105.6 µs per cycle
        let fd = BusTiming::fd(1e6, 5e6);
        assert!((fd.cycle_time_worst_s() - 318.2e-6).abs() < 1e-12);
        assert!((fd.load(1000.0) - 0.3182).abs() < 1e-9);
        assert!(fd.check_rate(2000.0, 0.9).is_ok());
        let e = fd.check_rate(3000.0, 0.9).unwrap_err();
        assert!(
            e.contains("CAN FD bus at 1000/5000 kbit/s") && e.contains("max 2828 Hz"),
            "{e}"
        );
        // without a faster data phase FD carries 1 kHz no better than the budget allows
        let slow = BusTiming::fd(1e6, 1e6);
        assert!(!slow.brs());
        assert!(slow.check_rate(1000.0, 0.9).is_err());
        assert!(BusTiming::fd(1e6, 0.5e6).validate().is_err());
        assert!(BusTiming::fd(1e6, 20e6).validate().is_err());
    }

    #[test]
    fn exact_bits_lie_between_nominal_and_worst_case() {
        for dlc in 0..=8 {
            for pattern in [0x00u8, 0xFF, 0x55, 0x0F] {
                let f = CanFrame::new(0x7FF & (0x555 + dlc as u16), &vec![pattern; dlc]).unwrap();
                let b = exact_bits(&f).total();
                assert!(
                    b >= frame_bits_nominal(dlc) && b <= frame_bits_worst(dlc),
                    "dlc {dlc} {pattern:#x}: {b}"
                );
            }
        }
        for &len in &super::super::frame::FD_LENGTHS {
            for pattern in [0x00u8, 0xFF, 0x55, 0x0F, 0xF0] {
                let f = CanFrame::new_fd(0x180, &vec![pattern; len], true).unwrap();
                let (b, lo, hi) = (
                    exact_bits(&f),
                    fd_frame_bits_nominal(len),
                    fd_frame_bits_worst(len),
                );
                assert!(
                    b.nominal >= lo.nominal && b.nominal <= hi.nominal,
                    "{len} {pattern:#x}: {b:?}"
                );
                assert!(
                    b.data >= lo.data && b.data <= hi.data,
                    "{len} {pattern:#x}: {b:?}"
                );
            }
        }
        // all-zero payloads stuff a bit every four: clearly more than nominal
        let zeros = CanFrame::new(0x000, &[0; 8]).unwrap();
        assert!(exact_bits(&zeros).total() > frame_bits_nominal(8) + 15);
        let fd_zeros = CanFrame::new_fd(0x180, &[0; 48], true).unwrap();
        assert!(exact_bits(&fd_zeros).data > fd_frame_bits_nominal(48).data + 70);
        // CRC-15 of the empty message is 0
        assert_eq!(crc15(&[]), 0);
        // an FD frame without the switch is all at the nominal rate
        let t = BusTiming::fd(1e6, 5e6);
        let no_brs = CanFrame::new_fd(0x180, &[0x55; 48], false).unwrap();
        assert!((t.frame_time_s(&no_brs) - exact_bits(&no_brs).total() as f64 / 1e6).abs() < 1e-15);
        assert!(t.frame_time_s(&fd_zeros) <= t.frame_time_worst_s(&fd_zeros));
    }
}
