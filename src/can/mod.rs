//! The CAN layer: the frame type ([`frame`], classic and FD), time on the wire and bus load
//! ([`timing`]), the sans-IO protocol codec ([`protocol`], no formats), the DBC view of a
//! message ([`signals`]) and the [`CanBus`] abstraction; with the `daemon` feature also
//! candump logs (`candump`) and the backends (`virtual_bus` in-process, `socketcan_bus` on
//! Linux).

pub mod bus;
#[cfg(feature = "daemon")]
pub mod candump;
pub mod frame;
pub mod protocol;
pub mod signals;
#[cfg(all(target_os = "linux", feature = "daemon"))]
pub mod socketcan_bus;
pub mod timing;
#[cfg(feature = "daemon")]
pub mod virtual_bus;

pub use bus::{BusError, BusEvent, CanBus, Filter};
pub use frame::{CanFrame, Framing};
pub use protocol::{Message, decode, encode};
pub use timing::{BusTiming, bus_load, check_rate};
#[cfg(feature = "daemon")]
pub use virtual_bus::{VirtualBus, VirtualConfig, VirtualEndpoint};
