//! The daemon's status as an operator reads it (`pa10 status`, `pa10 watch`): state in words,
//! the tool in mm and degrees, a joint table in degrees with the distance to the nearest limit
//! (the nominal PA10's limits) and motor − link setpoint (the compensation, plus any following
//! error), and one line of cycle statistics. Pure functions of a [`Status`]; the `--json` output stays
//! the wire schema.

use std::fmt::Write as _;

use nalgebra::{Quaternion, UnitQuaternion};
use pa10::daemon::wire::{ModelStatus, Status};
use pa10::model::JointLimits;

/// The full view: several lines, each ending in a newline. `limits` (rad) gives each joint's
/// distance to its nearest limit.
pub fn render(s: &Status, limits: &JointLimits) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "pa10d {}{} · servo {} · motion lease {} · speed scaling {:.0} % · t = {:.1} s",
        s.state,
        if s.in_position { ", in position" } else { "" },
        s.servo.as_deref().unwrap_or("unknown"),
        if s.leased { "held" } else { "free" },
        100.0 * s.speed_scaling,
        s.time_s
    );
    if let Some(f) = &s.fault {
        let _ = writeln!(out, "FAULT  {f}  (pa10 reset clears it)");
    }
    let p = s.tool_position.map(|v| v * 1e3);
    let (roll, pitch, yaw) = rpy_deg(&s.tool_quaternion);
    let _ = writeln!(
        out,
        "tool   x {:+9.3}  y {:+9.3}  z {:+9.3} mm · roll {:+8.3}  pitch {:+8.3}  yaw {:+8.3} ° (fixed axes X, Y, Z; base frame){}",
        p[0],
        p[1],
        p[2],
        roll,
        pitch,
        yaw,
        s.position_sigma_mm
            .map(|m| format!(" · model σ {m:.3} mm"))
            .unwrap_or_default()
    );
    let c = s.payload_com.map(|v| v * 1e3);
    let _ = writeln!(
        out,
        "load   {:.1} N ({:.2} kg) at [{:.0}, {:.0}, {:.0}] mm in the tool frame",
        s.payload_n,
        s.payload_n / pa10::model::STANDARD_GRAVITY,
        c[0],
        c[1],
        c[2]
    );
    if let Some(m) = &s.model {
        let _ = writeln!(out, "model  {}", model_words(m));
    }
    if let Some(r) = &s.last_refusal {
        let _ = writeln!(
            out,
            "refused {} at t = {:.1} s ({:.1} s ago): {}",
            if r.request.is_empty() {
                "a malformed line"
            } else {
                &r.request
            },
            r.time_s,
            (s.time_s - r.time_s).max(0.0),
            r.error
        );
    }
    let _ = writeln!(
        out,
        "joint   link [°]   motor [°]   to limit [°]   torque [N·m]   current [A]   motor − link [mrad]"
    );
    for j in 0..6 {
        let q = s.setpoint[j];
        let to_limit = (q - limits.lower[j]).min(limits.upper[j] - q);
        let _ = writeln!(
            out,
            "  J{}   {:+9.3}   {:+9.3}   {:12.1}   {:+12.2}   {:+11.3}   {:+19.3}",
            j + 1,
            q.to_degrees(),
            s.q_motor[j].to_degrees(),
            to_limit.to_degrees(),
            s.tau[j],
            s.current[j],
            (s.q_motor[j] - q) * 1e3
        );
    }
    let _ = writeln!(out, "cycle  {}", cycle_line(s));
    if let Some(r) = &s.recording {
        let _ = writeln!(
            out,
            "record {} {} · {} cycles written, {} dropped{}",
            if r.active { "writing" } else { "stopped" },
            r.path,
            r.written,
            r.dropped_queue + r.dropped_write,
            r.error
                .as_ref()
                .map(|e| format!(" · error: {e}"))
                .unwrap_or_default()
        );
    }
    if let Some(e) = &s.stream_end {
        let _ = writeln!(out, "stream {e}");
    }
    out
}

/// The model in force in words: its kind, what it holds, its file and since when.
pub fn model_words(m: &ModelStatus) -> String {
    let joints = |js: &[u8]| {
        js.iter()
            .map(|j| format!("J{j}"))
            .collect::<Vec<_>>()
            .join(" ")
    };
    let mut words = m.kind.name().to_owned();
    if !m.springs.is_empty() {
        let _ = write!(words, " · springs {}", joints(&m.springs));
    }
    if !m.friction.is_empty() {
        let _ = write!(words, " · friction {}", joints(&m.friction));
    }
    if !m.discovered.is_empty() {
        let _ = write!(words, " · discovered {}", m.discovered.join(", "));
    }
    let _ = write!(words, " · {} since t = {:.1} s", m.file, m.since_s);
    words
}

/// One line of cycle statistics: rate, wake-up jitter p50/p99, compute p99, bus load,
/// overruns, lock waits.
pub fn cycle_line(s: &Status) -> String {
    let c = &s.cycle;
    format!(
        "{:.0} Hz · jitter p50/p99 {:.0}/{:.0} µs · compute p99 {:.0} µs · bus {:.1} % worst case · {} overruns in {} cycles · {} lock waits",
        c.rate_hz,
        c.jitter_us[0],
        c.jitter_us[1],
        c.compute_us[1],
        c.bus_load_pct,
        c.overruns,
        c.cycles,
        c.lock_waits
    )
}

/// One line for a piped `pa10 watch`: what an operator follows changing.
pub fn line(s: &Status) -> String {
    let p = s.tool_position.map(|v| v * 1e3);
    let q: Vec<String> = s
        .setpoint
        .iter()
        .map(|v| format!("{:+.2}", v.to_degrees()))
        .collect();
    format!(
        "t {:.2} s · {} · tool [{:+.3}, {:+.3}, {:+.3}] mm · joints [{}] ° · load {:.0} N{}",
        s.time_s,
        s.state,
        p[0],
        p[1],
        p[2],
        q.join(", "),
        s.payload_n,
        s.fault
            .as_ref()
            .map(|f| format!(" · FAULT {f}"))
            .unwrap_or_default()
    ) + &s
        .last_refusal
        .as_ref()
        .map(|r| {
            format!(
                " · last refused {} at t {:.2} s: {}",
                r.request, r.time_s, r.error
            )
        })
        .unwrap_or_default()
}

/// Roll, pitch, yaw (°) of a unit quaternion `[w, x, y, z]`: rotations about the fixed X, Y,
/// Z axes in that order.
pub fn rpy_deg(q: &[f64; 4]) -> (f64, f64, f64) {
    let u = UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3]));
    let (r, p, y) = u.euler_angles();
    (r.to_degrees(), p.to_degrees(), y.to_degrees())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The simulated daemon's status, holding at the simulator's home with 45 N declared.
    fn status() -> Status {
        use pa10::daemon::wire::{Answer, ApiRequest, Reply};
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/config/sim.yaml");
        let settings = pa10::daemon::config::Config::load(std::path::Path::new(path))
            .expect("config/sim.yaml");
        let mut ls = pa10::sim::rig::Lockstep::from_config(&settings).expect("the simulated arm");
        ls.run_until_ready(2.0).expect("ready");
        let r = ls.call(ApiRequest::SetPayload {
            newtons: Some(45.0),
            mass_kg: None,
            com: None,
        });
        assert!(matches!(r, Reply::Ok(_)), "{r:?}");
        ls.run_for(0.1);
        // a move beyond J2's limit, refused
        let r = ls.call(ApiRequest::MoveJoints {
            q: [0.0, 3.0, 1.5, 0.0, 1.0, 0.0],
        });
        assert!(matches!(r, Reply::Refused(_)), "{r:?}");
        ls.run_for(0.1);
        match ls.call(ApiRequest::Status {}) {
            Reply::Ok(Answer::Status(s)) => *s,
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn the_view_names_the_state_and_gives_millimetres_degrees_and_the_limits() {
        let s = status();
        let limits = *pa10::model::Model::nominal().limits();
        let v = render(&s, &limits);
        assert!(s.in_position, "{s:?}");
        assert!(v.starts_with("pa10d holding, in position · servo "), "{v}");
        let p = s.tool_position.map(|x| x * 1e3);
        assert!(v.contains(&format!("x {:+9.3}", p[0])), "{v}");
        assert!(v.contains("load   45.0 N (4.59 kg)"), "{v}");
        // a joint row in degrees, with its distance to the nearest limit
        let j2 = s.setpoint[1];
        let to = (j2 - limits.lower[1])
            .min(limits.upper[1] - j2)
            .to_degrees();
        let row = v
            .lines()
            .find(|l| l.starts_with("  J2 "))
            .expect("a J2 row");
        assert!(row.contains(&format!("{:+9.3}", j2.to_degrees())), "{row}");
        assert!(row.contains(&format!("{to:12.1}")), "{row}");
        assert!(v.contains("Hz · jitter p50/p99"), "{v}");
        assert!(!v.contains("e-"), "no raw floats: {v}");
        // the model in force, and the refusal in the daemon's words
        let m = s.model.as_ref().expect("status.model");
        assert_eq!(m.kind, pa10::daemon::wire::ModelKind::Nominal, "{m:?}");
        assert!(m.file.ends_with("model-nominal.yaml"), "{m:?}");
        assert!(
            v.contains(&format!("model  nominal · {} since t = 0.0 s", m.file)),
            "{v}"
        );
        let r = s.last_refusal.as_ref().expect("status.last_refusal");
        let refused = v
            .lines()
            .find(|l| l.starts_with("refused"))
            .expect("a refusal line");
        assert!(
            refused.starts_with("refused move_joints at t = "),
            "{refused}"
        );
        assert!(
            refused.ends_with(&r.error) && r.error.contains("joint 2"),
            "{refused}"
        );
        // the piped line: state, tool and joints on one line
        let l = line(&s);
        assert!(
            l.contains("holding") && l.contains("mm") && !l.contains('\n'),
            "{l}"
        );
    }

    #[test]
    fn roll_pitch_yaw_of_quarter_turns() {
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let (r, p, y) = rpy_deg(&[h, 0.0, 0.0, h]); // 90° about z
        assert!(r.abs() < 1e-9 && p.abs() < 1e-9 && (y - 90.0).abs() < 1e-9);
        let (r, _, _) = rpy_deg(&[h, h, 0.0, 0.0]);
        assert!((r - 90.0).abs() < 1e-9);
    }
}
