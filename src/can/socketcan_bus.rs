//! The SocketCAN backend (Linux; real adapters and vcan) over the socketcan crate's tokio
//! support: a raw socket for classic CAN, or an FD socket (`CAN_RAW_FD_FRAMES`, the crate's
//! `CanFdSocket`) that sends and receives classic and CAN FD frames alike. Error frames are
//! received and surface as [`BusEvent::ErrorFrame`], a bus-off report as [`BusEvent::BusOff`].
//! Configuring the interface (bit rates, FD mode, MTU 72, up) is the system's job, not this
//! code's; opening an FD socket on an interface whose MTU is not CAN FD's is refused. Exercised
//! for real by the `[vcan]` VM test, classic and FD.

use std::os::fd::{AsRawFd, RawFd};
use std::time::Duration;

use socketcan::{CanAnyFrame, CanFilter, EmbeddedFrame, Socket, SocketOptions, StandardId};
use tokio::io::Interest;
use tokio::io::unix::AsyncFd;

use super::bus::{BusError, BusEvent, CanBus, Filter};
use super::frame::{CanFrame, Framing};

/// The kernel's MTU of a CAN FD interface (`sizeof(struct canfd_frame)`), bytes.
pub const CANFD_MTU: u32 = 72;

/// A raw CAN socket, classic or FD.
enum Sock {
    Classic(socketcan::CanSocket),
    Fd(socketcan::CanFdSocket),
}

impl AsRawFd for Sock {
    fn as_raw_fd(&self) -> RawFd {
        match self {
            Sock::Classic(s) => s.as_raw_fd(),
            Sock::Fd(s) => s.as_raw_fd(),
        }
    }
}

impl Sock {
    fn set_nonblocking(&self) -> std::io::Result<()> {
        match self {
            Sock::Classic(s) => s.set_nonblocking(true),
            Sock::Fd(s) => s.set_nonblocking(true),
        }
    }
    fn set_error_filter_accept_all(&self) -> std::io::Result<()> {
        match self {
            Sock::Classic(s) => s.set_error_filter_accept_all(),
            Sock::Fd(s) => s.set_error_filter_accept_all(),
        }
    }
    fn set_filters(&self, f: &[CanFilter]) -> std::io::Result<()> {
        match (self, f.is_empty()) {
            (Sock::Classic(s), true) => s.set_filter_accept_all(),
            (Sock::Classic(s), false) => s.set_filters(f),
            (Sock::Fd(s), true) => s.set_filter_accept_all(),
            (Sock::Fd(s), false) => s.set_filters(f),
        }
    }
    fn write(&self, frame: &CanFrame) -> std::io::Result<()> {
        let bad = |what| std::io::Error::new(std::io::ErrorKind::InvalidInput, what);
        let id = StandardId::new(frame.id()).ok_or_else(|| bad("identifier beyond 11 bits"))?;
        if frame.is_fd() {
            let Sock::Fd(s) = self else {
                return Err(bad("a CAN FD frame on a classic socket"));
            };
            let flags = if frame.brs() {
                socketcan::id::FdFlags::BRS
            } else {
                socketcan::id::FdFlags::empty()
            };
            let f = socketcan::CanFdFrame::with_flags(id, frame.data(), flags)
                .ok_or_else(|| bad("frame construction"))?;
            return s.write_frame(&f);
        }
        let f =
            socketcan::CanFrame::new(id, frame.data()).ok_or_else(|| bad("frame construction"))?;
        match self {
            Sock::Classic(s) => s.write_frame(&f),
            Sock::Fd(s) => s.write_frame(&CanAnyFrame::from(f)),
        }
    }
    /// The next frame, classic and FD alike.
    fn read(&self) -> std::io::Result<CanAnyFrame> {
        match self {
            Sock::Classic(s) => s.read_frame().map(CanAnyFrame::from),
            Sock::Fd(s) => s.read_frame(),
        }
    }
}

/// A SocketCAN interface. Opening it does not need an async runtime: the socket registers
/// with the reactor of the runtime that first sends or receives on it (the daemon's control
/// thread), so it can be opened by the caller and handed over.
pub struct SocketCanBus {
    sock: Option<Sock>,
    fd: Option<AsyncFd<Sock>>,
}

fn io(e: impl std::fmt::Display) -> BusError {
    BusError::Io(e.to_string())
}

/// An interface's MTU from sysfs, bytes; `None` when it cannot be read.
fn mtu(iface: &str) -> Option<u32> {
    std::fs::read_to_string(format!("/sys/class/net/{iface}/mtu"))
        .ok()?
        .trim()
        .parse()
        .ok()
}

impl SocketCanBus {
    /// Opens `iface` (e.g. `can0`, `vcan0`) for classic CAN, non-blocking, and asks for every
    /// error frame.
    pub fn open(iface: &str) -> Result<Self, BusError> {
        Self::open_with(iface, Framing::Classic)
    }

    /// Opens `iface` for `framing`: a CAN FD socket for [`Framing::Fd`], refused (with the
    /// command that fixes it) when the interface's MTU is not [`CANFD_MTU`].
    pub fn open_with(iface: &str, framing: Framing) -> Result<Self, BusError> {
        if iface.is_empty()
            || iface.len() > 15
            || iface.contains(['/', '\0'])
            || iface == "."
            || iface == ".."
        {
            return Err(BusError::Io(format!("`{iface}` is not an interface name")));
        }
        let open = |e: std::io::Error| BusError::Io(format!("{iface}: {e}"));
        let sock = match framing {
            Framing::Classic => Sock::Classic(socketcan::CanSocket::open(iface).map_err(open)?),
            Framing::Fd => {
                if let Some(m) = mtu(iface)
                    && m != CANFD_MTU
                {
                    return Err(BusError::Io(format!(
                        "{iface}: MTU {m}, not a CAN FD interface (ip link set {iface} mtu {CANFD_MTU}, or set bus.fd: false)"
                    )));
                }
                Sock::Fd(socketcan::CanFdSocket::open(iface).map_err(open)?)
            }
        };
        sock.set_nonblocking().map_err(io)?;
        sock.set_error_filter_accept_all().map_err(io)?;
        Ok(Self {
            sock: Some(sock),
            fd: None,
        })
    }

    /// The socket registered with the current runtime's reactor (on first use).
    fn fd(&mut self) -> Result<&AsyncFd<Sock>, BusError> {
        if self.fd.is_none() {
            let sock = self.sock.take().ok_or(BusError::Closed)?;
            // SAFETY: each socketcan socket owns its descriptor (an `OwnedFd`), which stays
            // open and the same until the socket is dropped, and the `AsyncFd` owns the socket.
            #[allow(unsafe_code)]
            let fd = unsafe { AsyncFd::register(sock) }.map_err(|e| io(e.to_string()))?;
            self.fd = Some(fd);
        }
        self.fd.as_ref().ok_or(BusError::Closed)
    }

    fn socket(&self) -> Option<&Sock> {
        self.fd.as_ref().map(|f| f.get_ref()).or(self.sock.as_ref())
    }
}

impl CanBus for SocketCanBus {
    async fn send(&mut self, frame: CanFrame) -> Result<(), BusError> {
        if frame.is_fd() && matches!(self.socket(), Some(Sock::Classic(_))) {
            return Err(BusError::FdUnsupported);
        }
        self.fd()?
            .async_io(Interest::WRITABLE, |s| s.write(&frame))
            .await
            .map_err(io)
    }

    /// Waits for the next event until one absolute deadline, `timeout` from the call: frames
    /// the loop skips (remote frames, extended identifiers) do not restart the wait.
    async fn recv(&mut self, timeout: Duration) -> Result<BusEvent, BusError> {
        let deadline = tokio::time::Instant::now() + timeout;
        let fd = self.fd()?;
        loop {
            let read = fd.async_io(Interest::READABLE, |s| s.read());
            let f = match tokio::time::timeout_at(deadline, read).await {
                Err(_) => return Err(BusError::Timeout),
                Ok(r) => r.map_err(io)?,
            };
            match f {
                CanAnyFrame::Error(e) => {
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
                CanAnyFrame::Remote(_) => continue,
                CanAnyFrame::Normal(d) => {
                    let socketcan::Id::Standard(id) = d.id() else {
                        continue;
                    };
                    if let Some(fr) = CanFrame::new(id.as_raw(), d.data()) {
                        return Ok(BusEvent::Frame(fr));
                    }
                }
                CanAnyFrame::Fd(d) => {
                    let socketcan::Id::Standard(id) = d.id() else {
                        continue;
                    };
                    if let Some(fr) = CanFrame::new_fd(id.as_raw(), d.data(), d.is_brs()) {
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
        sock.set_filters(&f).map_err(io)
    }
}
