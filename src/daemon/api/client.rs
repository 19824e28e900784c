//! The blocking client of `pa10d`'s socket: one [`ApiRequest`] a connection, its [`Reply`]
//! read back with a time limit and a size limit, and `subscribe`'s stream of status replies.
//! The `pa10` CLI and the ROS 2 bridge call the daemon through it; the Python client
//! (`clients/python`) is its counterpart outside Rust.

use std::io::{BufRead, BufReader, Read, Write};
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::time::Duration;

use crate::daemon::wire::{Answer, ApiRequest, Refused, Reply, Status};

/// How long a call waits for the daemon's answer (and to send its request), s.
pub const CALL_TIMEOUT_S: u64 = 10;

/// The longest reply line a client reads, bytes (a status is ≈ 2 kB).
pub const MAX_REPLY_BYTES: u64 = 1 << 20;

/// Why a call to the daemon failed.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// The socket could not be reached.
    #[error("connecting to pa10d at {path} (is it running?): {source}")]
    Connect {
        /// The socket.
        path: PathBuf,
        /// The system's reason.
        source: std::io::Error,
    },
    /// Sending or reading failed (including the time limit).
    #[error("pa10d at {path}: {source}")]
    Io {
        /// The socket.
        path: PathBuf,
        /// The system's reason.
        source: std::io::Error,
    },
    /// The daemon closed the connection without a (complete) reply line.
    #[error("pa10d at {path} closed the connection without a complete answer ({bytes} bytes)")]
    Closed {
        /// The socket.
        path: PathBuf,
        /// Bytes read before it closed (at most [`MAX_REPLY_BYTES`]).
        bytes: usize,
    },
    /// The answer is not a reply of this protocol.
    #[error("pa10d at {path} answered {bytes} bytes that are not a reply: {source}")]
    Malformed {
        /// The socket.
        path: PathBuf,
        /// The answer's length, bytes.
        bytes: usize,
        /// What serde found wrong.
        source: serde_json::Error,
    },
    /// The daemon refused the request (nothing changed).
    #[error("pa10d refused: {0}")]
    Refused(#[from] Refused),
    /// The daemon accepted the request but answered something else than it answers to it.
    #[error("pa10d answered {cmd} with an unexpected reply: {reply:?}")]
    Unexpected {
        /// The request's name.
        cmd: &'static str,
        /// What came back.
        reply: Box<Answer>,
    },
}

/// A client of one daemon socket. Every call opens its own connection (the motion lease is
/// per connection: hold one with [`Client::connect`] to keep it).
#[derive(Debug, Clone)]
pub struct Client {
    path: PathBuf,
    timeout: Duration,
}

impl Client {
    /// A client of the socket at `path`, waiting [`CALL_TIMEOUT_S`] for each answer.
    pub fn new(path: impl Into<PathBuf>) -> Self {
        Self {
            path: path.into(),
            timeout: Duration::from_secs(CALL_TIMEOUT_S),
        }
    }

    /// The same client with another time limit per answer.
    pub fn with_timeout(self, timeout: Duration) -> Self {
        Self { timeout, ..self }
    }

    /// The daemon's socket.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// A connection of its own (for the lease, or several requests in a row).
    pub fn connect(&self) -> Result<Connection, ClientError> {
        let s = UnixStream::connect(&self.path).map_err(|source| ClientError::Connect {
            path: self.path.clone(),
            source,
        })?;
        let limit = Some(self.timeout);
        let io = |source| ClientError::Io {
            path: self.path.clone(),
            source,
        };
        s.set_read_timeout(limit).map_err(io)?;
        s.set_write_timeout(limit).map_err(io)?;
        Ok(Connection {
            path: self.path.clone(),
            reader: BufReader::new(s),
            line: String::new(),
        })
    }

    /// Sends `req` on a new connection and returns the reply, a refusal included.
    pub fn send(&self, req: &ApiRequest) -> Result<Reply, ClientError> {
        self.connect()?.send(req)
    }

    /// Sends `req`; a refusal is [`ClientError::Refused`].
    pub fn call(&self, req: &ApiRequest) -> Result<Answer, ClientError> {
        Ok(self.send(req)?.into_result()?)
    }

    /// The daemon's status.
    pub fn status(&self) -> Result<Status, ClientError> {
        match self.call(&ApiRequest::Status {})? {
            Answer::Status(s) => Ok(*s),
            other => Err(ClientError::Unexpected {
                cmd: "status",
                reply: Box::new(other),
            }),
        }
    }

    /// Subscribes at `rate_hz`: every item is the next status reply.
    pub fn subscribe(&self, rate_hz: f64) -> Result<Subscription, ClientError> {
        let mut c = self.connect()?;
        // a sample every 1/rate_hz s: the time limit must allow it
        let wait = self
            .timeout
            .max(Duration::from_secs_f64(2.0 / rate_hz.max(0.1)));
        c.set_timeout(wait)?;
        c.write(&ApiRequest::Subscribe { rate_hz })?;
        Ok(Subscription(c))
    }
}

/// One open connection to the daemon.
#[derive(Debug)]
pub struct Connection {
    path: PathBuf,
    reader: BufReader<UnixStream>,
    line: String,
}

impl Connection {
    fn io(&self, source: std::io::Error) -> ClientError {
        ClientError::Io {
            path: self.path.clone(),
            source,
        }
    }

    fn set_timeout(&mut self, t: Duration) -> Result<(), ClientError> {
        self.reader
            .get_ref()
            .set_read_timeout(Some(t))
            .map_err(|e| self.io(e))
    }

    fn write(&mut self, req: &ApiRequest) -> Result<(), ClientError> {
        let mut line = serde_json::to_string(req).map_err(|e| self.io(e.into()))?;
        line.push('\n');
        self.reader
            .get_mut()
            .write_all(line.as_bytes())
            .map_err(|e| self.io(e))
    }

    fn read(&mut self) -> Result<Reply, ClientError> {
        self.line.clear();
        let n = (&mut self.reader)
            .take(MAX_REPLY_BYTES)
            .read_line(&mut self.line)
            .map_err(|e| ClientError::Io {
                path: self.path.clone(),
                source: e,
            })?;
        if n == 0 || !self.line.ends_with('\n') {
            return Err(ClientError::Closed {
                path: self.path.clone(),
                bytes: n,
            });
        }
        serde_json::from_str(&self.line).map_err(|source| ClientError::Malformed {
            path: self.path.clone(),
            bytes: n,
            source,
        })
    }

    /// Sends `req` and returns the reply, a refusal included.
    pub fn send(&mut self, req: &ApiRequest) -> Result<Reply, ClientError> {
        self.write(req)?;
        self.read()
    }

    /// Sends `req`; a refusal is [`ClientError::Refused`].
    pub fn call(&mut self, req: &ApiRequest) -> Result<Answer, ClientError> {
        Ok(self.send(req)?.into_result()?)
    }
}

/// `subscribe`'s stream: each item the next reply (a status, or the refusal that ended it).
#[derive(Debug)]
pub struct Subscription(Connection);

impl Iterator for Subscription {
    type Item = Result<Reply, ClientError>;

    fn next(&mut self) -> Option<Self::Item> {
        Some(self.0.read())
    }
}
