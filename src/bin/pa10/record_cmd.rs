//! `pa10 record start|stop|info|recover|export`: recording every control cycle to MCAP through the
//! daemon, and reading recordings back (docs/recording.md).

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Subcommand;
use pa10::daemon::wire::{Answer, ApiRequest};

use crate::client_cmd::{Conn, checked};
use pa10::record::read;

/// `pa10 record …`
#[derive(Debug, Subcommand)]
pub enum RecordCmd {
    /// Start recording every cycle (a file inside the daemon's `record.dir`).
    Start {
        #[command(flatten)]
        conn: Conn,
        /// A plain file name (default `pa10d-<unix time>.mcap`).
        #[arg(long, value_name = "NAME")]
        out: Option<String>,
        /// Stop after this long, s.
        #[arg(long, value_name = "S")]
        duration: Option<f64>,
    },
    /// Stop recording.
    Stop(Conn),
    /// Channels, message counts, duration and the recorder's drops of a recording file.
    Info {
        /// The MCAP file.
        file: PathBuf,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
    /// Rewrite a recording cut short by a crash (`kill -9`, a power loss) as a whole MCAP
    /// file (summary and indexes) that the standard readers read: every message before the
    /// damage.
    Recover {
        /// The damaged MCAP file.
        input: PathBuf,
        /// The new file (refused when it exists).
        output: PathBuf,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
    /// Write `cycles.csv` and `events.csv` of a recording into a folder.
    Export {
        /// The MCAP file.
        file: PathBuf,
        /// The folder.
        #[arg(long, value_name = "DIR")]
        csv: PathBuf,
    },
}

/// `pa10 record …`.
pub fn run(c: &RecordCmd) -> Result<()> {
    match c {
        RecordCmd::Start {
            conn,
            out,
            duration,
        } => {
            let req = ApiRequest::RecordStart {
                file: out.clone(),
                duration_s: *duration,
            };
            match checked(&mut crate::client_cmd::Socket(conn.clone()), req)? {
                Answer::Recording { path } => println!("recording to {path}"),
                other => anyhow::bail!("pa10d answered record_start with {other:?}"),
            }
            Ok(())
        }
        RecordCmd::Stop(conn) => {
            checked(
                &mut crate::client_cmd::Socket(conn.clone()),
                ApiRequest::RecordStop {},
            )?;
            println!("stopped");
            Ok(())
        }
        RecordCmd::Recover {
            input,
            output,
            json,
        } => {
            let r = pa10::record::recover::recover(input, output)?;
            if *json {
                println!("{}", serde_json::to_string(&r)?);
                return Ok(());
            }
            let n: u64 = r.channels.values().sum();
            println!(
                "{}: {n} messages written ({})",
                output.display(),
                r.channels
                    .iter()
                    .map(|(t, n)| format!("{t} {n}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            );
            match &r.truncated {
                Some(t) => println!("  {} ended early ({t}); the rest is lost", input.display()),
                None => println!("  {} was whole", input.display()),
            }
            Ok(())
        }
        RecordCmd::Info { file, json } => {
            let i = read::info(file).with_context(|| format!("reading {}", file.display()))?;
            if *json {
                println!("{}", serde_json::to_string(&i)?);
                return Ok(());
            }
            println!("{}", file.display());
            println!(
                "  span {:.3} … {:.3} s ({:.3} s)",
                i.span_s[0],
                i.span_s[1],
                i.span_s[1] - i.span_s[0]
            );
            for (topic, n) in &i.channels {
                println!("  {topic}: {n} messages");
            }
            println!("  cycles with incomplete feedback: {}", i.incomplete);
            if let Some(t) = &i.truncated {
                println!(
                    "  the file ends early ({t}): a recording cut short; what precedes is read"
                );
            }
            if i.recorder.is_empty() {
                println!("  recorder counts: not in this file (a rotated file before the last)");
            } else {
                for (k, v) in &i.recorder {
                    println!("  recorder {k}: {v}");
                }
            }
            Ok(())
        }
        RecordCmd::Export { file, csv } => {
            let [c, e] = read::export_csv(file, csv)?;
            println!("wrote {} and {}", c.display(), e.display());
            Ok(())
        }
    }
}
