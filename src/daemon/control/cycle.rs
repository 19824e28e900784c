//! The steps of one control cycle, in the order [`Controller::step`] runs them:
//!
//! 1. [`take_feedback`](Controller::take_feedback) — the cycle's joint state, the stale-feedback
//!    and controller-fault checks;
//! 2. [`advance_setpoint`](Controller::advance_setpoint) — the setpoint source in force (a
//!    move, a trajectory under the speed scaling ramp, a stream with its deadline, a stop's
//!    deceleration);
//! 3. [`torque_estimate`](Controller::torque_estimate) — the torque source's estimate
//!    (`estimate.rs`);
//! 4. [`note_directions`](Controller::note_directions) and
//!    [`compensated_target`](Controller::compensated_target) — the motor target that puts the
//!    link at the setpoint;
//! 5. [`position_loop`](Controller::position_loop) — following-error and joint-limit checks,
//!    speed commands within the limits.
//!
//! Each step is a method on plain data with no clock and no allocation; a step that finds a
//! fault returns it, and `step` stops the arm with it.

use super::hold::hold_brake;
use super::*;

impl Controller {
    /// Step 1: bookkeeping of this cycle's feedback `fb` (`None`: it did not arrive). `Ok(None)`
    /// when the loop commands zero (already faulted, or no feedback yet); a fault when the
    /// controller has been silent longer than the feedback timeout, in cycles the loop ran
    /// and listened through, or reports a fault itself.
    pub(super) fn take_feedback(
        &mut self,
        now_s: f64,
        fb: Option<&JointState>,
    ) -> Result<Option<JointState>, Fault> {
        match fb {
            Some(f) => {
                if let Some(prev) = self.last_state {
                    self.note_motor_speed(&prev, f);
                }
                self.last_feedback_s = f.stamp_s;
                self.last_state = Some(*f);
                self.missed = 0;
            }
            None => self.missed = self.missed.saturating_add(1),
        }
        if matches!(self.activity, Activity::Faulted(_)) {
            return Ok(None);
        }
        // the controller's silence is judged in cycles the loop ran and listened through: a
        // host pause of the loop itself is not evidence against the controller (its own
        // watchdog, `limits.controller_watchdog_ms`, judges the loop)
        let listened = f64::from(self.missed) * self.p.period_s;
        if listened > self.p.feedback_timeout_s + 1e-9 {
            return Err(Fault::StaleFeedback {
                missed_cycles: self.missed,
                listened_ms: listened * 1e3,
                age_ms: (now_s - self.last_feedback_s) * 1e3,
                limit_ms: self.p.feedback_timeout_s * 1e3,
            });
        }
        let Some(state) = self.last_state else {
            return Ok(None);
        };
        if state.controller_fault {
            return Err(Fault::Controller);
        }
        Ok(Some(state))
    }

    /// Step 2: the setpoint (link angles, rad; speeds, rad/s) at `now_s` from the source in
    /// force, and the speed scaling's ramp toward what was asked.
    pub(super) fn advance_setpoint(&mut self, now_s: f64) -> Result<(), Fault> {
        if let Activity::Moving { mv, start_s } = &self.activity {
            let t = now_s - start_s;
            self.setpoint = mv
                .sample(&self.model, t, &self.setpoint.q)
                .map_err(Fault::Setpoint)?;
            if t >= mv.duration() {
                self.setpoint.qd = [0.0; 6];
                self.activity = Activity::Holding;
            }
        }
        // the speed scaling ramps toward what was asked
        let ramp = self.p.period_s / SCALING_RAMP_S;
        self.scaling += (self.scaling_target - self.scaling).clamp(-ramp, ramp);
        if let Activity::Following {
            traj, tau, ended_s, ..
        } = &mut self.activity
        {
            *tau = (*tau + self.scaling * self.p.period_s).min(traj.duration());
            let s = traj.sample(*tau);
            self.setpoint.q = s.q;
            for j in 0..6 {
                self.setpoint.qd[j] = if *tau < traj.duration() {
                    self.scaling * s.qd[j]
                } else {
                    0.0
                };
            }
            self.trajectory.progress = *tau / traj.duration();
            if *tau >= traj.duration() && ended_s.is_none() {
                *ended_s = Some(now_s);
            }
        }
        if let Activity::Streaming {
            stream,
            last_s,
            target_v,
        } = self.activity
        {
            if now_s - last_s > self.p.stream_deadline_s {
                self.stream_end = Some(match stream {
                    Stream::Servo(_) => "servo: no setpoint within servo.deadline_ms; stopped",
                    Stream::Jog(_) | Stream::Twist { .. } => {
                        "jog: no command within servo.deadline_ms; stopped"
                    }
                });
                self.stop();
            } else {
                self.stream_step(stream, &target_v);
            }
        }
        if let Activity::Stopping { decel } = self.activity {
            let dt = self.p.period_s;
            let mut moving = false;
            for j in 0..6 {
                let v = self.setpoint.qd[j];
                let nv = if v > 0.0 {
                    (v - decel[j] * dt).max(0.0)
                } else {
                    (v + decel[j] * dt).min(0.0)
                };
                self.setpoint.q[j] += 0.5 * (v + nv) * dt;
                self.setpoint.qd[j] = nv;
                moving |= nv != 0.0;
            }
            if !moving {
                self.activity = Activity::Holding;
            }
        }
        Ok(())
    }

    /// Step 3: the joint torques (N·m) the compensation uses, from the configured source
    /// ([`TorqueEstimator::estimate`]).
    pub(super) fn torque_estimate(&mut self, state: &JointState) -> [f64; 6] {
        let load = self.load();
        let inputs = EstimateInputs {
            model: &self.model,
            load: &load,
            setpoint: &self.setpoint,
            holding: matches!(self.activity, Activity::Holding),
            current: &state.current,
        };
        self.estimator.estimate(&self.p, &inputs)
    }

    /// Step 4a: the direction each joint moves in (the side its backlash is taken up on);
    /// a joint at rest keeps its last one.
    pub(super) fn note_directions(&mut self) {
        for (d, v) in self.direction.iter_mut().zip(&self.setpoint.qd) {
            if *v != 0.0 {
                *d = v.signum();
            }
        }
    }

    /// Step 4b: the motor target (rad) that puts the link at the setpoint under `tau` — and,
    /// when the model holds load effects outside the joints (a sagging tool, a bending link:
    /// [`Model::load_correction`](crate::model::Model::load_correction)), the links where
    /// they put the tool at the setpoint's rigid pose under the payload.
    pub(super) fn compensated_target(&self, tau: &[f64; 6]) -> Result<[f64; 6], Fault> {
        let q = self
            .model
            .load_correction(&self.setpoint.q, self.p.payload_n);
        self.model
            .compensate(&q, Torques::Given(tau), &self.direction)
            .map(|c| c.q_motor)
            .map_err(|_| Fault::Setpoint(MoveError::NonFinite("compensated target")))
    }

    /// Step 1a: the motor speeds from two consecutive resolver readings (rad/s), low-passed at
    /// [`MOTOR_SPEED_HZ`]; a gap of 0.1 s or more is not differentiated.
    fn note_motor_speed(&mut self, prev: &JointState, now: &JointState) {
        let dt = now.stamp_s - prev.stamp_s;
        if dt > 0.0 && dt < 0.1 {
            let a = 1.0 - (-std::f64::consts::TAU * MOTOR_SPEED_HZ * dt).exp();
            for j in 0..6 {
                let v = (now.q_motor[j] - prev.q_motor[j]) / dt;
                self.motor_speed[j] += a * (v - self.motor_speed[j]);
            }
        }
    }

    /// Step 5: the position loop on the motor side, `speed = q̇_setpoint + K·(target − q_motor)`
    /// clamped to the speed limits (rad/s); holding, an error within the joint's holding band
    /// (`hold_deadband`, widened by the hunting guard: `hold.rs`) counts as zero and
    /// `hold_damping` × the resolvers' motor speed is taken off, more on a slip's speed
    /// (`hold::hold_brake`: a drive breaking away from sticking is braked at once instead of
    /// slipping past the target). After the
    /// following-error and joint-limit checks (the link angle estimated as the measured motor
    /// angle less the compensation). Returns the speeds and those link angles (rad).
    pub(super) fn position_loop(
        &self,
        state: &JointState,
        target: &[f64; 6],
    ) -> Result<([f64; 6], [f64; 6]), Fault> {
        let lim = self.model.limits();
        let mut out = [0.0; 6];
        let mut link = [0.0; 6];
        let holding = matches!(self.activity, Activity::Holding);
        let gain = match self.p.gain_inertia_kgm2 {
            Some(_) => {
                let kg = self.p.payload_n / self.model.gravity().norm().max(f64::MIN_POSITIVE);
                let inertia = self
                    .model
                    .link_inertia(&self.setpoint.q, kg, &self.p.payload_com);
                self.p.loop_gain(inertia[1])
            }
            None => self.p.gain,
        };
        for j in 0..6 {
            let e = target[j] - state.q_motor[j];
            if e.abs() > self.p.following_error {
                return Err(Fault::FollowingError {
                    joint: j + 1,
                    error: e.abs(),
                    limit: self.p.following_error,
                });
            }
            link[j] = state.q_motor[j] - (target[j] - self.setpoint.q[j]);
            if link[j] < lim.lower[j] - 1e-3 || link[j] > lim.upper[j] + 1e-3 {
                return Err(Fault::JointLimit {
                    joint: j + 1,
                    value: link[j],
                });
            }
            let e = if holding && e.abs() <= self.hold.band(j) {
                0.0
            } else {
                e
            };
            let damping = if holding {
                hold_brake(self.p.hold_damping, self.motor_speed[j])
            } else {
                0.0
            };
            out[j] = (self.setpoint.qd[j] + gain * e - damping)
                .clamp(-self.p.limits.speed[j], self.p.limits.speed[j]);
        }
        Ok((out, link))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::daemon::vocab::{BLEND_HZ, TorqueSource};

    const PERIOD: f64 = 0.002;

    fn params() -> LoopParams {
        super::test_params()
    }

    fn state(q_motor: [f64; 6], current: [f64; 6], stamp_s: f64) -> JointState {
        JointState {
            q_motor,
            current,
            stamp_s,
            controller_fault: false,
        }
    }

    const Q0: [f64; 6] = [0.1, 0.4, 0.3, 0.0, 0.5, 0.0];

    fn controller() -> Controller {
        Controller::new(Model::nominal(), params(), &state(Q0, [0.0; 6], 0.0))
    }

    #[test]
    fn feedback_silence_faults_after_the_timeout_in_listened_cycles() {
        let mut c = controller();
        // 0.02 s at 2 ms: ten silent cycles are within the timeout, the eleventh is not
        for k in 1..=10 {
            assert!(matches!(
                c.take_feedback(k as f64 * PERIOD, None),
                Ok(Some(_))
            ));
        }
        let f = c.take_feedback(11.0 * PERIOD, None);
        assert!(
            matches!(
                f,
                Err(Fault::StaleFeedback {
                    missed_cycles: 11,
                    ..
                })
            ),
            "{f:?}"
        );
        // a feedback resets the count; a controller fault is a fault
        let mut bad = state(Q0, [0.0; 6], 0.03);
        assert!(matches!(c.take_feedback(0.03, Some(&bad)), Ok(Some(_))));
        bad.controller_fault = true;
        assert_eq!(c.take_feedback(0.032, Some(&bad)), Err(Fault::Controller));
    }

    #[test]
    fn a_faulted_loop_takes_feedback_but_commands_nothing() {
        let mut c = controller();
        c.halt(Fault::Controller);
        let s = state(Q0, [0.0; 6], 0.002);
        assert_eq!(c.take_feedback(0.002, Some(&s)), Ok(None));
        assert_eq!(c.step(0.004, Some(&s)), [0.0; 6]);
    }

    #[test]
    fn measured_torques_pass_a_first_order_low_pass() {
        let mut c = controller();
        let s = state(Q0, [1.0; 6], 0.0);
        let alpha = 1.0 - (-std::f64::consts::TAU * 20.0 * PERIOD).exp();
        let t1 = c.torque_estimate(&s);
        assert!((t1[0] - 10.0 * alpha).abs() < 1e-12, "{t1:?}");
        // after many cycles it settles at current × constant
        let mut t = t1;
        for _ in 0..2000 {
            t = c.torque_estimate(&s);
        }
        assert!((t[3] - 10.0).abs() < 1e-9, "{t:?}");
    }

    #[test]
    fn model_torques_are_the_statics_at_the_setpoint() {
        let mut p = params();
        p.torque_source = TorqueSource::Model;
        let mut c = Controller::new(Model::nominal(), p, &state(Q0, [5.0; 6], 0.0));
        let t = c.torque_estimate(&state(Q0, [5.0; 6], 0.0));
        let expect = Model::nominal().static_torques(&c.setpoint().q, &ExternalLoad::default());
        assert_eq!(t, expect);
        assert!(t[1].abs() > 1.0, "gravity on J2: {t:?}");
    }

    #[test]
    fn blended_torques_learn_the_measured_excess_at_rest_slowly_and_freeze_it_in_motion() {
        let mut p = params();
        p.torque_source = TorqueSource::Blended;
        let kt = p.torque_constants;
        let mut c = Controller::new(Model::nominal(), p, &state(Q0, [0.0; 6], 0.0));
        let model = Model::nominal().static_torques(&c.setpoint().q, &ExternalLoad::default());
        // currents that say 12 N·m more than the model on every joint (an undeclared load)
        let current: [f64; 6] = std::array::from_fn(|j| (model[j] + 12.0) / kt[j]);
        let s = state(Q0, current, 0.0);
        // the first cycle barely moves (no fast path from the currents to the command) ...
        let t1 = c.torque_estimate(&s);
        let alpha = 1.0 - (-std::f64::consts::TAU * BLEND_HZ * PERIOD).exp();
        assert!((t1[1] - model[1] - 12.0 * alpha).abs() < 1e-9, "{t1:?}");
        // ... one time constant (0.8 s at 0.2 Hz) learns 63 %, ten learn it all
        let tc = (1.0 / (std::f64::consts::TAU * BLEND_HZ) / PERIOD).round() as usize;
        let mut t = t1;
        for _ in 1..tc {
            t = c.torque_estimate(&s);
        }
        assert!(((t[1] - model[1]) / 12.0 - 0.632).abs() < 0.01, "{t:?}");
        for _ in 0..9 * tc {
            t = c.torque_estimate(&s);
        }
        assert!((t[1] - model[1] - 12.0).abs() < 1e-3, "{t:?}");
        // in motion the correction is frozen: friction torques in the currents never enter
        c.activity = Activity::Stopping { decel: [1.0; 6] };
        let rubbing: [f64; 6] = std::array::from_fn(|j| (model[j] + 40.0) / kt[j]);
        let frozen = c.torque_estimate(&state(Q0, rubbing, 0.0));
        assert!((frozen[1] - t[1]).abs() < 1e-9, "{frozen:?} vs {t:?}");
    }

    #[test]
    fn the_position_loop_clamps_to_the_speed_limits_and_checks_the_following_error() {
        let c = controller();
        let s = state(Q0, [0.0; 6], 0.0);
        let mut target = Q0;
        target[0] += 0.001; // gain 20: 0.02 rad/s
        target[1] += 0.009; // 0.18 rad/s
        let (speeds, link) = c.position_loop(&s, &target).expect("within limits");
        assert!((speeds[0] - 0.02).abs() < 1e-12 && (speeds[1] - 0.18).abs() < 1e-12);
        assert_eq!(speeds[2], 0.0);
        // the link is estimated as the motor angle less the compensation
        assert!((link[0] - (Q0[0] - 0.001)).abs() < 1e-12);
        target[1] = Q0[1] + 0.02;
        assert!(matches!(
            c.position_loop(&s, &target),
            Err(Fault::FollowingError { joint: 2, .. })
        ));
        let mut fast = params();
        fast.following_error = 1.0;
        let c = Controller::new(Model::nominal(), fast, &s);
        target[1] = Q0[1] + 0.5; // 10 rad/s asked
        let (speeds, _) = c.position_loop(&s, &target).expect("within limits");
        assert_eq!(speeds[1], 1.0, "clamped to the speed limit");
    }

    #[test]
    fn the_gain_falls_in_proportion_to_the_shoulder_inertia_above_its_limit() {
        let s = state(Q0, [0.0; 6], 0.0);
        let mut target = Q0;
        target[1] += 0.001;
        let m = Model::nominal();
        let kg90 = 90.0 / m.gravity().norm();
        let bare = m.link_inertia(&Q0, 0.0, &[0.0; 3])[1];
        let loaded = m.link_inertia(&Q0, kg90, &[0.0; 3])[1];
        assert!(loaded > 1.5 * bare, "{bare} vs {loaded} kg·m²");
        let speed_at = |payload_n: f64, limit: Option<f64>| {
            let mut p = params();
            p.payload_n = payload_n;
            p.gain_inertia_kgm2 = limit;
            let c = Controller::new(Model::nominal(), p, &s);
            c.position_loop(&s, &target).expect("within limits").0[1]
        };
        // gain 20 1/s, 1 mrad: 0.02 rad/s at or below the limit
        assert!((speed_at(0.0, Some(bare)) - 0.02).abs() < 1e-12);
        let expected = 0.02 * bare / loaded;
        assert!((speed_at(90.0, Some(bare)) - expected).abs() < 1e-12);
        assert!((speed_at(90.0, Some(loaded * 1.01)) - 0.02).abs() < 1e-12);
        assert!((speed_at(90.0, None) - 0.02).abs() < 1e-12);
    }

    #[test]
    fn holding_errors_within_the_deadband_get_no_correction_and_moving_ones_do() {
        let s = state(Q0, [0.0; 6], 0.0);
        let mut p = params();
        p.hold_deadband = 2e-5;
        let mut c = Controller::new(Model::nominal(), p, &s);
        let mut target = Q0;
        target[1] += 1.5e-5; // within the band
        target[2] += 3e-5; // outside: gain 20 → 6e-4 rad/s
        c.hold
            .update(PERIOD, true, 2e-5, &target, &s.q_motor, &[0.0; 6], |_| 0.0);
        let (speeds, _) = c.position_loop(&s, &target).expect("within limits");
        assert_eq!(speeds[1], 0.0);
        assert!((speeds[2] - 6e-4).abs() < 1e-12);
        // moving, the band does not apply
        let mut q = Q0;
        q[1] += 0.1;
        let mv = Move::joints(Q0, q, &c.params().limits).expect("a valid move");
        c.start_move(mv, 0.0).expect("accepted");
        let (speeds, _) = c.position_loop(&s, &target).expect("within limits");
        assert!((speeds[1] - 3e-4).abs() < 1e-12, "{}", speeds[1]);
    }

    #[test]
    fn holding_damping_brakes_the_motor_speed_the_resolvers_show() {
        let mut p = params();
        p.hold_damping = 2.0;
        let mut c = Controller::new(Model::nominal(), p, &state(Q0, [0.0; 6], 0.0));
        // J2 slipping at 0.05 rad/s for 0.2 s: the estimate follows within a few 1/(2π·50 Hz)
        let mut s = state(Q0, [0.0; 6], 0.0);
        for k in 1..=100 {
            s.q_motor[1] = Q0[1] + 0.05 * k as f64 * PERIOD;
            s.stamp_s = k as f64 * PERIOD;
            c.take_feedback(s.stamp_s, Some(&s))
                .expect("fresh feedback");
        }
        let (speeds, _) = c.position_loop(&s, &s.q_motor).expect("within limits");
        // 2 × 0.05, and SLIP_DAMPING on its excess over the slip speed
        let want = hold_brake(2.0, 0.05);
        assert!((want - 0.1 - 2.0 * 0.04).abs() < 1e-12);
        assert!((speeds[1] + want).abs() < 1e-3, "{}", speeds[1]);
        assert_eq!(speeds[0], 0.0);
        // moving, no damping term
        let mut q = Q0;
        q[0] += 0.1;
        let mv = Move::joints(Q0, q, &c.params().limits).expect("a valid move");
        c.start_move(mv, s.stamp_s).expect("accepted");
        let (speeds, _) = c.position_loop(&s, &s.q_motor).expect("within limits");
        assert_eq!(speeds[1], 0.0);
    }

    #[test]
    fn a_joint_outside_its_limits_is_a_fault() {
        let mut c = controller();
        let lim = Model::nominal().limits().upper[4];
        let mut q = Q0;
        q[4] = lim + 0.01;
        // the motor on its target, the link estimate (= the setpoint) beyond the limit
        c.setpoint.q = q;
        let s = state(q, [0.0; 6], 0.0);
        assert!(matches!(
            c.position_loop(&s, &q),
            Err(Fault::JointLimit { joint: 5, .. })
        ));
    }

    #[test]
    fn a_stop_decelerates_the_setpoint_to_rest() {
        let mut c = controller();
        c.setpoint.qd = [0.2, 0.0, 0.0, 0.0, 0.0, -0.1];
        c.activity = Activity::Streaming {
            stream: Stream::Jog([0.0; 6]),
            last_s: 0.0,
            target_v: [0.0; 6],
        };
        c.stop();
        let mut n = 0;
        while !matches!(c.activity, Activity::Holding) {
            c.advance_setpoint(n as f64 * PERIOD).expect("no fault");
            n += 1;
            assert!(n < 1000, "never came to rest");
        }
        // 0.2 rad/s at 2 rad/s²: 0.1 s, both joints together
        assert!((49..=51).contains(&n), "{n} cycles");
        assert_eq!(c.setpoint.qd, [0.0; 6]);
        assert!(
            (c.setpoint.q[0] - (Q0[0] + 0.01)).abs() < 1e-3,
            "{:?}",
            c.setpoint.q
        );
    }

    #[test]
    fn directions_follow_the_setpoint_speed_and_hold_at_rest() {
        let mut c = controller();
        c.setpoint.qd = [0.1, -0.1, 0.0, 0.0, 0.0, 0.0];
        c.note_directions();
        c.setpoint.qd = [0.0; 6];
        c.note_directions();
        assert_eq!(&c.direction[..3], &[1.0, -1.0, 0.0]);
        // the compensated target at rest and no torque is the setpoint plus what the
        // model's joint errors add (none on the nominal model)
        let t = c.compensated_target(&[0.0; 6]).expect("finite");
        assert!(
            t.iter().zip(&Q0).all(|(a, b)| (a - b).abs() < 1e-12),
            "{t:?}"
        );
    }

    #[test]
    fn a_model_loaded_while_holding_is_reached_by_a_glide_not_a_step() {
        use crate::model::Stiffness;
        // holding with model torques on the rigid nominal; the new model has a J2 spring
        let mut p = params();
        p.torque_source = TorqueSource::Model;
        let mut c = Controller::new(Model::nominal(), p, &state(Q0, [0.0; 6], 0.0));
        let mut s = state(Q0, [0.0; 6], 0.0);
        let mut k = 0;
        let mut cycle = |c: &mut Controller, s: &mut JointState| {
            k += 1;
            s.stamp_s = k as f64 * PERIOD;
            c.step(s.stamp_s, Some(s));
            c.output().target
        };
        let before = cycle(&mut c, &mut s);
        let mut d = Model::nominal().data().clone();
        d.stiffness[1] = Some(Stiffness {
            klin: 2.0e4,
            kcub: 0.0,
        });
        c.load_model(Model::new(d).expect("a valid model"))
            .expect("accepted while holding");
        let mut last = before;
        let mut biggest = 0.0f64;
        let n = (GLIDE_S / PERIOD).round() as usize + 2;
        for _ in 0..n {
            let t = cycle(&mut c, &mut s);
            biggest = biggest.max((t[1] - last[1]).abs());
            last = t;
        }
        let goal = c.compensated_target(&c.output().tau).expect("finite");
        let change = goal[1] - before[1];
        assert!(
            change.abs() > 1e-3,
            "the spring moves J2's target: {change}"
        );
        assert!((last[1] - goal[1]).abs() < 1e-12, "reached after the glide");
        // at most the cycloid's peak rate (twice the mean) each cycle: no step
        assert!(
            biggest <= 2.0 * change.abs() * PERIOD / GLIDE_S * 1.001,
            "{biggest}"
        );
    }

    /// A sticking drive's constants (MuJoCo's `stick` plant's, link-side units): its PI speed
    /// loop's gains (N·m·s/rad, N·m/rad), Coulomb and static friction (N·m), rotor (kg·m²) and
    /// viscous drag (N·m·s/rad).
    struct Drive {
        kp: f64,
        ki: f64,
        fc: f64,
        fs: f64,
        j: f64,
        b: f64,
    }

    /// MuJoCo's sticking J6 at friction ×1: its slip after breakaway (≈ 0.6·Fc / Ki ≈ 3 mrad)
    /// is far wider than twice a 0.1 mrad band.
    const J6: Drive = Drive {
        kp: 8.0,
        ki: 160.0,
        fc: 1.8,
        fs: 1.6 * 1.8,
        j: 0.02,
        b: 0.3,
    };

    /// MuJoCo's sticking J6 at friction ×2: braked beyond 1 × its speed on its slips, it still
    /// slips past a 0.1 mrad band both ways.
    const J6_X2: Drive = Drive {
        fc: 2.0 * J6.fc,
        fs: 2.0 * J6.fs,
        ..J6
    };

    /// MuJoCo's sticking J2 at friction ×2 (cold grease, a worn drive): Coulomb 54 N·m.
    const J2_X2: Drive = Drive {
        kp: 400.0,
        ki: 8000.0,
        fc: 54.0,
        fs: 1.6 * 54.0,
        j: 1.2,
        b: 8.0,
    };

    /// A [`Drive`] in motion or stuck: it sticks when its speed crosses zero with the speed
    /// loop's torque within the static level, and breaks away when the torque exceeds it.
    struct Sticky {
        d: Drive,
        q: f64,
        w: f64,
        integral: f64,
        stuck: bool,
    }

    impl Sticky {
        fn advance(&mut self, speed: f64, dt: f64) {
            let d = &self.d;
            let h = dt / 20.0;
            for _ in 0..20 {
                let err = speed - self.w;
                self.integral += err * h;
                let tau = d.kp * err + d.ki * self.integral;
                if self.stuck {
                    if tau.abs() <= d.fs {
                        continue;
                    }
                    self.stuck = false;
                }
                let dir = if self.w != 0.0 {
                    self.w.signum()
                } else {
                    tau.signum()
                };
                let w = self.w + h * (tau - d.fc * dir - d.b * self.w) / d.j;
                if w * self.w < 0.0 || (self.w == 0.0 && w * dir < 0.0) {
                    self.w = 0.0;
                    self.stuck = tau.abs() <= d.fs;
                } else {
                    self.w = w;
                }
                self.q += h * self.w;
            }
        }
    }

    /// What a [`Sticky`] drive did under the loop for 30 s from stuck off its target.
    struct StickyRun {
        /// How often the error crossed from one side of the 0.1 mrad band to the other.
        sides: usize,
        /// When the loop first said in position, s.
        in_position_s: Option<f64>,
        /// After that: the farthest the drive moved (rad) and the cycles out of position.
        moved: f64,
        lost: usize,
        /// |target − motor| where it was accepted, rad.
        accepted_rad: f64,
    }

    /// Runs drive `d` as the arm's joint `j` (0-based) under the loop (deadband 0.1 mrad,
    /// `hold_damping` `damping`), stuck `offset` rad past its target, the tool at `tool`
    /// (flange frame, m).
    fn sticky(j: usize, d: Drive, damping: f64, offset: f64, tool: [f64; 3]) -> StickyRun {
        let mut p = params();
        p.hold_deadband = 1e-4;
        p.hold_damping = damping;
        let model = Model::nominal()
            .with_tool(&crate::model::frame_from_pose(tool, [1.0, 0.0, 0.0, 0.0]))
            .expect("a tool");
        let mut c = Controller::new(model, p, &state(Q0, [0.0; 6], 0.0));
        let mut drive = Sticky {
            d,
            q: Q0[j] + offset,
            w: 0.0,
            integral: 0.0,
            stuck: true,
        };
        let (mut sides, mut last_side, mut in_position_at) = (0, 0.0, None);
        let (mut moved, mut lost) = (0.0f64, 0);
        // the first reading 0.1 s after the controller's: the resolvers' jump to the drive's
        // offset is not a speed (a gap of 0.1 s is not differentiated)
        for k in 1..=15_000 {
            let t = k as f64 * PERIOD;
            let mut q = Q0;
            q[j] = drive.q;
            let speeds = c.step(0.1 + t, Some(&state(q, [0.0; 6], 0.1 + t)));
            let e = c.output().target[j] - drive.q;
            if e.abs() > 1e-4 && e.signum() != last_side {
                sides += 1;
                last_side = e.signum();
            }
            match in_position_at {
                None if c.in_position() => in_position_at = Some((t, drive.q)),
                None => {}
                Some((_, q)) => {
                    moved = moved.max((drive.q - q).abs());
                    lost += usize::from(!c.in_position());
                }
            }
            drive.advance(speeds[j], PERIOD);
        }
        StickyRun {
            sides,
            in_position_s: in_position_at.map(|(t, _)| t),
            moved,
            lost,
            accepted_rad: in_position_at
                .map_or(f64::NAN, |(_, q)| (c.output().target[j] - q).abs()),
        }
    }

    #[test]
    fn a_sticking_drive_that_hunts_its_band_is_accepted_where_it_sticks_and_in_position() {
        // the tool point 20 mm off J6's axis: 0.3 mrad of J6 moves it 6 µm (not "on the axis");
        // at ×1 friction its slips are braked into the band, at ×2 they still cross it
        let r = sticky(5, J6_X2, 1.0, 3e-4, [0.02, 0.0, 0.1]);
        // it hunted (crossed its band at least once) and then stayed where it was accepted
        assert!(
            r.sides >= 2,
            "the drive never crossed its band: {}",
            r.sides
        );
        let t = r.in_position_s.expect("in position within 30 s");
        // a breakaway slips millradians; coming to rest, a few µrad
        assert!(
            r.moved < 2e-5 && r.lost == 0,
            "after {t} s: moved {} rad, out of position {} cycles",
            r.moved,
            r.lost
        );
        let e = r.accepted_rad;
        assert!(e > 1e-4 && e <= 1e-3, "accepted {e} rad from the target");
    }

    #[test]
    fn a_stuck_wrist_roll_about_the_tool_point_is_accepted_where_it_rests_without_hunting() {
        // the tool point on J6's axis: J6's error does not move it
        let r = sticky(5, J6, 1.0, 7.8e-4, [0.0, 0.0, 0.35]);
        let t = r.in_position_s.expect("in position");
        assert!(t < 0.1, "in position after {t} s");
        assert!(r.sides <= 1 && r.moved < 2e-5 && r.lost == 0, "{}", r.sides);
        assert!((r.accepted_rad - 7.8e-4).abs() < 2e-5, "{}", r.accepted_rad);
    }

    #[test]
    fn a_sticking_shoulder_at_twice_the_friction_is_braked_on_its_slips_and_rests_in_its_band() {
        // J2's breakaway at ×2 friction releases 32 N·m over Coulomb: unbraked beyond 1 × its
        // speed it slips ≈ 1 mrad, past a 0.1 mrad band both ways, and hunted for 20 s
        // (13–14 crossings, never in position) before slips were braked
        for offset in [3e-4, 7.8e-4, -5e-4] {
            let r = sticky(1, J2_X2, 1.0, offset, [0.0, 0.0, 0.1]);
            let t = r.in_position_s.expect("in position within 30 s");
            assert!(r.sides <= 6, "{offset}: crossed its band {} times", r.sides);
            // in its own band, not accepted by the hunting guard (J2 moves the tool point)
            assert!(
                r.accepted_rad <= 1e-4,
                "{offset}: {} rad off",
                r.accepted_rad
            );
            assert!(
                r.moved < 2e-5 && r.lost == 0,
                "{offset}: after {t} s moved {}",
                r.moved
            );
        }
    }
}
