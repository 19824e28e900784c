//! A recording cut short (`kill -9`, a power loss) rewritten whole: every message before the
//! damage, with its channel and schema, into a new MCAP file with its summary and indexes, so
//! that the standard readers (the Python `mcap` package, Foxglove) read it
//! (`pa10 record recover IN OUT`).

use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::Path;

use super::read::{ReadError, load};

/// What [`recover`] wrote.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Recovered {
    /// Messages written, per channel topic.
    pub channels: BTreeMap<String, u64>,
    /// Why the input ended early, when it did (`None`: it was whole).
    pub truncated: Option<String>,
}

/// Reads `input` up to where it is damaged and writes what it holds to `output` (a new file:
/// an existing one is refused) as a complete MCAP file. On an error nothing is left at
/// `output`.
pub fn recover(input: &Path, output: &Path) -> Result<Recovered, ReadError> {
    let buf = load(input)?;
    let created = std::cell::Cell::new(false);
    let r = rewrite(&buf, input, output, &created);
    if r.is_err() && created.get() {
        let _ = std::fs::remove_file(output);
    }
    r
}

fn rewrite(
    buf: &[u8],
    input: &Path,
    output: &Path,
    created: &std::cell::Cell<bool>,
) -> Result<Recovered, ReadError> {
    let bad = |path: &Path, e: &dyn std::fmt::Display| ReadError::Format {
        path: path.to_path_buf(),
        error: e.to_string(),
    };
    let io = |path: &Path, e: std::io::Error| ReadError::Io {
        path: path.to_path_buf(),
        error: e.to_string(),
    };
    let file = std::fs::File::options()
        .write(true)
        .create_new(true)
        .open(output)
        .map_err(|e| io(output, e))?;
    created.set(true);
    let mut w = mcap::WriteOptions::new()
        .profile("")
        .library("pa10 record recover")
        .create(BufWriter::new(file))
        .map_err(|e| bad(output, &e))?;
    // input channel id → output channel id
    let mut ids: BTreeMap<u16, u16> = BTreeMap::new();
    let mut out = Recovered {
        channels: BTreeMap::new(),
        truncated: None,
    };
    for m in mcap::MessageStream::new(buf).map_err(|e| bad(input, &e))? {
        let m = match m {
            Ok(m) => m,
            Err(e) => {
                out.truncated = Some(e.to_string());
                break;
            }
        };
        let id = match ids.get(&m.channel.id) {
            Some(id) => *id,
            None => {
                let schema = match &m.channel.schema {
                    Some(s) => w
                        .add_schema(&s.name, &s.encoding, &s.data)
                        .map_err(|e| bad(output, &e))?,
                    None => 0,
                };
                let id = w
                    .add_channel(
                        schema,
                        &m.channel.topic,
                        &m.channel.message_encoding,
                        &m.channel.metadata,
                    )
                    .map_err(|e| bad(output, &e))?;
                ids.insert(m.channel.id, id);
                id
            }
        };
        let header = mcap::records::MessageHeader {
            channel_id: id,
            sequence: m.sequence,
            log_time: m.log_time,
            publish_time: m.publish_time,
        };
        w.write_to_known_channel(&header, &m.data)
            .map_err(|e| bad(output, &e))?;
        *out.channels.entry(m.channel.topic.clone()).or_insert(0) += 1;
    }
    w.finish().map_err(|e| bad(output, &e))?;
    Ok(out)
}
