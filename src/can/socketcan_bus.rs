//! The SocketCAN backend (Linux; real adapters and vcan) over the socketcan crate's tokio
//! support. Error frames are received and surface as [`BusEvent::ErrorFrame`], a bus-off
//! report as [`BusEvent::BusOff`]. Configuring the interface (bitrate, up) is the system's
//! job, not this code's. Exercised for real by the `[vcan]` VM test.

use std::time::Duration;

use socketcan::{CanFilter, EmbeddedFrame, Socket, SocketOptions, StandardId};
use tokio::io::Interest;
use tokio::io::unix::AsyncFd;

use super::bus::{BusError, BusEvent, CanBus, Filter};
use super::protocol::CanFrame;

/// A SocketCAN interface. Opening it does not need an async runtime: the socket registers
/// with the reactor of the runtime that first sends or receives on it (the daemon's control
/// thread), so it can be opened by the caller and handed over.
pub struct SocketCanBus {
    sock: Option<socketcan::CanSocket>,
    fd: Option<AsyncFd<socketcan::CanSocket>>,
}

fn io(e: impl std::fmt::Display) -> BusError {
    BusError::Io(e.to_string())
}

impl SocketCanBus {
    /// Opens `iface` (e.g. `can0`, `vcan0`), non-blocking, and asks for every error frame.
    pub fn open(iface: &str) -> Result<Self, BusError> {
        let sock =
            socketcan::CanSocket::open(iface).map_err(|e| BusError::Io(format!("{iface}: {e}")))?;
        sock.set_nonblocking(true).map_err(io)?;
        sock.set_error_filter_accept_all().map_err(io)?;
        Ok(Self {
            sock: Some(sock),
            fd: None,
        })
    }

    /// The socket registered with the current runtime's reactor (on first use).
    fn fd(&mut self) -> Result<&AsyncFd<socketcan::CanSocket>, BusError> {
        if self.fd.is_none() {
            let sock = self.sock.take().ok_or(BusError::Closed)?;
            // SAFETY: `socketcan::CanSocket` owns its descriptor (an `OwnedFd`), which stays
            // open and the same until the socket is dropped, and the `AsyncFd` owns the socket.
            #[allow(unsafe_code)]
            let fd = unsafe { AsyncFd::register(sock) }.map_err(|e| io(e.to_string()))?;
            self.fd = Some(fd);
        }
        self.fd.as_ref().ok_or(BusError::Closed)
    }

    fn socket(&self) -> Option<&socketcan::CanSocket> {
        self.fd.as_ref().map(|f| f.get_ref()).or(self.sock.as_ref())
    }
}

impl CanBus for SocketCanBus {
    async fn send(&mut self, frame: CanFrame) -> Result<(), BusError> {
        let id = StandardId::new(frame.id()).ok_or_else(|| io("identifier beyond 11 bits"))?;
        let f =
            socketcan::CanFrame::new(id, frame.data()).ok_or_else(|| io("frame construction"))?;
        self.fd()?
            .async_io(Interest::WRITABLE, |s| s.write_frame(&f))
            .await
            .map_err(io)
    }

    /// Waits for the next event until one absolute deadline, `timeout` from the call: frames
    /// the loop skips (remote frames, extended identifiers) do not restart the wait.
    async fn recv(&mut self, timeout: Duration) -> Result<BusEvent, BusError> {
        let deadline = tokio::time::Instant::now() + timeout;
        let fd = self.fd()?;
        loop {
            let read = fd.async_io(Interest::READABLE, |s| s.read_frame());
            let f = match tokio::time::timeout_at(deadline, read).await {
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
                    if let Some(fr) = CanFrame::new(id.as_raw(), d.data()) {
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
        let sock = self.socket().ok_or(BusError::Closed)?;
        if f.is_empty() {
            sock.set_filter_accept_all().map_err(io)
        } else {
            sock.set_filters(&f).map_err(io)
        }
    }
}
