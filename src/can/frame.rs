//! The one frame type of the CAN layer, both directions and both formats: [`CanFrame`] holds a
//! classic CAN data frame (11-bit identifier, 0–8 bytes) or a CAN FD data frame (ISO
//! 11898-1:2015: 0–8, 12, 16, 20, 24, 32, 48 or 64 bytes, with or without the bit-rate switch),
//! and [`Framing`] names which of the two a bus's cyclic traffic uses. Plain data, `Copy`, no
//! allocation: the codec, the backends and the loop pass it by value.

/// Largest payload of a CAN FD frame, bytes.
pub const FD_MAX_LEN: usize = 64;

/// The payload lengths a CAN FD frame can have, bytes (DLC 0…15).
pub const FD_LENGTHS: [usize; 16] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64];

/// The frame format of a bus's cyclic traffic (COMMAND and FEEDBACK; CONTROL, STATE, SYNC and
/// ERROR are classic frames on both).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "record", derive(schemars::JsonSchema))]
#[serde(rename_all = "lowercase")]
pub enum Framing {
    /// Classic CAN: six COMMAND and six FEEDBACK frames of 8 bytes per cycle.
    #[default]
    Classic,
    /// CAN FD: one COMMAND_FD (32 bytes) and one FEEDBACK_FD (48 bytes) per cycle, sent with
    /// the bit-rate switch.
    Fd,
}

/// A CAN data frame with an 11-bit identifier: classic (≤ 8 bytes) or FD (≤ 64 bytes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct CanFrame {
    id: u16,
    len: u8,
    fd: bool,
    brs: bool,
    data: [u8; FD_MAX_LEN],
}

impl CanFrame {
    /// A classic frame; `None` when `id` exceeds 11 bits or `data` 8 bytes.
    pub fn new(id: u16, data: &[u8]) -> Option<Self> {
        if data.len() > 8 {
            return None;
        }
        Self::with(id, data, false, false)
    }

    /// A CAN FD frame, with the bit-rate switch when `brs`; `None` when `id` exceeds 11 bits
    /// or `data`'s length is not one of [`FD_LENGTHS`].
    pub fn new_fd(id: u16, data: &[u8], brs: bool) -> Option<Self> {
        if !FD_LENGTHS.contains(&data.len()) {
            return None;
        }
        Self::with(id, data, true, brs)
    }

    fn with(id: u16, data: &[u8], fd: bool, brs: bool) -> Option<Self> {
        if id > 0x7FF {
            return None;
        }
        let mut d = [0u8; FD_MAX_LEN];
        d[..data.len()].copy_from_slice(data);
        Some(Self {
            id,
            len: data.len() as u8,
            fd,
            brs,
            data: d,
        })
    }

    /// A classic frame of `len` zero bytes, usable in constants; `None` when `id` exceeds 11
    /// bits or `len` 8.
    pub const fn new_const(id: u16, len: u8) -> Option<Self> {
        if id > 0x7FF || len > 8 {
            return None;
        }
        Some(Self {
            id,
            len,
            fd: false,
            brs: false,
            data: [0; FD_MAX_LEN],
        })
    }

    /// The 11-bit identifier.
    pub fn id(&self) -> u16 {
        self.id
    }

    /// The data bytes.
    pub fn data(&self) -> &[u8] {
        &self.data[..self.len as usize]
    }

    /// Payload length, bytes (for a classic frame its DLC; for an FD frame the length its DLC
    /// code stands for, see [`CanFrame::dlc_code`]).
    pub fn dlc(&self) -> usize {
        self.len as usize
    }

    /// The 4-bit DLC code on the wire (FD: 9…15 stand for 12…64 bytes).
    pub fn dlc_code(&self) -> u8 {
        FD_LENGTHS
            .iter()
            .position(|&l| l == self.len as usize)
            .unwrap_or(0) as u8
    }

    /// Whether this is a CAN FD frame.
    pub fn is_fd(&self) -> bool {
        self.fd
    }

    /// Whether an FD frame's data phase runs at the data bit rate (bit-rate switch).
    pub fn brs(&self) -> bool {
        self.brs
    }

    /// The same frame with `data` as its payload (same identifier, format and length
    /// rules); `None` when the length does not fit the format.
    pub fn with_data(&self, data: &[u8]) -> Option<Self> {
        if self.fd {
            Self::new_fd(self.id, data, self.brs)
        } else {
            Self::new(self.id, data)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lengths_and_formats_are_checked() {
        assert!(CanFrame::new(0x800, &[]).is_none());
        assert!(CanFrame::new(0x100, &[0; 9]).is_none());
        assert!(CanFrame::new_fd(0x100, &[0; 9], true).is_none());
        assert!(CanFrame::new_fd(0x800, &[0; 8], true).is_none());
        let f = CanFrame::new_fd(0x180, &[7; 48], true).expect("48 bytes is an FD length");
        assert_eq!(
            (f.dlc(), f.dlc_code(), f.is_fd(), f.brs()),
            (48, 14, true, true)
        );
        assert_eq!(
            CanFrame::new_fd(0x1, &[0; 64], false).map(|f| f.dlc_code()),
            Some(15)
        );
        let c = CanFrame::new(0x10, &[1, 2]).expect("classic");
        assert_eq!((c.dlc(), c.dlc_code(), c.is_fd()), (2, 2, false));
        assert_eq!(c.with_data(&[3]).map(|f| f.data().to_vec()), Some(vec![3]));
        assert!(c.with_data(&[0; 12]).is_none());
        assert_eq!(f.with_data(&[1; 12]).map(|f| f.dlc_code()), Some(9));
    }
}
