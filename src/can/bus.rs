//! The [`CanBus`] abstraction: what the daemon and the simulator need from a CAN interface,
//! and nothing more. Backends (feature `daemon`): `crate::can::virtual_bus` (in-process) and, on Linux,
//! `crate::can::socketcan_bus` (SocketCAN, incl. vcan).

use std::future::Future;
use std::time::Duration;

use super::protocol::CanFrame;

/// Something that arrived from the bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BusEvent {
    /// A data frame.
    Frame(CanFrame),
    /// An error frame was seen (the controller's error report, as text-free flags).
    ErrorFrame {
        /// Raw error class bits (SocketCAN `CAN_ERR_*`), 0 on the virtual bus.
        class: u32,
    },
    /// The controller went bus-off: nothing can be sent until it recovers.
    BusOff,
}

/// Why a bus operation failed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum BusError {
    /// Nothing arrived within the timeout.
    #[error("receive timed out")]
    Timeout,
    /// The controller is bus-off.
    #[error("bus off")]
    BusOff,
    /// The bus (or the other side of a virtual bus) is gone.
    #[error("bus closed")]
    Closed,
    /// A CAN FD frame sent on a classic interface (a classic bus, or a SocketCAN interface
    /// whose MTU is 16: `ip link set can0 mtu 72`).
    #[error("a CAN FD frame on a classic CAN interface")]
    FdUnsupported,
    /// An operating-system error.
    #[error("CAN interface error: {0}")]
    Io(String),
}

/// An acceptance filter: a frame passes when `id & mask == self.id & mask`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Filter {
    /// Identifier to match.
    pub id: u16,
    /// Bits of the identifier that must match.
    pub mask: u16,
}

impl Filter {
    /// Exactly `id`.
    pub fn exact(id: u16) -> Self {
        Self { id, mask: 0x7FF }
    }
    /// Whether `id` passes.
    pub fn accepts(&self, id: u16) -> bool {
        id & self.mask == self.id & self.mask
    }
}

/// Whether `id` passes `filters` (no filters: everything passes).
pub fn passes(filters: &[Filter], id: u16) -> bool {
    filters.is_empty() || filters.iter().any(|f| f.accepts(id))
}

/// A CAN interface: send frames, receive events with a timeout, filter by identifier.
pub trait CanBus: Send {
    /// Sends one frame.
    fn send(&mut self, frame: CanFrame) -> impl Future<Output = Result<(), BusError>> + Send;
    /// The next event, or [`BusError::Timeout`] after `timeout`.
    fn recv(
        &mut self,
        timeout: Duration,
    ) -> impl Future<Output = Result<BusEvent, BusError>> + Send;
    /// Replaces the acceptance filters (empty: accept everything).
    fn set_filters(&mut self, filters: &[Filter]) -> Result<(), BusError>;
}
