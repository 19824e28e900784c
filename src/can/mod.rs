//! The CAN layer: the sans-IO protocol codec ([`protocol`], no formats), the DBC view of a
//! message ([`signals`]), candump logs ([`candump`]) and the [`CanBus`] abstraction with its
//! backends ([`virtual_bus`] in-process, `socketcan_bus` on Linux).

pub mod bus;
pub mod candump;
pub mod protocol;
pub mod signals;
#[cfg(target_os = "linux")]
pub mod socketcan_bus;
pub mod virtual_bus;

pub use bus::{BusError, BusEvent, CanBus, Filter};
pub use protocol::{Frame, Message, bus_load, check_rate, decode, encode};
pub use virtual_bus::{VirtualBus, VirtualConfig, VirtualEndpoint};
