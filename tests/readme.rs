//! The README's daemon workflows run as a newcomer runs them: the `$ ` lines of its blocks
//! "Run the daemon on the simulated robot", "Drive it as a planner …" and "Record every
//! cycle", verbatim, in one shell, against a fresh `pa10d` on the simulated arm, with the
//! built `pa10` and `pa10d` first on `PATH`. Each command must succeed and print every line the
//! README shows under it, word for word (numbers vary from run to run, words must not; `…`
//! stands for anything).
//!
//! The shell's working directory is a copy of `config/` whose `sim.yaml` differs from the
//! shipped one only in two tolerances every test of the `pa10d` binary relaxes (a loaded CI
//! machine's writeback once held the daemon 113 ms); the socket and the record directory are
//! the README's own (`/tmp/pa10d-sim.sock`, `/tmp/pa10d-recordings`).

use std::path::Path;
use std::process::Command;

use crate::common::realtime_lock;

/// The `$ ` lines of the README's block containing `marker`, each with the lines shown under
/// it (its expected output).
fn block(readme: &str, marker: &str) -> Vec<(String, Vec<String>)> {
    let blocks: Vec<&str> = readme.split("```").skip(1).step_by(2).collect();
    let b = blocks
        .iter()
        .find(|b| b.contains(marker))
        .unwrap_or_else(|| panic!("no README block with {marker:?}"));
    let mut steps: Vec<(String, Vec<String>)> = Vec::new();
    for line in b.lines().skip(1) {
        if let Some(cmd) = line.strip_prefix("$ ") {
            steps.push((cmd.to_owned(), Vec::new()));
        } else if let Some((_, shown)) = steps.last_mut()
            && !line.trim().is_empty()
        {
            shown.push(line.to_owned());
        }
    }
    steps
}

/// A line with every number (a digit run not glued to a word, with its sign and decimals)
/// as `#` and every run of blanks as one space.
fn norm(line: &str) -> String {
    let c: Vec<char> = line.trim().chars().collect();
    let mut out = String::new();
    let mut i = 0;
    while i < c.len() {
        let glued = i > 0 && c[i - 1].is_alphanumeric();
        let signed = matches!(c[i], '+' | '-') && c.get(i + 1).is_some_and(char::is_ascii_digit);
        if !glued && (c[i].is_ascii_digit() || signed) {
            i += 1;
            while i < c.len() && (c[i].is_ascii_digit() || c[i] == '.') {
                i += 1;
            }
            out.push('#');
        } else if c[i].is_whitespace() {
            while i < c.len() && c[i].is_whitespace() {
                i += 1;
            }
            out.push(' ');
        } else {
            out.push(c[i]);
            i += 1;
        }
    }
    out
}

/// Whether `printed` is the line the README `shown`: the same words, any numbers, an
/// elision (`…`, `...`) standing for anything.
fn same_line(shown: &str, printed: &str) -> bool {
    let shown = norm(shown).replace('…', "...");
    let printed = norm(printed);
    let mut pieces = shown.split("...");
    let first = pieces.next().unwrap_or_default();
    let Some(mut rest) = printed.strip_prefix(first) else {
        return false;
    };
    let pieces: Vec<&str> = pieces.collect();
    if pieces.is_empty() {
        return rest.is_empty();
    }
    for p in pieces {
        match rest.find(p) {
            Some(at) => rest = &rest[at + p.len()..],
            None => return false,
        }
    }
    true
}

fn copy_config(to: &Path) {
    let from = Path::new(env!("CARGO_MANIFEST_DIR")).join("config");
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(&from).unwrap() {
        let e = e.unwrap();
        if e.file_type().unwrap().is_file() {
            std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
        }
    }
    let sim = to.join("sim.yaml");
    let text = std::fs::read_to_string(&sim).unwrap();
    std::fs::write(&sim, crate::common::ci_tolerances(&text)).unwrap();
}

#[test]
fn the_readme_drives_the_simulated_daemon_records_and_reads_the_status_as_written() {
    let _serial = realtime_lock();
    let readme =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("README.md")).unwrap();
    let mut steps = block(&readme, "pa10d --config config/sim.yaml &");
    steps.extend(block(&readme, "pa10 trajectory path.csv --wait"));
    steps.extend(block(&readme, "pa10 record start"));
    assert!(steps.len() >= 12, "{steps:?}");
    assert!(
        steps
            .iter()
            .any(|(c, _)| c.starts_with("pa10 record info /tmp/pa10d-recordings/campaign1.mcap")),
        "the README's recording block changed: {steps:?}"
    );

    let dir = std::env::temp_dir().join(format!("pa10-readme-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    copy_config(&dir.join("config"));
    // the README's recording name: a file left by an earlier run would be refused
    for f in std::fs::read_dir("/tmp/pa10d-recordings")
        .into_iter()
        .flatten()
    {
        let f = f.unwrap().path();
        if f.file_name()
            .unwrap()
            .to_string_lossy()
            .starts_with("campaign1")
        {
            std::fs::remove_file(f).unwrap();
        }
    }

    // one shell: `&` and `export` carry over; a marker before each step splits the output;
    // `pa10 watch` runs until interrupted, here for 2 s
    let bin = Path::new(env!("CARGO_BIN_EXE_pa10d")).parent().unwrap();
    let mut script = String::from(
        "set -e\ntrap 'kill $(jobs -p) 2>/dev/null; wait' EXIT\n\
         pa10() { if [ \"$1\" = watch ]; then timeout 2 pa10 \"$@\" || [ $? = 124 ]; \
         else command pa10 \"$@\"; fi; }\n",
    );
    for (i, (cmd, _)) in steps.iter().enumerate() {
        script.push_str(&format!("echo '@@ {i}'\n{cmd}\n"));
        if cmd.starts_with("pa10d --config") {
            // a newcomer waits for the daemon's socket before the next command
            script.push_str(
                "for _ in $(seq 100); do [ -S /tmp/pa10d-sim.sock ] && break; sleep 0.1; done\n",
            );
        }
    }
    let out = Command::new("bash")
        .arg("-c")
        .arg(&script)
        .current_dir(&dir)
        .env(
            "PATH",
            format!("{}:{}", bin.display(), std::env::var("PATH").unwrap()),
        )
        .env_remove("PA10D_SOCKET")
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    let mut printed = stdout.split("@@ ").skip(1);
    for (i, (cmd, shown)) in steps.iter().enumerate() {
        let section = printed.next().unwrap_or_default();
        assert!(section.starts_with(&format!("{i}\n")), "{stdout}");
        for s in shown.iter().filter(|s| !matches!(s.trim(), "…" | "...")) {
            assert!(
                section.lines().any(|l| same_line(s, l)),
                "`{cmd}` printed no line like the README's {s:?}:\n{section}"
            );
        }
    }
    // the recording the README reads is whole, and its export is there
    let rec = Path::new("/tmp/pa10d-recordings/campaign1.mcap");
    let info = pa10::record::read::info(rec).unwrap();
    assert!(info.truncated.is_none());
    assert!(pa10::record::read::cycles(rec).unwrap().len() > 500);
    assert!(dir.join("campaign1-csv").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_shown_line_matches_on_words_not_numbers() {
    assert!(same_line(
        "  J1      +5.730      +5.730          171.3",
        "  J1     -12.308     -12.309          164.7"
    ));
    assert!(same_line(
        "pa10d holding · t = 3.2 s",
        "pa10d holding · t = 15.0 s"
    ));
    assert!(!same_line(
        "pa10d holding · t = 3.2 s",
        "pa10d moving · t = 3.2 s"
    ));
    assert!(same_line(
        "trajectory 1 succeeded; error [rad] [...]",
        "trajectory 2 succeeded; error [rad] [0.1, 0.2]"
    ));
    assert!(!same_line(
        "trajectory 1 succeeded; error [rad] [...]",
        "trajectory 2 aborted; error [rad] [0.1]"
    ));
    assert!(!same_line("bus 84.8 %", "bus 84.8 % worst case"));
    assert!(same_line(
        "config/sim.yaml: valid",
        "config/sim.yaml: valid"
    ));
}
