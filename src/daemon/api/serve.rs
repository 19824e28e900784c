//! The API's tokio shell: the Unix socket (one daemon per socket path), connections with
//! their size and time limits, line framing, and rate-limited logging of refusals. Each line
//! is parsed by [`super::parse`] and goes to [`super::handle_from`]; nothing here knows a
//! request's meaning but `subscribe`'s (a stream, not one reply).

use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::time::Duration;

use tokio::io::{AsyncBufReadExt, AsyncWriteExt, BufReader};
use tokio::net::UnixListener;

use super::*;

/// Serves clients on `path` (created with `mode`) until `stop` turns true, at most
/// `max_clients` at once (one more gets a refusal line and is closed). Claim the path first
/// ([`SocketLock::claim`]): a stale socket file is replaced, a live one must not be.
///
/// Accepting never gives up: an error (e.g. EMFILE when the process is out of descriptors)
/// is logged once per burst and retried after a back-off of 10 ms doubling to 1 s, and the
/// count is in [`ApiHealth`].
pub async fn serve(
    path: &Path,
    mode: u32,
    max_clients: usize,
    core: Arc<SharedCore>,
    health: Arc<ApiHealth>,
    mut stop: tokio::sync::watch::Receiver<bool>,
) -> std::io::Result<()> {
    let _ = std::fs::remove_file(path);
    let listener = UnixListener::bind(path)?;
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode))?;
    }
    let mut backoff = Duration::from_millis(10);
    loop {
        let accepted = tokio::select! {
            c = listener.accept() => c,
            _ = stop.changed() => break,
        };
        let conn = match accepted {
            Ok((conn, _)) => {
                if backoff > Duration::from_millis(10) {
                    tracing::info!("accepting clients again");
                }
                backoff = Duration::from_millis(10);
                health.accept_failing.store(false, Ordering::Relaxed);
                conn
            }
            Err(e) => {
                health.accept_errors.fetch_add(1, Ordering::Relaxed);
                if !health.accept_failing.swap(true, Ordering::Relaxed) {
                    tracing::error!(error = %e, "accepting a client failed; retrying with back-off");
                }
                tokio::time::sleep(backoff).await;
                backoff = (backoff * 2).min(Duration::from_secs(1));
                continue;
            }
        };
        if health.clients.load(Ordering::Relaxed) >= max_clients {
            health.refused_clients.fetch_add(1, Ordering::Relaxed);
            let e = err(format!(
                "too many clients ({max_clients} connected, api.max_clients); try again later"
            ));
            let _ = conn.try_write(&reply_line(&e));
            continue;
        }
        health.clients.fetch_add(1, Ordering::Relaxed);
        let (core, health) = (core.clone(), health.clone());
        tokio::spawn(async move {
            let id = NEXT_CLIENT.fetch_add(1, Ordering::Relaxed);
            connection(conn, core.clone(), id).await;
            // its lease ends with it (a controlled stop if it was moving the arm)
            let _ = lock(&core).submit_from(id, Command::Disconnected);
            health.clients.fetch_sub(1, Ordering::Relaxed);
        });
    }
    let _ = std::fs::remove_file(path);
    Ok(())
}

/// How the API is doing, for `pa10d`'s systemd watchdog and logs.
#[derive(Debug, Default)]
pub struct ApiHealth {
    /// Clients connected now.
    pub clients: AtomicUsize,
    /// Clients refused for `api.max_clients`.
    pub refused_clients: AtomicU64,
    /// `accept()` errors so far.
    pub accept_errors: AtomicU64,
    /// The last `accept()` failed (cleared by the next success).
    pub accept_failing: AtomicBool,
}

/// The exclusive claim of one daemon on its socket path: a lock file beside the socket
/// (`<socket>.lock`, holding the owner's PID) locked for the daemon's lifetime.
#[derive(Debug)]
pub struct SocketLock {
    _file: std::fs::File,
    path: std::path::PathBuf,
}

impl SocketLock {
    /// Claims `socket`; refused, naming the owner's PID, when another process holds it.
    pub fn claim(socket: &Path) -> Result<Self, String> {
        use std::io::{Read, Seek, Write};
        let path = socket.with_extension("lock");
        let mut file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(|e| format!("{}: {e}", path.display()))?;
        if file.try_lock().is_err() {
            let mut pid = String::new();
            let _ = file.read_to_string(&mut pid);
            return Err(format!(
                "{} is served by another pa10d (pid {}, holding {}); stop it first",
                socket.display(),
                pid.trim(),
                path.display()
            ));
        }
        file.set_len(0)
            .and_then(|()| file.rewind())
            .and_then(|()| write!(file, "{}", std::process::id()))
            .map_err(|e| format!("{}: {e}", path.display()))?;
        Ok(Self { _file: file, path })
    }

    /// The lock file.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

/// The longest request line, bytes; a longer one is refused and the connection closed.
pub const MAX_LINE_BYTES: usize = 64 * 1024;

/// How long a connection may stay silent (or take to send one line), s.
pub const IDLE_TIMEOUT_S: u64 = 300;

/// How long one request may take to be answered, s (planning, reading a model file).
pub const REQUEST_TIMEOUT_S: u64 = 10;

/// What reading one request line gave.
#[derive(Debug, PartialEq, Eq)]
enum LineRead {
    /// A line (without its newline) is in the buffer.
    Line,
    /// The client closed the connection.
    Eof,
    /// More than [`MAX_LINE_BYTES`] without a newline.
    TooLong,
}

/// Reads one line into `buf` (cleared first), never buffering more than [`MAX_LINE_BYTES`].
async fn read_line<R: tokio::io::AsyncBufRead + Unpin>(
    r: &mut R,
    buf: &mut Vec<u8>,
) -> std::io::Result<LineRead> {
    buf.clear();
    loop {
        let avail = r.fill_buf().await?;
        if avail.is_empty() {
            return Ok(if buf.is_empty() {
                LineRead::Eof
            } else {
                LineRead::Line
            });
        }
        let (take, done) = match avail.iter().position(|&b| b == b'\n') {
            Some(i) => (i, true),
            None => (avail.len(), false),
        };
        if buf.len() + take > MAX_LINE_BYTES {
            let n = if done { take + 1 } else { take };
            r.consume(n);
            return Ok(LineRead::TooLong);
        }
        buf.extend_from_slice(&avail[..take]);
        r.consume(if done { take + 1 } else { take });
        if done {
            return Ok(LineRead::Line);
        }
    }
}

/// One client connection: lines in, answers out, until the client leaves, falls silent for
/// [`IDLE_TIMEOUT_S`] or sends a line longer than [`MAX_LINE_BYTES`].
/// Connection ids (0 is [`LOCAL`]).
static NEXT_CLIENT: AtomicU64 = AtomicU64::new(1);

async fn connection(conn: tokio::net::UnixStream, core: Arc<SharedCore>, id: ClientId) {
    let (r, mut w) = conn.into_split();
    let mut r = BufReader::new(r);
    let mut buf = Vec::with_capacity(1024);
    let idle = Duration::from_secs(IDLE_TIMEOUT_S);
    let mut limiter = LogLimiter::default();
    let started = std::time::Instant::now();
    loop {
        let read = match tokio::time::timeout(idle, read_line(&mut r, &mut buf)).await {
            Err(_) => {
                let e = err(format!(
                    "no complete request for {IDLE_TIMEOUT_S} s; closing"
                ));
                let _ = write_reply(&mut w, &e).await;
                return;
            }
            Ok(Err(_)) | Ok(Ok(LineRead::Eof)) => return,
            Ok(Ok(read)) => read,
        };
        if read == LineRead::TooLong {
            let e = err(format!(
                "request longer than {MAX_LINE_BYTES} bytes without a newline; closing"
            ));
            let _ = write_reply(&mut w, &e).await;
            return;
        }
        let Ok(line) = std::str::from_utf8(&buf) else {
            if !write_reply(&mut w, &err("bad request: not UTF-8 text")).await {
                return;
            }
            continue;
        };
        let (cmd, resp) = match parse(line) {
            Ok(ApiRequest::Subscribe { rate_hz }) => {
                if !(0.1..=100.0).contains(&rate_hz) {
                    if !write_reply(&mut w, &err("rate_hz must be within 0.1…100 Hz")).await {
                        return;
                    }
                    continue;
                }
                let mut tick = tokio::time::interval(Duration::from_secs_f64(1.0 / rate_hz));
                loop {
                    tick.tick().await;
                    if !write_reply(&mut w, &status_reply(&core)).await {
                        return;
                    }
                }
            }
            Ok(req) => {
                let cmd = req.name();
                // Off the runtime's thread: planning takes about a millisecond, reading a
                // model file is blocking IO.
                let c = core.clone();
                let work = tokio::task::spawn_blocking(move || handle_from(&c, req, id));
                let resp = match tokio::time::timeout(Duration::from_secs(REQUEST_TIMEOUT_S), work)
                    .await
                {
                    Ok(Ok(r)) => r,
                    Ok(Err(_)) => err("internal error while handling the request"),
                    Err(_) => err(format!("no answer within {REQUEST_TIMEOUT_S} s")),
                };
                (cmd, resp)
            }
            Err(refusal) => {
                let cmd = ApiRequest::name_in(line);
                note_refusal(&core, cmd, &refusal);
                (cmd, refusal)
            }
        };
        let span = tracing::info_span!("request", cmd = %cmd);
        span.in_scope(|| match &resp {
            // status is polled (often at 100 Hz): keep it out of the journal
            Reply::Ok(_) if cmd == "status" => tracing::debug!("done"),
            Reply::Ok(_) => tracing::info!("done"),
            Reply::Refused(error) => {
                let kind = if cmd.is_empty() { "malformed" } else { cmd };
                match limiter.check(kind, started.elapsed().as_secs_f64()) {
                    LogVerdict::Log { suppressed: 0 } => tracing::warn!(%error, "refused"),
                    LogVerdict::Log { suppressed } => tracing::warn!(
                        %error,
                        suppressed,
                        "refused (and {suppressed} more like it on this connection, not logged)"
                    ),
                    LogVerdict::Suppress => {}
                }
            }
        });
        if !write_reply(&mut w, &resp).await {
            return;
        }
    }
}

/// One reply as a line of JSON text.
fn reply_line(reply: &Reply) -> Vec<u8> {
    // a reply is plain data with string keys: it always serialises
    let mut line = serde_json::to_vec(reply).unwrap_or_default();
    line.push(b'\n');
    line
}

/// Writes one reply line; false when the client has gone.
async fn write_reply(w: &mut tokio::net::unix::OwnedWriteHalf, reply: &Reply) -> bool {
    w.write_all(&reply_line(reply)).await.is_ok()
}

/// Refusals logged per connection, per kind of request and per [`LOG_WINDOW_S`].
pub const LOG_PER_WINDOW: u32 = 5;
/// The rate limiter's window, s.
pub const LOG_WINDOW_S: f64 = 10.0;
/// Kinds tracked per connection; further kinds share one entry.
const LOG_KINDS: usize = 16;

/// What to do with one refusal's log line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LogVerdict {
    /// Log it, saying how many like it were suppressed since the last logged one.
    Log {
        /// Refusals of this kind not logged since.
        suppressed: u64,
    },
    /// Do not log it (counted).
    Suppress,
}

/// A per-connection log rate limiter: at most [`LOG_PER_WINDOW`] refusals of a kind per
/// [`LOG_WINDOW_S`]; the first one logged after a quiet spell carries the count of those
/// suppressed. Pure: the caller passes the time.
#[derive(Debug, Default)]
pub struct LogLimiter {
    kinds: Vec<(String, f64, u32, u64)>,
}

impl LogLimiter {
    /// The verdict for a refusal of `kind` at `now_s` (s, any origin, non-decreasing).
    pub fn check(&mut self, kind: &str, now_s: f64) -> LogVerdict {
        let kind = truncate(kind, 32);
        let i = match self.kinds.iter().position(|k| k.0 == kind) {
            Some(i) => i,
            None if self.kinds.len() < LOG_KINDS => {
                self.kinds.push((kind, now_s, 0, 0));
                self.kinds.len() - 1
            }
            None => LOG_KINDS - 1,
        };
        let (_, start, logged, suppressed) = &mut self.kinds[i];
        if now_s - *start >= LOG_WINDOW_S {
            *start = now_s;
            *logged = 0;
        }
        if *logged < LOG_PER_WINDOW {
            *logged += 1;
            LogVerdict::Log {
                suppressed: std::mem::take(suppressed),
            }
        } else {
            *suppressed += 1;
            LogVerdict::Suppress
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refusals_are_logged_a_few_per_window_and_the_rest_counted() {
        let mut l = LogLimiter::default();
        let mut logged = 0;
        for k in 0..1000 {
            if l.check("move_joints", k as f64 * 0.001) != LogVerdict::Suppress {
                logged += 1;
            }
        }
        assert_eq!(logged, LOG_PER_WINDOW);
        // another kind has its own budget
        assert_eq!(l.check("estop", 1.0), LogVerdict::Log { suppressed: 0 });
        // the next window logs again and says how many were dropped
        assert_eq!(
            l.check("move_joints", 10.5),
            LogVerdict::Log {
                suppressed: 1000 - u64::from(LOG_PER_WINDOW)
            }
        );
        // a flood of distinct kinds is bounded too
        for k in 0..10_000 {
            l.check(&format!("kind{k}"), 11.0);
        }
        assert!(l.kinds.len() <= LOG_KINDS);
    }
}
