//! Streamed setpoints: starting a servo, jog or twist stream, and one cycle's step of it
//! (the target speeds ramped within the limits; a twist mapped to joint speeds through the
//! Jacobian), and the end of a trajectory or stream.

use super::*;

impl Controller {
    /// A streamed command at `now_s`: a servo target (link positions, rad, inside the
    /// limits) or jog velocities (rad/s, within the speed limits). Starts the stream from
    /// holding or continues one; refused during a move, a trajectory or a stop.
    pub fn stream(&mut self, stream: Stream, now_s: f64) -> Result<(), CommandError> {
        let lim = self.p.limits;
        if let Stream::Twist { twist, .. } = &stream {
            let n = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
            let (lin, ang) = (n(&twist[..3]), n(&twist[3..]));
            if !(lin.is_finite() && ang.is_finite())
                || lin > MAX_TWIST_LINEAR
                || ang > MAX_TWIST_ANGULAR
            {
                return Err(CommandError::Invalid(format!(
                    "tool twist: {lin:.4} m/s and {ang:.4} rad/s must be finite and within {MAX_TWIST_LINEAR} m/s and {MAX_TWIST_ANGULAR} rad/s"
                )));
            }
        }
        let (v, what) = match &stream {
            Stream::Servo(q) => (q, "servo position"),
            Stream::Jog(v) => (v, "jog velocity"),
            Stream::Twist { .. } => (&[0.0; 6], "tool twist"),
        };
        for j in 0..6 {
            if !v[j].is_finite() {
                return Err(CommandError::Invalid(format!(
                    "{what} of joint {} is not finite",
                    j + 1
                )));
            }
            let bad = match stream {
                Stream::Servo(_) => v[j] < lim.lower[j] || v[j] > lim.upper[j],
                Stream::Jog(_) => v[j].abs() > lim.speed[j],
                Stream::Twist { .. } => false,
            };
            if bad {
                return Err(CommandError::Invalid(match stream {
                    Stream::Servo(_) => format!(
                        "{what} of joint {}: {:.4} rad is outside [{:.4}, {:.4}] rad",
                        j + 1,
                        v[j],
                        lim.lower[j],
                        lim.upper[j]
                    ),
                    Stream::Jog(_) | Stream::Twist { .. } => format!(
                        "{what} of joint {}: {:.4} rad/s is beyond the {:.4} rad/s limit",
                        j + 1,
                        v[j],
                        lim.speed[j]
                    ),
                }));
            }
        }
        let target_v = match (&self.activity, stream) {
            (
                Activity::Streaming {
                    stream: Stream::Servo(old),
                    last_s,
                    ..
                },
                Stream::Servo(new),
            ) if now_s > *last_s => std::array::from_fn(|j| {
                ((new[j] - old[j]) / (now_s - last_s)).clamp(-lim.speed[j], lim.speed[j])
            }),
            _ => [0.0; 6],
        };
        match &self.activity {
            Activity::Faulted(f) => Err(CommandError::Faulted(f.clone())),
            Activity::Holding | Activity::Streaming { .. } => {
                self.stream_end = None;
                self.activity = Activity::Streaming {
                    stream,
                    last_s: now_s,
                    target_v,
                };
                Ok(())
            }
            _ => Err(CommandError::Busy),
        }
    }

    /// Joint velocities (rad/s) that move the tool at `twist` from the current setpoint, by
    /// the model's Jacobian (numerical, 7 forward kinematics, no allocation); scaled down as a
    /// whole (direction kept) to the speed limits × scaling. `None` near a singularity,
    /// where that would need more than ten times a joint's speed limit.
    fn twist_to_joints(&self, twist: &[f64; 6], tool_frame: bool) -> Option<[f64; 6]> {
        use nalgebra::{Matrix6, Vector3, Vector6};
        let q = self.setpoint.q;
        let f0 = self.model.fk(&q);
        let h = 1e-7;
        let mut jac = Matrix6::zeros();
        for j in 0..6 {
            let mut qh = q;
            qh[j] += h;
            let f1 = self.model.fk(&qh);
            let dp = (f1.translation.vector - f0.translation.vector) / h;
            let dr = (f1.rotation * f0.rotation.inverse()).scaled_axis() / h;
            for r in 0..3 {
                jac[(r, j)] = dp[r];
                jac[(r + 3, j)] = dr[r];
            }
        }
        let (mut v, mut w) = (
            Vector3::new(twist[0], twist[1], twist[2]),
            Vector3::new(twist[3], twist[4], twist[5]),
        );
        if tool_frame {
            v = f0.rotation * v;
            w = f0.rotation * w;
        }
        let qd = jac
            .lu()
            .solve(&Vector6::new(v.x, v.y, v.z, w.x, w.y, w.z))?;
        let lim = self.p.limits;
        let mut scale = 1.0f64;
        for j in 0..6 {
            let vmax = lim.speed[j] * self.scaling;
            if !qd[j].is_finite() || qd[j].abs() > 10.0 * lim.speed[j] {
                return None;
            }
            if qd[j].abs() > vmax {
                scale = scale.min(vmax / qd[j].abs());
            }
        }
        Some(std::array::from_fn(|j| qd[j] * scale))
    }

    /// Marks the running trajectory as ended (no effect on any other activity).
    pub(super) fn end_trajectory(&mut self, state: TrajectoryState, result: TrajectoryResult) {
        if self.trajectory.state == TrajectoryState::Executing {
            self.trajectory.state = state;
            self.trajectory.result = result;
        }
    }

    /// One cycle of a stream: toward the servo target or at the jog velocity, each joint
    /// within its speed (× scaling) and acceleration limits and braking before its range
    /// ends. No allocation.
    pub(super) fn stream_step(&mut self, stream: Stream, target_v: &[f64; 6]) {
        let dt = self.p.period_s;
        let lim = self.p.limits;
        let stream = match stream {
            Stream::Twist { twist, tool_frame } => match self.twist_to_joints(&twist, tool_frame) {
                Some(v) => Stream::Jog(v),
                None => {
                    self.stream_end = Some(
                        "jog: the tool twist needs joint speeds beyond the limits here (near a singularity); stopped",
                    );
                    self.stop();
                    return;
                }
            },
            s => s,
        };
        for j in 0..6 {
            let (q, v) = (self.setpoint.q[j], self.setpoint.qd[j]);
            let (vmax, a) = (lim.speed[j] * self.scaling, lim.acceleration[j]);
            let want = match stream {
                Stream::Servo(target) => {
                    let e = target[j] - q;
                    // the target's own speed, plus the fastest approach from which the
                    // target can still be reached at rest
                    let approach =
                        e.signum() * vmax.min((2.0 * a * e.abs()).sqrt()).min(e.abs() / dt);
                    (target_v[j] * self.scaling + approach).clamp(-vmax, vmax)
                }
                // (a twist was turned into joint velocities above)
                Stream::Jog(vel) | Stream::Twist { twist: vel, .. } => {
                    let w = vel[j].clamp(-vmax, vmax);
                    // brake before the range ends
                    let room = if w > 0.0 {
                        lim.upper[j] - q
                    } else {
                        q - lim.lower[j]
                    };
                    w.signum() * w.abs().min((2.0 * a * room.max(0.0)).sqrt())
                }
            };
            let nv = v + (want - v).clamp(-a * dt, a * dt);
            self.setpoint.q[j] = q + 0.5 * (v + nv) * dt;
            self.setpoint.qd[j] = nv;
        }
    }
}
