//! The SocketCAN backend (Linux; real adapters and vcan) over the socketcan crate's tokio
//! support. Error frames are received and surface as [`BusEvent::ErrorFrame`], a bus-off
//! report as [`BusEvent::BusOff`]. Configuring the interface (bitrate, up) is the system's
//! job, not this code's. Exercised for real by the `[vcan]` VM test.

use std::time::Duration;

use socketcan::{CanFilter, EmbeddedFrame, SocketOptions, StandardId};

use super::bus::{BusError, BusEvent, CanBus, Filter};
use super::protocol::Frame;

/// A SocketCAN interface.
pub struct SocketCanBus {
    sock: socketcan::tokio::CanSocket,
}

fn io(e: impl std::fmt::Display) -> BusError {
    BusError::Io(e.to_string())
}

impl SocketCanBus {
    /// Opens `iface` (e.g. `can0`, `vcan0`) and asks for every error frame.
    pub fn open(iface: &str) -> Result<Self, BusError> {
        let sock = socketcan::tokio::CanSocket::open(iface)
            .map_err(|e| BusError::Io(format!("{iface}: {e}")))?;
        sock.set_error_filter_accept_all().map_err(io)?;
        Ok(Self { sock })
    }
}

impl CanBus for SocketCanBus {
    async fn send(&mut self, frame: Frame) -> Result<(), BusError> {
        let id = StandardId::new(frame.id()).ok_or_else(|| io("identifier beyond 11 bits"))?;
        let f =
            socketcan::CanFrame::new(id, frame.data()).ok_or_else(|| io("frame construction"))?;
        self.sock.write_frame(f).await.map_err(io)
    }

    async fn recv(&mut self, timeout: Duration) -> Result<BusEvent, BusError> {
        loop {
            let f = match tokio::time::timeout(timeout, self.sock.read_frame()).await {
                Err(_) => return Err(BusError::Timeout),
                Ok(r) => r.map_err(io)?,
            };
            match f {
                socketcan::CanFrame::Error(e) => {
                    let err = e.into_error();
                    if err
                        .causes()
                        .any(|c| matches!(c, socketcan::ErrorCause::BusOff))
                    {
                        return Ok(BusEvent::BusOff);
                    }
                    return Ok(BusEvent::ErrorFrame {
                        class: e.error_bits(),
                    });
                }
                socketcan::CanFrame::Remote(_) => continue,
                socketcan::CanFrame::Data(d) => {
                    let socketcan::Id::Standard(id) = d.id() else {
                        continue;
                    };
                    if let Some(fr) = Frame::new(id.as_raw(), d.data()) {
                        return Ok(BusEvent::Frame(fr));
                    }
                }
            }
        }
    }

    fn set_filters(&mut self, filters: &[Filter]) -> Result<(), BusError> {
        let f: Vec<CanFilter> = filters
            .iter()
            .map(|f| CanFilter::new(f.id as u32, f.mask as u32))
            .collect();
        if f.is_empty() {
            self.sock.set_filter_accept_all().map_err(io)
        } else {
            self.sock.set_filters(&f).map_err(io)
        }
    }
}
